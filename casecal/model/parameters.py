"""Names, units and selection of the geometric parameters of a serial arm.

The full parameter vector of a robot is, in this order:

- per joint ``i`` (1-based, base to tip): ``theta{i}``, ``d{i}``, ``a{i}``, ``alpha{i}``, and
  ``beta{i}`` for the links that carry Hayati's extra rotation (see `casecal.model.kinematics`);
- the base frame: ``base_x``, ``base_y``, ``base_z`` (m), ``base_rx``, ``base_ry``,
  ``base_rz`` (rad);
- the tool frame: ``tool_x`` … ``tool_rz``, likewise.

A robot measured in several sessions (`casecal.model.robot.Session`: the instrument, or
the probe, re-mounted between them) has, after all of these and the error terms'
parameters, one more frame per session beyond the first, named after the session's label:
``base_x@B`` … ``base_rz@B`` (and ``tool_x@B`` … where each session has its own tool). The
first session's frames are the plain ``base_*`` and ``tool_*``.

A robot read from a URDF has, instead of the DH rows, per movable joint the six numbers of
its origin in the file's own frames, named after the joint: ``{joint}.x``, ``.y``, ``.z``
(m), ``.roll``, ``.pitch``, ``.yaw`` (rad), and for a revolute joint a zero offset of the
joint angle, ``{joint}.offset`` (rad). (A prismatic joint has none: a constant along its
axis is a shift of the origin, which x, y, z carry.) The set is redundant on purpose; the
identifiability analysis reduces it to a base set.

A tree read from a URDF (several measured tips, `casecal.model.tree`) has each tip's frame
``{tip}.x`` … ``{tip}.yaw`` (its link's name) in place of the tool frame, first in the
vector (`urdf_parameter_names` says why); a joint on the path to several tips is one set of
parameters, shared.

Lengths are in metres and angles in radians everywhere inside casecal.
"""

from __future__ import annotations

import dataclasses
import fnmatch
import math
import re
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

from ..errors import CalibrationError

JOINT_FAMILIES = ("theta", "d", "a", "alpha", "beta")
FRAME_AXES = ("x", "y", "z", "rx", "ry", "rz")
LENGTH_FAMILIES = frozenset({"d", "a"})
_JOINT_RE = re.compile(r"^(theta|alpha|beta|d|a)(\d+)$")


def frame_names(frame: str, session: str = "") -> tuple[str, ...]:
    """The six names of a frame's parameters, e.g. ``base_x`` … ``base_rz``; of a later
    session's frame (`session`: its label), ``base_x@B`` … ``base_rz@B``."""
    mark = f"{SESSION_MARK}{session}" if session else ""
    return tuple(f"{frame}_{axis}{mark}" for axis in FRAME_AXES)


SESSION_MARK = "@"
"""Separates a per-session frame parameter's name from its session's label: ``base_x@B``."""

SESSION_FRAMES = ("base", "tool")
"""The frames a session may have of its own: where the instrument stood, where the probe sat."""

_LABEL_RE = re.compile(r"^[\w-]+$")


def plain_name(name: str) -> str:
    """`name` without its session label: ``base_rx@B`` -> ``base_rx``."""
    return name.split(SESSION_MARK, 1)[0]


def session_label(name: str) -> str:
    """The session label of a per-session parameter (``base_x@B`` -> ``B``), else ``""``."""
    return name.partition(SESSION_MARK)[2]


def check_session_label(label, where: str = "") -> str:
    """`label` as a str fit to name parameters (``base_x@label``), or a CalibrationError.

    Letters (any script), digits, ``_`` and ``-``: a space, ``@``, ``.``, ``,`` or a
    wildcard would make names that `select` and the name rules misread.
    """
    at = f" ({where})" if where else ""
    if not isinstance(label, str):
        raise CalibrationError(f"session label {label!r}{at} is not text: give labels as str")
    text = label
    if not _LABEL_RE.match(text):
        raise CalibrationError(
            f"session label {label!r}{at} cannot name parameters (base_x@LABEL): use "
            "letters, digits, '_' or '-' only, e.g. 'day1' or '2024-05-03'"
        )
    return text


def session_parameter_names(labels: Sequence[str], frames: Sequence[str]) -> tuple[str, ...]:
    """The names of the later sessions' own frames: per label, per frame, six names."""
    return tuple(n for label in labels for frame in frames for n in frame_names(frame, label))


def parameter_names(
    n_joints: int, beta_joints: Iterable[int], n_points: int = 0
) -> tuple[str, ...]:
    """Names of the full parameter vector, in canonical order.

    Parameters
    ----------
    n_joints : int
        Number of joints.
    beta_joints : iterable of int
        1-based indices of the links that carry a Hayati ``beta``.
    n_points : int
        Measured points (reflectors) on the tool, each ``point{k}_x/y/z`` in the tool
        frame (m); 0 means the tool frame's origin is the one measured point.

    Returns
    -------
    tuple of str, length ``4 * n_joints + len(beta_joints) + 12 + 3 * n_points``
    """
    betas = set(beta_joints)
    names: list[str] = []
    for i in range(1, n_joints + 1):
        names += [f"theta{i}", f"d{i}", f"a{i}", f"alpha{i}"]
        if i in betas:
            names.append(f"beta{i}")
    points = [f"point{k}_{a}" for k in range(1, n_points + 1) for a in "xyz"]
    return (*names, *frame_names("base"), *frame_names("tool"), *points)


URDF_ORIGIN = ("x", "y", "z", "roll", "pitch", "yaw")


def urdf_parameter_names(
    joint_names: Sequence[str],
    joint_types: str,
    n_points: int = 0,
    passive=(),
    tips=(),
    parents=(),
) -> tuple[str, ...]:
    """Names of the full parameter vector of a URDF chain, in canonical order.

    Per movable joint the origins of the mimic joints walked before it (`passive`: per
    joint, tuples whose first item is the mimic joint's name), then its own origin
    ``{joint}.x`` … ``{joint}.yaw`` and, when revolute, ``{joint}.offset``; then the base
    and tool frames and the points, as for DH.

    A tree (`tips`: (name, joint it rides on) per tip, `parents`: per joint the joint it
    hangs from; `casecal.model.tree`) has no tool frame and no points, and its order
    serves its base set: `casecal.identification.analysis.pivot_order` offers the frames
    it knows by name (base, points, tool) first and the rest in this order, estimating the
    first parameter of each blind group and holding the others. So first come the tips'
    frames ``{tip}.x`` … ``{tip}.yaw`` (m, rad), which, like the tool frame, absorb the
    last joints' parameters exactly; then the joints by how many tips they carry (those of
    one tip's branch first, then those shared by two, …; in joint order among equals),
    because a joint that carries several branches, estimated in their place, would have
    to be compensated in every other branch (a 1 mrad turn of an elbow's origin standing
    for a turn of the torso hundreds of times as large); then the base frame.
    """
    passive = passive or ((),) * len(joint_names)
    per_joint = []
    for joint, kind, before in zip(joint_names, joint_types, passive, strict=True):
        names = [f"{p[0]}.{c}" for p in before for c in URDF_ORIGIN]
        names += [f"{joint}.{c}" for c in URDF_ORIGIN]
        per_joint.append(names + ([f"{joint}.offset"] if kind == "R" else []))
    if tips:
        if n_points:
            raise ValueError("internal error: a tree has no measured points")
        frames = [f"{name}.{c}" for name, _ in tips for c in URDF_ORIGIN]
        joints = [n for i in tree_order(parents, tips) for n in per_joint[i]]
        return (*frames, *joints, *frame_names("base"))
    points = [f"point{k}_{a}" for k in range(1, n_points + 1) for a in "xyz"]
    names = [n for names in per_joint for n in names]
    return (*names, *frame_names("base"), *frame_names("tool"), *points)


def tree_order(parents: Sequence[int], tips) -> list[int]:
    """A tree's joints (0-based) in the order of its parameters: by how many of the `tips`
    ((name, joint) pairs) each carries, in joint order among equals (`urdf_parameter_names`)."""
    carried = [0] * len(parents)
    for _, joint in tips:
        while joint >= 0:
            carried[joint] += 1
            joint = parents[joint]
    return sorted(range(len(parents)), key=lambda i: (carried[i], i))


@dataclass(frozen=True)
class Unit:
    """What casecal knows of a parameter unit.

    Attributes
    ----------
    shown, factor : str, float
        The unit of tables and the factor from SI to it (mm and 1e3 for metres).
    plausible : float
        The largest deviation expected of a real arm, SI: holding a parameter beats
        estimating it when its standard error exceeds its deviation, past this any.
    poorly : float
        A standard error above this marks an estimate the data barely constrain.
    generous : float
        A generous deviation by which to judge whether a term matters.
    """

    shown: str
    factor: float
    plausible: float
    poorly: float
    generous: float


UNITS = {
    "m": Unit("mm", 1e3, 2.5e-3, 1e-3, 0.01),
    "rad": Unit("deg", 180.0 / math.pi, math.radians(0.5), math.radians(0.1), 0.01),
    # joint compliance: an industrial arm's joints give 1e-7 to 1e-5 rad per N·m
    "rad/(N·m)": Unit("µrad/(N·m)", 1e6, 2e-5, 5e-7, 2e-5),
    # a lumped gravity term: compliance times a weight (1e-6 rad/(N·m) · 1e3 N)
    "rad/m": Unit("mrad/m", 1e3, 1e-2, 1e-3, 1e-2),
    # a body's mass as a parameter (casecal.model.masses): a CAD off by kilograms; a
    # robot whose bodies are much heavier or lighter gives its own (with_plausible)
    "kg": Unit("kg", 1.0, 5.0, 1.0, 1.0),
}

SIZE_WORDS = {"length": "m", "angle": "rad", "compliance": "rad/(N·m)"}
"""Words for the SI units of geometry in `casecal.Robot.with_plausible` and robot files."""


def unit_facts(si: str, sizes=()) -> Unit:
    """`UNITS[si]` with a robot's own sizes in place of the defaults.

    Parameters
    ----------
    si : str
        A key of `UNITS` ("m", "rad", ...).
    sizes : tuple of (str, float, float)
        ``(unit, plausible, poorly)`` triples, SI (`casecal.Robot.sizes`); a unit not
        listed keeps `UNITS`' sizes.
    """
    facts = UNITS[si]
    for u, plausible, poorly in sizes:
        if u == si:
            return dataclasses.replace(facts, plausible=plausible, poorly=poorly)
    return facts


def facts_of(name: str, sizes=()) -> Unit:
    """What casecal knows of parameter `name`'s unit (`unit`), with a robot's `sizes`
    (`unit_facts`): its plausible deviation and the standard error past which its
    estimate is poorly determined."""
    return unit_facts(unit(name), sizes)


SANE_SIZE = {"m": 0.5, "rad": 0.5}
"""Plausible deviations at or past these (SI: 0.5 m, 0.5 rad ≈ 29°) are no calibration's:
millimetres or degrees given where metres or radians are taken (`checked_sizes`)."""


def _check_sane(si: str, plausible: float, poorly: float, label: str) -> None:
    limit = SANE_SIZE.get(si)
    if limit is not None and plausible >= limit:
        unit = "m" if si == "m" else "rad"
        hint = "millimetres in metres" if si == "m" else "degrees in radians"
        raise CalibrationError(
            f"{label}: a plausible deviation of {_what(si)} of {plausible:g} {unit} is no "
            f"robot's error (sizes are SI: {hint}?); e.g. length=0.01 for 10 mm, "
            "angle=math.radians(2) for 2°"
        )
    if poorly > plausible:
        raise CalibrationError(
            f"{label}: the poorly determined bound of {_what(si)} ({_size_text(si, poorly)}) "
            f"exceeds its plausible deviation ({_size_text(si, plausible)}); it is the "
            "smaller of the two (the defaults' ratio: 0.4 for lengths, 0.2 for angles)"
        )


def checked_sizes(sizes, label: str = "robot") -> tuple[tuple[str, float, float], ...]:
    """`sizes` as `casecal.Robot.sizes` keeps them: ``(unit, plausible, poorly)`` triples
    of known units with positive, finite SI values, one per unit, sorted by unit, and
    without the triples that equal `UNITS`' defaults (a robot given the defaults is the
    robot without sizes).

    Raises
    ------
    CalibrationError
        An unknown unit, a unit given twice, or a size that is not a positive finite number.
    """
    out: dict[str, tuple[float, float]] = {}
    try:
        triples = [tuple(t) for t in sizes]
    except TypeError:
        raise CalibrationError(
            f"{label}: sizes must be (unit, plausible, poorly) triples, SI; "
            "use Robot.with_plausible(length=..., angle=...)"
        ) from None
    for triple in triples:
        if len(triple) != 3:
            raise CalibrationError(
                f"{label}: sizes entry {triple!r} is not a (unit, plausible, poorly) triple"
            )
        si, plausible, poorly = triple
        if si not in UNITS:
            raise CalibrationError(
                f"{label}: plausible size for unit {si!r}: casecal knows no such unit; use "
                f"length, angle or one of {', '.join(map(repr, UNITS))}"
            )
        if si in out:
            raise CalibrationError(f"{label}: plausible size for unit {si!r} given twice")
        values = []
        for what, v in (("plausible deviation", plausible), ("poorly determined bound", poorly)):
            number = isinstance(v, int | float) and not isinstance(v, bool)
            shown = _size_text(si, v) if number else repr(v)
            if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
                raise CalibrationError(
                    f"{label}: {what} of {_what(si)} is {shown}; give a positive finite number"
                )
            if not v > 0:
                raise CalibrationError(
                    f"{label}: {what} of {_what(si)} is {shown}; it must be positive "
                    "(it is a size: the largest deviation expected, a standard error)"
                )
            values.append(float(v))
        _check_sane(si, values[0], values[1], label)
        out[si] = (values[0], values[1])
    return tuple(
        (si, p, q)
        for si, (p, q) in sorted(out.items())
        # the defaults (to rounding: 0.5° · 0.2 is 0.1° to the last bit or two) are none
        if not (
            math.isclose(p, UNITS[si].plausible, rel_tol=1e-12)
            and math.isclose(q, UNITS[si].poorly, rel_tol=1e-12)
        )
    )


def sized(si: str, value, label: str = "robot") -> tuple[str, float, float]:
    """One ``(unit, plausible, poorly)`` triple from `value`: a plausible deviation (SI),
    whose poorly determined bound is then the default's in the same ratio (`UNITS`:
    2.5 mm and 1 mm, so 10 mm gives 4 mm), or a ``(plausible, poorly)`` pair."""
    if si not in UNITS:
        raise CalibrationError(
            f"{label}: plausible size for unit {si!r}: casecal knows no such unit; use "
            f"length, angle or one of {', '.join(map(repr, UNITS))}"
        )
    if isinstance(value, tuple | list):
        if len(value) != 2:
            raise CalibrationError(
                f"{label}: plausible size of {_what(si)}: give a number or a "
                "(plausible, poorly) pair, SI"
            )
        return (si, value[0], value[1])
    ratio = UNITS[si].poorly / UNITS[si].plausible
    if isinstance(value, bool) or not isinstance(value, int | float):
        return (si, value, value)  # checked_sizes says what is wrong
    return (si, value, value * ratio)


def _what(si: str) -> str:
    words = {v: k for k, v in SIZE_WORDS.items()}
    return f"{words[si]}s ({si})" if si in words else f"unit {si!r}"


def _size_text(si: str, value: float) -> str:
    facts = UNITS[si]
    u = "°" if facts.shown == "deg" else " " + facts.shown
    return f"{value * facts.factor:.3g}{u}"


def sizes_text(sizes) -> str:
    """The plausible deviations and poorly determined bounds of `sizes`, in words, e.g.
    "plausible deviations 10 mm, 2° (default 2.5 mm, 0.5°); standard errors above 4 mm,
    0.4° poorly determined (default 1 mm, 0.1°)"; "" for the defaults."""
    if not sizes:
        return ""
    units = [si for si, _, _ in sizes]

    def sizes_of(key) -> str:
        return ", ".join(_size_text(si, key(unit_facts(si, sizes))) for si in units)

    def defaults(key) -> str:
        return ", ".join(_size_text(si, key(UNITS[si])) for si in units)

    return (
        f"plausible deviations {sizes_of(lambda f: f.plausible)} (default "
        f"{defaults(lambda f: f.plausible)}); standard errors above "
        f"{sizes_of(lambda f: f.poorly)} poorly determined (default "
        f"{defaults(lambda f: f.poorly)})"
    )


def poorly_text(sizes=()) -> str:
    """The poorly determined bounds of lengths and angles in words: "1 mm or 0.1°" by
    default."""
    return " or ".join(_size_text(si, unit_facts(si, sizes).poorly) for si in ("m", "rad"))


_COMPLIANCE_RE = re.compile(r"^c\d+(_[uv])?$")  # torsion c{i}, bending c{i}_u, c{i}_v
_LUMPED_RE = re.compile(r"^g\d+_\d+([mxyz])$")
_MASS_RE = re.compile(r"^m\d+$")  # a body's mass (casecal.model.masses)


def is_length(name: str) -> bool:
    """True for parameters measured in metres, False for those in radians (and the
    compliance terms' own units, `unit`)."""
    if _COMPLIANCE_RE.match(name) or _LUMPED_RE.match(name) or _MASS_RE.match(name):
        return False
    name = plain_name(name)
    if "." in name:  # a URDF joint's origin: {joint}.x … {joint}.offset
        return name.rsplit(".", 1)[1] in ("x", "y", "z")
    match = _JOINT_RE.match(name)
    if match:
        return match.group(1) in LENGTH_FAMILIES
    return name.rsplit("_", 1)[-1] in ("x", "y", "z")


_DECLARED: dict[str, str] = {}
"""Units that error terms declared for their parameters (`declare_unit`)."""


def declare_unit(name: str, si: str, facts: Unit | None = None) -> None:
    """Record that parameter `name` is in unit `si` (a key of `UNITS`, or a new one
    described by `facts`); error terms with ``units=`` call this."""
    if facts is not None:
        UNITS.setdefault(si, facts)
    if si not in UNITS:
        raise CalibrationError(
            f"parameter {name!r}: unit {si!r} is unknown; use one of {', '.join(UNITS)} or "
            "describe it with a casecal.model.parameters.Unit"
        )
    _DECLARED[name] = si


def unit(name: str) -> str:
    """SI unit of a parameter: ``"m"``, ``"rad"`` or, for a joint compliance ``c{i}``,
    ``"rad/(N·m)"`` (see `UNITS`); what an error term declared for its own."""
    if name in _DECLARED:
        return _DECLARED[name]
    if _COMPLIANCE_RE.match(name):
        return "rad/(N·m)"
    if _MASS_RE.match(name):
        return "kg"
    lumped = _LUMPED_RE.match(name)
    if lumped:
        return "rad/m" if lumped.group(1) == "m" else "rad"
    return "m" if is_length(name) else "rad"


def select(
    names: Sequence[str], spec: str | Iterable[str] | None, default: str = "all"
) -> list[str]:
    """Resolve a ``parameters=`` argument into names, in canonical order.

    Parameters
    ----------
    names : sequence of str
        Every parameter of the robot, in canonical order.
    spec : str, iterable of str or None
        ``"all"``; an exact name (``"theta2"``); a family (``"a"`` or ``"a*"`` means
        ``a1 … an``, the ``*`` standing for the joint index only, so it never catches
        ``alpha2``); ``"base"``/``"base_*"`` or ``"tool"``/``"tool_*"`` for a frame's six
        parameters; or any other shell-style pattern (``"theta[1-3]"``, ``"base_r*"``).
        A comma-separated string is split. ``None`` means `default`.
    default : str
        What ``None`` means.

    Returns
    -------
    list of str
        The matched names, each once, in the order of `names`.

    Raises
    ------
    CalibrationError
        When a token matches nothing.
    """
    if spec is None:
        spec = default
    if isinstance(spec, str):
        tokens = [t.strip() for t in spec.split(",") if t.strip()]
    else:
        try:
            tokens = list(spec)
        except TypeError:
            raise CalibrationError(
                f"parameters={spec!r} is not understood; give names, families like 'a*', or 'all'"
            ) from None
    if not tokens:
        raise CalibrationError("no parameters selected; give names, families like 'a*', or 'all'")
    chosen: set[str] = set()
    for token in tokens:
        if not isinstance(token, str) or not token:
            raise CalibrationError(f"parameter selection {token!r} is not a non-empty string")
        matched = _match(names, token)
        if not matched:
            raise CalibrationError(
                f"parameter selection {token!r} matches no parameter of this robot; "
                f"use 'all', a family ({', '.join(f + '*' for f in JOINT_FAMILIES)}, base_*, "
                f"tool_*) or names from: {', '.join(names)}"
            )
        chosen.update(matched)
    return [n for n in names if n in chosen]


def _match(names: Sequence[str], token: str) -> list[str]:
    if token == "all":
        return list(names)
    if token in names:
        return [token]
    family = token[:-1] if token.endswith("*") else token
    if family in JOINT_FAMILIES:
        return [n for n in names if (m := _JOINT_RE.match(n)) and m.group(1) == family]
    # dotted names are a URDF joint's (a joint may be called base_joint or point_a)
    if family.rstrip("_") in ("base", "tool"):
        return [n for n in names if n.startswith(family.rstrip("_") + "_") and "." not in n]
    if family.rstrip("_") == "point":
        return [n for n in names if n.startswith("point") and "." not in n]
    return [n for n in names if fnmatch.fnmatchcase(n, token)]
