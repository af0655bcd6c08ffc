"""Worker processes die with the report that started them (issue 20, findings 7 and 13).

Each test runs a real process pool the way the report does, in a child Python whose
`build_report` is replaced by one that maps long sleeps over `study_runner`'s executor, and
then signals that child as a supervisor (SIGKILL, SIGTERM to the parent only) or a terminal
(SIGINT to the whole process group) would.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time

import pytest

pytestmark = pytest.mark.skipif(sys.platform != "linux", reason="reads /proc")

CHILD = textwrap.dedent(
    """
    import sys, time
    import casecal.report as report
    from casecal import cli

    def build_report(out, executor, workers, scheduler, **kwargs):
        with report.study_runner(executor, workers, scheduler, progress=False) as run:
            run.map(abs, [-1, -2, -3, -4])  # every worker started
            print(" ".join(map(str, run._pool._processes)), flush=True)
            # one long task for two workers: one busy, one idle (the idle one printed
            # the KeyboardInterrupt tracebacks of finding 13)
            run.map(time.sleep, [600])

    report.build_report = build_report
    sys.exit(cli.main(["report", "-o", sys.argv[1], "--workers", "2"]))
    """
)


def _alive(pid: int) -> bool:
    """Whether `pid` runs (a zombie waiting for its reaper counts as gone)."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            state = f.read().rsplit(")", 1)[1].split()[0]
    except (FileNotFoundError, ProcessLookupError):
        return False
    return state not in ("Z", "X")


def _wait_gone(pids, seconds=10.0) -> list[int]:
    """The pids still running after up to `seconds`."""
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        left = [p for p in pids if _alive(p)]
        if not left:
            return []
        time.sleep(0.1)
    return [p for p in pids if _alive(p)]


def _start(tmp_path):
    """The child running a pool of two workers on long tasks, and the workers' pids."""
    proc = subprocess.Popen(
        [sys.executable, "-c", CHILD, str(tmp_path / "out")],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,  # its own process group, as a shell gives a job
    )
    line = proc.stdout.readline()
    if not line.strip():
        proc.kill()
        pytest.fail(f"the child printed no worker pids: {proc.communicate()[1]}")
    pids = [int(p) for p in line.split()]
    assert len(pids) == 2
    time.sleep(0.5)  # the long task reached a worker
    return proc, pids


def _finish(proc, pids) -> str:
    """Reap the child, kill (by pid) any worker a failing test left behind, and return the
    child's stderr (read last: a surviving worker holds the pipe open)."""
    try:
        proc.wait(timeout=30)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()
    for pid in pids:
        if _alive(pid):
            os.kill(pid, signal.SIGKILL)
    err = proc.stderr.read()
    proc.stdout.close()
    proc.stderr.close()
    return err


def test_sigkill_of_the_parent_takes_the_workers_down(tmp_path):
    proc, pids = _start(tmp_path)
    os.kill(proc.pid, signal.SIGKILL)  # the parent only, as a supervisor does
    left = _wait_gone(pids)
    _finish(proc, pids)
    assert not left, f"workers {left} outlived their killed parent"


def test_sigterm_of_the_parent_exits_cleanly_and_takes_the_workers_down(tmp_path):
    proc, pids = _start(tmp_path)
    os.kill(proc.pid, signal.SIGTERM)
    left = _wait_gone(pids)
    err = _finish(proc, pids)
    assert not left, f"workers {left} outlived their terminated parent"
    assert proc.returncode in (130, 143), (proc.returncode, err)
    assert "Traceback" not in err
    assert not (tmp_path / "out").exists() or not any((tmp_path / "out").iterdir())


def test_ctrl_c_of_a_report_prints_one_line_and_no_worker_traceback(tmp_path):
    proc, pids = _start(tmp_path)
    os.killpg(proc.pid, signal.SIGINT)  # a terminal signals the whole job
    left = _wait_gone(pids)
    err = _finish(proc, pids)
    assert "Traceback" not in err and "KeyboardInterrupt" not in err, err
    assert proc.returncode == 130, (proc.returncode, err)
    assert err.strip().splitlines() == ["casecal: interrupted; nothing was written"], err
    assert not left, f"workers {left} outlived the interrupted report"
