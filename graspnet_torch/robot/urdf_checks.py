"""The checks of a parsed URDF, run once when it is read (:class:`~graspnet_torch.robot.chain.UrdfModel`),
so every entry point gets them before any kinematics: each mistake is one :class:`ConfigError` line
naming the file, the joint or link, and the attribute.

- the size: at most :data:`MAX_URDF_LINKS` links and joints, :data:`MAX_URDF_SHAPES` shapes, no
  link more than :data:`MAX_URDF_DEPTH` joints below its root (far beyond any robot: these bound
  the time and memory of building the kinematic tree);
- the tree: every joint's parent and child are links of the file, no link is the child of two
  joints, no link is its own ancestor (a cycle), no name is used twice;
- the joints: of a type pytorch-kinematics knows (revolute, continuous, prismatic, fixed), origins
  finite (translations within +-:data:`MAX_URDF_LENGTH_M`), axes finite and of length 1e-6 to
  1e6, limits finite (a prismatic joint's within +-:data:`MAX_URDF_LENGTH_M`) with ``lower <=
  upper``, a ``<mimic>`` of another joint of the file with a finite multiplier and offset;
- the links' shapes: origins finite, box, cylinder and sphere sizes finite and not negative, mesh
  scales finite.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from graspnet_torch.errors import ConfigError
from graspnet_torch.settings import clip, short

__all__ = ["MAX_URDF_DEPTH", "MAX_URDF_LENGTH_M", "MAX_URDF_LINKS", "MAX_URDF_SHAPES", "check_urdf"]

MAX_URDF_LENGTH_M = 100.0  # a joint's translation or a prismatic limit: far beyond any robot's
MAX_URDF_LINKS = 1000  # links, and joints: a humanoid with two dexterous hands has about 100
MAX_URDF_DEPTH = 64  # joints from the root to any link (pytorch-kinematics builds its tree recursively)
MAX_URDF_SHAPES = 10_000  # <visual> and <collision> elements of all links

MOVABLE = ("revolute", "continuous", "prismatic")


def _numbers(values: Any) -> list[float] | None:
    try:
        return [float(v) for v in values]
    except (TypeError, ValueError):
        return None


def _check_numbers(values: Any, where: str, bound: float | None = None, unit: str = "") -> None:
    """``values`` (a sequence, or None: the URDF default) finite, within +-``bound`` when given."""
    if values is None:
        return
    numbers = _numbers(values)
    if numbers is None or not all(math.isfinite(v) and (bound is None or abs(v) <= bound) for v in numbers):
        within = f" within +-{bound:g}{unit}" if bound is not None else ""
        shown = numbers if numbers is not None else values
        if isinstance(shown, list) and len(shown) == 1:
            raise ConfigError(f"{where}={short(shown[0])}: expected a finite number{within}")
        raise ConfigError(f"{where}={short(shown)}: expected finite numbers{within}")


def _check_origin(origin: Any, where: str) -> None:
    if origin is None:
        return
    _check_numbers(origin.xyz, f"{where} <origin> xyz", MAX_URDF_LENGTH_M, " m")
    _check_numbers(origin.rpy, f"{where} <origin> rpy")


def _check_tree(robot: Any, where: str) -> None:
    """Names used once, joints between links of the file, one parent per link, no cycle."""
    for what, items in (("links", robot.links), ("joints", robot.joints)):
        if len(items) > MAX_URDF_LINKS:
            raise ConfigError(f"{where}: {len(items)} {what}; at most {MAX_URDF_LINKS} are supported")
    shapes = sum(len(link.visuals) + len(link.collisions) for link in robot.links)
    if shapes > MAX_URDF_SHAPES:
        raise ConfigError(f"{where}: {shapes} <visual> and <collision> elements; at most {MAX_URDF_SHAPES} are "
                          f"supported")
    links: set[str] = set()
    for link in robot.links:
        if link.name in links:
            raise ConfigError(f"{where}: link '{clip(str(link.name), 60)}' is defined twice")
        links.add(link.name)
    joints: set[str] = set()
    parent_of: dict[str, Any] = {}
    for joint in robot.joints:
        name = clip(str(joint.name), 60)
        if joint.name in joints:
            raise ConfigError(f"{where}: joint '{name}' is defined twice")
        joints.add(joint.name)
        for role, link in (("parent", joint.parent), ("child", joint.child)):
            if link not in links:
                raise ConfigError(f"{where}: joint '{name}' <{role}> link '{clip(str(link), 60)}' is not a link "
                                  f"of the file")
        if joint.parent == joint.child:
            raise ConfigError(f"{where}: joint '{name}' joins link '{clip(str(joint.child), 60)}' to itself")
        if joint.child in parent_of:
            raise ConfigError(f"{where}: link '{clip(str(joint.child), 60)}' is the child of two joints, "
                              f"'{clip(str(parent_of[joint.child].name), 60)}' and '{name}' (a URDF is a tree)")
        parent_of[joint.child] = joint
    # one parent per link: walking up from each link either ends at a root or comes back (a cycle)
    depth: dict[str, int] = {}
    for start in (link.name for link in robot.links):  # in file order: the same line every time
        path: list[str] = []
        seen: set[str] = set()
        link = start
        while link in parent_of and link not in depth:
            if link in seen:
                cycle = path[path.index(link):]
                joint_names = ", ".join(f"'{clip(str(parent_of[c].name), 40)}'" for c in cycle[:6])
                loop = " <- ".join(clip(c, 40) for c in [*cycle[:6], link])
                more = f" and {len(cycle) - 6} more" if len(cycle) > 6 else ""
                raise ConfigError(f"{where}: joints {joint_names}{more} form a cycle: link '{clip(link, 60)}' is its "
                                  f"own ancestor ({loop}; a URDF is a tree)")
            seen.add(link)
            path.append(link)
            link = parent_of[link].parent
        below = depth.get(link, 0)
        for k, name in enumerate(reversed(path), start=1):
            depth[name] = below + k
        if path and depth[path[0]] > MAX_URDF_DEPTH:
            raise ConfigError(f"{where}: link '{clip(path[0], 60)}' is {depth[path[0]]} joints below its root link; "
                              f"at most {MAX_URDF_DEPTH} are supported")


def _check_joint(joint: Any, names: set[str], where: str) -> None:
    what = f"{where}: joint '{clip(str(joint.name), 60)}'"
    if joint.type not in (*MOVABLE, "fixed"):  # floating, planar: pytorch-kinematics has no such joint
        raise ConfigError(f"{what} type='{clip(str(joint.type), 40)}': not supported (expected revolute, continuous, "
                          f"prismatic or fixed)")
    _check_origin(joint.origin, what)
    if joint.type == "fixed":
        return
    if joint.axis is not None:
        axis = _numbers(joint.axis)
        if axis is None or len(axis) != 3 or not all(math.isfinite(a) for a in axis) \
                or not 1e-6 <= math.hypot(*axis) <= 1e6:
            raise ConfigError(f"{what} <axis> xyz={short(axis if axis is not None else joint.axis)}: expected a "
                              f"direction (3 finite numbers, of length 1e-6 to 1e6)")
    limit = joint.limit
    if limit is not None and joint.type != "continuous":  # a continuous joint's limits are not read
        bound = MAX_URDF_LENGTH_M if joint.type == "prismatic" else None
        for key, value in (("lower", limit.lower), ("upper", limit.upper)):
            if value is not None:
                _check_numbers([value], f"{what} <limit> {key}", bound, " m" if bound else "")
        if limit.lower is not None and limit.upper is not None and float(limit.lower) > float(limit.upper):
            raise ConfigError(f"{what} <limit>: lower={float(limit.lower):g} > upper={float(limit.upper):g}")
    mimic = joint.mimic
    if mimic is not None:
        if mimic.joint not in names:
            raise ConfigError(f"{what} <mimic> joint='{clip(str(mimic.joint), 60)}' is not a joint of the file")
        if mimic.joint == joint.name:
            raise ConfigError(f"{what} <mimic> joint='{clip(str(mimic.joint), 60)}': a joint cannot mimic itself")
        for key, value in (("multiplier", mimic.multiplier), ("offset", mimic.offset)):
            if value is not None:
                _check_numbers([value], f"{what} <mimic> {key}")


def _check_shapes(link: Any, where: str) -> None:
    from pytorch_kinematics.urdf_parser_py.urdf import Box, Cylinder, Mesh, Sphere

    what = f"{where}: link '{clip(str(link.name), 60)}'"
    elements: Iterable[tuple[str, Any]] = [*(("visual", v) for v in link.visuals),
                                           *(("collision", c) for c in link.collisions)]
    for kind, element in elements:
        _check_origin(element.origin, f"{what} <{kind}>")
        g = element.geometry
        if isinstance(g, Box):
            sizes = [("size", g.size)]
        elif isinstance(g, Cylinder):
            sizes = [("radius", [g.radius]), ("length", [g.length])]
        elif isinstance(g, Sphere):
            sizes = [("radius", [g.radius])]
        else:
            sizes = []
        for key, values in sizes:
            _check_numbers(values, f"{what} <{kind}> {key}")
            if values is not None and any(float(v) < 0 for v in values):
                shown = list(values) if len(values) > 1 else values[0]
                raise ConfigError(f"{what} <{kind}> {key}={short(shown)}: expected sizes >= 0")
        if isinstance(g, Mesh):
            _check_numbers(g.scale, f"{what} <{kind}> <mesh> scale")


def check_urdf(robot: Any, path: str | Path) -> None:
    """Refuse, in one :class:`ConfigError` line naming ``path``, a parsed URDF (pytorch-kinematics'
    ``URDF``) this project cannot compute with (see the module docstring)."""
    where = clip(str(path), 200)
    _check_tree(robot, where)
    names = {j.name for j in robot.joints}
    for joint in robot.joints:
        _check_joint(joint, names, where)
    for link in robot.links:
        _check_origin(link.origin, f"{where}: link '{clip(str(link.name), 60)}'")
        _check_shapes(link, where)
