"""The paper's Table 1 re-made: one-shot and iterated beside the paper's numbers.

Writes its CSV tables and PNG figures into reports/ (or -o DIR). Run:
    python studies/seed_table1.py [--quick] [-o reports]
"""

from casecal.report.script import main

if __name__ == "__main__":
    main("table1", __doc__)
