"""A 10-million-row measurement file under a memory limit (issue 20, finding 12).

Reading it raised a MemoryError traceback: the parser held every value as a Python string,
about 10 times the file. Now the file, not the parser, bounds the memory: with an address
space of 3 times the file (beyond what the interpreter holds already) it is read, and
with less the answer is one line saying how many rows would fit.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys

import pytest

from casecal.cli import main

pytestmark = [
    pytest.mark.slow,
    pytest.mark.skipif(sys.platform != "linux", reason="RLIMIT_AS and /proc are Linux's"),
]

ROWS = 10_000_000

READ = """
import resource, sys
import casecal as cc
from casecal.errors import CalibrationError
big, small, factor = sys.argv[1], sys.argv[2], float(sys.argv[3])
robot = cc.load_robot("puma560")
tile = cc.read_csv(small, robot)  # imports, kernels: what any run holds before reading
status = open("/proc/self/status").read()
held = int(status.split("VmSize:")[1].split()[0]) * 1024
limit = int(held + factor * int(sys.argv[4]))
resource.setrlimit(resource.RLIMIT_AS, (limit, limit))
try:
    meas = cc.read_csv(big, robot)
except CalibrationError as exc:
    print(f"casecal: error: {exc}", file=sys.stderr)
    sys.exit(2)
# every value as the small file's: the big one is its first 100 rows again and again
same = all(
    (getattr(meas, a).reshape(-1, 100, *getattr(meas, a).shape[1:]) == getattr(tile, a)[:100]).all()
    for a in ("q", "positions")
)
print(meas.n_poses, same)
"""


@pytest.fixture(scope="module")
def big(tmp_path_factory):
    folder = tmp_path_factory.mktemp("big")
    free = shutil.disk_usage(folder).free
    if free < 4e9:
        pytest.skip(f"{free / 1e9:.1f} GB free in {folder}; a 10-million-row file needs 2 GB")
    small = folder / "small.csv"
    argv = ["simulate", "puma560", "--poses", "100", "--schedule", "uniform", "--noise", "0.01mm"]
    assert main([*argv, "-o", str(small)]) == 0
    head, body = small.read_text().split("\n", 1)
    path = folder / "big.csv"
    with open(path, "w") as fh:  # the same 100 poses again and again: written in seconds
        fh.write(head + "\n")
        block = body * 1000
        for _ in range(ROWS // 100_000):
            fh.write(block)
    small.write_text(head + "\n" + body * 5)  # 500 rows: enough to build the kernels
    yield path, small
    path.unlink()


def read_under_limit(big, factor):
    path, small = big
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1"}
    size = path.stat().st_size
    argv = [sys.executable, "-c", READ, str(path), str(small), str(factor), str(size)]
    return subprocess.run(argv, capture_output=True, text=True, env=env)


def test_ten_million_rows_are_read_in_three_times_the_file(big):
    done = read_under_limit(big, 3.0)
    assert "Traceback" not in done.stderr, done.stderr
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == [str(ROWS), "True"]


def test_too_little_memory_is_one_line_saying_what_fits(big):
    done = read_under_limit(big, 0.5)
    assert done.returncode == 2, done.stderr
    assert done.stderr.count("\n") == 1 and "Traceback" not in done.stderr, done.stderr
    assert "not enough memory to read the file" in done.stderr
    assert "rows would fit" in done.stderr and "MB" in done.stderr, done.stderr
