"""The report: runs the studies and writes every figure (PNG), table (CSV) and one PDF.

`build_report` is what ``casecal report`` runs; each study also runs alone from the scripts
in ``studies/``. This package is a leaf: the core never imports it.
"""

from __future__ import annotations

import platform
import sys
import time
from collections.abc import Callable
from pathlib import Path

from ..errors import CalibrationError
from .common import StudyResult, style
from .folder import building_folder, discard, publish
from .pose_count import pose_count_sweep
from .studies_beyond import enough_poses, optimal_poses, relative_measurements
from .studies_compliance import compliance_study
from .studies_elastic import elastic_study
from .studies_paper import planar_arms, scara_observability, table1
from .studies_sweeps import noise_sweep, six_axis

STUDIES: dict[str, Callable] = {
    "table1": table1,
    "planar_arms": planar_arms,
    "scara": scara_observability,
    "pose_count": pose_count_sweep,
    "noise": noise_sweep,
    "six_axis": six_axis,
    "optimal_poses": optimal_poses,
    "calibrate_until": enough_poses,
    "relative": relative_measurements,
    "compliance": compliance_study,
    "elastic": elastic_study,
}
NAMES = {
    "table1": "the paper's Table 1",
    "planar_arms": "planar arms",
    "scara": "SCARA observability",
    "pose_count": "pose count",
    "noise": "noise",
    "six_axis": "six-axis arms with Hayati's beta",
    "optimal_poses": "optimal poses",
    "calibrate_until": "calibrate until a target",
    "relative": "relative measurements",
    "compliance": "compliance under gravity",
    "elastic": "an elastic humanoid tree",
}
"""Each study in words, as ``casecal report --help`` and the title page name them."""
PDF_TABLES = {"table1", "scara_blind_spots", "six_axis_observability"}
OUTPUTS = frozenset(
    {
        "casecal-report.pdf",
        "calibrate_until.png",
        "calibrate_until_runs.csv",
        "compliance.png",
        "compliance_trials.csv",
        "elastic.png",
        "elastic_trials.csv",
        "noise_sweep.png",
        "noise_trials.csv",
        "optimal_poses.png",
        "optimal_poses_trials.csv",
        "planar_arms.csv",
        "planar_arms.png",
        "pose_count_error.png",
        "pose_count_observability.png",
        "pose_count_trials.csv",
        "relative_measurements.png",
        "relative_trials.csv",
        "residual_histograms.png",
        "scara_blind_spots.csv",
        "scara_singular_values.png",
        "singular_spectra.png",
        "six_axis_beta.png",
        "six_axis_observability.csv",
        "six_axis_trials.csv",
        "table1.csv",
        "table1_bars.png",
    }
)
"""The names the studies write, refused up front where a file of the user's holds one
(`casecal.report.folder.publish` checks, at the end, what they did write)."""


class Progress:
    """Reports the studies' progress on stderr: `casecal.studies.executor.Executor`'s
    ``progress(done, total)``, told by `run_studies` which study runs.

    On a terminal, a tqdm bar labelled with the study (``study 4/11 pose count``); otherwise
    (a log file, a pipe, CI) plain lines, no carriage returns: the study started, roughly
    every 10 % of its tasks once it has run `quiet` seconds, and finished with its time.
    """

    def __init__(self, stream=None, tty: bool | None = None, quiet: float = 5.0):
        self._stream, self._tty, self.quiet = stream, tty, quiet
        self.label, self.bar, self.t0 = "", None, time.perf_counter()
        self._total, self._next, self._done = 0, 0, 0

    @property
    def stream(self):
        return self._stream if self._stream is not None else sys.stderr

    @property
    def tty(self) -> bool:
        if self._tty is not None:
            return self._tty
        isatty = getattr(self.stream, "isatty", None)
        return bool(isatty and isatty())

    def _line(self, text: str) -> None:
        print(f"{self.label}: {text}", file=self.stream, flush=True)

    def start(self, k: int, n: int, name: str) -> None:
        """Study `k` of `n` (from 1) begins."""
        self._close_bar()
        self.label = f"study {k}/{n} {NAMES.get(name, name)}"
        self.t0, self._total, self._next, self._done = time.perf_counter(), 0, 0, 0
        if not self.tty:
            self._line("started")

    def finish(self) -> None:
        self._close_bar()
        if not self.tty:
            self._line(f"finished in {time.perf_counter() - self.t0:.1f} s")

    def __call__(self, done: int, total: int) -> None:
        if self.tty:
            self._bar(done, total)
            return
        step = max(1, -(-total // 10))  # every ~10 %
        if total != self._total or done <= self._done:
            self._total, self._next = total, step  # a new map over other tasks
        self._done = done
        if done >= self._next or done == total:
            self._next = (done // step + 1) * step
            elapsed = time.perf_counter() - self.t0
            if elapsed >= self.quiet:
                self._line(f"{done}/{total} tasks ({100 * done // total} %), {elapsed:.0f} s")

    def _bar(self, done: int, total: int) -> None:
        bar = self.bar
        if bar is None or bar.total != total or done < bar.n:
            from tqdm import tqdm

            self._close_bar()
            bar = self.bar = tqdm(
                total=total, unit="task", leave=False, desc=self.label, file=self.stream
            )
        bar.update(done - bar.n)
        if done == total:
            self._close_bar()

    def _close_bar(self) -> None:
        if self.bar is not None:
            self.bar.close()
            self.bar = None


def study_runner(executor: str = "processes", workers=None, scheduler=None, progress: bool = True):
    """The `Executor` the studies run their trials on, reporting through a `Progress`
    (a labelled bar on a terminal, plain lines elsewhere) unless `progress` is false."""
    from ..studies.executor import Executor

    return Executor(executor, workers, scheduler, Progress() if progress else None)


def run_studies(names, out: Path, quick: bool, run, log=None) -> list[StudyResult]:
    """Run the named studies into `out` (created); `log(message)` reports progress.

    When `run`'s progress is a `Progress`, it is told which study (k of n) runs.
    """
    out.mkdir(parents=True, exist_ok=True)
    style()
    progress = getattr(run, "progress", None)
    progress = progress if isinstance(progress, Progress) else None
    results = []
    for k, name in enumerate(names, 1):
        t0 = time.perf_counter()
        if progress:
            progress.start(k, len(names), name)
        results.append(STUDIES[name](out, quick=quick, run=run))
        if progress:
            progress.finish()
        if log:
            log(f"{name}: {time.perf_counter() - t0:.1f} s")
    return results


def build_report(
    out="reports",
    quick: bool = False,
    executor: str = "processes",
    workers=None,
    scheduler=None,
    progress: bool = True,
    log=None,
) -> Path:
    """Run every study and write ``casecal-report.pdf`` with all figures and tables in `out`.

    Parameters
    ----------
    out : str or path
        Output folder (created).
    quick : bool
        Smaller grids (fewer poses, noise levels and trials): about a minute on 2 cores.
    executor, workers, scheduler
        See `casecal.study.run_study` (``"dask"`` with a scheduler address for a cluster).
    progress : bool
        Progress bars on a terminal.
    log : callable(str), optional
        Receives one line per finished study.

    Returns
    -------
    Path of the PDF.
    """
    out = Path(out)
    folder = building_folder(out, OUTPUTS)  # swapped in whole at the end (report.folder)
    try:
        n = _build(folder, quick, executor, workers, scheduler, progress, log)
        publish(folder, out)
    except OSError as exc:  # a full disk: say where, and that nothing changed
        discard(folder)
        raise CalibrationError(
            f"cannot write the report beside {str(out)!r}: {exc.strerror or exc}; "
            f"{'the report there is unchanged' if out.exists() else 'nothing was written'} "
            "(free some space, or give another folder with -o)"
        ) from None
    except BaseException:  # a failure, Ctrl-C: no half-built folder is left
        discard(folder)
        raise
    pdf = out / "casecal-report.pdf"
    if log:
        log(f"{n} figures; report written to {pdf}")
    return pdf


def _build(folder: Path, quick, executor, workers, scheduler, progress, log) -> int:
    """Run the studies and write the PDF into `folder`; the number of figures."""
    import casadi
    import numpy
    import pandas
    import scipy

    from .. import __version__
    from .pdf import write_pdf

    t0 = time.perf_counter()
    with study_runner(executor, workers, scheduler, progress) as run:
        run.check_reachable()
        results = run_studies(list(STUDIES), folder, quick, run, log)
    elapsed = time.perf_counter() - t0
    settings = [
        f"casecal {__version__}; Python {platform.python_version()}; CasADi {casadi.__version__}; "
        f"NumPy {numpy.__version__}; SciPy {scipy.__version__}; pandas {pandas.__version__}",
        f"Machine: {platform.machine()}, {platform.system()}; executor: {executor}"
        + (f" ({scheduler})" if isinstance(scheduler, str) else ""),
        f"Grid: {'quick' if quick else 'full'}; studies: {'; '.join(NAMES[n] for n in STUDIES)}; "
        f"computed in {elapsed:.0f} s",
        "",
        "Starting point: N. W. Simpson and M. J. D. Hayes, 'Kinematic Calibration of Industrial "
        "Manipulators'. Each robot is a CasADi graph of its DH chain with exact parameter "
        "Jacobians; deviations are identified by the paper's one-shot SVD and by iterated "
        "Gauss-Newton. Units: mm and degrees in tables and figures, SI inside.",
        "",
        "Conventions of every study unless its caption says otherwise:",
        "  deviations:  random sign, magnitude 0.5-1.5 x (0.1 mm, 0.01 deg), on the",
        "               parameters 200 uniform poses can identify individually",
        "  noise:       Gaussian, independent per coordinate, sigma given per figure",
        "  held-out:    200 uniform poses per robot, true against calibrated model",
        "  seeds:       every trial's seed descends from the study seed (in the CSVs)",
        "",
        "Files beside this PDF: every figure as PNG and every table, including one row per",
        "Monte Carlo trial, as CSV.",
    ]
    n = write_pdf(folder / "casecal-report.pdf", "casecal report", settings, results, PDF_TABLES)
    return n
