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


def study_runner(executor: str = "processes", workers=None, scheduler=None, progress: bool = True):
    """The `Executor` the studies run their trials on, with a progress bar on a terminal."""
    from ..studies.executor import Executor

    bar = None

    def tick(done, total):
        nonlocal bar
        if not (progress and sys.stderr.isatty()):
            return
        if bar is None or bar.total != total or done < bar.n:
            from tqdm import tqdm

            if bar is not None:
                bar.close()
            bar = tqdm(total=total, unit="task", leave=False)
        bar.update(done - bar.n)
        if done == total:
            bar.close()
            bar = None

    return Executor(executor, workers, scheduler, tick)


def run_studies(names, out: Path, quick: bool, run, log=None) -> list[StudyResult]:
    """Run the named studies into `out` (created); `log(message)` reports progress."""
    out.mkdir(parents=True, exist_ok=True)
    style()
    results = []
    for name in names:
        t0 = time.perf_counter()
        results.append(STUDIES[name](out, quick=quick, run=run))
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
