"""URDF-convention joints in robot files (TOML): one ``[[joints]]`` table per actuated
joint (name, type, axis, xyz, rpy, offset, limits) and its mimic joints (``passive``)."""

from __future__ import annotations

import numpy as np

from ..errors import CalibrationError
from .urdf import PassiveJoint, UrdfJoint

_ROW_KEYS = {"name", "type", "axis", "xyz", "rpy", "offset", "limits", "passive"}
_PASSIVE_KEYS = {"name", "type", "axis", "xyz", "rpy", "master", "multiplier", "offset"}


def joint_from_row(row: dict, where: str, length: float, angle: float, label: str, number):
    """A `UrdfJoint` from one ``[[joints]]`` table of a robot file with convention "urdf"."""
    unknown = sorted(set(row) - _ROW_KEYS)
    if unknown:
        raise CalibrationError(f"{label}: {where} has unknown key {unknown[0]!r}")
    if not isinstance(row.get("name"), str) or row.get("type") not in ("R", "P"):
        raise CalibrationError(f'{label}: {where} needs name = "..." and type = "R" or "P"')

    def triple(key, scale, default=None):
        value = row.get(key, default)
        if not isinstance(value, list) or len(value) != 3:
            raise CalibrationError(f"{label}: {where}.{key} must be [x, y, z]")
        return tuple(number(v, label, f"{where}.{key}") * scale for v in value)

    axis = np.array(triple("axis", 1.0))
    if np.linalg.norm(axis) == 0:
        raise CalibrationError(f"{label}: {where}.axis is zero")
    limits = None
    if "limits" in row:
        lim = row["limits"]
        if not isinstance(lim, list) or len(lim) != 2:
            raise CalibrationError(f"{label}: {where}.limits must be [min, max]")
        scale = length if row["type"] == "P" else angle
        limits = tuple(number(v, label, f"{where}.limits") * scale for v in lim)
    passive = []
    for k, item in enumerate(row.get("passive", []), start=1):
        if not isinstance(item, dict) or set(item) - _PASSIVE_KEYS or "master" not in item:
            raise CalibrationError(
                f"{label}: {where}.passive[{k}] needs name, type, axis, xyz, rpy, master "
                "(1-based actuated joint), multiplier, offset"
            )
        sub = joint_from_row(
            {key: item[key] for key in ("name", "type", "axis", "xyz", "rpy") if key in item},
            f"{where}.passive[{k}]",
            length,
            angle,
            label,
            number,
        )
        scale = angle if sub.type == "R" else length
        passive.append(
            PassiveJoint(
                sub.name,
                sub.type,
                sub.axis,
                sub.xyz,
                sub.rpy,
                int(item["master"]) - 1,
                number(item.get("multiplier", 1.0), label, f"{where}.passive[{k}].multiplier"),
                number(item.get("offset", 0.0), label, f"{where}.passive[{k}].offset") * scale,
            )
        )
    return UrdfJoint(
        name=row["name"],
        type=row["type"],
        axis=tuple(float(v) for v in axis / np.linalg.norm(axis)),
        xyz=triple("xyz", length, [0, 0, 0]),
        rpy=triple("rpy", angle, [0, 0, 0]),
        offset=number(row.get("offset", 0.0), label, f"{where}.offset") * angle,
        limits=limits,
        passive=tuple(passive),
    )


def joint_to_lines(j: UrdfJoint, quote) -> list[str]:
    """The lines of one ``[[joints]]`` table (m, rad) that `joint_from_row` reads back."""

    def three(values):
        return "[" + ", ".join(repr(float(v)) for v in values) + "]"

    lines = [
        f"name = {quote(j.name)}",
        f"type = {quote(j.type)}",
        f"axis = {three(j.axis)}",
        f"xyz = {three(j.xyz)}",
        f"rpy = {three(j.rpy)}",
        f"offset = {float(j.offset)!r}",
    ]
    if j.limits is not None:
        lines.append(f"limits = [{float(j.limits[0])!r}, {float(j.limits[1])!r}]")
    if j.passive:
        items = [
            f"{{name = {quote(p.name)}, type = {quote(p.type)}, axis = {three(p.axis)}, "
            f"xyz = {three(p.xyz)}, rpy = {three(p.rpy)}, master = {p.master + 1}, "
            f"multiplier = {float(p.multiplier)!r}, offset = {float(p.offset)!r}}}"
            for p in j.passive
        ]
        lines.append("passive = [" + ", ".join(items) + "]")
    return lines
