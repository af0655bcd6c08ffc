"""The noise-aware rank: which structurally identifiable parameters the data determine.

A parameter the poses can see in principle may still be known only to metres (the paper's
lockstep schedule), or only to degrees through a lever of a few tenths of a millimetre (a
wrist angle seen through a tool point near the wrist centre). Estimating it then adds
noise, not information, and can blur the estimates beside it. `prune` decides, at the
point where a round of the fit ended, what to hold.

What a parameter's uncertainty does to predictions is its *spread*: the RMS displacement of
the measured points, over poses across the workspace, that its uncertainty adds given all
the others, i.e. the drop in the predicted variance ``mean |J_work C J_workᵀ|`` when it is
held (exact for a Gaussian: ``|J_work C e_j|² / C_jj``). Marginal standard errors would
overstate it for correlated parameters: coaxial joints know their sum well and only their
difference poorly. A parameter (other than the frames, `UNPRUNED_PREFIXES`) with a standard
error above `NEGLIGIBLE_SE` is held when

- its spread exceeds the whole error a calibration corrects (`WIDE`): such an estimate
  could only make the robot worse where it was not measured (*too wide*); or
- its standard error exceeds the plausible deviation of its unit (the robot's `sizes`;
  by default `UNITS`: 2.5 mm, 0.5°)
  while its spread is below half the noise and its estimate is within `SIGNIFICANT`
  standard errors of its start: it changes nothing a measurement could see (*useless*).
  The bias holding it leaves is at most its spread, so a few such parameters together stay
  within the noise; an estimate that stands out of its standard error is seen by the data,
  however loosely, and is kept, unless it has wandered beyond `ALIAS` plausible deviations
  (an alias, not a deviation).

Parameters already estimated are judged first, among themselves; then each newcomer (a
parameter that became visible where the round ended) is admitted only if nothing becomes
undetermined with it: a later round adds what the data see and never spoils what is
estimated (d4 seen through a 0.2 mm tool offset must not make a3 undeterminable).
Parameters are held one at a time, the latest first, and the others' covariance is
conditioned exactly, so correlated pairs lose one member, not both.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..model.parameters import facts_of
from .linalg import Reduction, column_scales, nr_threshold

NEGLIGIBLE_SE = 1e-9
"""Standard errors (m or rad) below this are rounding: never a reason to hold a parameter."""

SIGNIFICANT = 3.3
"""An estimate this many standard errors from its start is seen by the data: the 99.9 %
level (a t-statistic; the audit's χ² tests use the same level), shared among the
candidates (Bonferroni: 4.2 for 43), so that of several loosely seen newcomers none is
kept by chance."""

ALIAS = 20
"""An estimate beyond this many plausible deviations (`UNITS`, or the robot's `sizes`) whose
standard error is already
implausible is an alias (a wrist angle turned half a turn, its tool offset flipped),
not a deviation."""

UNPRUNED_PREFIXES = ("base_", "point")
"""Parameters without a meaningful nominal value (where the instrument stands, where a
reflector sits): estimated whenever visible, never held for being close to the start."""

WIDE = "more than the whole error a calibration corrects"
"""The error compared is the uncalibrated robot's where positions are measured, and a
plausible robot's error where contacts (points, planes) hide it (`casecal.identification.
contact.plausible_error`): calling the latter "uncalibrated" overstated what was gained."""

HELD_LEVEL = 1 - 1e-6
"""Quantile of χ² for the gain of freeing held parameters: stricter than the audit's 99.9 %,
since the linearised gain of parameters seen through levers of tenths of a millimetre has
a heavier tail than χ² (0.2 % of fits pass 99.9 % by chance where 0.1 % should); a
parameter the data do see gains tens to hundreds of noise variances."""


def chi2_quantile(level: float, dof: int) -> float:
    """The `level` quantile of χ² with `dof` degrees of freedom."""
    from scipy.special import chdtri  # imported here: scipy adds a second to startup

    return float(chdtri(dof, 1.0 - level))


def held_gain(linear: Reduction, names, estimated, held, at_size: bool = False) -> float:
    """Cost decrease (one linearised step) that freeing `held` would add to what the
    `estimated` parameters can still gain; `linear`: the weighted ``[J | r]`` of all
    `names` at the point. `at_size`: contact data only, the robot's size left out
    (`Reduction.decrease_at_size`)."""
    est = [names.index(n) for n in estimated]
    both = [names.index(n) for n in names if n in estimated or n in held]
    if at_size:
        return linear.columns(both).decrease_at_size() - linear.columns(est).decrease_at_size()
    return linear.columns(both).solve()[1] - linear.columns(est).solve()[1]


def held_matter(gain: float, n_held: int, cost: float, dof: int, known: bool):
    """Whether freeing `n_held` held parameters, which would lower the cost by `gain`, is
    beyond chance.

    With a stated σ (costs in noise variances) the gain is a χ² statistic. Without one, it
    is compared with what would remain once they are freed (an F test): measuring it
    against the present residual variance would be circular, since that variance holds
    the very effect being tested.

    Returns
    -------
    matter : bool
    statistic, bound : float
        The χ² (or F) statistic and its `HELD_LEVEL` quantile.
    """
    if n_held == 0 or gain <= 0:
        return False, 0.0, np.inf
    if known:
        return (
            2.0 * gain > chi2_quantile(HELD_LEVEL, n_held),
            2.0 * gain,
            chi2_quantile(HELD_LEVEL, n_held),
        )
    rest_dof = dof - n_held
    if rest_dof <= 0 or cost - gain <= 0:
        return False, 0.0, np.inf
    from scipy.special import fdtri  # the F quantile

    statistic = (gain / n_held) / ((cost - gain) / rest_dof)
    bound = float(fdtri(n_held, rest_dof, HELD_LEVEL))
    return statistic > bound, statistic, bound


@dataclass(frozen=True)
class Reduced:
    """The linearised least squares of the candidates, reduced to its small R factor.

    ``[J | r] = Q [R | Qᵀr]``: every sub-problem on a subset of the columns is solved from
    R and ``Qᵀr`` alone, so the tall Jacobian is factorised once per round.
    """

    R: np.ndarray
    Qtr: np.ndarray
    rss_out: float  # |r|² − |Qᵀr|²: what no candidate can explain
    rows: int
    known: bool

    @classmethod
    def of(cls, linear: Reduction, known: bool) -> Reduced:
        return cls(linear.R, linear.Qtr, linear.rss_out, linear.rows, known)

    def fit(self, subset: list[int]) -> tuple[np.ndarray, np.ndarray]:
        """Step and covariance of the parameters `subset` alone (the others at the point)."""
        Rs = self.R[:, subset]
        norms, _ = column_scales(Rs)
        U, s, Vt = np.linalg.svd(Rs / norms, full_matrices=False)
        keep = s > nr_threshold(s, (self.rows, len(subset)))
        proj = U[:, keep].T @ self.Qtr
        step = (Vt[keep].T @ (proj / s[keep])) / norms
        C = ((Vt[keep].T / s[keep] ** 2) @ Vt[keep]) / np.outer(norms, norms)
        if not self.known:
            dof = self.rows - len(subset)
            rss = self.rss_out + float(self.Qtr @ self.Qtr - proj @ proj)
            C = C * (rss / dof if dof > 0 else np.nan)
        return step, C


def prune(
    linear,
    names,
    candidates,
    offsets,
    known,
    e0,
    J_work,
    noise,
    established,
    protected=(),
    sizes=(),
):
    """Which of the structurally identifiable `candidates` to hold (module doc).

    Parameters
    ----------
    linear : Reduction
        Of the weighted Jacobian (all `names`) and residual at the current point.
    names, candidates : sequence of str
        `candidates` in seniority (what was estimated, then newcomers in pivot order).
    offsets : ndarray, shape (len(candidates),)
        The candidates' current deviations from their start values, SI.
    known : bool
        Whether the weights are 1/σ.
    e0 : float
        Uncalibrated RMS error, m.
    J_work : ndarray, shape (3 n, len(names))
        Unweighted Jacobian of n measured points at workspace poses, m per unit.
    noise : float or None
        RMS noise of a measured point, m; None when no σ is stated: then it is taken from
        what the candidates would leave after one more step.
    established : set of str
        Candidates estimated in the round that just ended; the others are newcomers.
    protected : set of str
        Candidates never held as useless: held once, they turned out to matter.
    sizes : tuple of (str, float, float)
        The robot's own plausible deviations (`casecal.Robot.sizes`); () for `UNITS`'.

    Returns
    -------
    keep : list of str
    dropped : dict of str to str
        Each held candidate with the reason, in words and units.
    """
    if not candidates:
        return [], {}
    idx = [names.index(n) for n in candidates]
    reduced = Reduced.of(linear.columns(idx), known)
    if noise is None:  # per-coordinate RMS of what all candidates leave, times √3
        step, _ = reduced.fit(list(range(len(idx))))
        rest = reduced.rss_out + float(np.sum((reduced.Qtr - reduced.R @ step) ** 2))
        noise = float(np.sqrt(3 * rest / reduced.rows))
    judge = _Judge(reduced, candidates, offsets, e0, J_work[:, idx], noise, established, sizes)
    judge.untried |= np.array([n in protected for n in candidates])
    keep, dropped = judge.hold([k for k, n in enumerate(candidates) if n in established])
    for k, name in enumerate(candidates):
        if name in established:
            continue
        trial, held = judge.hold([*keep, k])
        if not held or (name not in held and judge.significant(trial, k)):
            # nothing spoiled; or the data clearly see the newcomer, and what it makes
            # undetermined is held by the usual rules instead
            keep = trial
            dropped.update(held)
        else:  # the newcomer, or what it would spoil for no gain the data show: leave it out
            dropped[name] = held.get(name) or (
                "its effect is seen only through parameters already estimated, which it "
                f"would leave undetermined ({', '.join(held)})"
            )
    return [candidates[k] for k in sorted(keep)], dropped


class _Judge:
    """Applies the two rules of the module doc to subsets of the candidates."""

    def __init__(self, reduced, candidates, offsets, e0, W, noise, established, sizes=()):
        self.reduced, self.candidates, self.offsets = reduced, candidates, offsets
        self.e0, self.W, self.noise = e0, W, noise
        self.n_points = W.shape[0] / 3
        self.free = np.array([not n.startswith(UNPRUNED_PREFIXES) for n in candidates])
        self.sizes = sizes
        self.plausible = np.array([facts_of(n, sizes).plausible for n in candidates])
        # the 99.9 % level shared among the candidates (Bonferroni): of 18 loosely seen
        # harmonics, one 3.3 standard errors out happens by chance in one fit of 20
        from scipy.special import ndtri

        self.level = max(SIGNIFICANT, float(-ndtri(0.0005 / max(len(candidates), 1))))
        # without σ, residuals still hold what an unfitted newcomer may explain
        self.untried = np.array([not reduced.known and n not in established for n in candidates])

    def significant(self, subset: list[int], k: int) -> bool:
        """Whether candidate `k`'s estimate, fitted with `subset`, stands out of its error."""
        step, C = self.reduced.fit(subset)
        i = subset.index(k)
        se = np.sqrt(max(C[i, i], 0.0))
        est = self.offsets[k] + step[i]
        return bool(abs(est) >= self.level * se and abs(est) <= ALIAS * self.plausible[k])

    def hold(self, subset: list[int]) -> tuple[list[int], dict]:
        """`subset` minus what must be held, and why (by candidate name)."""
        if not subset:
            return [], {}
        step, C = self.reduced.fit(subset)
        est = self.offsets[subset] + step  # linearised estimates, from the start values
        active = list(range(len(subset)))
        dropped = {}
        while active:
            a = np.array(active)
            Ca = C[np.ix_(a, a)]
            var = np.clip(np.diag(Ca), 0.0, None)
            se = np.sqrt(var)
            cols = [subset[i] for i in a]
            explained = np.sum((self.W[:, cols] @ Ca) ** 2, axis=0)
            spread = np.sqrt(explained / np.where(var > 0, var, np.inf) / self.n_points)
            too_wide = spread > self.e0
            faint = np.abs(est[a]) < self.level * se
            faint |= np.abs(est[a]) > ALIAS * self.plausible[cols]  # an alias
            useless = (
                (se > self.plausible[cols])
                & (spread <= 0.5 * self.noise)
                & faint
                & ~self.untried[cols]
            )
            bad = self.free[cols] & (se > NEGLIGIBLE_SE) & (too_wide | useless)
            if not bad.any():
                break
            pos = int(np.flatnonzero(bad)[-1])  # the latest goes first
            j = int(a[pos])
            name = self.candidates[subset[j]]
            dropped[name] = _reason(
                name, se[pos], spread[pos], self.e0, bool(too_wide[pos]), self.sizes
            )
            c = C[:, j].copy()
            est = est - c / C[j, j] * est[j]  # the others, given this one at its start
            C = C - np.outer(c, c) / C[j, j]
            active.remove(j)
        return [subset[i] for i in active], dropped


def _reason(name: str, se: float, spread: float, e0: float, too_wide: bool, sizes=()) -> str:
    facts = facts_of(name, sizes)
    scale, u = facts.factor, "°" if facts.shown == "deg" else facts.shown
    text = f"its standard error would be {se * scale:.3g} {u}"
    if too_wide:
        return (
            text + f", moving the tool by {spread * 1e3:.3g} mm RMS on poses across the "
            f"workspace, {WIDE} ({e0 * 1e3:.3g} mm)"
        )
    limit = facts.plausible * scale
    return (
        text + f", more than any real deviation ({limit:g} {u}), while it moves the tool by "
        f"only {spread * 1e3:.3g} mm RMS, below the noise"
    )
