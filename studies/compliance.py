"""A heavy arm bending under gravity: rigid against compliant models, masses known and unknown.

Writes its CSV tables and PNG figures into reports/ (or -o DIR). Run:
    python studies/compliance.py [--quick] [-o reports]
"""

from casecal.report.script import main

if __name__ == "__main__":
    main("compliance", __doc__)
