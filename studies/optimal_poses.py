"""Which poses to measure: D-optimal poses against uniform ones, by pose count.

Writes its CSV tables and PNG figures into reports/ (or -o DIR). Run:
    python studies/optimal_poses.py [--quick] [-o reports]
"""

from casecal.report.script import main

if __name__ == "__main__":
    main("optimal_poses", __doc__)
