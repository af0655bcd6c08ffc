"""R, RR, RRR: the paper's claims for 10 poses, and the one-shot error against deviation size.

Writes its CSV tables and PNG figures into reports/ (or -o DIR). Run:
    python studies/planar_arms.py [--quick] [-o reports]
"""

from casecal.report.script import main

if __name__ == "__main__":
    main("planar_arms", __doc__)
