"""What may be written: a calibration without the estimates it calls poorly determined.

An estimate whose standard error exceeds its unit's `poorly` bound (the robot's `sizes`; by
default 1 mm, 0.1°) is noise amplified along a direction the poses barely see: the
Scorbot's θ5 at the paper's schedule is 0.75° ± 18.6° where the truth is 0. The fit may
pass its audit with it (the measured points do not care), but a controller given that
value turns a joint by it.
Before a calibrated robot is written, such estimates are held at nominal and the rest
refitted; the refit's own audit (its "parameters not asked for do not matter" check sees
the held ones) says whether the data needed them.
"""

from __future__ import annotations

from .calibration import Calibration
from .fit import identify
from .rank import UNPRUNED_PREFIXES


def held_as_poorly_determined(cal: Calibration) -> tuple[str, ...]:
    """The estimates of `cal` that are poorly determined and may be held at nominal: not
    the frames (base, reflectors), whose nominal is no value at all, nor the frames each
    session has of its own (a fit of sessions always estimates them)."""
    own = {n for fit in cal.sessions.values() for n in fit.names}
    return tuple(
        n for n in cal.poorly_determined if not n.startswith(UNPRUNED_PREFIXES) and n not in own
    )


def hold_poorly_determined(cal: Calibration, measurements, **options) -> Calibration:
    """`cal`, or the same fit again with its poorly determined estimates held at nominal.

    Parameters
    ----------
    cal : Calibration
    measurements : Measurements
        The ones `cal` was fitted to.
    **options
        Passed to `casecal.identify` as for `cal` (noise, loss, truth, …).

    Returns
    -------
    Calibration
        `cal` itself when nothing is poorly determined; else the last refit (its
        `parameters` leave the held ones out). A refit that fails its audit is returned
        as it is: the data needed what was held.
    """
    asked = len(cal.parameters)
    held: list[str] = []
    # holding some can leave others poorly determined in turn: a pass for each at most
    while held_as_poorly_determined(cal) and cal.success and len(held) < asked:
        held += held_as_poorly_determined(cal)
        names = [n for n in cal.parameters if n not in held]
        cal = identify(cal.nominal, measurements, names, cal.method, **options)
    return cal
