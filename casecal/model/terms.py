"""Error terms beyond rigid geometry, added to a joint's angle: ``θ_i + q_i + Δ_i(q, p)``.

A term is a Python function that returns a CasADi expression of the joint values and of
new named parameters; everything downstream (exact Jacobians, identifiability, standard
errors, the summary, compiled kernels, TOML) treats its parameters like the geometric
ones. The built-in terms use the same mechanism:

- **Joint compliance under gravity** (`compliance`): ``Δ_i = c_i τ_i(q)``, τ_i the gravity
  torque about joint i of the bodies beyond it, from their masses and centres of mass
  (``c{i}``, rad/(N·m)). The torques are computed on the rigid chain: the deflection's
  effect on the torques is second order (1e-6 of them for 1e-6 rad/(N·m)).
- **Joint-angle harmonics** (`harmonics`): ``Δ_i = Σ_k h{i}_s{k} sin(k q_i) +
  h{i}_c{k} cos(k q_i)`` (rad): gear eccentricity, encoder errors.

A user term: ``ErrorTerm(kind, joint, parameters, build)`` with
``build(ctx: TermContext, term: ErrorTerm) -> SX`` (rad, for a revolute joint), attached
with `Robot.with_terms`. Its compiled kernels are cached on disk under a key of the CasADi
graph it builds (`ErrorTerm.by_graph`): an edit anywhere in what the function reads that
changes the numbers changes the graph, and so the key.
"""

from __future__ import annotations

import copy
import dataclasses
import functools
import numbers
from collections.abc import Callable
from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from ..errors import CalibrationError
from .code_key import code_key, fingerprint  # noqa: F401  (fingerprint: public)
from .parameters import declare_unit

STANDARD_GRAVITY = 9.80665  # m/s²


@dataclass(frozen=True)
class TermContext:
    """What a term's function can build on, all CasADi SX.

    Attributes
    ----------
    q : SX, shape (dof,)
        Joint values, rad (R) or m (P).
    p : callable(str) -> SX
        A parameter's symbol by name (the term's own and any geometric one).
    axes, points, bodies : lists
        Per joint, on the rigid chain in the world frame: unit axis, a point on it, and
        the pose of the body it moves (see `casecal.model.chainwalk.Walk`).
    gravity : SX, shape (3,)
        Gravity's acceleration in the world frame, m/s².
    inputs : dict of str to SX
        The robot's per-pose inputs (`Robot.inputs`), e.g. ``inputs["temperature_c"]``.
    tool : SX, 4 × 4
        World pose of the tool frame on the rigid chain (None on a tree).
    carried : tuple of tuple of int
        Per joint, the 0-based joints whose bodies it carries (`beyond`); empty for a
        serial chain, where joint i carries i … n-1.
    names : frozenset of str
        Every parameter of the robot (a term may read any, e.g. the masses of
        `casecal.model.masses`).
    """

    q: ca.SX
    p: Callable
    axes: list
    points: list
    bodies: list
    gravity: ca.SX
    inputs: dict = field(default_factory=dict)
    tool: ca.SX | None = None
    carried: tuple = ()
    names: frozenset = frozenset()

    def beyond(self, joint: int) -> tuple[int, ...]:
        """The 0-based joints whose bodies joint `joint` (1-based) carries: on a tree the
        joints below it in every branch, on a serial chain those after it."""
        if self.carried:
            return self.carried[joint - 1]
        return tuple(range(joint - 1, len(self.bodies)))


@dataclass(frozen=True)
class ErrorTerm:
    """An error term on joint `joint` (1-based) with its own parameters.

    Attributes
    ----------
    kind : str
        Names the term's function (and keys the kernel cache).
    joint : int
    parameters : tuple of str
        New parameter names, unique on the robot.
    build : callable(TermContext, ErrorTerm) -> SX
        With `target` "angle": the term's value, rad, added to the joint's angle. With
        "link": a 4 × 4 transform (SX) applied after the joint's link, in its frame (a
        length that grows with temperature: ``Trans(k·ΔT, 0, 0)``).
    values : tuple of float
        The parameters' current values, SI (zeros by default).
    data : tuple
        Numbers the function reads (hashable), e.g. masses.
    target : {"angle", "link"}
    units : tuple
        Per parameter, its SI unit (a key of `casecal.model.parameters.UNITS`, or a pair
        (unit, `Unit`) describing a new one, e.g. ``("m/K", Unit("µm/K", 1e6, 1e-3, 1e-5,
        1e-3))``); by default read from the name (``*_x``: m, ``c{i}``: rad/(N·m), else
        rad). Tables, the noise-aware rank and the audit use it.
    """

    kind: str
    joint: int
    parameters: tuple[str, ...]
    build: Callable = field(compare=False, repr=False)
    values: tuple[float, ...] = ()
    data: tuple = ()
    target: str = "angle"
    code: str = ""
    units: tuple = ()

    def __post_init__(self):
        if isinstance(self.parameters, str):  # ("k23") is a string, not a tuple of one
            object.__setattr__(self, "parameters", (self.parameters,))
        object.__setattr__(self, "parameters", tuple(self.parameters))
        if not isinstance(self.joint, numbers.Integral) or isinstance(self.joint, bool):
            raise CalibrationError(f"error term {self.kind!r}: joint must be a joint number")
        object.__setattr__(self, "joint", int(self.joint))
        if not callable(self.build):
            raise CalibrationError(f"error term {self.kind!r}: build must be a function")
        # the function's own code keys the compiled kernels: an edited function never
        # reuses a kernel built from its earlier version
        object.__setattr__(self, "code", _code(self.build))
        if self.units:
            if len(self.units) != len(self.parameters):
                raise CalibrationError(f"error term {self.kind!r}: give one unit per parameter")
            for name, u in zip(self.parameters, self.units, strict=True):
                si, facts = (u, None) if isinstance(u, str) else u
                declare_unit(name, si, facts)
        values = tuple(float(v) for v in self.values) or (0.0,) * len(self.parameters)
        if len(values) != len(self.parameters) or not all(np.isfinite(values)):
            raise CalibrationError(
                f"error term {self.kind!r} on joint {self.joint}: give one finite value per "
                "parameter"
            )
        object.__setattr__(self, "values", values)
        if self.target not in ("angle", "link"):
            raise CalibrationError(f"error term {self.kind!r}: target must be 'angle' or 'link'")

    @property
    def by_graph(self) -> bool:
        """Whether the term's kernels are keyed on disk by the CasADi graph it builds (a
        function not casecal's own), not by `code` (`_code`)."""
        return self.code.startswith(BY_GRAPH)

    def on_disk(self) -> ErrorTerm:
        """This term as it names kernels on disk: without this process's identity of its
        function, which a term keyed by its graph holds in `code`."""
        if not self.by_graph:
            return self
        term = copy.copy(self)
        object.__setattr__(term, "code", BY_GRAPH)
        return term

    @property
    def shape(self) -> tuple:
        """What the symbolic graph depends on: everything but the values."""
        return (self.kind, self.joint, self.parameters, self.data, self.target, self.code)


BY_GRAPH = "graph"


def _code(build) -> str:
    """The key of `build` in `Structure`, which keys the chain's graph in this process and
    its kernels on disk.

    casecal's own terms: the key of their code and data (`casecal.model.code_key`; the
    model's source is keyed with the kernels). Any other function, or one whose key misses
    something it reads: `BY_GRAPH`, that key and this process's identity of `build`, so that
    two such functions never share a graph in a process; on disk their kernels are keyed
    by the graph they build (`Chain.graph_digest`), which is what is compiled, so that no
    edit to a user's code, however indirect, is served old numbers.
    """
    key = code_key(build)
    inner = build
    while isinstance(inner, functools.partial):
        inner = inner.func
    own = str(getattr(inner, "__module__", None)).startswith("casecal.model.")
    if own and not key.unseen:
        return key.digest
    return f"{BY_GRAPH} {key.digest} {id(build):x}"


def joint_deltas(terms, walk, q, p, gravity, inputs=None, tool=None, known=(), carried=()) -> tuple:
    """Per joint, Δ_i (SX, 0 where no term acts) and the transform after its link (SX
    4 × 4, or None); `known` are the robot's own parameter names, `carried` as
    `TermContext.carried`."""
    deltas = [ca.SX(0) for _ in range(q.numel())]
    after = [None] * q.numel()
    for term in terms:
        i = term.joint - 1

        def symbol(name, term=term):
            if name not in term.parameters and name not in known:
                raise CalibrationError(
                    f"error term {term.kind!r} asks for parameter {name!r}, which is neither "
                    "its own nor the robot's"
                )
            return p(name)

        ctx = TermContext(
            q,
            symbol,
            walk.axes,
            walk.points,
            walk.bodies,
            gravity,
            inputs or {},
            tool,
            carried,
            frozenset(known) | frozenset(term.parameters),
        )
        try:
            value = term.build(ctx, term)
            value = ca.SX(value)
        except CalibrationError:
            raise
        except Exception as exc:  # a user's function may fail in any way
            raise CalibrationError(
                f"error term {term.kind!r} on joint {term.joint}: its function failed "
                f"({type(exc).__name__}: {' '.join(str(exc).split())[:200]}); it must return a "
                "CasADi SX expression"
            ) from None
        if term.target == "angle":
            if value.shape != (1, 1):
                raise CalibrationError(
                    f"error term {term.kind!r}: an angle term returns a scalar, not "
                    f"{value.shape[0]} × {value.shape[1]}"
                )
            deltas[i] = deltas[i] + value
        else:
            if value.shape != (4, 4):
                raise CalibrationError(f"error term {term.kind!r}: a link term returns a 4 × 4")
            after[i] = value if after[i] is None else after[i] @ value
    return deltas, after


# --- built-in terms -----------------------------------------------------------------


def gravity_torque(ctx: TermContext, joint: int, inertials) -> ca.SX:
    """Gravity's torque about joint `joint` (1-based) of the bodies it carries, N·m: the
    component along its axis of `casecal.model.elastic.gravity_moment`.

    `inertials` holds per joint (mass kg, centre of mass xyz m in the body's frame), or
    None for a body without mass; the robot's mass parameters take their place where it
    has them (`casecal.model.masses`).
    """
    from .elastic import gravity_moment

    return ca.dot(gravity_moment(ctx, joint, inertials), ctx.axes[joint - 1])


def _compliance(ctx: TermContext, term: ErrorTerm) -> ca.SX:
    (name,) = term.parameters
    *inertials, payload_com = term.data
    torque = gravity_torque(ctx, term.joint, inertials)
    if PAYLOAD in ctx.inputs and ctx.tool is not None:
        # the payload's mass (kg, per pose) at its centre of mass in the tool frame
        i = term.joint - 1
        centre = ctx.tool[:3, :3] @ ca.DM(payload_com) + ctx.tool[:3, 3]
        weight = ctx.inputs[PAYLOAD] * ctx.gravity
        torque = torque + ca.dot(ca.cross(centre - ctx.points[i], weight), ctx.axes[i])
    return ctx.p(name) * torque


PAYLOAD = "payload_kg"
"""The per-pose input (`Robot.inputs`) that compliance reads as the payload's mass, kg."""


def compliance(joint: int, inertials, value: float = 0.0, payload_com=(0.0, 0.0, 0.0)) -> ErrorTerm:
    """Joint `joint`'s compliance ``c{joint}`` (rad/(N·m)) under the gravity torque of the
    bodies beyond it (`inertials`: per joint (mass, com) or None) and of a payload
    (``payload_kg`` among the robot's inputs, at `payload_com` in the tool frame, m)."""
    data = tuple(None if x is None else (float(x[0]), tuple(map(float, x[1]))) for x in inertials)
    data += (tuple(float(v) for v in payload_com),)
    return ErrorTerm("compliance", joint, (f"c{joint}",), _compliance, (value,), data)


def _harmonics(ctx: TermContext, term: ErrorTerm) -> ca.SX:
    (order,) = term.data
    qi = ctx.q[term.joint - 1]
    total = ca.SX(0)
    for k in range(1, order + 1):
        total = total + ctx.p(f"h{term.joint}_s{k}") * ca.sin(k * qi)
        total = total + ctx.p(f"h{term.joint}_c{k}") * ca.cos(k * qi)
    return total


def harmonics(joint: int, order: int, values=()) -> ErrorTerm:
    """``Σ_k h{joint}_s{k} sin(k q) + h{joint}_c{k} cos(k q)``, k = 1 … `order` (rad)."""
    if not isinstance(order, numbers.Integral) or isinstance(order, bool) or order < 1:
        raise CalibrationError(f"harmonics of joint {joint}: order must be an integer >= 1")
    order = int(order)
    names = tuple(f"h{joint}_{t}{k}" for k in range(1, order + 1) for t in ("s", "c"))
    return ErrorTerm("harmonics", joint, names, _harmonics, tuple(values), (order,))


def _lumped(ctx: TermContext, term: ErrorTerm) -> ca.SX:
    i = term.joint - 1
    down = ctx.gravity / STANDARD_GRAVITY  # unit vector: the lumped terms carry g
    total = ca.SX(0)
    for k in ctx.beyond(term.joint):
        body = ctx.bodies[k]
        moment = body[:3, :3] @ ca.vertcat(*(ctx.p(f"g{term.joint}_{k + 1}{a}") for a in "xyz"))
        arm = (body[:3, 3] - ctx.points[i]) * ctx.p(f"g{term.joint}_{k + 1}m")
        total = total + ca.dot(ca.cross(moment + arm, down), ctx.axes[i])
    return total


def lumped_compliance(joint: int, n_joints: int, carried=None) -> ErrorTerm:
    """Joint `joint`'s deflection under gravity with masses unknown, linear in lumped terms:
    per body k it carries, ``g{joint}_{k}m = c·m_k·g`` (rad/m) and ``g{joint}_{k}x/y/z =
    c·m_k·g·r_k`` (rad, r_k the centre of mass in body k's frame). `carried`: the 0-based
    joints whose bodies it carries (a tree's, `casecal.model.chainwalk.carried`); None for
    a serial chain's joint, which carries those after it."""
    bodies = range(joint, n_joints + 1) if carried is None else [k + 1 for k in carried]
    names = tuple(f"g{joint}_{k}{a}" for k in bodies for a in ("m", "x", "y", "z"))
    return ErrorTerm("lumped_compliance", joint, names, _lumped, (), (n_joints,))


def _lateral(ctx: TermContext, term: ErrorTerm) -> ca.SX:
    from .elastic import lateral_turn

    return lateral_turn(ctx, term)


BUILT_IN = {
    "compliance": _compliance,
    "harmonics": _harmonics,
    "lumped_compliance": _lumped,
    "lateral_compliance": _lateral,
}


def check_terms(robot) -> None:
    """Raise CalibrationError unless `robot`'s terms, inertials and gravity fit it."""
    n = len(robot.joints)
    seen: set[str] = set()
    geometric = set()
    if robot.terms:
        geometric = set(dataclasses.replace(robot, terms=(), auto_beta=False).parameter_names)
    for t in robot.terms:
        if not isinstance(t, ErrorTerm) or not 1 <= t.joint <= n:
            raise CalibrationError(f"robot {robot.name!r}: an error term on a joint it lacks")
        if t.target == "angle" and robot.joints[t.joint - 1].type != "R":
            raise CalibrationError(
                f"robot {robot.name!r}: error term {t.kind!r} on prismatic joint {t.joint}; "
                "terms act on revolute joints"
            )
        clash = seen.intersection(t.parameters) | geometric.intersection(t.parameters)
        if clash:
            raise CalibrationError(
                f"robot {robot.name!r}: error term {t.kind!r} names parameter "
                f"{sorted(clash)[0]!r}, which the robot already has; choose another name"
            )
        seen.update(t.parameters)
    if robot.inertials and len(robot.inertials) != n:
        raise CalibrationError(f"robot {robot.name!r}: give one inertial (or None) per joint")
    g = np.asarray(robot.gravity, dtype=float)
    if g.shape != (3,) or not np.isclose(np.linalg.norm(g), 1.0):
        raise CalibrationError(f"robot {robot.name!r}: gravity must be a unit vector (x, y, z)")


def refreshed(robot) -> tuple:
    """`robot`'s terms with the compliance terms reading its current masses and payload
    (a robot whose masses were replaced after `with_compliance` must not keep the old)."""
    out = []
    for t in robot.terms:
        if t.kind in ("compliance", "lateral_compliance"):
            if not robot.inertials:
                raise CalibrationError(
                    f"robot {robot.name!r} has compliance terms but no masses; give its "
                    "inertials, or use lumped terms (with_compliance on a robot without masses)"
                )
            fresh = compliance(t.joint, robot.inertials, payload_com=robot.payload_com)
            if t.kind == "lateral_compliance":
                from .elastic import lateral_terms

                (fresh,) = lateral_terms(robot, [t.joint])
            t = dataclasses.replace(t, data=fresh.data)
        out.append(t)
    return tuple(out)


def compliance_terms(robot, joints=None, lumped=None, lateral=False) -> list[ErrorTerm]:
    """Compliance terms of `robot` on `joints` (None: the revolute joints whose gravity
    torque is not zero at every pose, judged on 64 poses within the limits); lumped terms
    when the robot has no masses (or `lumped` is True); with `lateral`, each joint's
    bending across its axis too (`casecal.model.elastic`; masses needed)."""
    from .chainwalk import carried

    n = len(robot.joints)
    known = bool(robot.inertials) and any(x is not None for x in robot.inertials)
    known = known if lumped is None else not lumped
    candidates = [i for i in range(1, n + 1) if robot.joints[i - 1].type == "R"]
    chosen = candidates if joints is None else [int(j) for j in joints]
    bad = [j for j in chosen if j not in candidates]
    if bad:
        raise CalibrationError(f"robot {robot.name!r}: joint {bad[0]} is not a revolute joint")
    below = carried(robot.parents) if robot.tip_frames else [None] * n
    terms = [
        compliance(j, robot.inertials, payload_com=robot.payload_com)
        if known
        else lumped_compliance(j, n, below[j - 1])
        for j in chosen
    ]
    if lateral:
        if not known:
            raise CalibrationError(
                f"robot {robot.name!r}: lateral compliance needs the bodies' masses "
                "(inertials), not lumped terms: give the masses, or leave lateral out"
            )
        from .elastic import lateral_terms

        terms += lateral_terms(robot, chosen)
    if joints is not None:
        return terms
    probe = robot.uncoupled().with_terms(*terms)  # n model joints
    lo, hi = probe.limits.T
    q = lo + (hi - lo) * np.random.default_rng(0).random((64, n))
    moving = []
    for t in terms:  # a joint whose gravity torque is zero at every pose carries no load
        J, _ = probe.position_jacobian(q, list(t.parameters))
        moving.append(np.abs(J).max() > 1e-12)
    return [t for t, m in zip(terms, moving, strict=True) if m]
