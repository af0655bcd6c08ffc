"""An elastic humanoid tree: rigid against joint and joint + lateral compliance.

Writes its CSV table and PNG figure into reports/ (or -o DIR); the same robot calibrated
from a CSV as a user would, against a stand-in simulated without casecal, is
studies/humanoid_upper_body.py. Run:
    python studies/elastic_humanoid.py [--quick] [-o reports]
"""

from casecal.report.script import main

if __name__ == "__main__":
    main("elastic", __doc__)
