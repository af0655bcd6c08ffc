"""What the SCARA cannot see from positions, and why.

Writes its CSV tables and PNG figures into reports/ (or -o DIR). Run:
    python studies/scara_observability.py [--quick] [-o reports]
"""

from casecal.report.script import main

if __name__ == "__main__":
    main("scara", __doc__)
