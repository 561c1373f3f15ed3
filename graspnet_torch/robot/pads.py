"""Finger pads: where each finger touches an object in the "surface" contact model.

A finger's *pad* is a point on its distal link's surface and the outward unit normal there, both
in the finger's *tip frame*: the frame the finger kernels compute (the finger chain's tip link,
moved by the config's ``tip_offset``; same axes as the tip link). A grasp puts the pad point on
the contact with the pad normal along the object's inward normal
(:func:`graspnet_torch.collision.surface.pad_targets`), instead of the tip frame's origin.

A robot config may give a finger's pad (``fingers.<name>.pad: {link, point, normal}``, in
``link``'s frame; :class:`~graspnet_torch.robot.config.PadCfg`); the link must be the tip link or
one of its ancestors rigidly attached to it (only fixed joints between them), so that the pad is
constant in the tip frame. Otherwise the pad is *derived* from the URDF:

- the *distal link*: the nearest link at or above the tip, rigidly attached to it, that has
  collision geometry (none: refused in one line naming the finger and what to give);
- the *normal*: the direction the tip moves when the finger's last free joint closes (the sense,
  increasing or decreasing, whose limit puts the tip nearer the palm frame's origin:
  :func:`closing_sense`), from the finger kernel's Jacobian at the home posture, in the tip frame
  (for a revolute last joint ``axis x (tip - joint origin)``, for a prismatic one its axis;
  constant in the tip frame when the last free joint is the chain's last joint);
- the *point*: the distal link's support point in the normal's direction (the largest ``n . x``
  over its collision surface); points within ``TIE`` (0.5 mm) of the largest are ties, broken by
  the one nearest the tip's normal line (the line through the tip frame's origin along the
  normal): where that line leaves the surface within the tie band, the exit point itself (exact
  for primitives, by ray casting for meshes), else the nearest of points sampled densely over
  the surface.

For the shipped ``hand`` (a cylinder along x ending in a sphere centred on the tip, flexion about
z) the four fingers' pads are derived: ``point = (0, r, 0)``, ``normal = (0, 1, 0)``, depth r, the
distal sphere's radius. Its thumb's is given in the config, ``(0, 0, -r)`` and ``(0, 0, -1)``: the
thumb has no axial rotation, and its closing side (+y) faces the index finger's pad within 30
degrees in 0.1 % of random pinches, the given side in about a third (``tests/robot/test_pads.py``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any, Protocol

import numpy as np
import torch

from graspnet_torch.errors import ConfigError
from graspnet_torch.robot.config import PadCfg, RobotCfg
from graspnet_torch.robot.fingers import FingerKernel
from graspnet_torch.robot.geometry import link_shapes, support, surface_points
from graspnet_torch.robot.transforms import pose_to_matrix_np

__all__ = ["SHIFT_M", "TIE", "Pad", "centred_config", "closing_sense", "derived_pad", "finger_pads"]

TIE = 5e-4  # m: support points within this of the largest n . x are ties
SHIFT_M = 1e-6  # m: a pad point this far off its tip's normal line moves the tip onto that line (centred_config)
SAMPLES = 4000  # surface points per shape where the normal line does not decide


class _Robot(Protocol):  # what finger_pads reads of a Robot (robot/robot.py imports this module)
    cfg: RobotCfg
    urdf: Any
    fingers: dict[str, Any]

    def home_posture(self, dtype: torch.dtype = torch.float64) -> Any: ...


@dataclass(frozen=True, eq=False)
class Pad:
    """A finger's pad, in its tip frame.

    Attributes:
        link: the distal link that carries it.
        point: (3,) the pad point (m), tip frame.
        normal: (3,) its outward unit normal, tip frame.
    """

    link: str
    point: np.ndarray
    normal: np.ndarray

    @property
    def depth(self) -> float:
        """``point . normal`` (m): how far out along its normal the pad lies from the tip frame's
        origin (the shipped hand: the distal sphere's radius)."""
        return float(self.point @ self.normal)


def finger_pads(robot: _Robot) -> dict[str, Pad]:
    """Finger name -> :class:`Pad`, in the robot's finger order: the config's ``pad`` where given
    (checked: :class:`ConfigError` naming the file and key), else derived (module docstring).
    A robot without fingers (a gripper) has none: ``{}``."""
    if not robot.fingers:
        return {}
    home = robot.home_posture().fingers.numpy()
    shapes = None
    out = {}
    for k, (name, finger) in enumerate(robot.fingers.items()):
        cfg = robot.cfg.fingers[name]
        tip_in_link = np.eye(4) if cfg.tip_offset is None else pose_to_matrix_np([*cfg.tip_offset, 0, 0, 0])
        if cfg.pad is not None:
            out[name] = _given(robot, name, cfg.pad, tip_in_link)
            continue
        if shapes is None:
            shapes = {}
            for s in link_shapes(robot.urdf, "collision"):
                shapes.setdefault(s.link, []).append(s)
        normal = _closing_direction(robot, name, finger, home[k, :finger.n_joints])
        out[name] = _derived(robot, name, tip_in_link, normal, shapes)
    return out


def centred_config(robot: _Robot, pads: dict[str, Pad]) -> RobotCfg | None:
    """The robot's config with each finger's tip moved onto its pad's normal line, or None where
    every pad ``pads`` (:func:`finger_pads`) lies on it already (within ``SHIFT_M``).

    The surface contact model puts a finger's pad on its contact as the sphere of radius ``depth``
    about the tip point (``tip + depth * outward normal`` on the contact); a pad point off the line
    through the tip along the pad normal (a tip frame at the end of a rounded fingertip, as the
    Allegro's, or at a knuckle, as the D'Claw's) would leave the real pad that far from where the
    model puts it. So the tip point is moved, in its link's frame, by the pad point's part across
    the normal (the config's ``tip_offset`` plus that part), and the pad is given at the same place
    on the same link (``pad:``): in the new tip frame its point is ``depth * normal``. Every part
    of the package then reads the one tip point (kinematics, the FCNN, the point and surface
    models, the results)."""
    fingers = dict(robot.cfg.fingers)
    for name, pad in pads.items():
        across = pad.point - (pad.point @ pad.normal) * pad.normal
        if not float(np.linalg.norm(across)) >= SHIFT_M:
            continue
        chain = fingers[name]
        offset = (np.zeros(3) if chain.tip_offset is None else np.asarray(chain.tip_offset, dtype=np.float64)) + across
        tip_in_link = pose_to_matrix_np([*offset, 0.0, 0.0, 0.0])
        T = np.linalg.inv(_link_in_tip(robot, pad.link, chain.tip, tip_in_link))  # the new tip frame -> the link
        point, normal = T[:3, :3] @ (pad.point - across) + T[:3, 3], T[:3, :3] @ pad.normal
        fingers[name] = replace(chain, tip_offset=tuple(float(v) for v in offset),
                                pad=PadCfg(pad.link, tuple(float(v) for v in point), tuple(float(v) for v in normal)))
    return replace(robot.cfg, fingers=fingers) if fingers != dict(robot.cfg.fingers) else None


def derived_pad(robot: _Robot, name: str, normal: np.ndarray) -> Pad:
    """The pad of finger ``name`` facing ``normal`` (3,), unit, in its tip frame: on its distal
    link's collision surface, where it reaches farthest along ``normal`` (module docstring)."""
    cfg = robot.cfg.fingers[name]
    tip_in_link = np.eye(4) if cfg.tip_offset is None else pose_to_matrix_np([*cfg.tip_offset, 0, 0, 0])
    shapes: dict[str, list] = {}
    for s in link_shapes(robot.urdf, "collision"):
        shapes.setdefault(s.link, []).append(s)
    return _derived(robot, name, tip_in_link, normal, shapes)


def _rigid_links(robot: _Robot, tip: str, root: str) -> list[str]:
    """The tip link and its ancestors up to the first movable joint (or the chain's root), nearest first."""
    links, link = [tip], tip
    joint = robot.urdf.parent_joint.get(link)
    while joint is not None and joint.type == "fixed" and link != root:
        link = joint.parent
        links.append(link)
        joint = robot.urdf.parent_joint.get(link)
    return links


def _link_in_tip(robot: _Robot, link: str, tip: str, tip_in_link: np.ndarray) -> np.ndarray:
    """(4, 4) the pose of ``link`` (rigidly attached to ``tip``) in the tip frame."""
    return np.linalg.inv(robot.urdf.fixed_transform(link, tip) @ tip_in_link)


def _given(robot: _Robot, name: str, pad: PadCfg, tip_in_link: np.ndarray) -> Pad:
    """A config's pad, checked against the URDF and moved into the tip frame."""
    where = f"{robot.cfg.source}: fingers.{name}.pad.link"
    chain = robot.fingers[name].chain
    robot.urdf.check_link(pad.link, where)
    tip = chain.tip
    if pad.link not in _rigid_links(robot, tip, chain.root):
        path, link = [], tip
        while link != pad.link and link in robot.urdf.parent_joint:
            joint = robot.urdf.parent_joint[link]
            path.append(joint)
            link = joint.parent
        moving = [j for j in path if j.type != "fixed"]
        if link != pad.link or not moving:
            raise ConfigError(f"{where}: link '{pad.link}' is not the tip link '{tip}' of finger '{name}' or one of "
                              f"its ancestors")
        raise ConfigError(f"{where}: link '{pad.link}' is not rigidly attached to the tip '{tip}' ({moving[-1].type} "
                          f"joint '{moving[-1].name}' between them); give the pad on a link with only fixed joints "
                          f"between it and the tip")
    T = _link_in_tip(robot, pad.link, tip, tip_in_link)
    normal = T[:3, :3] @ np.asarray(pad.normal, dtype=np.float64)
    point = T[:3, :3] @ np.asarray(pad.point, dtype=np.float64) + T[:3, 3]
    return Pad(pad.link, point, normal / np.linalg.norm(normal))


def closing_sense(finger: Any, q: np.ndarray) -> float:
    """+1 where the finger's last free joint closes it as it increases, -1 as it decreases: the
    sense whose limit puts the tip nearer the palm frame's origin (the other free joints at ``q``
    (n_f,), the home posture). A finger curls toward its palm; URDFs disagree on the sign (the
    shipped hand closes positively, the Dexmate F5D6's fingers and TriFinger's negatively)."""
    chain, near = finger.chain, []
    for limit in (chain.lower[-1], chain.upper[-1]):
        at = np.array(q, dtype=np.float64)
        at[-1] = limit
        near.append(float(np.linalg.norm((finger.base_in_palm @ chain.transform(at))[:3, 3])))
    return 1.0 if near[1] <= near[0] else -1.0


def _closing_direction(robot: _Robot, name: str, finger: Any, q: np.ndarray) -> np.ndarray:
    """(3,) unit direction, tip frame, in which the tip moves as the finger's last free joint
    closes (:func:`closing_sense`), at the free joints ``q`` (n_f,) (the home posture)."""
    chain = finger.chain
    qt = torch.as_tensor(q, dtype=torch.float64)
    _, J = FingerKernel(chain).position_jacobian(qt)
    R = chain.transform(q)[:3, :3]  # the tip frame in the finger's base frame
    v = closing_sense(finger, q) * (R.T @ J[:, -1].numpy())
    norm = float(np.linalg.norm(v))
    if not norm > 1e-9:
        raise ConfigError(f"{robot.cfg.source}: fingers.{name}: its last free joint '{chain.joint_names[-1]}' does "
                          f"not move its tip at the home posture, so no pad normal can be derived; give "
                          f"fingers.{name}.pad: {{link: <link>, point: [x, y, z], normal: [nx, ny, nz]}}")
    return v / norm


def _derived(robot: _Robot, name: str, tip_in_link: np.ndarray, normal: np.ndarray, shapes: dict) -> Pad:
    """The pad of finger ``name`` on its distal link's collision surface (module docstring);
    :class:`ConfigError` where no link from its tip up to its last movable joint has any."""
    chain = robot.fingers[name].chain
    tip = chain.tip
    rigid = _rigid_links(robot, tip, chain.root)
    distal = next((link for link in rigid if shapes.get(link)), None)
    if distal is None:
        raise ConfigError(f"{robot.cfg.source}: fingers.{name}: no pad can be derived: none of its links "
                          f"{', '.join(repr(x) for x in rigid)} (its tip, rigidly attached) has collision geometry; "
                          f"give the link a <collision> in the URDF, or give fingers.{name}.pad: {{link: <link>, "
                          f"point: [x, y, z], normal: [nx, ny, nz]}}")
    T = _link_in_tip(robot, distal, tip, tip_in_link)
    placed = [(s, T @ s.origin) for s in shapes[distal]]
    height = max(support(s, P, normal) for s, P in placed)
    exits = [t for t in (_line_exit(s, P, normal, height) for s, P in placed) if t is not None]
    if exits and max(exits) >= height - TIE:
        return Pad(distal, max(exits) * normal, normal)
    points = np.concatenate([surface_points(s, P, SAMPLES) for s, P in placed])
    band = points[points @ normal >= height - TIE]
    lateral = np.linalg.norm(band - np.outer(band @ normal, normal), axis=1)
    return Pad(distal, band[int(np.argmin(lateral))], normal)


def _mesh_vertices(s: Any, P: np.ndarray) -> np.ndarray:
    return np.asarray(s.mesh.vertices, dtype=np.float64) @ P[:3, :3].T + P[:3, 3]


def _interval(o: float, d: float, lo: float, hi: float) -> tuple[float, float] | None:
    """The t with ``lo <= o + t d <= hi`` (a slab), or None."""
    if abs(d) < 1e-12:
        return (-math.inf, math.inf) if lo <= o <= hi else None
    a, b = (lo - o) / d, (hi - o) / d
    return min(a, b), max(a, b)


def _disc(o: np.ndarray, d: np.ndarray, r: float) -> tuple[float, float] | None:
    """The t with ``|o + t d| <= r`` (o, d: (2,) or (3,)), or None."""
    a = float(d @ d)
    if a < 1e-24:
        return (-math.inf, math.inf) if o @ o <= r * r else None
    b, c = float(o @ d) / a, (float(o @ o) - r * r) / a
    if b * b - c < 0:
        return None
    root = math.sqrt(b * b - c)
    return -b - root, -b + root


def _line_exit(s: Any, P: np.ndarray, n: np.ndarray, height: float) -> float | None:
    """The largest t at which the line ``t n`` (through the tip frame's origin) lies in a shape
    placed by ``P``, or None where it misses."""
    if s.kind == "mesh":
        import trimesh

        mesh = trimesh.Trimesh(_mesh_vertices(s, P), np.asarray(s.mesh.faces), process=False)
        start = (height + 1.0) * n
        hits, _, _ = mesh.ray.intersects_location(start[None], -n[None], multiple_hits=True)
        return float((hits @ n).max()) if len(hits) else None
    o, d = -P[:3, :3].T @ P[:3, 3], P[:3, :3].T @ n
    if s.kind == "sphere":
        parts = [_disc(o, d, s.size[0])]
    elif s.kind == "box":
        parts = [_interval(o[i], d[i], -s.size[i] / 2, s.size[i] / 2) for i in range(3)]
    else:
        parts = [_disc(o[:2], d[:2], s.size[0]), _interval(o[2], d[2], -s.size[1] / 2, s.size[1] / 2)]
    if any(p is None for p in parts):
        return None
    lo, hi = max(p[0] for p in parts), min(p[1] for p in parts)
    return hi if lo <= hi else None
