"""Parameter sweeps with Monte Carlo trials: `Grid`, `run_study`, `run_trial`.

A study crosses robots × pose schedules × pose counts × noise levels × methods × trials and
returns one tidy DataFrame, one row per trial. Everything random descends from the one
study seed through the trial's own key, so a row can be re-run alone (`run_trial`) and a
study is reproducible bit for bit, whatever executor ran it:

- the *truth* (synthetic deviations) of trial t for a robot: seed (study, robot, t);
- the *poses* of a schedule and count: seed (study, robot, schedule, n) (fixed across
  noise levels, methods and trials, so their Jacobian at nominal is shared);
- the *noise* of a trial: seed (study, robot, schedule, n, noise, t), the same for every
  method (common random numbers make method comparisons sharper).

Trials are run in groups of one robot, schedule and pose count; the nominal Jacobian and
its identifiability analysis are computed once per group and noise level (see
`casecal.identification.fit`). Groups go to local processes (default) or a dask cluster.
"""

from __future__ import annotations

import logging
import time
import zlib
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass

import numpy as np
import pandas as pd

from ..data.measurements import Measurements
from ..design import poses
from ..errors import CalibrationError
from ..identification.analysis import observability
from ..identification.fit import METHODS, identify
from ..model.catalog import load_robot
from ..model.parameters import is_length, select
from .executor import Executor

log = logging.getLogger(__name__)

SCHEDULES = ("seed", "uniform")


@dataclass(frozen=True)
class Grid:
    """The inputs of a study.

    Attributes
    ----------
    robots : tuple of str
        Catalog names or robot files.
    poses : tuple of int
        Pose counts N.
    noise : tuple of float
        Measurement noise σ per coordinate, m.
    methods : tuple of str
        Identification methods (see `casecal.identify`).
    schedules : tuple of str
        ``"seed"`` (the paper's) and/or ``"uniform"``.
    trials : int
        Monte Carlo repetitions per cell.
    parameters : tuple of str
        What is identified (default: the paper's θ, a, d).
    truth_parameters : tuple of str or None
        Which parameters get synthetic deviations; default: those of `parameters` that 200
        uniform poses can identify individually (a deviation on a blind parameter is only
        absorbed to first order by its group, and would blur every error in the table).
    length_scale, angle_scale : float
        Deviations are drawn with magnitude uniform in [0.5, 1.5] × scale and a random
        sign: m and rad (default 0.1 mm and 0.01°).
    holdout : int
        Uniform poses on which the calibrated robot is compared with the true one.
    seed : int
        The study seed.
    """

    robots: tuple[str, ...] = ("scorbot",)
    poses: tuple[int, ...] = (25, 100)
    noise: tuple[float, ...] = (0.0,)
    methods: tuple[str, ...] = ("svd",)
    schedules: tuple[str, ...] = ("seed",)
    trials: int = 1
    parameters: tuple[str, ...] = ("theta*", "a*", "d*")
    truth_parameters: tuple[str, ...] | None = None
    length_scale: float = 0.1e-3
    angle_scale: float = np.deg2rad(0.01)
    holdout: int = 200
    seed: int = 0

    def __post_init__(self) -> None:
        for name in ("robots", "poses", "noise", "methods", "schedules", "parameters"):
            value = getattr(self, name)
            object.__setattr__(
                self, name, (value,) if isinstance(value, str | int | float) else tuple(value)
            )
        bad = [m for m in self.methods if m not in METHODS]
        if bad:
            raise CalibrationError(f"unknown method {bad[0]!r}; use {', '.join(METHODS)}")
        bad = [s for s in self.schedules if s not in SCHEDULES]
        if bad:
            raise CalibrationError(f"unknown schedule {bad[0]!r}; use {', '.join(SCHEDULES)}")
        if any(n < 1 for n in self.poses) or self.trials < 1:
            raise CalibrationError("pose counts and trials must be positive integers")
        if any(not np.isfinite(s) or s < 0 for s in self.noise):
            raise CalibrationError("noise levels must be finite and non-negative (m)")

    @property
    def size(self) -> int:
        """Number of trials (rows) in the study."""
        return (
            len(self.robots)
            * len(self.schedules)
            * len(self.poses)
            * len(self.noise)
            * len(self.methods)
            * self.trials
        )


@dataclass(frozen=True)
class Trial:
    """One row of a study: a cell of the grid and a repetition index."""

    robot: str
    schedule: str
    n_poses: int
    noise: float
    method: str
    trial: int


def derive_seed(study_seed: int, *key) -> int:
    """A 64-bit seed from the study seed and a key, stable across runs and machines."""
    entropy = [int(study_seed) & 0xFFFFFFFF, zlib.crc32("|".join(map(str, key)).encode())]
    return int(np.random.SeedSequence(entropy).generate_state(2, np.uint64)[0])


def trials(grid: Grid) -> list[Trial]:
    """Every trial of `grid`, in a fixed order."""
    return [
        Trial(robot, schedule, n, sigma, method, t)
        for robot in grid.robots
        for schedule in grid.schedules
        for n in grid.poses
        for sigma in grid.noise
        for method in grid.methods
        for t in range(grid.trials)
    ]


def truth_for(grid: Grid, robot, trial: int) -> dict[str, float]:
    """Synthetic deviations (SI) of `trial` for `robot` (module doc)."""
    if grid.truth_parameters is None:
        holdout_q = poses.uniform(
            robot, 200, seed=derive_seed(grid.seed, robot.name, "identifiable")
        )
        names = observability(robot, holdout_q, list(grid.parameters)).identifiable
    else:
        names = select(robot.parameter_names, list(grid.truth_parameters))
    rng = np.random.default_rng(derive_seed(grid.seed, robot.name, "truth", trial))
    magnitude = rng.uniform(0.5, 1.5, len(names)) * rng.choice([-1.0, 1.0], len(names))
    return {
        n: float(m * (grid.length_scale if is_length(n) else grid.angle_scale))
        for n, m in zip(names, magnitude, strict=True)
    }


def pose_set(grid: Grid, robot, schedule: str, n: int) -> np.ndarray:
    """The poses of a schedule and count (the same for every trial)."""
    if schedule == "seed":
        return poses.seed_schedule(robot, n)
    return poses.uniform(robot, n, seed=derive_seed(grid.seed, robot.name, "poses", n))


def run_trial(grid: Grid, trial: Trial) -> dict:
    """Run one trial alone; gives the same row as inside `run_study`."""
    return run_group(grid, [trial])[0]


def run_group(grid: Grid, group: Sequence[Trial]) -> list[dict]:
    """Run trials that share robot, schedule and pose count (shared work done once)."""
    first = group[0]
    robot = load_robot(first.robot)
    q = pose_set(grid, robot, first.schedule, first.n_poses)
    q_holdout = poses.uniform(
        robot, grid.holdout, seed=derive_seed(grid.seed, robot.name, "holdout")
    )
    rows = []
    truths: dict[int, tuple[dict, object, np.ndarray, np.ndarray]] = {}
    for trial in group:
        if trial.trial not in truths:
            truth = truth_for(grid, robot, trial.trial)
            true = robot.with_deviations(truth)
            truths[trial.trial] = (truth, true, true.position(q), true.position(q_holdout))
        truth, true, exact, holdout_true = truths[trial.trial]
        noise_seed = derive_seed(
            grid.seed, robot.name, trial.schedule, trial.n_poses, repr(trial.noise), trial.trial
        )
        noise = np.random.default_rng(noise_seed).normal(size=exact.shape) * trial.noise
        meas = Measurements(q=q, positions=exact + noise, sigma=trial.noise)
        row = {**asdict(trial), "noise_mm": trial.noise * 1e3, "seed": noise_seed}
        del row["noise"]
        t0 = time.perf_counter()
        try:
            cal = identify(robot, meas, list(grid.parameters), trial.method, truth=truth)
        except CalibrationError as exc:
            row.update(success=False, message=str(exc), wall_time_s=time.perf_counter() - t0)
            rows.append(row)
            continue
        row["wall_time_s"] = time.perf_counter() - t0
        errors = cal.errors()
        holdout_err = cal.robot.position(q_holdout) - holdout_true
        before_err = robot.position(q_holdout) - holdout_true
        row.update(
            success=cal.success,
            message=cal.message,
            iterations=cal.iterations,
            n_estimated=len(cal.estimated),
            n_unidentifiable=len(cal.unidentifiable),
            rank=cal.observability.rank,
            O1=cal.observability.indices["O1"],
            O3=cal.observability.indices["O3"],
            rms_fit_mm=cal.rms * 1e3,
            rms_holdout_mm=float(np.sqrt(np.mean(np.sum(holdout_err**2, axis=1)))) * 1e3,
            rms_holdout_before_mm=float(np.sqrt(np.mean(np.sum(before_err**2, axis=1)))) * 1e3,
            max_abs_rel_error=max((abs(e) for e in errors.values()), default=float("nan")),
        )
        for name in cal.parameters:
            row[f"true_{name}"] = truth.get(name, 0.0)
            row[f"dev_{name}"] = cal.deviations[name]
            row[f"se_{name}"] = cal.standard_errors[name]
            row[f"err_{name}"] = errors.get(name, float("nan"))
        rows.append(row)
    return rows


def _groups(grid: Grid) -> list[list[Trial]]:
    groups: dict[tuple, list[Trial]] = {}
    for t in trials(grid):
        groups.setdefault((t.robot, t.schedule, t.n_poses), []).append(t)
    return list(groups.values())


def run_study(
    grid: Grid,
    executor: str | Executor = "processes",
    workers: int | None = None,
    scheduler: str | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> pd.DataFrame:
    """Run every trial of `grid` and return one row per trial.

    Parameters
    ----------
    grid : Grid
    executor : {"processes", "serial", "dask"} or Executor
        Where the trials run (`casecal.studies.executor.Executor`); an Executor carries
        its own workers, scheduler and progress.
    workers : int, optional
    scheduler : str or dask Client, optional
        For ``"dask"``: a scheduler address (``"tcp://host:8786"``) or a Client; None
        starts a LocalCluster.
    progress : callable(done, total), optional
        Called after each batch of trials finishes (the core itself never prints).

    Returns
    -------
    pandas.DataFrame
        Columns: robot, schedule, n_poses, noise_mm, method, trial, seed, success, message,
        iterations, wall_time_s, n_estimated, n_unidentifiable, rank, O1, O3, rms_fit_mm,
        rms_holdout_mm, rms_holdout_before_mm, max_abs_rel_error, and per parameter
        true_*, dev_*, se_* (SI) and err_* (relative error). Rows in `trials` order.
    """
    own = not isinstance(executor, Executor)
    if own:
        executor = Executor(executor, workers, scheduler, progress)
    # trials of one robot, schedule and pose count share their poses; batches of them, about
    # four per worker in all, keep every worker busy however few groups the grid has
    size = max(1, -(-grid.size // (4 * executor.n_workers)))
    batches = [
        (grid, group[i : i + size]) for group in _groups(grid) for i in range(0, len(group), size)
    ]
    try:
        results = executor.map(_run_batch, batches, cost=lambda b: b[1][0].n_poses * len(b[1]))
    finally:
        if own:  # workers of an executor made here stop here; a caller's live on
            executor.close()
    return pd.DataFrame([row for batch in results for row in batch])


def _run_batch(task) -> list[dict]:
    grid, batch = task
    return run_group(grid, batch)


def summarise(df: pd.DataFrame, by: Sequence[str], value: str) -> pd.DataFrame:
    """Median and 10th/90th percentiles of `value` per group (for Monte Carlo bands)."""
    g = df.groupby(list(by))[value]
    out = pd.DataFrame(
        {
            "median": g.median(),
            "p10": g.quantile(0.1),
            "p90": g.quantile(0.9),
            "count": g.count(),
        }
    )
    return out.reset_index()


__all__ = [
    "Grid",
    "Trial",
    "derive_seed",
    "run_group",
    "run_study",
    "run_trial",
    "summarise",
    "trials",
]
