"""KR 15/2: relative (distance) measurements against absolute positions, by count.

Writes its CSV tables and PNG figures into reports/ (or -o DIR). Run:
    python studies/relative_measurements.py [--quick] [-o reports]
"""

from casecal.report.script import main

if __name__ == "__main__":
    main("relative", __doc__)
