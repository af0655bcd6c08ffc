"""The robot model: immutable joints, frames and the forward kinematics API on top of them."""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Mapping, Sequence
from dataclasses import InitVar, dataclass, field

import casadi as ca
import numpy as np

from ..errors import CalibrationError
from . import kinematics
from .parameters import FRAME_AXES, SESSION_FRAMES, check_session_label, select
from .rotation_chart import deviated, deviations_between

DEFAULT_REVOLUTE_LIMITS = (-math.pi, math.pi)
"""Limits (rad) assumed for a revolute joint whose table gives none."""


@dataclass(frozen=True)
class Joint:
    """One row of a DH table, in SI units.

    Attributes
    ----------
    type : {"R", "P"}
        Revolute (q adds to ``theta``) or prismatic (q adds to ``d``).
    a, d : float
        Link length and link offset, m.
    alpha, theta : float
        Link twist and constant joint-angle offset, rad.
    beta : float or None
        Hayati's tilt about the link's y axis, rad; None when the link has none
        (see `casecal.model.kinematics`).
    limits : (float, float) or None
        Joint range, rad (R) or m (P); None when no source gives one.
    """

    type: str
    a: float
    alpha: float
    d: float
    theta: float = 0.0
    beta: float | None = None
    limits: tuple[float, float] | None = None


@dataclass(frozen=True)
class Frame:
    """A rigid transform ``Trans(xyz) · Rz(rz) Ry(ry) Rx(rx)``.

    xyz in m; rpy = (rx, ry, rz) in rad.
    """

    xyz: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rpy: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def matrix(self) -> np.ndarray:
        """The 4 × 4 homogeneous matrix, shape (4, 4)."""
        cs = [(np.cos(v), np.sin(v)) for v in self.rpy]
        return np.array(ca.evalf(kinematics.frame_transform(self.xyz, cs)), dtype=float)


@dataclass(frozen=True)
class Session:
    """The frames of a measurement session after the first (`Robot.sessions`).

    Attributes
    ----------
    label : str
        The session's label, which names its parameters (``base_x@label``): letters,
        digits, ``_`` and ``-`` (`casecal.model.parameters.check_session_label`).
    base : Frame
        Where the instrument stood in this session: its base frame, SI.
    tool : Frame or None
        The session's own tool frame (the probe re-mounted), SI; None: the robot's tool.
    """

    label: str
    base: Frame = field(default_factory=Frame)
    tool: Frame | None = None


@dataclass(frozen=True)
class Robot:
    """An immutable serial arm: DH table, convention, base and tool frames.

    Build one with `casecal.load_robot`; derive variants with `with_deviations` and
    `with_parameters`. All numbers are SI (m, rad).

    Attributes
    ----------
    name : str
    joints : tuple of Joint
        Base to tip.
    convention : {"dh", "mdh"}
        Standard DH or modified DH (Craig); see `casecal.model.kinematics`.
    base, tool : Frame
        World-to-first-frame and flange-to-tool-point transforms.
    full_name, source, confidence : str, tuple of str, str
        Where the numbers come from and how sure that source is.
    points : tuple of (x, y, z)
        Measured points (reflectors) in the tool frame, m; empty: the tool frame's origin
        is what is measured. Each adds parameters ``point{k}_x/y/z``.
    calibrated_from, calibrated_chain : str, tuple
        The nominal robot a calibrated one came from (name or path), and for a URDF the
        chain's (base link, tip link); `casecal.model.catalog.nominal_of` loads it.
    urdf : casecal.model.urdf.UrdfSource or None
        For a robot read from a URDF: the text and the chain's ends, so that saving it
        as URDF changes only the calibrated numbers.
    terms : tuple of casecal.model.terms.ErrorTerm
        Error terms beyond rigid geometry on the joint angles (`with_compliance`,
        `with_joint_harmonics`, `with_terms`); their parameters follow the frames'.
    inertials : tuple
        Per joint, the body it moves: (mass kg, centre of mass (x, y, z) m in that body's
        frame), or None; empty when unknown. Gravity terms need them.
    gravity : (float, float, float)
        Gravity's direction in the base frame; (0, 0, -1) for a floor mount.
    inputs : tuple of (str, float)
        Per-pose inputs beyond the joints that error terms read (``payload_kg``, a
        temperature), each with the reference value a pose without it takes. Joint
        arrays may then carry them as extra columns after the joints (`with_inputs`).
    payload_com : (float, float, float)
        The payload's centre of mass in the tool frame, m (with a ``payload_kg`` input).
    parents, tip_frames : tuple of int, tuple of casecal.model.tree.Tip
        A kinematic tree (several measured tips, `casecal.model.tree`): per joint the index
        of the joint it hangs from (-1: the base), and the tips with their frames, which
        replace the tool frame. Both empty for a serial chain.
    sessions : tuple of Session
        For measurements of several sessions (the instrument re-mounted between them): the
        frames of every session after the first, whose frames are `base` and `tool`.
        Joint arrays then carry one indicator per later session after the joints and
        inputs (1 in its session's column, all 0 for the first session; a pose without
        them is the first session's); see `with_sessions` and `casecal.model.kinematics`.
        Empty by default: one session.
    sizes : tuple of (str, float, float)
        This robot's own sizes of a real deviation, ``(unit, plausible, poorly)`` per SI
        unit ("m", "rad", …), in place of the industrial defaults of
        `casecal.model.parameters.UNITS` (2.5 mm and 1 mm, 0.5° and 0.1°): the largest
        deviation expected of it, and the standard error past which an estimate is poorly
        determined. Empty (the default): the industrial sizes. Set with `with_plausible`;
        they decide what identification holds, and are no part of the kinematics.
    coupling : casecal.model.coupling.Coupling or None
        The model's joint values from the controller's, ``q_model = M q + b``
        (`with_coupling`); None: the controller's joints are the model's. With a coupling,
        every joint value the API takes or returns is the controller's (`dof` of them),
        and `limits` bound the controller joints (`casecal.model.coupling`).
    coupled_from : Robot or None
        Set by `uncoupled` (the model of a coupled robot, as `identify` fits it): the
        coupled robot, so that poses drawn for the model (`casecal.poses.uniform`: the
        audit's, the workspace's) are the controller's mapped through the coupling, poses
        the robot can take; not a joint box that moves a passive joint on its own. No
        part of the kinematics, comparison or repr.
    auto_beta : bool, init only
        Give Hayati's ``beta = 0`` to every link with parallel neighbouring axes whose
        ``beta`` is None (the rule in `casecal.model.kinematics`). Default True.
    """

    name: str
    joints: tuple[Joint, ...]
    convention: str = "dh"
    base: Frame = field(default_factory=Frame)
    tool: Frame = field(default_factory=Frame)
    full_name: str = ""
    source: tuple[str, ...] = ()
    confidence: str = ""
    points: tuple[tuple[float, float, float], ...] = ()
    calibrated_from: str = ""
    calibrated_chain: tuple = ()
    urdf: object = None
    terms: tuple = ()
    inertials: tuple = ()
    gravity: tuple[float, float, float] = (0.0, 0.0, -1.0)
    inputs: tuple = ()
    payload_com: tuple[float, float, float] = (0.0, 0.0, 0.0)
    parents: tuple[int, ...] = ()
    tip_frames: tuple = ()
    sessions: tuple = ()
    sizes: tuple = ()
    coupling: object = None
    coupled_from: object = field(default=None, repr=False, compare=False)
    auto_beta: InitVar[bool] = True

    def __post_init__(self, auto_beta: bool) -> None:
        try:
            self._settle(auto_beta)
        finally:  # the checks may ask for the structure before the fields are settled
            self.__dict__.pop("structure", None)

    def _settle(self, auto_beta: bool) -> None:
        """Check the fields and put them in their canonical form (tuples, refreshed terms,
        automatic βs)."""
        from .parameters import checked_sizes
        from .terms import check_terms, refreshed

        if self.parents or self.tip_frames:
            from .tree import check_tree

            check_tree(self)  # first: what a tree does not support is said as such
        object.__setattr__(self, "terms", tuple(self.terms))
        if self.sizes:
            object.__setattr__(self, "sizes", checked_sizes(self.sizes, f"robot {self.name!r}"))
        if self.coupling is not None:
            object.__setattr__(self, "coupling", _checked_coupling(self))
        check_terms(self)
        object.__setattr__(self, "terms", refreshed(self))
        object.__setattr__(self, "sessions", _sessions(self.name, self.sessions))
        if self.convention not in ("dh", "mdh", "urdf"):
            raise CalibrationError(
                f"robot {self.name!r}: convention {self.convention!r} is unknown; "
                "use 'dh' (standard) or 'mdh' (modified/Craig)"
            )
        joints = tuple(self.joints)
        if not joints:
            raise CalibrationError(f"robot {self.name!r} has no joints; give at least one")
        if self.convention == "urdf":
            from .urdf import check_joints

            check_joints(self.name, joints)
            object.__setattr__(self, "joints", joints)
            object.__setattr__(self, "source", tuple(self.source))
            object.__setattr__(self, "points", _points(self.name, self.points))
            return
        for i, joint in enumerate(joints, start=1):
            if joint.type not in ("R", "P"):
                raise CalibrationError(
                    f"robot {self.name!r}, joint {i}: type {joint.type!r} is unknown; "
                    "use 'R' or 'P'"
                )
            values = [joint.a, joint.alpha, joint.d, joint.theta, joint.beta or 0.0]
            if not all(math.isfinite(v) for v in values):
                raise CalibrationError(f"robot {self.name!r}, joint {i}: a non-finite DH value")
        if auto_beta:
            n = len(joints)
            joints = tuple(
                dataclasses.replace(j, beta=0.0)
                if j.beta is None and kinematics.needs_beta(self.convention, i, n, j.alpha)
                else j
                for i, j in enumerate(joints, start=1)
            )
        object.__setattr__(self, "joints", joints)
        object.__setattr__(self, "source", tuple(self.source))
        object.__setattr__(self, "points", _points(self.name, self.points))

    # --- description ------------------------------------------------------------------

    @property
    def dof(self) -> int:
        """Number of joints: the controller's (as many as the model's without a coupling)."""
        return len(self.joints) if self.coupling is None else self.coupling.n_controller

    @property
    def model_dof(self) -> int:
        """Number of the kinematic model's joints (`joints`)."""
        return len(self.joints)

    @property
    def tips(self) -> tuple[str, ...]:
        """Names of the measured tips: a tree's tip links; for a serial chain one, its URDF
        tip link (``"tool"`` for a DH robot, or a URDF robot from a robot file)."""
        if self.tip_frames:
            return tuple(t.name for t in self.tip_frames)
        tip = getattr(self.urdf, "tip_link", None)
        return (tip,) if isinstance(tip, str) else ("tool",)

    @property
    def is_tree(self) -> bool:
        """Whether the robot is a kinematic tree (several tips, `casecal.model.tree`)."""
        return bool(self.tip_frames)

    @property
    def controller_joints(self) -> tuple:
        """Per controller joint, what it is: ``.type`` ("R" or "P") and ``.limits`` (rad or
        m, None when none are given). Without a coupling, the `joints` themselves."""
        if self.coupling is None:
            return self.joints
        from .coupling import ControllerJoint, controller_type

        c = self.coupling
        limits = [j.limits for j in self.joints] if c.square else list(c.limits)
        types = self.joint_types
        return tuple(
            ControllerJoint(controller_type(c.M, types, k), limits[k])
            for k in range(c.n_controller)
        )

    @property
    def controller_types(self) -> str:
        """One letter per controller joint, e.g. ``"RRPR"`` (`joint_types` without a
        coupling)."""
        return "".join(j.type for j in self.controller_joints)

    def model_joints(self, q) -> np.ndarray:
        """The kinematic model's joint values at controller joint values `q`.

        Parameters
        ----------
        q : array-like, shape (dof,) or (N, dof)
            Controller joint values, rad (R) or m (P); per-pose inputs may follow the
            joints.

        Returns
        -------
        ndarray, shape (model_dof,) or (N, model_dof) (inputs passed through)
            ``q @ M.T + b`` (`coupling`); `q` itself, as an array, without a coupling.
        """
        q2, single = check_joint_values(q, self.dof, len(self.inputs), len(self.sessions))
        if self.coupling is not None:
            q2 = self.coupling.model(q2)
        return q2[0] if single else q2

    def uncoupled(self) -> Robot:
        """The kinematic model alone: this robot without its coupling, taking model joint
        values. Its joints' limits are the ranges the controller joints' limits map them
        into (`casecal.model.coupling.hull`), for sampling poses of the model. Itself when
        there is no coupling."""
        if self.coupling is None:
            return self
        from .coupling import hull

        ranges = hull(self.coupling, self.limits)
        joints = tuple(
            dataclasses.replace(j, limits=r) for j, r in zip(self.joints, ranges, strict=True)
        )
        return dataclasses.replace(
            self, joints=joints, coupling=None, coupled_from=self, auto_beta=False
        )

    def recoupled(self, like: Robot) -> Robot:
        """This robot (a model `uncoupled` from `like`, e.g. calibrated) with `like`'s
        coupling and joint limits back; itself when `like` has no coupling."""
        if like.coupling is None:
            return self
        joints = tuple(
            dataclasses.replace(j, limits=o.limits)
            for j, o in zip(self.joints, like.joints, strict=True)
        )
        return dataclasses.replace(
            self, joints=joints, coupling=like.coupling, coupled_from=None, auto_beta=False
        )

    def with_coupling(self, M, b=None, limits=None) -> Robot:
        """A new Robot whose model joints follow the controller's: ``q_model = M q + b``.

        Parameters
        ----------
        M : array-like, shape (model_dof, n_controller)
            One row per model joint (`joints`), one column per controller joint (the
            joint values the API then takes, the CSV's ``q1`` … ``qn``); dimensionless (a
            controller joint drives model joints of its own type).
        b : array-like, shape (model_dof,), optional
            Constant offsets, rad (revolute model joint) or m (prismatic). Default 0.
        limits : sequence of (float, float) or None, optional
            Only with fewer controller joints than model joints: per controller joint its
            [min, max] (rad or m) or None (a revolute joint without limits). With as many,
            the joint rows' limits bound the controller joints, row i joint i. With fewer
            and none given, a robot whose joint rows carry limits (a URDF's) gives each
            controller joint those of the model joint it alone drives (``q_i = c q_k + b``:
            a torso's actuated joints), and the coupled joints' own limits are dropped (the
            controller's bound them); a controller joint driving no model joint alone
            needs `limits`. Given, they replace the joint rows' limits.

        Returns
        -------
        Robot
            With the identity (and no offset), this robot without a coupling.

        Raises
        ------
        CalibrationError
            A matrix of the wrong shape or not finite, a controller joint driving nothing
            or both revolute and prismatic joints, controller joints that move the model
            alike, limits in the wrong place (`casecal.model.coupling.make_coupling`).

        Examples
        --------
        A parallelogram arm whose model joint 3 turns by -(J2 + J3):

        >>> M = np.eye(6); M[2, 1] = M[2, 2] = -1.0  # doctest: +SKIP
        >>> arm = load_robot("kr16_2").with_coupling(M)  # doctest: +SKIP
        """
        from .coupling import controller_limits_of_rows, make_coupling

        label = f"robot {self.name!r}"
        joints = self.joints
        try:
            shape = np.shape(np.asarray(M, dtype=float))
        except (TypeError, ValueError):
            shape = ()  # `make_coupling` says what is wrong with it
        fewer = len(shape) == 2 and 0 < shape[1] < shape[0] == len(joints)
        if fewer and any(j.limits is not None for j in joints):
            # a URDF's joints all carry limits: the controller's are those of the model
            # joints they drive alone, and the rows keep none (`make_coupling` wants them
            # in one place)
            if limits is None:
                limits = controller_limits_of_rows(M, b, joints, label)
            joints = tuple(dataclasses.replace(j, limits=None) for j in joints)
        coupling = make_coupling(M, b, limits, joints, label)
        if coupling is None:
            return dataclasses.replace(self, coupling=None, auto_beta=False)
        return dataclasses.replace(self, joints=joints, coupling=coupling, auto_beta=False)

    @property
    def n_inputs(self) -> int:
        """Columns of a pose: the joints, then the per-pose `inputs`."""
        return self.dof + len(self.inputs)

    def with_inputs(self, **references: float) -> Robot:
        """A new Robot that reads per-pose inputs (e.g. ``payload_kg=0.0``), given after
        the joints in joint arrays (the reference value where a pose gives none)."""
        known = dict(self.inputs)
        for name, value in references.items():
            if not name.isidentifier() or name.startswith("q"):
                raise CalibrationError(f"input name {name!r}: use a word like temperature_c")
            known[name] = float(value)
        return dataclasses.replace(self, inputs=tuple(known.items()), auto_beta=False)

    def with_sessions(self, labels, frames=("base",)) -> Robot:
        """A new Robot measured in sessions: `labels` (str) of the sessions after the first,
        each with its own `frames` (``("base",)`` or ``("base", "tool")``), starting at
        this robot's base and tool. No labels: the robot without sessions."""
        frames = tuple(frames)
        unknown = [f for f in frames if f not in SESSION_FRAMES]
        if unknown or "base" not in frames:
            raise CalibrationError(
                f"per-session frames {frames!r}: give ('base',) or ('base', 'tool'); each "
                "session has its own base frame (where the instrument stood)"
            )
        if self.tip_frames and "tool" in frames:
            raise CalibrationError(
                "a tree has no tool frame: its tips' frames are shared by every session; "
                "give per-session frames ('base',)"
            )
        tool = self.tool if "tool" in frames else None
        sessions = tuple(Session(label, self.base, tool) for label in labels)
        return dataclasses.replace(self, sessions=sessions, auto_beta=False)

    @property
    def session_frames(self) -> tuple[str, ...]:
        """Which frames each later session has of its own: () without sessions, else
        ``("base",)`` or ``("base", "tool")``."""
        if not self.sessions:
            return ()
        return ("base", "tool") if self.sessions[0].tool is not None else ("base",)

    def with_plausible(
        self,
        length: float | None = None,
        angle: float | None = None,
        compliance: float | None = None,
        **by_unit,
    ) -> Robot:
        """A new Robot with its own sizes of a real deviation (`sizes`), SI.

        Identification holds a parameter whose standard error exceeds its unit's plausible
        deviation (and whose effect is below the noise), and calls an estimate whose
        standard error exceeds the poorly determined bound poorly determined (the
        command's ``identify -o`` does not write those). The industrial defaults
        (`casecal.model.parameters.UNITS`: 2.5 mm, 0.5°) suit a calibrated-class arm; a
        robot whose links are off by centimetres (a humanoid measured by motion capture)
        needs its own, or its fits hold at their start what the data do see.

        Parameters
        ----------
        length : float or (float, float), optional
            The plausible deviation of lengths, m; alone, the poorly determined bound is
            the default's in the same ratio (0.4: 10 mm gives 4 mm); a pair gives
            ``(plausible, poorly)``. None: unchanged.
        angle : float or (float, float), optional
            The same for angles, rad (ratio 0.2: 2° gives 0.4°).
        compliance : float or (float, float), optional
            The same for joint compliances (``c{i}``, ``c{i}_u``, ``c{i}_v``), rad/(N·m);
            the default 2e-5 suits an industrial arm, a light humanoid's joints give
            1e-4 to 4e-3.
        **by_unit : float or (float, float)
            Other units by their key in `UNITS`, e.g. ``**{"rad/(N·m)": 1e-4}``.

        Returns
        -------
        Robot
            Sizes given replace this robot's, the others kept; a unit given its default
            sizes has none of its own again (``robot.with_plausible(length=2.5e-3,
            angle=math.radians(0.5))`` is the robot without sizes).

        Raises
        ------
        CalibrationError
            A unit casecal does not know, or a size that is not a positive finite number.

        Examples
        --------
        >>> humanoid = robot.with_plausible(length=0.01, angle=math.radians(2))  # doctest: +SKIP
        """
        from .parameters import SIZE_WORDS, checked_sizes, sized

        label = f"robot {self.name!r}"
        given = dict(by_unit)
        for word, value in (("length", length), ("angle", angle), ("compliance", compliance)):
            if value is not None:
                if SIZE_WORDS[word] in given:
                    raise CalibrationError(
                        f"{label}: {word} and {SIZE_WORDS[word]!r} both give the size of "
                        f"unit {SIZE_WORDS[word]!r}; give one"
                    )
                given[SIZE_WORDS[word]] = value
        kept = {si: (p, q) for si, p, q in self.sizes}
        for si, value in given.items():
            _, p, q = sized(si, value, label)
            kept[si] = (p, q)
        sizes = checked_sizes([(si, p, q) for si, (p, q) in kept.items()], label)
        return dataclasses.replace(self, sizes=sizes, auto_beta=False)

    def unit_facts(self, name: str):
        """What this robot takes a real deviation of parameter `name` to be: its unit's
        `casecal.model.parameters.Unit` with this robot's `sizes` (``.plausible``,
        ``.poorly``, SI)."""
        from .parameters import facts_of

        return facts_of(name, self.sizes)

    @property
    def joint_types(self) -> str:
        """One letter per joint, e.g. ``"RRPR"``."""
        return "".join(j.type for j in self.joints)

    @functools.cached_property
    def structure(self) -> kinematics.Structure:
        """What the CasADi graph depends on (everything but the numbers).

        Computed once per robot (it is frozen; memo keys ask for it at every evaluation)."""
        shapes = tuple(dataclasses.replace(t, values=()) for t in self.terms)
        extra = {"terms": shapes, "gravity": tuple(self.gravity)} if self.terms else {}
        if self.inputs:
            extra["inputs"] = tuple(self.inputs)
        if self.tip_frames:
            extra["parents"] = self.parents
            extra["tips"] = tuple((t.name, t.parent) for t in self.tip_frames)
        if self.sessions:
            extra["sessions"] = tuple(s.label for s in self.sessions)
            extra["session_frames"] = self.session_frames
        if self.convention == "urdf":
            return kinematics.Structure(
                "urdf",
                self.joint_types,
                n_points=len(self.points),
                joint_names=tuple(j.name for j in self.joints),
                axes=tuple(j.axis for j in self.joints),
                passive=tuple(tuple(p.shape for p in j.passive) for j in self.joints)
                if any(j.passive for j in self.joints)
                else (),
                **extra,
            )
        betas = tuple(i for i, j in enumerate(self.joints, start=1) if j.beta is not None)
        return kinematics.Structure(
            self.convention, self.joint_types, betas, len(self.points), **extra
        )

    @property
    def parameter_names(self) -> tuple[str, ...]:
        """Names of every geometric parameter, in canonical order."""
        return self.structure.names

    @property
    def parameters(self) -> dict[str, float]:
        """Every geometric parameter by name, SI (m, rad), in canonical order."""
        return dict(zip(self.parameter_names, self.vector().tolist(), strict=True))

    def vector(self) -> np.ndarray:
        """The full parameter vector, shape (n_params,), in the order of `parameter_names`."""
        if self.tip_frames:
            return self._tree_vector()
        values: list[float] = []
        for j in self.joints:
            if self.convention == "urdf":
                values += [v for p in j.passive for v in (*p.xyz, *p.rpy)]
                values += [*j.xyz, *j.rpy] + ([j.offset] if j.type == "R" else [])
                continue
            values += [j.theta, j.d, j.a, j.alpha]
            if j.beta is not None:
                values.append(j.beta)
        values += [*self.base.xyz, *self.base.rpy, *self.tool.xyz, *self.tool.rpy]
        values += [v for p in self.points for v in p]
        values += [v for t in self.terms for v in t.values]
        return np.array(values + self._session_values(), dtype=float)

    def _session_values(self) -> list[float]:
        """The later sessions' own frames, in the order of `session_parameter_names`."""
        values: list[float] = []
        for session in self.sessions:
            for frame in [session.base] + ([session.tool] if session.tool is not None else []):
                values += [*frame.xyz, *frame.rpy]
        return values

    def _tree_vector(self) -> np.ndarray:
        """`vector` of a tree: its tips' frames, the joints in the order of
        `casecal.model.parameters.tree_order`, the base frame."""
        from .parameters import tree_order

        tips = tuple((t.name, t.parent) for t in self.tip_frames)
        values: list[float] = [v for t in self.tip_frames for v in (*t.xyz, *t.rpy)]
        for i in tree_order(self.parents, tips):
            j = self.joints[i]
            values += [v for p in j.passive for v in (*p.xyz, *p.rpy)]
            values += [*j.xyz, *j.rpy] + ([j.offset] if j.type == "R" else [])
        values += [*self.base.xyz, *self.base.rpy]
        values += [v for t in self.terms for v in t.values]
        return np.array(values + self._session_values(), dtype=float)

    @property
    def limits(self) -> np.ndarray:
        """Joint limits, shape (dof, 2), rad or m; revolute joints without limits get ±π.

        Raises
        ------
        CalibrationError
            For a prismatic joint without limits (there is no sensible default stroke).
        """
        rows = []
        for i, j in enumerate(self.controller_joints, start=1):
            if j.limits is not None:
                rows.append(j.limits)
            elif j.type == "R":
                rows.append(DEFAULT_REVOLUTE_LIMITS)
            else:
                raise CalibrationError(
                    f"robot {self.name!r}: prismatic joint {i} has no limits; add "
                    "'limits = [min, max]' to its [[joints]] table"
                )
        return np.array(rows, dtype=float)

    @property
    def reach(self) -> float | None:
        """An upper bound of the distance from the base frame to any measured point, m.

        The sum of every link's |a| and |d|, a prismatic joint's largest travel, and the
        tool and reflector offsets: no pose of the arm puts a point farther out. None for
        a prismatic joint without limits. A tree's: every joint's (a bound for each
        branch) and its farthest tip's offset.
        """
        if self.coupling is not None:  # the model's joints over the controller's ranges
            return self.uncoupled().reach
        total = float(np.linalg.norm(self.tool.xyz))
        total += max((float(np.linalg.norm(t.xyz)) for t in self.tip_frames), default=0.0)
        total += max((float(np.linalg.norm(p)) for p in self.points), default=0.0)
        for j in self.joints:
            total += (
                float(np.linalg.norm(j.xyz)) if self.convention == "urdf" else abs(j.a) + abs(j.d)
            )
            if j.type == "P":
                if j.limits is None:
                    return None
                total += max(abs(v) for v in j.limits)
        return total

    # --- variants ---------------------------------------------------------------------

    def with_parameters(self, values: Mapping[str, float]) -> Robot:
        """A new Robot with the named parameters set to `values` (SI); the rest unchanged."""
        p = self.parameters
        for name, value in values.items():
            if name not in p:
                raise CalibrationError(
                    f"robot {self.name!r} has no parameter {name!r}; "
                    f"its parameters are: {', '.join(p)}"
                )
            try:
                value = float(value)
            except (TypeError, ValueError):
                raise CalibrationError(f"parameter {name!r}: {value!r} is not a number") from None
            if not math.isfinite(value):
                raise CalibrationError(f"parameter {name!r}: value {value} is not finite")
            p[name] = value
        from .vector import joints_from

        def frame(prefix: str, mark: str = "") -> Frame:
            v = [p[f"{prefix}_{axis}{mark}"] for axis in FRAME_AXES]
            return Frame(tuple(v[:3]), tuple(v[3:]))

        sessions = tuple(
            Session(
                s.label,
                frame("base", "@" + s.label),
                None if s.tool is None else frame("tool", "@" + s.label),
            )
            for s in self.sessions
        )

        points = tuple(
            tuple(p[f"point{k}_{a}"] for a in "xyz") for k in range(1, len(self.points) + 1)
        )
        terms = tuple(
            dataclasses.replace(t, values=tuple(p[n] for n in t.parameters)) for t in self.terms
        )
        tips = tuple(
            dataclasses.replace(
                t,
                xyz=tuple(p[f"{t.name}.{c}"] for c in "xyz"),
                rpy=tuple(p[f"{t.name}.{c}"] for c in ("roll", "pitch", "yaw")),
            )
            for t in self.tip_frames
        )
        return dataclasses.replace(
            self,
            joints=joints_from(self, p),
            base=frame("base"),
            tool=self.tool if tips else frame("tool"),
            points=points,
            terms=terms,
            tip_frames=tips,
            sessions=sessions,
            auto_beta=False,
        )

    def with_points(self, points) -> Robot:
        """A new Robot measured at `points` (tool frame, m, shape (m, 3)); () for the origin."""
        try:
            points = np.asarray(points, dtype=float).reshape(-1, 3)
        except (TypeError, ValueError):
            raise CalibrationError("points must be numbers, shape (m, 3), in m") from None
        return dataclasses.replace(
            self, points=tuple(map(tuple, np.asarray(points, float))), auto_beta=False
        )

    def with_terms(self, *terms) -> Robot:
        """A new Robot with the error terms `terms` (`casecal.model.terms.ErrorTerm`) added:
        ``with_terms(a, b)`` or ``with_terms([a, b])``."""
        from .terms import ErrorTerm

        if len(terms) == 1 and isinstance(terms[0], (list, tuple)):
            terms = tuple(terms[0])
        for term in terms:
            if not isinstance(term, ErrorTerm):
                raise CalibrationError(
                    f"with_terms takes ErrorTerm objects, not {type(term).__name__}"
                )
        return dataclasses.replace(self, terms=(*self.terms, *terms), auto_beta=False)

    def with_compliance(self, joints=None, lateral: bool = False, lumped=None) -> Robot:
        """A new Robot whose revolute joints `joints` (1-based; None: every joint that
        carries gravity load) turn by ``c{i}·τ_i`` under gravity, τ_i the torque about the
        joint of every body it carries (on a tree, across branches). Without masses
        (`inertials`), lumped terms ``g{i}_{k}*`` take their place.

        `lateral`: each joint also bends across its axis, by ``c{i}_u``, ``c{i}_v``
        (rad/(N·m)) times the gravity moment about two axes perpendicular to it
        (`casecal.model.elastic`; masses needed).

        `lumped`: True for lumped terms even where masses are known; ``"reduced"`` for
        the lumped terms without the exactly redundant ones (the same fit with half the
        parameters, `casecal.model.lumped_basis`; a chain). Which of them predict:
        `casecal.identification.lumped_select.select_lumped`.
        """
        from .terms import compliance_terms

        if lumped == "reduced":
            from .lumped_basis import reduced_lumped_terms

            if lateral:
                raise CalibrationError("lateral compliance needs masses, not lumped terms")
            return self.with_terms(*reduced_lumped_terms(self, joints))
        if lumped not in (None, True, False):
            raise CalibrationError(f"lumped must be None, True, False or 'reduced', not {lumped!r}")
        return self.with_terms(*compliance_terms(self, joints, lumped, lateral))

    def with_masses(self, joints=None) -> Robot:
        """A new Robot whose bodies' masses (``m{k}``, kg) and centres of mass
        (``m{k}_x/y/z``, m, in the frame joint k moves) are parameters, starting at its
        `inertials`, for compliance terms to read (`casecal.model.masses`); `joints`:
        the bodies (1-based; None: every body with a mass)."""
        from .masses import mass_terms

        return self.with_terms(*mass_terms(self, joints))

    def with_joint_harmonics(self, joint: int, order: int) -> Robot:
        """A new Robot with ``h{joint}_s{k}``, ``h{joint}_c{k}`` (k ≤ `order`) on a joint."""
        from .terms import harmonics

        return self.with_terms(harmonics(joint, order))

    def with_deviations(self, deviations: Mapping[str, float]) -> Robot:
        """A new Robot with `deviations` (SI: m, rad) added to the named parameters.

        The deviations of a frame's rotation (``base_rx`` … ``base_rz``, ``tool_r*``, a URDF
        origin's ``.roll``, ``.pitch``, ``.yaw``) turn it by ``Rz(δyaw) Ry(δpitch)`` between
        its nominal yaw and pitch and its roll (`casecal.model.rotation_chart`): that is
        adding them to the angles where the nominal pitch is 0 or δyaw is 0, and, unlike
        adding, turns the frame every way at pitch ±90° too. `deviations_from` inverts it.

        Examples
        --------
        >>> true = robot.with_deviations({"theta1": 1.745e-4, "a2": -2e-4})  # doctest: +SKIP
        """
        p = self.parameters
        unknown = [n for n in deviations if n not in p]
        if unknown:
            raise CalibrationError(
                f"robot {self.name!r} has no parameter {unknown[0]!r}; "
                f"its parameters are: {', '.join(p)}"
            )
        values = {}
        for n, v in deviations.items():
            try:
                values[n] = float(v)
            except (TypeError, ValueError):
                raise CalibrationError(f"deviation of {n!r}: {v!r} is not a number") from None
        return self.with_parameters(deviated(p, values))

    def deviations_from(self, nominal: Robot, names=None) -> dict[str, float]:
        """The deviations (SI) that `with_deviations` takes `nominal` to this robot by.

        Differences of lengths and lone angles; of a frame's rotation, the inverse of the
        turn `with_deviations` applies (`casecal.model.rotation_chart.deviations_between`).

        Parameters
        ----------
        nominal : Robot
            Of the same structure.
        names : sequence of str, optional
            Default: every parameter.
        """
        return deviations_between(nominal.parameters, self.parameters, names)

    # --- kinematics -------------------------------------------------------------------

    def fk(self, q) -> np.ndarray:
        """End-effector pose (tool frame in world); a tree's tips' frames.

        Parameters
        ----------
        q : array-like, shape (dof,) or (N, dof)
            Joint values, rad (R) or m (P).

        Returns
        -------
        ndarray, shape (4, 4) or (N, 4, 4); a tree: (tips, 4, 4) or (N, tips, 4, 4)
            Homogeneous transforms, translation in m.
        """
        return self._evaluate("fk", q)

    def position(self, q) -> np.ndarray:
        """Tool-point position, m: shape (3,) for q (dof,), (N, 3) for q (N, dof); a tree's
        tips' positions, (tips, 3) or (N, tips, 3), in the order of `tips`."""
        return self._evaluate("position", q)

    def measured_points(self, q) -> np.ndarray:
        """World positions of the measured points, m.

        Shape (N, m, 3) for q (N, dof), (m, 3) for one pose; with no `points` the tool
        origin is the one point (m = 1).
        """
        q2, single = check_joint_values(q, self.dof, len(self.inputs), len(self.sessions))
        if self.coupling is not None:
            q2 = self.coupling.model(q2)
        ch = kinematics.chain(self.structure)
        out = ch.evaluate("points", q2, self.vector()).reshape(q2.shape[0], -1, 3)
        return out[0] if single else out

    def position_jacobian(
        self, q, parameters=None, deviations: bool = False
    ) -> tuple[np.ndarray, list[str]]:
        """Exact Jacobian of the tool-point position with respect to geometric parameters.

        Parameters
        ----------
        q : array-like, shape (dof,) or (N, dof)
            Joint values, rad (R) or m (P).
        parameters : str, list of str or None
            Which parameters (names, families or ``"all"``; see `casecal.model.parameters.select`).
            Default None: every parameter.
        deviations : bool
            False: derivatives in the parameters' values (`with_parameters`). True: in
            their deviations (`with_deviations`), what `casecal.identify` estimates; they
            differ for the pitch and yaw of a rotation, whose columns in the angles are
            parallel to the roll's at pitch ±90° and in the deviations never are
            (`casecal.model.rotation_chart`).

        Returns
        -------
        J : ndarray, shape (3, k) or (N, 3, k)
            ∂position/∂p; m/m for lengths, m/rad for angles. A tree's tips' rows one tip
            after the other: (3 · tips, k) or (N, 3 · tips, k).
        names : list of str
            The k parameter names, in column order.
        """
        names = select(self.parameter_names, parameters)
        return self._evaluate("position_jacobian", q, names, deviations), names

    def pose_jacobian(
        self, q, parameters=None, deviations: bool = False
    ) -> tuple[np.ndarray, list[str]]:
        """Exact Jacobian of the pose error ``(δposition, δφ)`` with respect to parameters.

        The orientation error δφ is the rotation vector of ``R(p + δp) R(p)ᵀ`` (world frame),
        so column ``k`` of rows 3-5 is ``vee(∂R/∂p_k Rᵀ)``. `parameters` and `deviations` as
        for `position_jacobian`.

        Returns
        -------
        J : ndarray, shape (6, k) or (N, 6, k)
            Rows 0-2 in m per unit parameter, rows 3-5 in rad per unit parameter. A tree's
            six rows per tip one tip after the other: (6 · tips, k) or (N, 6 · tips, k).
        names : list of str
        """
        names = select(self.parameter_names, parameters)
        return self._evaluate("pose_jacobian", q, names, deviations), names

    def _evaluate(self, kind: str, q, names: Sequence[str] = (), deviations=False) -> np.ndarray:
        q2, single = check_joint_values(q, self.dof, len(self.inputs), len(self.sessions))
        if self.coupling is not None:
            q2 = self.coupling.model(q2)
        ch = kinematics.chain(self.structure)
        p = self.vector()
        columns = ch.columns(names) if names else ()
        out = ch.evaluate(kind, q2, p, columns, anchor=p if deviations else None)
        return out[0] if single else out

    def __repr__(self) -> str:
        return f"Robot({self.name!r}, {self.joint_types}, convention={self.convention!r})"


def _sessions(name: str, sessions) -> tuple[Session, ...]:
    """`sessions` checked: Session objects with clean, distinct labels, and the same
    frames of their own (each a tool, or none)."""
    sessions = tuple(sessions)
    if not sessions:
        return ()
    if not all(isinstance(s, Session) for s in sessions):
        raise CalibrationError(f"robot {name!r}: sessions must be casecal.model.robot.Session")
    labels = [check_session_label(s.label) for s in sessions]
    if len(set(labels)) != len(labels):
        raise CalibrationError(f"robot {name!r}: session labels repeat: {', '.join(labels)}")
    if len({s.tool is None for s in sessions}) > 1:
        raise CalibrationError(
            f"robot {name!r}: give every session its own tool frame, or none of them"
        )
    return sessions


def _checked_coupling(robot: Robot):
    """`robot.coupling` checked against its joints (`casecal.model.coupling.make_coupling`)."""
    from .coupling import Coupling, make_coupling

    c = robot.coupling
    label = f"robot {robot.name!r}"
    if not isinstance(c, Coupling):
        raise CalibrationError(
            f"{label}: coupling must be a casecal.model.coupling.Coupling; use "
            "Robot.with_coupling(M, b)"
        )
    return make_coupling(c.matrix, c.offset, c.limits, tuple(robot.joints), label)


def _points(name: str, points) -> tuple[tuple[float, float, float], ...]:
    points = tuple(tuple(float(v) for v in p) for p in points)
    if any(len(p) != 3 or not all(math.isfinite(v) for v in p) for p in points):
        raise CalibrationError(f"robot {name!r}: every point needs 3 finite numbers (m)")
    return points


def check_joint_values(q, dof: int, inputs: int = 0, sessions: int = 0) -> tuple[np.ndarray, bool]:
    """Validate joint values and return them as a C-contiguous float64 (N, dof) array.

    With `inputs` > 0 the robot reads per-pose inputs: (N, dof + inputs) is accepted too;
    with `sessions` > 0 session indicators after them (`Robot.sessions`): (N, dof + inputs
    + sessions) too.

    Returns
    -------
    q : ndarray, shape (N, dof) or (N, dof + inputs)
    single : bool
        True when the input was one pose of shape (dof,).
    """
    try:
        arr = np.asarray(q, dtype=float)
    except (TypeError, ValueError) as exc:
        raise CalibrationError(f"joint values are not numbers: {exc}") from None
    single = arr.ndim == 1
    arr = np.atleast_2d(arr)
    widths = (dof, dof + inputs) + ((dof + inputs + sessions,) if sessions else ())
    if arr.ndim != 2 or arr.shape[1] not in widths or arr.shape[0] == 0 or dof == 0:
        raise CalibrationError(
            f"joint values have shape {np.shape(q)}; give shape ({dof},) for one pose or "
            f"(N, {dof}) for N >= 1 poses of a robot with {dof} joints"
        )
    if not np.all(np.isfinite(arr)):
        bad = int(np.argwhere(~np.isfinite(arr))[0][0])
        raise CalibrationError(f"joint values of pose {bad} are not finite (NaN or inf)")
    return np.ascontiguousarray(arr), single
