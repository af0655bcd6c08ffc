"""KUKA KR 15/2 and Staubli RX 90B: parallel axes in standard DH, and what Hayati's beta fixes.

Writes its CSV tables and PNG figures into reports/ (or -o DIR). Run:
    python studies/six_axis.py [--quick] [-o reports]
"""

from casecal.report.script import main

if __name__ == "__main__":
    main("six_axis", __doc__)
