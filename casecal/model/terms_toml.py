"""Error terms, masses and gravity in robot files (TOML).

Per ``[[joints]]`` row, optionally ``mass`` (kg) and ``com`` (the centre of mass of the
body the joint moves, in its frame, length unit); at the top level ``gravity`` (a
direction in the base frame, default ``[0, 0, -1]``), ``inputs`` (per-pose inputs with
their reference values, e.g. ``inputs = {payload_kg = 0.0}``), ``payload_com`` (length
unit, tool frame); and the tables::

    [compliance]          # c{i} with masses, lumped g{i}_{k}* without; values in SI
    joints = [2, 3]
    c2 = 1.1e-6
    lateral = [2, 3]      # optional: these joints bend across their axes too (c{i}_u,
    c2_u = 4e-7           # c{i}_v; casecal.model.elastic; masses needed); true: every
                          # joint whose bending moment is not always zero

    [masses]              # bodies whose mass and centre of mass are parameters
    joints = [6]          # (casecal.model.masses): m{i} kg, m{i}_x/y/z in SI
    m6 = 12.5

    [compliance]          # or some lumped terms only (casecal.model.lumped_basis)
    joints = [2, 3]
    lumped = ["g2_2m", "g3_3z"]
    g2_2m = 1.2e-5

    [harmonics]           # h{i}_s{k}, h{i}_c{k} in the file's angle unit
    orders = [[2, 2]]     # [joint, order] pairs
    h2_s1 = 0.002

A robot with a term written in Python (`casecal.model.terms.ErrorTerm`) cannot be saved:
its function is not data.
"""

from __future__ import annotations

import numpy as np

from ..errors import CalibrationError
from .terms import compliance_terms, harmonics

TOP_KEYS = {"gravity", "compliance", "harmonics", "masses", "inputs", "payload_com", "terms"}
BUILT_IN_KINDS = {
    "compliance",
    "lumped_compliance",
    "lumped_compliance_subset",
    "lateral_compliance",
    "harmonics",
    "mass",
}
ROW_KEYS = {"mass", "com"}


def split_rows(rows: list[dict], length: float, label: str, number) -> tuple[list[dict], tuple]:
    """The rows without ``mass``/``com``, and the inertials they gave (() when none did)."""
    inertials, plain = [], []
    for i, row in enumerate(rows, start=1):
        if "mass" in row or "com" in row:
            com = row.get("com", [0, 0, 0])
            if not isinstance(com, list) or len(com) != 3 or "mass" not in row:
                raise CalibrationError(
                    f"{label}: joints[{i}] needs mass = <kg> and com = [x, y, z] together"
                )
            mass = number(row["mass"], label, f"joints[{i}].mass")
            if mass < 0:
                raise CalibrationError(f"{label}: joints[{i}].mass is negative")
            xyz = tuple(number(v, label, f"joints[{i}].com") * length for v in com)
            inertials.append((mass, xyz))
        else:
            inertials.append(None)
        plain.append({k: v for k, v in row.items() if k not in ROW_KEYS})
    return plain, (tuple(inertials) if any(x is not None for x in inertials) else ())


def add_terms(robot, data: dict, angle: float, label: str, number, length: float = 1.0):
    """`robot` with the gravity, compliance and harmonics of the file `data`."""
    import dataclasses

    if "gravity" in data:
        g = data["gravity"]
        if not isinstance(g, list) or len(g) != 3:
            raise CalibrationError(f"{label}: gravity must be a direction [x, y, z]")
        g = np.array([number(v, label, "gravity") for v in g])
        if not np.linalg.norm(g) > 0:
            raise CalibrationError(f"{label}: gravity must not be zero")
        robot = dataclasses.replace(robot, gravity=tuple(g / np.linalg.norm(g)), auto_beta=False)
    if "inputs" in data:
        table = data["inputs"]
        if not isinstance(table, dict):
            raise CalibrationError(f"{label}: inputs must be a table, e.g. {{payload_kg = 0.0}}")
        robot = robot.with_inputs(**{k: number(v, label, f"inputs.{k}") for k, v in table.items()})
    if "payload_com" in data:
        com = data["payload_com"]
        if not isinstance(com, list) or len(com) != 3:
            raise CalibrationError(f"{label}: payload_com must be [x, y, z]")
        xyz = tuple(number(v, label, "payload_com") * length for v in com)
        robot = dataclasses.replace(robot, payload_com=xyz, auto_beta=False)
    values = {}
    terms = []
    if "compliance" in data:
        table = _table(data, "compliance", label)
        joints = table.pop("joints", None)
        lumped = table.pop("lumped", None)
        lateral = table.pop("lateral", False)
        if joints is not None and not (isinstance(joints, list) and joints):
            raise CalibrationError(f"{label}: compliance.joints must be a list of joints")
        if not isinstance(lateral, bool) and not (
            isinstance(lateral, list) and all(isinstance(j, int) for j in lateral)
        ):
            raise CalibrationError(
                f"{label}: compliance.lateral must be true, false or a list of joints"
            )
        if isinstance(lumped, list):
            terms += _lumped_subsets(robot, joints, lumped, label)
        elif lumped is not None and not isinstance(lumped, bool):
            raise CalibrationError(
                f"{label}: compliance.lumped must be true, false or a list of lumped terms"
            )
        else:
            terms += compliance_terms(robot, joints, lumped, lateral is True)
        if isinstance(lateral, list) and lateral:
            from .elastic import lateral_terms

            terms += lateral_terms(robot, _joints(robot, lateral, label))
        values.update({k: number(v, label, f"compliance.{k}") for k, v in table.items()})
    if "masses" in data:
        from .masses import mass_terms

        table = _table(data, "masses", label)
        joints = table.pop("joints", None)
        if not (isinstance(joints, list) and joints and all(isinstance(j, int) for j in joints)):
            raise CalibrationError(f"{label}: masses.joints must be a list of joints")
        terms += mass_terms(robot, joints)
        given = {k: number(v, label, f"masses.{k}") for k, v in table.items()}
        _check_masses(given, label)
        values.update(given)
    if "harmonics" in data:
        table = _table(data, "harmonics", label)
        orders = table.pop("orders", None)
        if not isinstance(orders, list) or not all(
            isinstance(p, list) and len(p) == 2 and all(isinstance(v, int) for v in p)
            for p in orders
        ):
            raise CalibrationError(f"{label}: harmonics.orders must be [[joint, order], ...]")
        terms += [harmonics(j, k) for j, k in orders]
        values.update({k: number(v, label, f"harmonics.{k}") * angle for k, v in table.items()})
    terms += user_terms(data, label)
    if not terms:
        return robot
    robot = robot.with_terms(*terms)
    unknown = sorted(set(values) - set(robot.parameter_names))
    if unknown:
        raise CalibrationError(f"{label}: {unknown[0]!r} is not a parameter of these terms")
    return robot.with_parameters(values) if values else robot


def _joints(robot, joints: list[int], label: str) -> list[int]:
    bad = [j for j in joints if not 1 <= j <= len(robot.joints)]
    if bad:
        raise CalibrationError(f"{label}: compliance.lateral names joint {bad[0]}, which it lacks")
    return joints


def _lumped_subsets(robot, joints, names: list, label: str) -> list:
    """The lumped terms `names` (``g{j}_{k}m/x/y/z``) of `joints` (default: the joints
    they name), one term per joint."""
    from .lumped_basis import NAME, lumped_subset

    parsed = [NAME.match(n) if isinstance(n, str) else None for n in names]
    if not names or not all(parsed):
        raise CalibrationError(
            f"{label}: compliance.lumped must be true, false or a list of lumped terms by "
            'name (g<joint>_<body><m|x|y|z>), e.g. ["g2_2m", "g3_3z"]'
        )
    named = [int(m[1]) for m in parsed]
    joints = sorted(set(named)) if joints is None else [int(j) for j in joints]
    stray = [n for n, j in zip(names, named, strict=True) if j not in joints]
    if stray:
        raise CalibrationError(
            f"{label}: compliance.lumped names {stray[0]!r}, a term of a joint not in "
            f"compliance.joints {joints}; add the joint or remove the term"
        )
    by_joint = {j: [n for n, i in zip(names, named, strict=True) if i == j] for j in joints}
    try:
        return [lumped_subset(j, len(robot.joints), v) for j, v in by_joint.items() if v]
    except CalibrationError as exc:
        raise CalibrationError(f"{label}: compliance.lumped: {exc}") from None


def _check_masses(values: dict, label: str) -> None:
    """Refuse a negative mass and a centre of mass beyond 10 m: the table is SI whatever
    length_unit says, and 150 meant as mm would otherwise bend the robot by kilometres."""
    for name, v in values.items():
        if name[-2:] in ("_x", "_y", "_z") and abs(v) > 10.0:
            raise CalibrationError(
                f"{label}: masses.{name} = {v:g} m is no centre of mass; the [masses] table is "
                f"in SI (m) whatever length_unit says: {v:g} mm is {v / 1000:g}"
            )
        if name[-2:] not in ("_x", "_y", "_z") and v < 0:
            raise CalibrationError(f"{label}: masses.{name} = {v:g} kg is negative")


def _table(data: dict, key: str, label: str) -> dict:
    table = data[key]
    if not isinstance(table, dict):
        raise CalibrationError(f"{label}: [{key}] must be a table")
    return dict(table)


def terms_lines(robot) -> list[str]:
    """TOML lines (m, rad, SI terms) for `robot`'s gravity and terms; raises for a term
    written in Python."""
    lines = []
    if tuple(robot.gravity) != (0.0, 0.0, -1.0):
        lines.append("gravity = [" + ", ".join(repr(float(v)) for v in robot.gravity) + "]")
    if robot.inputs:
        pairs = ", ".join(f"{name} = {float(v)!r}" for name, v in robot.inputs)
        lines.append(f"inputs = {{{pairs}}}")
    if tuple(robot.payload_com) != (0.0, 0.0, 0.0):
        lines.append("payload_com = [" + ", ".join(repr(float(v)) for v in robot.payload_com) + "]")
    by_kind: dict[str, list] = {}
    for t in robot.terms:
        by_kind.setdefault(t.kind, []).append(t)
    other = [t for t in robot.terms if t.kind not in BUILT_IN_KINDS]
    user = [_user_lines(robot, t) for t in other]
    lumped_terms = by_kind.get("lumped_compliance", []) + by_kind.get(
        "lumped_compliance_subset", []
    )
    comp = by_kind.get("compliance", []) + lumped_terms
    if by_kind.get("compliance") and lumped_terms:
        raise CalibrationError(
            f"robot {robot.name!r}: compliance with masses and lumped terms together cannot "
            "be saved; keep one kind"
        )
    lateral = by_kind.get("lateral_compliance", [])
    if lateral and not by_kind.get("compliance"):
        raise CalibrationError(
            f"robot {robot.name!r}: lateral compliance without joint compliance cannot be "
            "saved; add the joints' compliance (with_compliance(lateral=True))"
        )
    if comp:
        lumped = "true" if lumped_terms else "false"
        if "lumped_compliance_subset" in by_kind:  # some terms only: name them
            lumped = "[" + ", ".join(f'"{n}"' for t in comp for n in t.parameters) + "]"
        lines += ["", "[compliance]", f"joints = {[t.joint for t in comp]}", f"lumped = {lumped}"]
        if lateral:
            lines.append(f"lateral = {[t.joint for t in lateral]}")
        comp = comp + lateral
        lines += [f"{n} = {v!r}" for t in comp for n, v in zip(t.parameters, t.values, strict=True)]
    if "mass" in by_kind:
        terms = by_kind["mass"]
        lines += ["", "[masses]", f"joints = {[t.joint for t in terms]}"]
        lines += [
            f"{n} = {v!r}" for t in terms for n, v in zip(t.parameters, t.values, strict=True)
        ]
    for block in user:
        lines += block
    if "harmonics" in by_kind:
        terms = by_kind["harmonics"]
        lines += ["", "[harmonics]", f"orders = {[[t.joint, t.data[0]] for t in terms]}"]
        lines += [
            f"{n} = {v!r}" for t in terms for n, v in zip(t.parameters, t.values, strict=True)
        ]
    return lines


def inertial_lines(robot, i: int) -> list[str]:
    """``mass`` and ``com`` lines of joint `i` (0-based), if the robot has them."""
    if not robot.inertials or robot.inertials[i] is None:
        return []
    mass, com = robot.inertials[i]
    return [f"mass = {float(mass)!r}", "com = [" + ", ".join(repr(float(v)) for v in com) + "]"]


def _user_lines(robot, term) -> list[str]:
    """A ``[[terms]]`` table for a term written in Python: its function by import path."""
    function = term.build
    module, name = getattr(function, "__module__", None), getattr(function, "__qualname__", "")
    if not module or module == "__main__" or "<" in name or "." in name:
        raise CalibrationError(
            f"robot {robot.name!r}: error term {term.kind!r} is a function that cannot be "
            "imported again (a lambda, a nested function or one in a script); define it at "
            "the top of a module to save it, or keep its values (--deviations-out)"
        )

    def quote(text: str) -> str:
        return '"' + text.replace("\\", "\\\\").replace('"', '\\"') + '"'

    units = ", ".join(quote(u if isinstance(u, str) else u[0]) for u in term.units)
    lines = [
        "",
        "[[terms]]",
        f"kind = {quote(term.kind)}",
        f"function = {quote(module + ':' + name)}",
        f"joint = {term.joint}",
        f"target = {quote(term.target)}",
        "parameters = [" + ", ".join(quote(n) for n in term.parameters) + "]",
        "values = [" + ", ".join(repr(float(v)) for v in term.values) + "]",
    ]
    if term.units:
        lines.append(f"units = [{units}]")
    if term.data:
        raise CalibrationError(
            f"robot {robot.name!r}: error term {term.kind!r} carries data; only terms whose "
            "function needs nothing but its parameters can be saved"
        )
    return lines


def user_terms(data: dict, label: str) -> list:
    """The ``[[terms]]`` tables of a robot file: terms whose functions are imported."""
    import importlib

    from .terms import ErrorTerm

    out = []
    for k, row in enumerate(data.get("terms", []), start=1):
        where = f"{label}: terms[{k}]"
        if not isinstance(row, dict) or not isinstance(row.get("function"), str):
            raise CalibrationError(f'{where} needs function = "module:name"')
        module, _, name = row["function"].partition(":")
        try:
            function = getattr(importlib.import_module(module), name)
        except (ImportError, AttributeError, ValueError) as exc:
            raise CalibrationError(
                f"{where}: function {row['function']!r} cannot be imported ({exc}); install "
                "or put on the path the module that defines it"
            ) from None
        try:
            out.append(
                ErrorTerm(
                    row.get("kind", name),
                    row.get("joint"),
                    tuple(row.get("parameters", ())),
                    function,
                    tuple(row.get("values", ())),
                    target=row.get("target", "angle"),
                    units=tuple(row.get("units", ())),
                )
            )
        except TypeError as exc:
            raise CalibrationError(f"{where}: {exc}") from None
    return out
