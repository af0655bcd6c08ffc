"""Error against the number of poses: per robot, paper's schedule against uniform poses,
one-shot against iterated.

Writes its CSV tables and PNG figures into reports/ (or -o DIR). Run:
    python studies/pose_count_sweep.py [--quick] [-o reports]
"""

from casecal.report.script import main

if __name__ == "__main__":
    main("pose_count", __doc__)
