"""The MuJoCo model of a grasp: the robot from its URDF, placed and held as a result reports it,
and the problem's object as a free body (MJCF text, :func:`grasp_mjcf`).

The protocol it serves (:mod:`graspnet_torch.physics.config`) is DexGraspBench's: friction 0.6
tangential / 0.02 torsional, elliptic cones, object 100 g, timestep 4 ms, an external force of the
object's weight along +-x, +-y, +-z in turn for 2 s each; holds when the object moves less than
5 cm and turns less than 15 degrees.

The model, in the problem's world frame:

- the robot's URDF tree, one body per link, written here from the package's own URDF model (its
  link frames, joint axes and limits, collision shapes: primitives as primitives, meshes by their
  convex hulls, whatever the file format or ``package://`` path), so MuJoCo's URDF reader and its
  mesh-path rules play no part;
- its root link fixed where the posture places it (a free hand: the palm pose; a robot with a body:
  its base at the world origin), the body joints (arm, mobile base) locked at the posture's values,
  a free hand's wrist joints (between its root and palm) locked where the robot holds them
  (:attr:`Robot.wrist <graspnet_torch.robot.robot.Robot.wrist>`): the links above the palm rigid
  with it;
- every other movable joint a MuJoCo joint within its limits, with a position actuator (gain
  ``kp``, joint damping and armature, force limit ``max_effort`` or the URDF ``effort``), mimic
  joints an equality constraint on their leader instead;
- link masses and inertias from the URDF where given, else from the collision shapes (density
  1000 kg/m^3); bodies without either get MuJoCo's bound mass;
- the robot's geoms collide with the object only (self-collision is the solver's check, and
  primitive hands overlap at their knuckles by design); the problem's obstacles are left out
  (DexGraspBench's check has no table);
- the object a free body (box, cylinder, sphere; a mesh by its convex pieces, the collision
  proxy's convex decomposition) of ``object_mass_kg``, uniform density, at the problem's pose.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np
from scipy.spatial import ConvexHull

from graspnet_torch.collision.convex import convex_pieces
from graspnet_torch.errors import ProblemError
from graspnet_torch.physics.config import PhysicsCfg
from graspnet_torch.robot.chain import joint_motion, origin_matrix
from graspnet_torch.robot.geometry import LinkShape, link_shapes
from graspnet_torch.robot.robot import Posture, Robot
from graspnet_torch.robot.transforms import pose_to_matrix_np

__all__ = ["OBJECT_BODY", "GraspModel", "grasp_mjcf", "posed_bodies", "quaternion"]

OBJECT_BODY = "grasped_object"
ROBOT_BITS = (2, 1)  # contype, conaffinity: robot geoms touch the object, never each other
OBJECT_BITS = (1, 2)


@dataclass(frozen=True)
class GraspModel:
    """The MJCF of a grasp and what the check needs to run it.

    Attributes:
        xml: the MJCF text.
        start: movable MuJoCo joint name -> its initial value (rad or m): the grasp posture.
        targets: actuator name (its joint's) -> its commanded value: the squeeze posture.
    """

    xml: str
    start: dict[str, float]
    targets: dict[str, float]


def _fmt(values) -> str:
    return " ".join(repr(float(v)) for v in np.ravel(values))


def quaternion(R: np.ndarray) -> np.ndarray:
    """(3, 3) rotation -> (4,) unit quaternion (w, x, y, z), from its largest component (exact to
    rounding everywhere)."""
    t = np.trace(R)
    if t >= max(R[0, 0], R[1, 1], R[2, 2]):
        w = math.sqrt(1.0 + t) / 2
        q = [w, (R[2, 1] - R[1, 2]) / (4 * w), (R[0, 2] - R[2, 0]) / (4 * w), (R[1, 0] - R[0, 1]) / (4 * w)]
    else:
        i = int(np.argmax(np.diag(R)))
        j, k = (i + 1) % 3, (i + 2) % 3
        v = np.zeros(3)
        v[i] = math.sqrt(max(0.0, 1.0 + R[i, i] - R[j, j] - R[k, k])) / 2
        v[j] = (R[j, i] + R[i, j]) / (4 * v[i])
        v[k] = (R[k, i] + R[i, k]) / (4 * v[i])
        q = [(R[k, j] - R[j, k]) / (4 * v[i]), *v]
    q = np.asarray(q)
    return q / np.linalg.norm(q)


def _place(el: ET.Element, T: np.ndarray) -> None:
    """Set an element's pos and quat from a (4, 4) pose in its parent's frame."""
    el.set("pos", _fmt(T[:3, 3]))
    el.set("quat", _fmt(quaternion(T[:3, :3])))


def _geom(parent: ET.Element, kind: str, size, T: np.ndarray | None, bits: tuple[int, int], **extra) -> ET.Element:
    g = ET.SubElement(parent, "geom", type=kind, contype=str(bits[0]), conaffinity=str(bits[1]))
    if size is not None:
        g.set("size", _fmt(size))
    if T is not None:
        _place(g, T)
    for k, v in extra.items():
        g.set(k, v)
    return g


def _body_name(link: str) -> str:
    """A link's body name: its own, but MuJoCo's ``world`` is taken (an arm's URDF root often has it)."""
    return "urdf_world" if link == "world" else link


def _primitive_size(kind: str, size) -> list[float]:
    """MuJoCo's size of a box (half extents), cylinder (radius, half length) or sphere (radius)."""
    if kind == "box":
        return [s / 2 for s in size]
    if kind == "cylinder":
        return [size[0], size[1] / 2]
    return [size[0]]


def _locked(robot: Robot) -> set[str]:
    """The joints a grasp's model locks: the body joints (arm, mobile base), a free hand's wrist
    joints and the mimic joints that follow one."""
    locked = set(robot.body_joint_names) | set(robot.wrist)
    return locked | {j for j, (leader, _, _) in robot.urdf.mimic_joints.items() if leader in locked}


def _joint_frame(robot: Robot, j) -> tuple[np.ndarray, np.ndarray, str]:
    """A URDF joint's child frame in its parent's at zero (4, 4), its unit axis and its motion kind."""
    urdf = robot.urdf
    T = origin_matrix(getattr(urdf.links[j.child], "origin", None)) @ origin_matrix(j.origin)
    return T, urdf.joint_axis(j.name), "prismatic" if j.type == "prismatic" else "revolute"


def posed_bodies(robot: Robot, posture: Posture) -> dict[str, np.ndarray]:
    """The bodies of a grasp's model that ``posture`` places, each (4, 4) in its parent's frame:
    the robot's root link (world frame: a free hand's palm pose, else the base) and each child of
    a locked movable joint (:func:`grasp_mjcf`). The rest of the model does not depend on the
    posture: a model built for one posture serves another once these are set (and its actuators'
    targets and joints' values)."""
    values, locked = robot.joint_values(posture), _locked(robot)
    out = {_body_name(robot.urdf.root_link): robot.link_frames(posture)[robot.urdf.root_link]}
    for j in robot.urdf.robot.joints:
        if j.type in ("revolute", "continuous", "prismatic") and j.name in locked:
            T, axis, kind = _joint_frame(robot, j)
            out[_body_name(j.child)] = T @ joint_motion(kind, axis, values.get(j.name, 0.0))
    return out


def grasp_mjcf(robot: Robot, obj, start: Posture, target: Posture, cfg: PhysicsCfg) -> GraspModel:
    """The MJCF of ``robot`` in posture ``start`` (its palm and body where ``start`` puts them),
    its actuators commanded to ``target``'s joints, holding ``obj`` (a problem's object:
    :class:`~graspnet_torch.robot.shape.Shape` kind, size, pose (6,) m/rad in the world, mesh,
    scale)."""
    if obj is None:
        raise ProblemError("the physics check needs the problem's object; this problem has none")
    urdf = robot.urdf
    root = urdf.root_link
    values, goals = robot.joint_values(start), robot.joint_values(target)
    mimic = urdf.mimic_joints
    locked, posed = _locked(robot), posed_bodies(robot, start)

    mj, asset, world, actuators, equality = _mjcf_skeleton(robot, cfg)

    shapes: dict[str, list] = {}
    for s in link_shapes(urdf, "collision"):
        shapes.setdefault(s.link, []).append(s)
    children: dict[str, list] = {}
    for j in urdf.robot.joints:
        children.setdefault(j.parent, []).append(j)

    root_el = ET.SubElement(world, "body", name=_body_name(root))
    _place(root_el, posed[_body_name(root)])
    start_q, targets, meshes = {}, {}, [0]

    def fill(body: ET.Element, link: str) -> None:
        _inertial(body, getattr(urdf.links[link], "inertial", None))
        _link_geoms(body, asset, shapes.get(link, []), meshes)
        for j in children.get(link, []):
            T, axis, kind = _joint_frame(robot, j)
            movable = j.type in ("revolute", "continuous", "prismatic")
            T = posed.get(_body_name(j.child), T)
            child = ET.SubElement(body, "body", name=_body_name(j.child))
            _place(child, T)
            if movable and j.name not in locked:
                _joint(child, j, axis, kind)
            fill(child, j.child)

    def _joint(child: ET.Element, j, axis: np.ndarray, kind: str) -> None:
        el = ET.SubElement(child, "joint", name=j.name, type="slide" if kind == "prismatic" else "hinge",
                           axis=_fmt(axis), damping=f"{cfg.damping:.9g}", armature=f"{cfg.armature:.9g}")
        lim = j.limit
        if j.type != "continuous" and lim is not None and lim.lower is not None and lim.upper is not None \
                and lim.lower < lim.upper:
            el.set("range", _fmt([lim.lower, lim.upper]))
        start_q[j.name] = values.get(j.name, 0.0)
        if j.name in mimic:
            leader, m, b = mimic[j.name]
            ET.SubElement(equality, "joint", joint1=j.name, joint2=leader, polycoef=_fmt([b, m, 0, 0, 0]))
            return
        effort = cfg.max_effort
        if lim is not None and lim.effort is not None and 0 < lim.effort < effort:
            effort = float(lim.effort)
        kp = cfg.kp_prismatic if kind == "prismatic" else cfg.kp
        ET.SubElement(actuators, "position", name=j.name, joint=j.name, kp=f"{kp:.9g}",
                      forcerange=_fmt([-effort, effort]), forcelimited="true")
        targets[j.name] = goals.get(j.name, 0.0)

    fill(root_el, root)
    _object(world, asset, obj, cfg)
    if not len(actuators):
        mj.remove(actuators)
    if not len(equality):
        mj.remove(equality)
    return GraspModel(ET.tostring(mj, encoding="unicode"), start_q, targets)


def _mjcf_skeleton(robot: Robot, cfg: PhysicsCfg) -> tuple[ET.Element, ET.Element, ET.Element, ET.Element, ET.Element]:
    """The model's root element with its compiler, option and default geom settings, and its empty
    asset, worldbody, actuator and equality sections (returned in this order after the root)."""
    mj = ET.Element("mujoco", model=f"grasp_{robot.name}")
    ET.SubElement(mj, "compiler", angle="radian", autolimits="true", balanceinertia="true", boundmass="1e-5",
                  boundinertia="1e-10", inertiafromgeom="auto")
    ET.SubElement(mj, "option", timestep=f"{cfg.timestep_s:.9g}", integrator="implicitfast", cone="elliptic",
                  gravity="0 0 -9.81" if cfg.gravity else "0 0 0")
    default = ET.SubElement(mj, "default")
    ET.SubElement(default, "geom", condim="4", friction=_fmt([cfg.friction, cfg.torsional_friction, 0.0]))
    asset = ET.SubElement(mj, "asset")
    world = ET.SubElement(mj, "worldbody")
    actuators = ET.SubElement(mj, "actuator")
    equality = ET.SubElement(mj, "equality")
    return mj, asset, world, actuators, equality


def _inertial(body: ET.Element, inertial: Any) -> None:
    """A link's URDF ``<inertial>`` (mass in kg, inertia in kg m^2 about its origin) as the body's
    ``inertial`` element, the inertia turned into the body's axes; nothing without a positive mass."""
    if inertial is not None and inertial.mass is not None and inertial.mass > 0:
        i = inertial.inertia
        T = origin_matrix(inertial.origin)
        inertia = np.array([[i.ixx, i.ixy, i.ixz], [i.ixy, i.iyy, i.iyz], [i.ixz, i.iyz, i.izz]]) \
            if i is not None else np.eye(3) * 1e-9
        inertia = T[:3, :3] @ inertia @ T[:3, :3].T  # in the body's axes: MuJoCo takes fullinertia or a quat
        full = [inertia[0, 0], inertia[1, 1], inertia[2, 2], inertia[0, 1], inertia[0, 2], inertia[1, 2]]
        ET.SubElement(body, "inertial", mass=f"{inertial.mass:.9g}", fullinertia=_fmt(full), pos=_fmt(T[:3, 3]))


def _link_geoms(body: ET.Element, asset: ET.Element, shapes: list[LinkShape], meshes: list[int]) -> None:
    """A link's collision shapes as the body's geoms: primitives as primitives, a mesh by its
    convex hull (an asset named by the running count ``meshes[0]``, which it advances)."""
    for s in shapes:
        if s.kind == "mesh":
            name = f"link_mesh_{meshes[0]}"
            meshes[0] += 1
            ET.SubElement(asset, "mesh", name=name, vertex=_fmt(s.mesh.convex_hull.vertices))
            _geom(body, "mesh", None, s.origin, ROBOT_BITS, mesh=name)
        else:
            _geom(body, s.kind, _primitive_size(s.kind, s.size), s.origin, ROBOT_BITS)


def _object(world: ET.Element, asset: ET.Element, obj, cfg: PhysicsCfg) -> None:
    """The object: a free body at its pose, its mass ``cfg.object_mass_kg`` spread uniformly."""
    body = ET.SubElement(world, "body", name=OBJECT_BODY)
    _place(body, pose_to_matrix_np(obj.pose))
    ET.SubElement(body, "freejoint", name=f"{OBJECT_BODY}_free")
    if obj.kind != "mesh":
        _geom(body, obj.kind, _primitive_size(obj.kind, obj.size), None, OBJECT_BITS, mass=f"{cfg.object_mass_kg:.9g}")
        return
    vertices, volume = _pieces(Path(obj.mesh).resolve(), obj.scale)
    density = cfg.object_mass_kg / max(volume, 1e-12)  # the pieces overlap little: about the mass asked
    for k, v in enumerate(vertices):
        ET.SubElement(asset, "mesh", name=f"object_piece_{k}", vertex=v)
        _geom(body, "mesh", None, None, OBJECT_BITS, mesh=f"object_piece_{k}", density=f"{density:.9g}")


@lru_cache(maxsize=32)
def _pieces(path: Path, scale) -> tuple[tuple[str, ...], float]:
    """A mesh object's convex pieces as MJCF vertex lists and their volumes' sum (per file and
    scale: a grasp check per grasp of one object writes them once)."""
    pieces = convex_pieces(path, scale).vertices
    return tuple(_fmt(v) for v in pieces), float(sum(ConvexHull(v).volume for v in pieces))
