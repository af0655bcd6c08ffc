"""How many poses are enough: calibrate until the predicted error is under 0.1 mm.

Writes its CSV tables and PNG figures into reports/ (or -o DIR). Run:
    python studies/calibrate_until.py [--quick] [-o reports]
"""

from casecal.report.script import main

if __name__ == "__main__":
    main("calibrate_until", __doc__)
