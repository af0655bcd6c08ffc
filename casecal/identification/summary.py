"""Text summary of a Calibration, in the manner of statsmodels' ``summary()``.

No timestamp and no mutation: the same result gives the same text.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from ..model.parameters import poorly_text, sizes_text
from .calibration import Calibration, Summary

if TYPE_CHECKING:
    import pandas as pd

WIDTH = 96
CONDITION_WARNING = 1e3


def _fmt(value, digits: int = 5) -> str:
    if isinstance(value, str):
        return value
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "-"
    return f"{value:.{digits}f}"


def format_table(df: pd.DataFrame) -> str:
    """Fixed-width text of a parameter table (numbers to 5 decimals, mm and degrees)."""
    cols = [c for c in df.columns if c != "status"]
    cells = [[str(c) for c in cols] + ["note"]]
    for _, row in df.iterrows():
        cells.append(
            [
                row[c] if c in ("parameter", "unit") else _fmt(row[c], 4 if c == "error_pct" else 5)
                for c in cols
            ]
            + [_short_status(row.get("status", ""))]
        )
    cols = [*cols, "note"]
    widths = [max(len(r[i]) for r in cells) for i in range(len(cols))]
    lines = []
    for k, r in enumerate(cells):
        line = "  ".join(
            c.ljust(w) if i < 2 or i == len(r) - 1 else c.rjust(w)
            for i, (c, w) in enumerate(zip(r, widths, strict=True))
        )
        lines.append(line.rstrip())
        if k == 0:
            lines.append("-" * len(line))
    return "\n".join(lines)


def _short_status(status: str) -> str:
    if status.startswith("held"):
        if "not determined" in status:
            return "held: not determined"
        return "held at fitted value" if "fitted to while" in status else "held at nominal"
    if status == "poorly determined":
        return "POORLY DETERMINED"
    if status.startswith("stands for"):
        return "= " + status.removeprefix("stands for ")
    return "" if status == "identified" else status


def build_summary(cal: Calibration) -> Summary:
    """Header, audit, table, diagnostics and numbered notes of `cal`."""
    obs = cal.observability
    left = [
        ("Robot:", f"{cal.nominal.name} ({cal.nominal.joint_types}, {cal.nominal.convention})"),
        ("Method:", cal.method),
        ("Status:", f"{cal.status} ({'success' if cal.success else 'FAILED'})"),
        ("Distances:", f"{cal.n_poses} (between pairs of poses)")
        if cal.measured == "distances"
        else ("Poses:", f"{cal.n_poses} ({cal.dof_residual + len(cal.estimated)} coordinates)"),
        ("Parameters:", f"{len(cal.parameters)} asked, {len(cal.estimated)} estimated"),
        ("Iterations:", f"{cal.iterations} in {cal.rounds} round{'s' * (cal.rounds != 1)}"),
    ]
    right = [
        ("RMS before:", f"{cal.rms_before * 1e3:.6f} mm"),
        ("RMS after:", f"{cal.rms * 1e3:.6f} mm"),
        ("Max before:", f"{cal.max_error_before * 1e3:.6f} mm"),
        ("Max after:", f"{cal.max_error * 1e3:.6f} mm"),
        ("Residual dof:", str(cal.dof_residual)),
        ("Std errors from:", "stated sigma" if cal.sigma_known else "residual scale"),
    ]
    title = "casecal calibration results".center(WIDTH)
    rule = "=" * WIDTH
    body = [f"{a:<13}{b:<35}{c:<18}{d}" for (a, b), (c, d) in zip(left, right, strict=True)]
    header = [rule, title, rule, *body, f"Message: {cal.message}"]
    if cal.audit is not None:
        header += ["Answer audit:", *(f"  {line}" for line in cal.audit.lines())]
    s = obs.singular_values
    diag = [
        f"Observability of the {len(obs.parameters)} asked-for parameters (column-scaled "
        f"Jacobian where the fit ended): rank {obs.rank} of {len(obs.parameters)}",
        "  indices of the structural base set: "
        + ", ".join(f"{k} = {v:.4g}" for k, v in obs.indices.items()),
        f"  singular values: largest {s[0]:.4g}, smallest non-zero "
        f"{s[obs.rank - 1] if obs.rank else 0:.4g}"
        if s.size
        else "  no parameters",
    ]
    return Summary(
        header="\n".join(header),
        table=cal.table,
        diagnostics="\n".join(diag),
        notes=tuple(_notes(cal)),
        sessions=_sessions(cal),
    )


def _sessions(cal: Calibration) -> str:
    """The sessions' fitted frames (mm, deg, ± one standard error), or "" for one."""
    if not cal.sessions:
        return ""
    from .sessions import table_text

    first = next(iter(cal.sessions))
    return (
        f"Frames of the {len(cal.sessions)} measurement sessions (the robot's base in each "
        f"session's instrument frame, ± one standard error; session {first}'s is the calibrated "
        f"robot's):\n{table_text(cal.sessions)}"
    )


FEW = 0.02
"""At most this fraction of the poses (and at least one) standing out can be gross values
in some rows; more is the fit's or the model's trouble, not the file's."""


def outliers_lead(outliers, n_poses: int) -> bool:
    """Whether a failed fit's message should lead with the poses that stand out: only a
    few of them (`FEW`); many are a model error or a stuck fit showing, not gross rows."""
    return 0 < len(outliers) <= max(1, FEW * n_poses)


def stand_out(outliers, loss: str = "linear", measured: str = "points") -> str:
    """Which poses stand out (file rows: the header is row 1; a camera's views by their
    0-based index) and what to do about them.

    A failed fit leads with this (`casecal.identification.fit.verdict`): a gross value in
    one row is the likelier cause than anything the audit then finds.
    """
    one = len(outliers) == 1
    more = " …" if len(outliers) > 12 else ""
    if measured == "pixels":  # arrays, not a file; no robust loss for cameras yet
        views = ", ".join(str(i) for i in outliers[:12]) + more
        which = "view stands out (view" if one else "views stand out (views"
        it = "it" if one else "them"
        return f"{len(outliers)} {which} {views}, 0-based): check {it}, or leave {it} out"
    rows = ", ".join(str(i + 2) for i in outliers[:12]) + more
    what = (
        f"{len(outliers)} {'pose stands' if one else 'poses stand'} out "
        f"(file {'row' if one else 'rows'} {rows}): check {'it' if one else 'them'}"
    )
    return what + (", or fit with a robust loss (--loss huber)" if loss == "linear" else "")


def _notes(cal: Calibration) -> list[str]:
    notes = []
    if not cal.success:
        reasons = (
            "; ".join(f"{c.name}: {c.text}" for c in cal.audit.failures)
            if cal.audit is not None and cal.audit.failures
            else cal.message
        )
        cause = f"{stand_out(cal.outliers, cal.loss, cal.measured)}; " if cal.outliers_lead else ""
        notes.append(f"The fit FAILED: {cause}{reasons}. Do not use these values.")
    if cal.start_note:
        notes.append(cal.start_note)
    if cal.nominal.coupling is not None:
        coupled = "; ".join(cal.nominal.coupling.describe(cal.nominal.joint_types))
        notes.append(
            f"Joint values are the controller's {cal.nominal.dof}, coupled to the model's "
            f"{cal.nominal.model_dof} ({coupled}); the fit ran in the model's joints and "
            "the coupling is no parameter of it."
        )
    if cal.nominal.sizes:
        notes.append(
            f"Sizes of a real deviation of {cal.nominal.name} (its own, not the industrial "
            f"defaults): {sizes_text(cal.nominal.sizes)}. A parameter whose standard error "
            "exceeds its plausible deviation while it moves the measured points by less "
            "than the noise is held."
        )
    if cal.joined:
        one = len(cal.joined) == 1
        notes.append(
            f"{_names(cal.joined)} moved nothing measured where the fit started but "
            f"{'does' if one else 'do'} where it ended (a tool point off the axes it started "
            f"on, for instance); a later round estimated {'it' if one else 'them'}."
        )
    notes += _held_notes(cal)
    if cal.loss != "linear":
        notes.append(f"Robust fit: {cal.loss} loss, by iteratively reweighted least squares.")
    if cal.outliers and not cal.outliers_lead:  # else the failure's note names them
        notes.append(f"{stand_out(cal.outliers, cal.loss, cal.measured)}.")
    poor = cal.poorly_determined
    if poor:
        shown = ", ".join(f"{n} ± {_se_text(n, cal.standard_errors[n])}" for n in poor[:6]) + (
            " …" if len(poor) > 6 else ""
        )
        bound = _poorly_bounds(cal, poor)
        notes.append(
            f"{len(poor)} estimates are poorly determined (standard error above {bound}): "
            f"{shown}. The poses barely constrain them and noise is amplified along them; "
            "do not use them without more or better-spread poses."
        )
    cond = cal.observability.indices.get("O2", np.inf)
    if np.isfinite(cond) and cond > CONDITION_WARNING:
        notes.append(
            f"The condition number of the structural base set is {cond:.3g}: some "
            "combinations are barely observable from these poses, and noise is amplified "
            "along them. More or better-spread poses help."
        )
    if not cal.sigma_known:
        notes.append(
            "No measurement sigma was given: standard errors use the residual scale "
            f"({_residual_scale(cal) * 1e3:.3g} mm per "
            f"{'distance' if cal.measured == 'distances' else 'coordinate'})."
        )
    return notes


def _held_notes(cal: Calibration) -> list[str]:
    """What was held and why, and what the estimates then stand for; counts match lists."""
    notes = []
    blind = [n for n in cal.held if n not in cal.pruned and n not in cal.frozen]
    if blind:
        inert = [n for n in blind if cal.held_reason(n).startswith("it moves nothing")]
        carried = [n for n in blind if n not in inert]
        text = (
            f"{len(blind)} of the asked-for parameters are blind at these poses and held at "
            f"nominal: {_names(blind)}."
        )
        if inert:
            verb = "moves" if len(inert) == 1 else "move"
            text += f" {len(inert)} of them {verb} nothing measured: {_names(inert)}."
        if carried:
            text += (
                f" The effects of the other {len(carried)} are carried by the estimates "
                "below, which stand for combinations."
            )
        notes.append(text)
    combos = [n for n in cal.estimated if cal.stands_for(n) != n]
    if combos:
        notes.append(
            f"{len(combos)} estimates stand for combinations (their row gives the value and "
            "interval of the combination, not of the parameter alone): "
            + "; ".join(f"{n} = {cal.stands_for(n)}" for n in combos)
            + "."
        )
    if cal.frozen:
        notes.append(
            f"{len(cal.frozen)} parameters were estimated in an earlier round but are blind "
            "where the fit ended; they are held at the values they were fitted to while "
            f"visible (any value fits as well): {_names(cal.frozen)}."
        )
    if cal.pruned:
        notes.append(
            f"{len(cal.pruned)} parameters are held at nominal because these data do not "
            "determine them: " + "; ".join(f"{n}: {why}" for n, why in cal.pruned.items()) + "."
        )
    return notes


def _names(names) -> str:
    return ", ".join(names)


def _poorly_bounds(cal: Calibration, names) -> str:
    """The poorly determined bounds of the units of `names` in words ("1 mm or 0.1°"; a
    lens's "5 px or 0.05" too)."""
    facts = {}
    for n in names:
        f = cal.nominal.unit_facts(n)
        facts.setdefault(f.shown, f)
    if set(facts) <= {"mm", "deg"}:
        return poorly_text(cal.nominal.sizes)
    shown = [f"{f.poorly * f.factor:g} {f.shown}".rstrip() for f in facts.values()]
    return " or ".join(shown)


def _se_text(name: str, se: float) -> str:
    from .calibration import display_unit

    u, f = display_unit(name)
    return f"{se * f:.3g} {u}".rstrip()


def _residual_scale(cal: Calibration) -> float:
    dof = max(cal.dof_residual, 1)
    return float(np.sqrt(np.sum(cal.residuals**2) / dof))
