"""Interleaved timing: run the contenders A B A B …, so a shared machine's idle and busy
moments fall on both alike, and report CPU time beside wall time.

A contender is a callable, timed in this process (wall: `time.perf_counter`, CPU:
`time.process_time`, every thread of the process), or a `Command`, run in a fresh
subprocess each time (wall around it; CPU from the ``RUSAGE_CHILDREN`` difference, i.e.
the child's user + system time including its imports; peak RSS as the child reports it
with `report`: its own ``VmHWM``, see `peak_rss_mib`). The table gives the median and the
minimum of each, and their ratios to a reference contender; the load averages before and
after and the core count are printed with it, since a time means little without them.
"""

from __future__ import annotations

import json
import os
import resource
import subprocess
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

MARK = "@@timing "


@dataclass
class Sample:
    """One run: wall and CPU seconds, peak RSS in MiB (subprocesses only), and what the
    callable returned or the child reported."""

    wall: float
    cpu: float
    rss: float = float("nan")
    result: object = None


@dataclass
class Command:
    """A contender run as a fresh subprocess: ``argv`` with ``env`` added to this process's.

    The child should end with `report` (its peak RSS and anything else, as one JSON line);
    that dict becomes the sample's `result`.
    """

    argv: list[str]
    env: dict = field(default_factory=dict)

    def __call__(self) -> Sample:
        env = {**os.environ, **self.env}
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        t0 = time.perf_counter()
        proc = subprocess.run(self.argv, env=env, capture_output=True, text=True)
        wall = time.perf_counter() - t0
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        if proc.returncode != 0:
            raise RuntimeError(
                f"{' '.join(self.argv)} failed ({proc.returncode}):\n{proc.stderr[-3000:]}"
            )
        cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
        lines = [ln for ln in proc.stdout.splitlines() if ln.startswith(MARK)]
        if not lines:
            raise RuntimeError(f"{' '.join(self.argv)} reported nothing:\n{proc.stdout[-3000:]}")
        info = json.loads(lines[-1][len(MARK) :])
        return Sample(wall, cpu, float(info.get("rss_mib", float("nan"))), info)


def report(**info) -> None:
    """In a child: print its peak RSS (MiB) and `info` as the line `Command` reads."""
    print(MARK + json.dumps({"rss_mib": peak_rss_mib(), **info}), flush=True)


def peak_rss_mib() -> float:
    """This process's peak RSS so far, MiB: ``VmHWM`` of /proc/self/status on Linux.

    Not ``getrusage(RUSAGE_SELF).ru_maxrss``: Linux carries the parent's peak into a
    child's across fork and exec (a child of a 400 MiB parent reports 400 MiB however
    little it uses), so a benchmark that starts its children from a process holding
    casecal and the data would charge both contenders that floor. Elsewhere ru_maxrss.
    """
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) / 1024  # kB
    except OSError:
        pass
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return rss / 1024 if sys.platform != "darwin" else rss / 2**20


def cores() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        return os.cpu_count() or 1


def load() -> str:
    return " ".join(f"{v:.2f}" for v in os.getloadavg())


@dataclass
class Timings:
    """Samples per contender, in the order given, and the machine's load around them."""

    samples: dict[str, list[Sample]]
    load_before: str
    load_after: str
    repeat: int

    def stat(self, name: str, what: str, how: Callable = np.median) -> float:
        return float(how([getattr(s, what) for s in self.samples[name]]))

    def table(self, reference: str, title: str = "", memory: bool | None = None) -> str:
        """Median and minimum wall and CPU of each contender, ratios to `reference`."""
        if memory is None:
            memory = any(np.isfinite(s.rss) for v in self.samples.values() for s in v)
        width = max(12, *(len(n) for n in self.samples))
        head = (
            f"{'':<{width}} | {'CPU s med':>9} {'min':>8} | {'wall s med':>10} {'min':>8} | "
            f"{'CPU ratio med':>13} {'min':>5} | {'wall ratio med':>14} {'min':>5}"
        )
        if memory:
            head += f" | {'peak MiB':>8} {'ratio':>5}"
        lines = []
        if title:
            lines.append(title)
        lines.append(
            f"  {self.repeat} interleaved runs each; {cores()} cores; "
            f"load average before {self.load_before}, after {self.load_after}"
        )
        lines.append(head)
        ref = {
            (w, h): self.stat(reference, w, f)
            for w in ("cpu", "wall", "rss")
            for h, f in (("med", np.median), ("min", np.min))
        }
        for name in self.samples:
            s = {
                (w, h): self.stat(name, w, f)
                for w in ("cpu", "wall", "rss")
                for h, f in (("med", np.median), ("min", np.min))
            }
            row = (
                f"{name:<{width}} | {s['cpu', 'med']:9.4f} {s['cpu', 'min']:8.4f} | "
                f"{s['wall', 'med']:10.4f} {s['wall', 'min']:8.4f} | "
                f"{s['cpu', 'med'] / ref['cpu', 'med']:12.2f}x "
                f"{s['cpu', 'min'] / ref['cpu', 'min']:4.2f}x | "
                f"{s['wall', 'med'] / ref['wall', 'med']:13.2f}x "
                f"{s['wall', 'min'] / ref['wall', 'min']:4.2f}x"
            )
            if memory:
                row += f" | {s['rss', 'med']:8.0f} "
                row += f"{s['rss', 'med'] / ref['rss', 'med']:4.2f}x"
            lines.append(row)
        lines.append(f"  ratios are to {reference!r}: median / median and min / min")
        return "\n".join(lines)


def interleave(contenders: dict[str, Callable], repeat: int, warmup: int = 0) -> Timings:
    """Run every contender once per round, in the given order, for `repeat` rounds.

    `warmup` rounds first, untimed. A callable's return value is kept in its sample's
    `result` (a `Command` returns its own `Sample`).
    """
    for _ in range(warmup):
        for fn in contenders.values():
            fn()
    samples: dict[str, list[Sample]] = {name: [] for name in contenders}
    before = load()
    for _ in range(repeat):
        for name, fn in contenders.items():
            if isinstance(fn, Command):
                samples[name].append(fn())
                continue
            t0, c0 = time.perf_counter(), time.process_time()
            out = fn()
            wall, cpu = time.perf_counter() - t0, time.process_time() - c0
            samples[name].append(Sample(wall, cpu, result=out))
    return Timings(samples, before, load(), repeat)
