"""A URDF's links and joints as a tree, and the serial chain walked through it.

URDF requires a tree: every link declared once, every joint naming two declared links,
no link with two parent joints and no closed loop. A file that breaks this is refused in
one line naming what breaks it, before any walk (a loop once made the walk below run
forever). Every walk is iterative, so that a chain thousands of joints long costs no
recursion.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET

from ..errors import CalibrationError

MOVABLE = {"revolute": "R", "continuous": "R", "prismatic": "P"}


def check_tree(root: ET.Element, joints: list, label: str) -> None:
    """Raise `CalibrationError` unless `joints` (each with ``name``, ``parent``, ``child``)
    and the ``<link>`` elements of `root` make a tree."""
    links: set[str] = set()
    for el in root.findall("link"):
        name = el.get("name")
        if not name:
            raise CalibrationError(f'{label}: a <link> has no name=; give each link a name="..."')
        if name in links:
            raise CalibrationError(
                f"{label}: link {name!r} is declared twice; a URDF names each link once"
            )
        links.add(name)
    seen: set[str] = set()
    for j in joints:
        if j.name in seen:
            raise CalibrationError(
                f"{label}: joint {j.name!r} appears twice; a URDF names each joint once"
            )
        seen.add(j.name)
        for role, link in (("parent", j.parent), ("child", j.child)):
            if link not in links:
                raise CalibrationError(
                    f"{label}, joint {j.name!r}: its {role} link {link!r} is not declared; add "
                    f'<link name="{link}"/> or correct the name'
                )
    loop = find_loop(joints)
    if loop is not None:
        names, through = loop
        raise CalibrationError(
            f"{label}: closed loop {' -> '.join(names)} (joints {', '.join(through)}); a URDF "
            "must be a tree: remove the joint that closes the loop"
        )
    parents: dict[str, list[str]] = {}
    for j in joints:
        parents.setdefault(j.child, []).append(j.name)
    for link, names in parents.items():
        if len(names) > 1:
            both = ", ".join(map(repr, names[:-1])) + f" and {names[-1]!r}"
            raise CalibrationError(
                f"{label}: link {link!r} has {'two' if len(names) == 2 else len(names)} "
                f"parent joints, {both}; a URDF must be a tree: keep one of them"
            )


def find_loop(joints: list) -> tuple[list[str], list[str]] | None:
    """A closed loop of `joints` as (links, first repeated at the end; joints), or None.

    An iterative depth-first walk from each link, links sorted so that the answer does not
    depend on the file's order.
    """
    below: dict[str, list] = {}
    for j in joints:
        below.setdefault(j.parent, []).append(j)
    state: dict[str, int] = {}  # 1: on the current path, 2: done
    for start in sorted(below):
        if start in state:
            continue
        path, used, pending = [start], [], [iter(below[start])]
        state[start] = 1
        while pending:
            j = next(pending[-1], None)
            if j is None:  # every joint below path[-1] done
                state[path.pop()] = 2
                pending.pop()
                if used:
                    used.pop()
            elif state.get(j.child) == 1:
                at = path.index(j.child)
                return [*path[at:], j.child], [*(k.name for k in used[at:]), j.name]
            elif j.child not in state:
                state[j.child] = 1
                path.append(j.child)
                used.append(j)
                pending.append(iter(below.get(j.child, ())))
    return None


def chain_path(joints: list, base_link: str | None, tip_link: str | None, label: str, links=None):
    """The joints from `base_link` to `tip_link` (defaults in `casecal.model.urdf.read_urdf`),
    in order, with the two ends; `joints` must pass `check_tree`. `links`: the names the
    file declares, in its order (default: those its joints name), listed when an end is
    not one of them."""
    if not joints:
        raise CalibrationError(
            f"{label}: the URDF has no joints: nothing moves; a robot to calibrate needs "
            "revolute, continuous or prismatic joints"
        )
    if all(j.kind == "fixed" for j in joints):
        raise CalibrationError(
            f"{label}: the URDF has no movable joint (only fixed ones); a robot to calibrate "
            "needs revolute, continuous or prismatic joints"
        )
    by_child = {j.child: j for j in joints}
    if links is None:
        links = list(dict.fromkeys(x for j in joints for x in (j.parent, j.child)))
    roots = sorted({j.parent for j in joints} - set(by_child))
    if base_link is None:
        if len(roots) != 1:
            raise CalibrationError(
                f"{label}: several root links ({', '.join(roots)}); give base_link= one of "
                "them (--base-link on the command line)"
            )
        base_link = roots[0]
    _check_named(base_link, "base", links, label)
    if tip_link is None:
        tip_link = _default_tip(joints, by_child, base_link, label)
    _check_named(tip_link, "tip", links, label)
    path = path_to(tip_link, base_link, by_child)
    if path is None:
        raise CalibrationError(f"{label}: link {tip_link!r} is not below {base_link!r}")
    return path, base_link, tip_link


def _check_named(link: str, end: str, links: list, label: str) -> None:
    """Refuse a chain end the file does not declare, listing (the first of) its links."""
    if link in links:
        return
    shown = ", ".join(links[:SHOWN]) + (f", ... ({len(links)} links)" if len(links) > SHOWN else "")
    raise CalibrationError(
        f"{label}: no link {link!r} in the file; its links: {shown}; give one of them with "
        f"--{end}-link ({end}_link= in Python)"
    )


SHOWN = 12
"""Links a message lists at most: a generated URDF may hold thousands."""


def path_to(link: str, base_link: str, by_child: dict) -> list | None:
    """The joints from `base_link` down to `link`, or None if `link` is not below it.

    Iterative, and a link met twice ends the walk: even a loop that `check_tree` did not
    see cannot make it run forever.
    """
    path, visited = [], set()
    while link != base_link:
        if link not in by_child or link in visited:
            return None
        visited.add(link)
        path.append(by_child[link])
        link = path[-1].parent
    return path[::-1]


def _default_tip(joints: list, by_child: dict, base_link: str, label: str) -> str:
    """The end of the one chain below `base_link` with the most movable joints (``tool0``
    among equals)."""
    leaves = sorted({j.child for j in joints} - {j.parent for j in joints})
    paths = {leaf: path_to(leaf, base_link, by_child) for leaf in leaves}
    paths = {k: v for k, v in paths.items() if v is not None}
    moving = {k: tuple(j.name for j in v if j.kind in MOVABLE) for k, v in paths.items()}
    most = max((len(m) for m in moving.values()), default=0)
    if most == 0:
        raise CalibrationError(
            f"{label}: no revolute, continuous or prismatic joint below {base_link!r}; give "
            "base_link= (--base-link on the command line) the link a movable chain starts at"
        )
    tips = [k for k, m in moving.items() if len(m) == most]
    if len({moving[k] for k in tips}) == 1 and "tool0" in tips:
        tips = ["tool0"]
    if len(tips) != 1:
        raise CalibrationError(
            f"{label}: more than one chain ends here; give tip_link= one of "
            f"{', '.join(tips)} (--tip-link on the command line), or a list of several for "
            f"the tree measured at each (--tip-link {','.join(tips[:2])})"
        )
    return tips[0]
