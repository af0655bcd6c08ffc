"""Symbolic kinematics: the CasADi graph of a serial chain and its exact parameter Jacobians.

One graph of the end-effector pose ``T(q, p)`` is built per robot *structure* (convention,
joint types, which links carry a Hayati ``beta``), never per numeric value: the numbers of a
robot, nominal or calibrated, are an input ``p`` of the graph. Everything else (position,
Jacobians of position and of a pose error with respect to any subset of ``p``) is derived
from that one graph by CasADi's algorithmic differentiation, so it is exact to rounding.

Link transforms
---------------
Standard DH (``"dh"``), link ``i``, with Hayati's ``beta_i`` where present::

    A_i = Rz(theta_i + q_i) Tz(d_i) Tx(a_i) Rx(alpha_i) Ry(beta_i)      (revolute)
    A_i = Rz(theta_i) Tz(d_i + q_i) Tx(a_i) Rx(alpha_i) Ry(beta_i)      (prismatic)

Modified DH (``"mdh"``, Craig), where ``a_i, alpha_i`` of row ``i`` are Craig's
``a_{i-1}, alpha_{i-1}``::

    A_i = Rx(alpha_i) Ry(beta_i) Tx(a_i) Rz(theta_i + q_i) Tz(d_i)     (prismatic: d_i + q_i)

The whole chain is ``T = B · A_1 ⋯ A_n · E`` with base ``B`` and tool ``E`` each
``Trans(x, y, z) · Rz(rz) Ry(ry) Rx(rx)``.

Sessions
--------
Measurements taken in several sessions, with the instrument (or the probe) re-mounted in
between, see the robot through one frame per session (`Structure.sessions`). Each pose
carries one indicator per later session, after its joints and inputs: ``e_s = 1`` for a
pose of session ``s``, all 0 for the first session. The frame of a pose is then

    B = (1 - Σ_s e_s) · B_1 + Σ_s e_s · B_s

(and likewise the tool where each session has its own). For one-hot indicators this is
exactly the pose's own session frame, bit for bit (products with exact 0 and 1), and the
Jacobian columns of the other sessions' frames are exactly zero: one graph, one fit.

Rotations about an anchor
-------------------------
A frame's rotation (base, tool, URDF origin) enters as ``Rz(ȳ) Ry(p̄) · Rz(yaw - ȳ)
Ry(pitch - p̄) · Rx(roll)``, with the anchor ``(p̄, ȳ)`` an input of every call
(`Chain.extended`). Without an anchor (0) that is ``Rz(yaw) Ry(pitch) Rx(roll)``, and the
Jacobian columns are the derivatives in the angles, as `Robot.position_jacobian` gives
them: at pitch ±90° those of roll and yaw are parallel. With the anchor at the parameters'
own values ``p₀``, the value at ``p₀ + x`` is the robot at ``p₀`` deviated by ``x`` as
`casecal.model.rotation_chart` defines it, and the columns are the derivatives in ``x``,
never parallel: what a fit steps in (`casecal.identification.problem`). Anchors are
inputs, not constants: one graph and one compiled kernel serve every robot of a structure.

Hayati's beta
-------------
When two consecutive joint axes are (nearly) parallel, the common normal between them can
slide along the axes, and the link offset ``d`` that locates it becomes ill-defined: a tiny
misalignment of the axes moves it by metres. Hayati and Mirmirani (1985) add a rotation
``beta`` about the link's y axis, which describes that misalignment smoothly. casecal gives
``beta_i`` (nominal value 0) to link ``i`` when, in standard DH, ``|sin alpha_i| < 0.01``
and ``i < n`` (axes of joints ``i`` and ``i+1`` parallel or antiparallel), and, in modified
DH, when ``|sin alpha_i| < 0.01`` and ``i > 1`` (axes of joints ``i-1`` and ``i``). The name
follows the link that carries it, as in Hayati's paper: on the PUMA 560 (standard DH, axes 2
and 3 parallel) it is ``beta2``.
"""

from __future__ import annotations

import dataclasses
import hashlib
import logging
from collections.abc import Sequence
from dataclasses import dataclass
from functools import cache, cached_property
from typing import NamedTuple

import casadi as ca
import numpy as np

from ..errors import CalibrationError
from . import _trig
from ._evaluate import BUILDING, COMPILE_MIN_POSES, HOT_CALLS, Evaluator, write_into
from .chainwalk import walk, walk_tree
from .parameters import parameter_names, session_parameter_names, urdf_parameter_names
from .rotation_chart import is_anchored

log = logging.getLogger(__name__)

PARALLEL_TOLERANCE = 0.01
"""Consecutive axes with ``|sin(alpha)|`` below this count as parallel (about 0.57°)."""

KINDS = (
    "fk",
    "position",
    "position_jacobian",
    "pose_jacobian",
    "points",
    "points_jacobian",
    "points_and_jacobian",
    "joint_jacobian",
)
PARAMETER_JACOBIANS = (
    "position_jacobian",
    "pose_jacobian",
    "points_jacobian",
    "points_and_jacobian",
)


# fields a serial chain of one session leaves empty, and out of its repr (`Structure`)
OPTIONAL_FIELDS = ("parents", "tips", "sessions", "session_frames")


@dataclass(frozen=True)
class Structure:
    """What a chain's graph depends on: everything but the numbers.

    Attributes
    ----------
    convention : {"dh", "mdh", "urdf"}
    joint_types : str
        One letter per joint, base to tip, ``"R"`` or ``"P"`` (e.g. ``"RRPR"``).
    beta_joints : tuple of int
        1-based indices of the links that carry a Hayati ``beta``.
    n_points : int
        Measured points on the tool (0: the tool frame's origin).
    joint_names, axes : tuple
        URDF only: each movable joint's name and unit axis (in its own frame).
    terms : tuple of ErrorTerm
        Error terms on the joint angles, their values zeroed (`casecal.model.terms`).
    gravity : (float, float, float)
        Gravity's direction in the base frame (for gravity terms).
    passive : tuple
        URDF only: per joint, the mimic joints walked before it (`PassiveJoint.shape`).
    inputs : tuple of (str, float)
        Per-pose inputs beyond the joints (a payload, a temperature) that error terms read,
        with the reference value used where a pose gives none.
    parents : tuple of int
        A tree only (`casecal.model.tree`): per joint, the 0-based index of the joint it
        hangs from (-1: the base). Empty for a serial chain.
    tips : tuple of (str, int)
        A tree only: per measured tip, its link's name and the joint it hangs from. Empty
        for a serial chain, whose one measured point is the tool frame's (or `n_points`).
    sessions : tuple of str
        Labels of the measurement sessions after the first, each with frames of its own
        (module doc); empty for one session.
    session_frames : tuple of str
        Which frames each session has of its own: ``("base",)`` or ``("base", "tool")``.
    """

    convention: str
    joint_types: str
    beta_joints: tuple[int, ...] = ()
    n_points: int = 0
    joint_names: tuple[str, ...] = ()
    axes: tuple[tuple[float, float, float], ...] = ()
    terms: tuple = ()
    gravity: tuple[float, float, float] = (0.0, 0.0, -1.0)
    passive: tuple = ()
    inputs: tuple = ()
    parents: tuple[int, ...] = ()
    tips: tuple[tuple[str, int], ...] = ()
    sessions: tuple[str, ...] = ()
    session_frames: tuple[str, ...] = ()

    def __repr__(self) -> str:
        # the compiled kernels' cache key (`casecal.model._native`): a serial chain's is
        # what it was before trees and sessions, so that their fields cost it nothing
        shown = [
            f"{f.name}={getattr(self, f.name)!r}"
            for f in dataclasses.fields(self)
            if f.name not in OPTIONAL_FIELDS or getattr(self, f.name)
        ]
        return f"Structure({', '.join(shown)})"

    @property
    def n_inputs(self) -> int:
        """Per-pose inputs of the graph: the joint values, then the `inputs` (covariates),
        then one indicator per later session (module doc)."""
        return len(self.joint_types) + len(self.inputs) + len(self.sessions)

    @property
    def by_graph(self) -> bool:
        """Whether an error term is keyed by the graph it builds, not by its code (a user's
        term, `casecal.model.terms.ErrorTerm.by_graph`): its kernels' key on disk then
        holds the graph's digest (`Chain.graph_digest`)."""
        return any(t.by_graph for t in self.terms)

    @property
    def kernel_key(self) -> Structure:
        """What names this structure's compiled kernels: itself, with the sessions' labels
        numbered (labels name parameters; the graph does not depend on them) and the
        terms keyed by their graph without this process's identity of their function."""
        changes = {}
        if self.sessions:
            changes["sessions"] = tuple(str(k) for k in range(2, len(self.sessions) + 2))
        if self.by_graph:
            changes["terms"] = tuple(t.on_disk() for t in self.terms)
        return dataclasses.replace(self, **changes) if changes else self

    @property
    def names(self) -> tuple[str, ...]:
        """Names of the full parameter vector (see `casecal.model.parameters`), then the
        parameters of the error terms (`casecal.model.terms`)."""
        extra = tuple(n for t in self.terms for n in t.parameters)
        if self.convention == "urdf":
            names = urdf_parameter_names(
                self.joint_names,
                self.joint_types,
                self.n_points,
                self.passive,
                self.tips,
                self.parents,
            )
        else:
            names = parameter_names(len(self.joint_types), self.beta_joints, self.n_points)
        return names + extra + session_parameter_names(self.sessions, self.session_frames)


def needs_beta(convention: str, index: int, n_joints: int, alpha: float) -> bool:
    """Whether link `index` (1-based) gets a Hayati ``beta`` by the rule in the module doc."""
    if abs(np.sin(alpha)) >= PARALLEL_TOLERANCE:
        return False
    return index < n_joints if convention == "dh" else index > 1


# --- elementary transforms, as CasADi SX ------------------------------------------------


def _rot(axis: str, c, s) -> ca.SX:
    """Rotation about `axis` given the cosine and sine of its angle."""
    T = ca.SX.eye(4)
    i, j = {"x": (1, 2), "y": (2, 0), "z": (0, 1)}[axis]
    T[i, i], T[i, j], T[j, i], T[j, j] = c, -s, s, c
    return T


def _trans(x, y, z) -> ca.SX:
    T = ca.SX.eye(4)
    T[0, 3], T[1, 3], T[2, 3] = x, y, z
    return T


ANCHOR = "@anchor"
"""Suffix of the keys of the anchors' (cos, sin) in the graph's trigonometry (`rotation_trig`)."""


def frame_transform(xyz, rpy_cs) -> ca.SX:
    """``Trans(x, y, z) · Rz(rz) Ry(ry) Rx(rx)``; `rpy_cs` holds (cos, sin) of rx, ry, rz.

    With five pairs, of rx, ry - ry₀, rz - rz₀, ry₀ and rz₀ (an anchor, module doc), the
    same rotation as ``Rz(rz₀) Ry(ry₀) · Rz(rz - rz₀) Ry(ry - ry₀) · Rx(rx)``.
    """
    if len(rpy_cs) == 5:
        (cx, sx), (cy, sy), (cz, sz), (acy, asy), (acz, asz) = rpy_cs
        turn = _rot("z", acz, asz) @ _rot("y", acy, asy) @ _rot("z", cz, sz)
        return _trans(*xyz) @ turn @ _rot("y", cy, sy) @ _rot("x", cx, sx)
    (cx, sx), (cy, sy), (cz, sz) = rpy_cs
    return _trans(*xyz) @ _rot("z", cz, sz) @ _rot("y", cy, sy) @ _rot("x", cx, sx)


def rotation_trig(trig: dict, names) -> list:
    """The (cos, sin) pairs `frame_transform` takes for the rotation named (roll, pitch,
    yaw) `names`: with the anchors of pitch and yaw where `trig` holds them."""
    pairs = [trig[n] for n in names]
    anchors = [trig.get(n + ANCHOR) for n in names[1:]]
    return pairs + anchors if all(a is not None for a in anchors) else pairs


def link_transform(
    convention, joint_type, q, theta, d, a, alpha_cs, beta_cs=None, joint_cs=None
) -> ca.SX:
    """The 4 × 4 transform of one link (module doc); `alpha_cs`, `beta_cs` are (cos, sin).

    `joint_cs`, when given, is (cos, sin) of a revolute joint's ``theta + q`` (then `q` and
    `theta` are not used).
    """
    if joint_type == "R":
        theta = theta + q
    else:
        d = d + q
    if joint_type == "R" and joint_cs is not None:
        rz = _rot("z", *joint_cs)
    else:
        rz = _rot("z", ca.cos(theta), ca.sin(theta))
    rx = _rot("x", *alpha_cs)
    tilt = ca.SX.eye(4) if beta_cs is None else _rot("y", *beta_cs)
    if convention == "dh":
        return rz @ _trans(0, 0, d) @ _trans(a, 0, 0) @ rx @ tilt
    return rx @ tilt @ _trans(a, 0, 0) @ rz @ _trans(0, 0, d)


def joint_motion(joint_type: str, axis, q, cs=None) -> ca.SX:
    """A URDF joint's motion: rotation by `q` about the unit `axis` (R, Rodrigues' formula)
    or translation by `q` along it (P); `cs`, when given, is (cos q, sin q)."""
    k = np.asarray(axis, dtype=float)
    if joint_type == "P":
        return _trans(*(float(v) * q if v else 0 for v in k))
    c, s = (ca.cos(q), ca.sin(q)) if cs is None else cs
    T = ca.SX.eye(4)
    skew = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    for i in range(3):
        for j in range(3):
            # exact zeros stay out of the graph: an axis along x, y or z gives the usual Rx..Rz
            value = (1 - c) * k[i] * k[j] if k[i] * k[j] else 0
            value = value + (c if i == j else 0) + (s * skew[i, j] if skew[i, j] else 0)
            T[i, j] = value
    return T


def is_constant_angle(name: str) -> bool:
    """Angles that do not combine with a joint variable: alpha, beta, base and tool
    rotations, and the roll, pitch and yaw of a URDF joint's origin."""
    if "." in name:
        return name.rsplit(".", 1)[1] in ("roll", "pitch", "yaw")
    return name.startswith(("alpha", "beta", "base_r", "tool_r"))


# --- the chain ------------------------------------------------------------------------


class _Graph(NamedTuple):
    """A chain's CasADi symbols and pose."""

    q: ca.SX  # the joint values and per-pose inputs, (n_inputs,)
    p: ca.SX  # the parameters, (n_params,)
    cos: ca.SX  # cos and sin of the constant angles (`Chain.angle_index`)
    sin: ca.SX
    pext: ca.SX  # p, cos, sin, then cos and sin of the anchors: the parameter input
    T: ca.SX  # the tool pose, 4 × 4; a tree's tips' poses stacked, (4 · tips) × 4
    qin: ca.SX  # q, jcos, jsin: the Functions' per-pose input
    jcos: ca.SX  # cos and sin of the revolute joints' angles (`Chain.joint_trig`)
    jsin: ca.SX


class Chain:
    """The CasADi graph of ``T(q, p)`` for one `Structure`, and evaluators derived from it.

    Build it through `chain` (cached per structure), not directly. Evaluators are built on
    first use per (kind, parameter subset) and cached.

    The constant angles (twists, betas, frame rotations) enter the graph through their
    cosine and sine, which are inputs computed once per call (`extended`) rather than once
    per pose: that removes two thirds of the trigonometry from the per-pose code. Their
    Jacobian columns follow exactly by the chain rule, ``∂/∂φ = -sin φ ∂/∂c + cos φ ∂/∂s``.

    The revolute joints' angles ``q_i + theta_i`` enter the same way, through a cosine and
    a sine per pose (`joint_trig`, `inputs`): the compiled kernels compute them for a block
    of poses at once in a loop the C compiler vectorises, which is three times faster than
    a libm call per angle inside the per-pose code (where they cost three quarters of it).
    Not where error terms act on the joint angles: those angles are made in the graph.
    """

    def __init__(self, structure: Structure):
        self.structure = structure
        self.names = structure.names
        self.index = {n: k for k, n in enumerate(self.names)}
        self.angle_index = [k for k, n in enumerate(self.names) if is_constant_angle(n)]
        # pitches and yaws: their angles enter relative to an anchor (module doc)
        self.relative = [t for t, k in enumerate(self.angle_index) if is_anchored(self.names[k])]
        self.anchor_index = [self.angle_index[t] for t in self.relative]
        self.joint_trig = self._joint_trig()
        self._graph = None
        self._evaluators: dict = {}
        self._small_calls: dict[str, int] = {}

    def _joint_trig(self) -> tuple[tuple[int, int], ...]:
        """Per revolute joint whose angle's cos and sin are per-pose inputs: (its column in
        q, the index of its angle offset in p), base to tip."""
        if self.structure.terms:
            return ()
        out = []
        for i, jt in enumerate(self.structure.joint_types):
            if jt == "R":
                offset = (
                    f"{self.structure.joint_names[i]}.offset"
                    if self.structure.convention == "urdf"
                    else f"theta{i + 1}"
                )
                out.append((i, self.index[offset]))
        return tuple(out)

    def inputs(self, q: np.ndarray, p: np.ndarray) -> np.ndarray:
        """The graph's per-pose input: `q` (N, n_inputs) followed by cos and sin of the
        `joint_trig` angles (what the compiled kernels compute themselves)."""
        if not self.joint_trig:
            return q
        columns, offsets = (list(v) for v in zip(*self.joint_trig, strict=True))
        cos, sin = _trig.cos_sin(q[:, columns] + p[offsets])
        return np.hstack([q, cos, sin])

    @property
    def graph(self) -> _Graph:
        """The CasADi symbols and the pose (`_Graph`), built on first use.

        A process whose compiled kernels are all in the disk cache never builds it.
        """
        if self._graph is None:
            with BUILDING:  # kernels run on several threads: one graph per chain
                if self._graph is None:
                    self._graph = self._build()
        return self._graph

    @cached_property
    def graph_digest(self) -> str:
        """SHA-256 of the serialized graph of ``T(q, p)``, from which every evaluator of the
        chain is derived: the disk key of kernels whose error terms are keyed by what they
        build rather than by their Python code (`Structure.by_graph`)."""
        g = self.graph
        text = ca.Function("T", [g.qin, g.pext], [g.T]).serialize()
        return hashlib.sha256(text.encode()).hexdigest()

    def _build(self):
        structure, m = self.structure, len(self.angle_index)
        q = ca.SX.sym("q", structure.n_inputs)
        p = ca.SX.sym("p", len(self.names))
        cos, sin = ca.SX.sym("cos", m), ca.SX.sym("sin", m)
        n_a = len(self.anchor_index)
        acos, asin = ca.SX.sym("acos", n_a), ca.SX.sym("asin", n_a)
        n_t = len(self.joint_trig)
        jcos, jsin = ca.SX.sym("jcos", n_t), ca.SX.sym("jsin", n_t)
        joint_trig = [None] * len(structure.joint_types)
        for t, (i, _) in enumerate(self.joint_trig):
            joint_trig[i] = (jcos[t], jsin[t])
        symbols = (q, p, cos, sin, ca.vertcat(p, cos, sin, acos, asin))
        joints = (ca.vertcat(q, jcos, jsin), jcos, jsin)
        trig = {self.names[k]: (cos[t], sin[t]) for t, k in enumerate(self.angle_index)}
        for t, k in enumerate(self.anchor_index):
            trig[self.names[k] + ANCHOR] = (acos[t], asin[t])
        P = {name: p[k] for k, name in enumerate(self.names)}

        dof = len(structure.joint_types)

        def frame(prefix, mark=""):
            xyz = [P[f"{prefix}_{a}{mark}"] for a in "xyz"]
            angles = [f"{prefix}_r{a}{mark}" for a in "xyz"]
            return frame_transform(xyz, rotation_trig(trig, angles))

        def session_frame(prefix):
            # each pose's own session's frame, exact for one-hot indicators (module doc)
            first = frame(prefix)
            if prefix not in structure.session_frames:
                return first
            at = dof + len(structure.inputs)
            e = [q[at + k] for k in range(len(structure.sessions))]
            out = (1 - sum(e[1:], e[0])) * first
            for e_s, label in zip(e, structure.sessions, strict=True):
                out = out + e_s * frame(prefix, "@" + label)
            return out

        base = session_frame("base")
        q_eff = [q[i] for i in range(dof)]
        tree = bool(structure.tips)
        if tree and structure.n_points:
            raise tree_refusal("measured points on a tool")

        def walked(q_eff, after=None, joint_trig=None):
            """(the graph's output, the Walk, the world poses the terms see as the tool)"""
            if tree:
                tips, w = walk_tree(structure, base, q_eff, P, trig, joint_trig, after)
                return ca.vertcat(*tips), w, None
            w = walk(structure, base, q_eff, P, trig, after, joint_trig)
            return w.T @ session_frame("tool"), w, w.T @ session_frame("tool")

        if structure.terms:
            from .chainwalk import carried
            from .terms import STANDARD_GRAVITY, joint_deltas

            _, rigid, tool = walked(q_eff)
            gravity = base[:3, :3] @ ca.DM(structure.gravity) * STANDARD_GRAVITY
            inputs = {name: q[dof + k] for k, (name, _) in enumerate(structure.inputs)}
            deltas, after = joint_deltas(
                structure.terms,
                rigid,
                q[:dof],
                P.__getitem__,
                gravity,
                inputs,
                tool,
                known=set(self.names),  # a term may read another's (masses)
                carried=carried(structure.parents) if tree else (),
            )
            q_eff = [qi + d for qi, d in zip(q_eff, deltas, strict=True)]
            return _Graph(*symbols, walked(q_eff, after)[0], *joints)
        return _Graph(*symbols, walked(q_eff, joint_trig=joint_trig)[0], *joints)

    def extended(self, p: np.ndarray, anchor: np.ndarray | None = None) -> np.ndarray:
        """The graph's input: `p`, cos and sin of its constant angles (pitches and yaws less
        their anchors), then cos and sin of the anchors.

        `anchor` (n_params,), default none (0): where the rotations' pitches and yaws are
        taken from (module doc); only those entries are read.
        """
        angles = p[self.angle_index]
        at = np.zeros(len(self.anchor_index)) if anchor is None else anchor[self.anchor_index]
        angles[self.relative] -= at
        return np.concatenate([p, np.cos(angles), np.sin(angles), np.cos(at), np.sin(at)])

    def _jacobian(self, expr: ca.SX, columns: tuple[int, ...]) -> ca.SX:
        """Exact ∂expr/∂p[columns], constant angles through their cos and sin.

        One `ca.jacobian` call over all the symbols involved, so CasADi can pick reverse
        mode (few outputs, many parameters); the angle columns are combined afterwards.
        """
        if not columns:
            return ca.SX(expr.numel(), 0)
        g = self.graph
        pairs = {k: (g.cos[t], g.sin[t]) for t, k in enumerate(self.angle_index)}
        pairs.update({k: (g.jcos[t], g.jsin[t]) for t, (_, k) in enumerate(self.joint_trig)})
        return self._chain_rule(expr, [(g.p[k], pairs.get(k)) for k in columns])

    @staticmethod
    def _chain_rule(expr: ca.SX, variables) -> ca.SX:
        """``∂expr/∂v`` for each ``(v, pair)`` of `variables`: where `pair` is the (cos,
        sin) of an angle that `v` turns, ``∂/∂v + (-sin ∂/∂cos + cos ∂/∂sin)``. One
        `ca.jacobian` call over all the symbols, so CasADi can pick reverse mode."""
        symbols, where = [], []
        for v, pair in variables:
            where.append((len(symbols), pair))
            symbols += [v, *(pair or ())]
        J = ca.jacobian(expr, ca.vertcat(*symbols))
        cols = []
        for first, pair in where:
            col = J[:, first]
            if pair is not None:
                c, s = pair
                col = col - s * J[:, first + 1] + c * J[:, first + 2]
            cols.append(col)
        return ca.horzcat(*cols)

    def columns(self, parameters: Sequence[str] | None) -> tuple[int, ...]:
        """Indices into the full vector of the named parameters (all when None)."""
        if parameters is None:
            return tuple(range(len(self.names)))
        return tuple(self.index[name] for name in parameters)

    def expression(self, kind: str, columns: tuple[int, ...] = ()) -> ca.SX:
        """The per-pose output of `kind`, laid out so that C order of the result is natural.

        CasADi stores matrices column-major, so each output is the transpose of what the
        caller sees: ``T.T`` gives a row-major 4 × 4, ``J.T`` (k × 3) a row-major 3 × k.
        A tree's graph holds its tips' poses stacked, (4 · tips) × 4: ``T.T`` is then the
        tips' row-major 4 × 4 one after the other (`output_shape`).
        """
        if self.structure.tips:
            return self._tree_expression(kind, columns)
        g = self.graph
        T = g.T
        position = T[:3, 3]
        if kind == "fk":
            return T.T
        if kind == "position":
            return position
        if kind == "joint_jacobian":
            # ∂(position, orientation)/∂q, 6 × dof: the orientation rows are vee(∂R/∂q_i Rᵀ)
            R = T[:3, :3]
            dof = len(self.structure.joint_types)
            pairs = {i: (g.jcos[t], g.jsin[t]) for t, (i, _) in enumerate(self.joint_trig)}
            joints = [(g.q[i], pairs.get(i)) for i in range(dof)]
            dR = self._chain_rule(ca.vec(R), joints)
            rows = []
            for i in range(dof):
                W = ca.reshape(dR[:, i], 3, 3) @ R.T
                rows.append(ca.vertcat(W[2, 1], W[0, 2], W[1, 0]))
            position_q = self._chain_rule(position, joints)
            return ca.vertcat(position_q, ca.horzcat(*rows)).T
        if kind in ("points", "points_jacobian", "points_and_jacobian"):
            points = self._points(T)
            if kind == "points":
                return points
            J = self._jacobian(points, columns)
            # the points as a last column: one pass gives a solver's residual and Jacobian
            return (J if kind == "points_jacobian" else ca.horzcat(J, points)).T
        J = self._jacobian(position, columns)
        if kind == "position_jacobian":
            return J.T
        if kind == "pose_jacobian":
            R = T[:3, :3]
            dR = self._jacobian(ca.vec(R), columns)  # 9 × k, column-major vec of R
            rows = []
            for k in range(len(columns)):
                W = ca.reshape(dR[:, k], 3, 3) @ R.T  # skew: dR R^T = [ω]×
                rows.append(ca.vertcat(W[2, 1], W[0, 2], W[1, 0]))
            omega = ca.horzcat(*rows) if rows else ca.SX(3, 0)
            return ca.vertcat(J, omega).T
        raise ValueError(f"unknown kind {kind!r}; expected one of {KINDS}")

    def _tree_expression(self, kind: str, columns: tuple[int, ...]) -> ca.SX:
        """`expression` of a tree: per tip what a serial chain gives of its tool, stacked
        tip after tip (the tips' positions are its measured points)."""
        g = self.graph
        tips = [g.T[4 * k : 4 * k + 4, :] for k in range(len(self.structure.tips))]
        positions = ca.vertcat(*(T[:3, 3] for T in tips))
        if kind == "fk":
            return g.T.T
        if kind in ("position", "points"):
            return positions
        if kind == "joint_jacobian":
            # per tip what a chain gives of its tool: 3 position rows, then vee(∂R/∂q_i Rᵀ)
            dof = len(self.structure.joint_types)
            pairs = {i: (g.jcos[t], g.jsin[t]) for t, (i, _) in enumerate(self.joint_trig)}
            joints = [(g.q[i], pairs.get(i)) for i in range(dof)]
            dp = self._chain_rule(positions, joints)
            dR = self._chain_rule(ca.vertcat(*(ca.vec(T[:3, :3]) for T in tips)), joints)
            rows = []
            for k, T in enumerate(tips):
                omega = []
                for i in range(dof):
                    W = ca.reshape(dR[9 * k : 9 * k + 9, i], 3, 3) @ T[:3, :3].T
                    omega.append(ca.vertcat(W[2, 1], W[0, 2], W[1, 0]))
                rows += [dp[3 * k : 3 * k + 3, :], ca.horzcat(*omega)]
            return ca.vertcat(*rows).T
        if kind not in PARAMETER_JACOBIANS:
            raise ValueError(f"unknown kind {kind!r}; expected one of {KINDS}")
        J = self._jacobian(positions, columns)
        if kind == "points_and_jacobian":
            return ca.horzcat(J, positions).T
        if kind in ("position_jacobian", "points_jacobian"):
            return J.T
        # pose_jacobian: per tip its 3 position rows, then its 3 rotation rows
        rows = []
        for k, T in enumerate(tips):
            dR = self._jacobian(ca.vec(T[:3, :3]), columns)
            omega = []
            for c in range(len(columns)):
                W = ca.reshape(dR[:, c], 3, 3) @ T[:3, :3].T
                omega.append(ca.vertcat(W[2, 1], W[0, 2], W[1, 0]))
            rows += [J[3 * k : 3 * k + 3, :], ca.horzcat(*omega) if omega else ca.SX(3, 0)]
        return ca.vertcat(*rows).T

    def function(self, kind: str, columns: tuple[int, ...] = ()) -> ca.Function:
        """A CasADi Function ``(q, p) -> out`` for one pose, dense output, CSE applied."""
        out = ca.densify(self.expression(kind, columns))
        g = self.graph
        f = ca.Function(
            f"casecal_{kind}", [g.qin, g.pext], [out], ["q", "p"], ["out"], {"cse": True}
        )
        if f.has_free():
            raise RuntimeError(f"internal error: {kind} graph has free symbols")
        return f

    def evaluate(
        self,
        kind: str,
        q: np.ndarray,
        p: np.ndarray,
        columns=(),
        out: np.ndarray | None = None,
        anchor: np.ndarray | None = None,
    ) -> np.ndarray:
        """Evaluate `kind` at N poses in one call.

        Parameters
        ----------
        kind : str
            One of `KINDS`: "fk", "position", "position_jacobian", "pose_jacobian",
            "points", "points_jacobian" (3m × k per pose), "points_and_jacobian" (the
            same with the points as a last column), "joint_jacobian".
        q : ndarray, shape (N, dof), float64
            Joint values (rad for R, m for P), already validated; then the per-pose
            inputs and session indicators (module doc), where the structure has them.
        p : ndarray, shape (n_params,), float64
            Full parameter vector, SI (extended here with the cosines and sines).
        columns : tuple of int
            Parameter indices for the Jacobians.
        out : ndarray, optional
            C-contiguous float64 array of the output's shape to write into: a batch loop
            that reuses one spares the allocator (fresh pages of megabytes per batch, with
            threads faulting them in against each other, cost more than the kernel).
        anchor : ndarray, shape (n_params,), optional
            The rotations' anchor (module doc). Default none: the columns of a pitch or
            yaw are derivatives in the angle. Given, the value at ``p = anchor + x`` is the
            robot at `anchor` deviated by ``x`` (`casecal.model.rotation_chart`), and the
            columns are the derivatives in ``x``.

        Returns
        -------
        ndarray, shape (N, 4, 4), (N, 3), (N, 3, k), (N, 6, k), (N, 3m), (N, 3m, k),
        (N, 3m, k + 1) or (N, 6, dof)
            `out` when given.
        """
        columns = tuple(columns)
        if q.shape[1] == len(self.structure.joint_types) and self.structure.inputs:
            # poses without the per-pose inputs take their reference values
            reference = [value for _, value in self.structure.inputs]
            q = np.hstack([q, np.broadcast_to(reference, (q.shape[0], len(reference)))])
        sessions = len(self.structure.sessions)
        if sessions and q.shape[1] == self.structure.n_inputs - sessions:
            # poses without session indicators are the first session's
            q = np.hstack([q, np.zeros((q.shape[0], sessions))])
        if q.shape[0] < COMPILE_MIN_POSES:
            hot = self._small_calls[kind] = self._small_calls.get(kind, 0) + 1
            if hot >= HOT_CALLS:
                jacobian = kind in PARAMETER_JACOBIANS
                every = tuple(range(len(self.names))) if jacobian else ()
                value = self._evaluator(kind, every).compiled(q, self.extended(p, anchor))
                if value is not None:
                    if kind == "points_and_jacobian":  # and the points, the last column
                        columns = (*columns, len(self.names))
                    value = value[..., list(columns)] if jacobian else value
                    return value if out is None else write_into(out, value)
        return self._evaluator(kind, columns)(q, self.extended(p, anchor), out)

    def _evaluator(self, kind: str, columns: tuple[int, ...]) -> Evaluator:
        key = (kind, columns)
        evaluator = self._evaluators.get(key)
        if evaluator is None:
            with BUILDING:
                evaluator = self._evaluators.setdefault(key, Evaluator(self, kind, columns))
        return evaluator

    def _points(self, T) -> ca.SX:
        """Stacked world positions (3m) of the measured points ``T · [p_k; 1]``."""
        m = self.structure.n_points
        if m == 0:
            return T[:3, 3]
        p = self.graph.p
        first = self.index["point1_x"]
        return ca.vertcat(
            *[T[:3, :3] @ p[first + 3 * j : first + 3 * j + 3] + T[:3, 3] for j in range(m)]
        )

    def output_shape(self, kind: str, k: int) -> tuple[int, ...]:
        """Per-pose output shape of `kind` with `k` parameter columns (C order).

        A tree's: "fk" (tips, 4, 4), "position" (tips, 3), and its Jacobians' rows stacked
        tip after tip: (3 · tips, k) for the positions and points, (6 · tips, k) for the
        pose (each tip's 3 position rows, then its 3 rotation rows) and, "joint_jacobian",
        the joints (6 · tips, dof), rows as for the pose.
        """
        if self.structure.tips:
            n = len(self.structure.tips)
            return {
                "fk": (n, 4, 4),
                "position": (n, 3),
                "position_jacobian": (3 * n, k),
                "pose_jacobian": (6 * n, k),
                "points": (3 * n,),
                "points_jacobian": (3 * n, k),
                "points_and_jacobian": (3 * n, k + 1),
                "joint_jacobian": (6 * n, len(self.structure.joint_types)),
            }[kind]
        m3 = 3 * max(self.structure.n_points, 1)
        return {
            "fk": (4, 4),
            "position": (3,),
            "position_jacobian": (3, k),
            "pose_jacobian": (6, k),
            "points": (m3,),
            "points_jacobian": (m3, k),
            "points_and_jacobian": (m3, k + 1),
            "joint_jacobian": (6, len(self.structure.joint_types)),
        }[kind]


def tree_refusal(what: str) -> CalibrationError:
    """The error for what trees (several tips) do not support yet."""
    return CalibrationError(
        f"{what} are not supported on a kinematic tree (a robot with several tips) yet: "
        "trees support forward kinematics, error terms (compliance, harmonics), simulate, "
        "identify, compensate and save for now; use one chain (tip_link= one link) for this"
    )


@cache
def chain(structure: Structure) -> Chain:
    """The one `Chain` of a structure (built once per process)."""
    log.debug("building CasADi chain for %s", structure)
    return Chain(structure)
