"""Error against measurement noise, with the predicted standard error beside the Monte Carlo spread.

Writes its CSV tables and PNG figures into reports/ (or -o DIR). Run:
    python studies/noise_sweep.py [--quick] [-o reports]
"""

from casecal.report.script import main

if __name__ == "__main__":
    main("noise", __doc__)
