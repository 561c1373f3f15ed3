"""Collision counts with python-fcl, the engine of record (docs/contact.md).

A :class:`CollisionScene` holds the robot's links (the URDF's ``<collision>`` primitives and meshes) and the
problem's environment: its obstacles and the grasped object. For a posture it counts

- the distinct (robot link, obstacle) pairs whose geometries intersect, and
- the robot links that penetrate the object by more than ``object_tolerance`` (2 mm), except the
  distal links of the fingers that touch it at their contacts (a gripper's jaws),
- for a robot with ``self_collision: true``, the pairs of its own links that intersect, among the
  pairs that are neither adjacent (one joint apart, links without geometry skipped) nor already
  intersecting at the home posture (joint housings that overlap by construction): the arm
  against its own platform,

and for a robot with a ``floor`` (a mobile base), the floor is an obstacle of every problem: a
slab whose top lies 1 mm below that height (the platform stands on it without touching),

with a broad phase (every shape's oriented box against every other's, all postures at once:
collision/boxes.py; only pairs whose boxes meet go further) and a narrow phase (FCL's
primitive-primitive tests; penetration depth by GJK/EPA).
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field

import numpy as np

from graspnet_torch.collision.boxes import boxes_apart, link_box, shape_box
from graspnet_torch.collision.geometry import fcl_geometry, fcl_transform, link_geometry, mesh_bvh
from graspnet_torch.collision.mesh import mesh_query, shape_points
from graspnet_torch.meshes import mesh_path
from graspnet_torch.robot.geometry import link_shapes
from graspnet_torch.robot.robot import Posture, Robot
from graspnet_torch.robot.shape import Shape
from graspnet_torch.robot.transforms import pose_to_matrix_np
from graspnet_torch.tasks.problem import GraspProblem

__all__ = ["CollisionReport", "CollisionScene", "environment_obstacles", "finger_pairs", "has_environment",
           "self_collision_pairs"]

FLOOR_SIZE = (100.0, 100.0, 1.0)  # m: the floor slab (centred under the world origin)
FLOOR_GAP = 0.001  # m: its top lies this far below the robot's floor height
BROAD_ROWS = 256  # postures per chunk of the broad phase (its arrays: rows x shape pairs x 4 x 4)


def environment_obstacles(robot: Robot, problem: GraspProblem) -> list[Shape]:
    """The problem's obstacles, then the robot's floor (when it has one) as a box obstacle."""
    obstacles = list(problem.obstacles)
    if robot.cfg.floor is not None:
        top = robot.cfg.floor - FLOOR_GAP
        pose = np.array([0.0, 0.0, top - FLOOR_SIZE[2] / 2, 0.0, 0.0, 0.0])
        obstacles.append(Shape("box", FLOOR_SIZE, pose))
    return obstacles


def has_environment(robot: Robot, problem: GraspProblem) -> bool:
    """Whether there is anything to collide with: an object, obstacles, a floor or own links."""
    return bool(problem.object is not None or problem.obstacles or robot.cfg.floor is not None
                or robot.cfg.self_collision)


def self_collision_pairs(robot: Robot) -> list[tuple[str, str]]:
    """The (link, link) pairs checked for self-collision (empty unless ``self_collision: true``):
    links with collision geometry, not adjacent (a joint apart, geometry-less links in between
    skipped), not rigidly joined (no movable joint between them) and not intersecting at the
    home posture (FCL). Computed once per robot."""
    cached = getattr(robot, "_self_collision_pairs", None)
    if cached is not None:
        return cached
    pairs = _apart_at_home(robot, None) if robot.cfg.self_collision else []
    robot._self_collision_pairs = pairs
    return pairs


def finger_pairs(robot: Robot) -> list[tuple[str, str]]:
    """The (link, link) pairs of two different fingers' links (with collision geometry, from the
    fingers' bases to their tips) that do not intersect at the home posture (FCL): fingers through
    each other (the surface contact model counts them). Computed once per robot."""
    cached = getattr(robot, "_finger_pairs", None)
    if cached is None:
        owner = {}
        for name, finger in robot.fingers.items():
            for joint in robot.urdf.path_joints(finger.chain.root, finger.chain.tip):
                owner[joint.child] = name
        cached = robot._finger_pairs = _apart_at_home(robot, owner)
    return cached


def _apart_at_home(robot: Robot, owner: dict[str, str] | None) -> list[tuple[str, str]]:
    """Pairs of links with collision geometry, not adjacent, not rigidly joined and not
    intersecting at the home posture; ``owner`` (link -> finger): only pairs of two fingers."""
    import fcl

    pairs: list[tuple[str, str]] = []
    shapes = link_shapes(robot.urdf, "collision")
    with_geometry = list(dict.fromkeys(s.link for s in shapes))

    def carrier(link: str) -> str | None:  # the nearest ancestor (or itself) with geometry
        while link not in with_geometry and link in robot.urdf.parent_joint:
            link = robot.urdf.parent_joint[link].parent
        return link if link in with_geometry else None

    def moved_by(link: str) -> frozenset:  # the movable joints between the root and the link (a wrist: held)
        joints = set()
        while link in robot.urdf.parent_joint:
            joint = robot.urdf.parent_joint[link]
            if joint.type != "fixed" and joint.name not in robot.wrist:
                joints.add(joint.name)
            link = joint.parent
        return frozenset(joints)

    adjacent = set()
    for link in with_geometry:
        if link in robot.urdf.parent_joint:
            parent = carrier(robot.urdf.parent_joint[link].parent)
            if parent is not None:
                adjacent.add(frozenset((link, parent)))
    frames = robot.link_frames(robot.home_posture())
    objects: dict[str, list] = {}
    for shape in shapes:
        placed = fcl_transform(frames[shape.link] @ shape.origin)
        obj = fcl.CollisionObject(link_geometry(shape), placed)
        objects.setdefault(shape.link, []).append(obj)
    for i, a in enumerate(with_geometry):
        for b in with_geometry[i + 1:]:
            if frozenset((a, b)) in adjacent or moved_by(a) == moved_by(b):  # adjacent or rigidly joined
                continue
            if owner is not None and (owner.get(a) is None or owner.get(b) is None or owner[a] == owner[b]):
                continue  # not two different fingers' links
            if any(fcl.collide(oa, ob, fcl.CollisionRequest(), fcl.CollisionResult())
                   for oa in objects[a] for ob in objects[b]):
                continue
            pairs.append((a, b))
    return pairs

OBJECT_TOLERANCE_M = 0.002


def _environment_object(shape: Shape):
    """An obstacle or the object as an FCL collision object at its pose in the world."""
    import fcl

    T = pose_to_matrix_np(shape.pose)
    if shape.kind == "mesh":
        geometry = mesh_bvh(mesh_path(shape.mesh), shape.scale)
    else:
        geometry = fcl_geometry(shape.kind, shape.size)
    return fcl.CollisionObject(geometry, fcl_transform(T))


@dataclass
class CollisionReport:
    """What :meth:`CollisionScene.check` found: ``count`` (INTERFACE.md's number), the colliding
    (link, obstacle index) pairs (obstacles in problem order, then the robot's floor), the links
    that penetrate the object (with depths in metres) and the colliding pairs of the robot's own
    links."""

    count: int
    obstacle_pairs: list[tuple[str, int]]
    object_links: dict[str, float]
    self_pairs: list[tuple[str, str]] = field(default_factory=list)


class CollisionScene:
    """A robot's links against a problem's obstacles and object.

    Args:
        robot: the robot (its URDF's collision primitives).
        problem: obstacles and object; its contact fingers' distal links may touch the object.
        object_tolerance: penetration of the object (metres) below which a link does not count.
        touching: whether the contact fingers' distal links (a gripper's jaws) may touch the object
            (the reported count); False: they count as any link does (a reach motion's approach).
        fingers_apart: also count two fingers' links that intersect (:func:`finger_pairs`).
    """

    def __init__(self, robot: Robot, problem: GraspProblem, object_tolerance: float = OBJECT_TOLERANCE_M,
                 touching: bool = True, fingers_apart: bool = False):
        import fcl

        self.robot, self.problem, self.object_tolerance = robot, problem, object_tolerance
        self.shapes = link_shapes(robot.urdf, "collision")
        self.link_objects = [fcl.CollisionObject(link_geometry(s), fcl.Transform()) for s in self.shapes]
        self.obstacles = [_environment_object(o) for o in environment_obstacles(robot, problem)]
        self.self_pairs = list(self_collision_pairs(robot))
        if fingers_apart:  # two fingers through each other count too (the surface contact model)
            self.self_pairs += [p for p in finger_pairs(robot) if p not in self.self_pairs]
        self.object = _environment_object(problem.object) if problem.object is not None else None
        self.touching = self.distal_links(robot, self.shapes, problem.fingers) if touching else set()
        # meshes: FCL finds where a link crosses the surface; inside and depth are measured (collision/mesh.py)

        elements = environment_obstacles(robot, problem)
        self._mesh_obstacles = {k: mesh_query(o) for k, o in enumerate(elements) if o.kind == "mesh"}
        self._mesh_object = mesh_query(problem.object) if problem.object is not None and \
            problem.object.kind == "mesh" else None
        self._points: dict[int, np.ndarray] = {}  # link shape index -> its points (shape frame)
        self._shapes_of: dict[str, list[int]] = {}  # link -> its shapes' indices
        for i, shape in enumerate(self.shapes):
            self._shapes_of.setdefault(shape.link, []).append(i)
        self._frame_of: np.ndarray | None = None  # shape -> its link's row in the frames (set on first use)
        self._frame_names: list[str] = []
        # the broad phase (collision/boxes.py): every shape's box, the obstacles', the object's, the
        # self-collision pairs' shape pairs
        boxes = [link_box(s) for s in self.shapes]
        self._box_pose = np.stack([b[0] for b in boxes]) if boxes else np.zeros((0, 4, 4))
        self._box_half = np.stack([b[1] for b in boxes]) if boxes else np.zeros((0, 3))
        around = [shape_box(o) for o in elements]
        self._obstacle_pose = np.stack([b[0] for b in around]) if around else np.zeros((0, 4, 4))
        self._obstacle_half = np.stack([b[1] for b in around]) if around else np.zeros((0, 3))
        self._object_box = shape_box(problem.object) if problem.object is not None else None
        self._object_shapes = np.array([s.link not in self.touching for s in self.shapes], dtype=bool)
        first, second, owner = [], [], []
        for p, (la, lb) in enumerate(self.self_pairs):
            for i in self._shapes_of.get(la, ()):
                for j in self._shapes_of.get(lb, ()):
                    first.append(i)
                    second.append(j)
                    owner.append(p)
        self._pair_first, self._pair_second = np.asarray(first, dtype=int), np.asarray(second, dtype=int)
        self._pair_owner = np.zeros((len(owner), len(self.self_pairs)))
        self._pair_owner[np.arange(len(owner)), owner] = 1.0

    @staticmethod
    def distal_links(robot: Robot, shapes: list, fingers: tuple[str, ...]) -> set[str]:
        """For each finger (and each marked point of a gripper), the link nearest its tip that
        carries collision geometry (the one that touches the object at the contact)."""
        with_geometry = {s.link for s in shapes}
        out = set()
        tips = [robot.cfg.fingers[f].tip for f in fingers] + list(robot.cfg.gripper_points)  # a gripper's jaws too
        for link in tips:
            while link not in with_geometry and link in robot.urdf.parent_joint:
                link = robot.urdf.parent_joint[link].parent
            out.add(link)
        return out

    def check(self, posture: Posture) -> CollisionReport:
        """The collision count of a posture and what makes it up."""
        return self.check_many([posture])[0]

    def check_many(self, postures: Sequence[Posture]) -> list[CollisionReport]:
        """:meth:`check` of several postures (their forward kinematics and broad phase in one pass)."""
        links, frames = self.robot.link_frames_array(postures)
        out = []
        for k in range(len(postures)):
            if k % BROAD_ROWS == 0:  # the broad phase by chunks: (rows, pairs, 4, 4) boxes at a time
                obstacle, near_object, own = self._broad_phase(links, frames[k: k + BROAD_ROWS])
            pairs, depths, self_pairs = [], {}, []
            at = k % BROAD_ROWS
            for kind, a, b in self._collisions(frames[k], obstacle[at], near_object[at], own[at]):
                if kind == "obstacle":
                    pairs.append((a, b))
                elif kind == "object":
                    depths[a] = b
                else:
                    self_pairs.append((a, b))
            out.append(CollisionReport(len(pairs) + len(depths) + len(self_pairs), sorted(pairs), depths, self_pairs))
        return out

    def collides_many(self, postures: Sequence[Posture]) -> np.ndarray:
        """(B,) bool: which postures have a collision (``check(p).count > 0``)."""
        return self.collides_at(*self.robot.link_frames_array(postures))

    def collides_at(self, links: list[str], frames: np.ndarray, touching: np.ndarray | None = None) -> np.ndarray:
        """(B,) bool: which of B placements of the links collide, each test stopping at its first
        collision. links: the L link names; frames: (B, L, 4, 4) their world poses
        (:meth:`Robot.link_frames_of <graspnet_torch.robot.robot.Robot.link_frames_of>`);
        touching: (B, S) which link shapes (``self.shapes``) may also touch the object in each."""
        out = np.zeros(len(frames), dtype=bool)
        for a in range(0, len(frames), BROAD_ROWS):  # the broad phase by chunks of placements
            part = frames[a: a + BROAD_ROWS]
            obstacle, near_object, own = self._broad_phase(links, part)
            if touching is not None:
                near_object &= ~touching[a: a + BROAD_ROWS]
            maybe = obstacle.any((1, 2)) | near_object.any(1) | own.any(1)
            for k in np.nonzero(maybe)[0]:
                out[a + k] = next(self._collisions(part[k], obstacle[k], near_object[k], own[k]), None) is not None
        return out

    def _broad_phase(self, links: list[str], frames: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The pairs whose boxes meet (collision/boxes.py) where the links (names; poses (B, L, 4, 4))
        are: (B, S, O) link shape and obstacle, (B, S) link shape and object (the touching links
        left out), (B, P) self-collision pair."""
        if self._frame_of is None or self._frame_names != links:
            row = {name: k for k, name in enumerate(links)}
            self._frame_of, self._frame_names = np.array([row[s.link] for s in self.shapes], dtype=int), list(links)
        B, S = len(frames), len(self.shapes)
        world = frames[:, self._frame_of] @ self._box_pose  # (B, S, 4, 4): each shape's box
        half = self._box_half
        obstacle = ~boxes_apart(world[:, :, None], half[None, :, None], self._obstacle_pose[None, None],
                                self._obstacle_half[None, None])
        if self._object_box is not None:
            near_object = ~boxes_apart(world, half[None], *self._object_box) & self._object_shapes
        else:
            near_object = np.zeros((B, S), dtype=bool)
        if len(self._pair_first):
            i, j = self._pair_first, self._pair_second
            meet = ~boxes_apart(world[:, i], half[i][None], world[:, j], half[j][None])
            own = meet.astype(np.float64) @ self._pair_owner > 0
        else:
            own = np.zeros((B, len(self.self_pairs)), dtype=bool)
        return obstacle, near_object, own

    def _collisions(self, frames: np.ndarray, obstacle: np.ndarray, near_object: np.ndarray, own: np.ndarray
                    ) -> Iterator[tuple[str, str, object]]:
        """The collisions of one posture, its link frames (L, 4, 4), among the pairs the broad
        phase let through: ``("obstacle", link, obstacle index)``, ``("self", link, link)`` and
        ``("object", link, depth)``; each link shape is placed (FCL) when first needed."""
        import fcl

        placed: set[int] = set()

        def put(i: int) -> None:
            if i not in placed:
                placed.add(i)
                self.link_objects[i].setTransform(fcl_transform(frames[self._frame_of[i]] @ self.shapes[i].origin))

        request = fcl.CollisionRequest()
        found: set[tuple[str, int]] = set()
        for i, k in zip(*np.nonzero(obstacle), strict=True):
            link, k = self.shapes[i].link, int(k)
            if (link, k) in found:
                continue
            put(i)
            if fcl.collide(self.link_objects[i], self.obstacles[k], request, fcl.CollisionResult()) or \
                    (k in self._mesh_obstacles and self._inside(i, *self._mesh_obstacles[k], first=True)):
                found.add((link, k))
                yield "obstacle", link, k
        for p in np.nonzero(own)[0]:
            a, b = self.self_pairs[p]
            for i in self._shapes_of[a] + self._shapes_of[b]:
                put(i)
            if any(fcl.collide(self.link_objects[i], self.link_objects[j], request, fcl.CollisionResult())
                   for i in self._shapes_of[a] for j in self._shapes_of[b]):
                yield "self", a, b
        if near_object.any():
            indices = np.nonzero(near_object)[0]
            for i in indices:
                put(i)
            for link, depth in self._object_depths(indices).items():
                yield "object", link, depth

    def _object_depths(self, indices: np.ndarray) -> dict[str, float]:
        """The links among the (placed) shapes ``indices`` that go into the object deeper than the
        tolerance, with a depth each reaches (m)."""
        import fcl

        depths: dict[str, float] = {}
        request = fcl.CollisionRequest(num_max_contacts=8, enable_contact=True)
        measured = []  # a mesh object: the links that cross its surface or may lie wholly inside
        for i in indices:
            shape = self.shapes[i]
            result = fcl.CollisionResult()
            crossing = fcl.collide(self.link_objects[i], self.object, request, result)
            if self._mesh_object is not None:
                measured.append((i, crossing))
            elif crossing:
                depth = max((c.penetration_depth for c in result.contacts), default=0.0)
                if depth > self.object_tolerance:
                    depths[shape.link] = max(depth, depths.get(shape.link, 0.0))
        if measured:  # the depth of each link's points below the mesh's surface (collision/mesh.py)
            query, pose = self._mesh_object
            points = [self._shape_points(i, pose) for i, _ in measured]
            points = [p if crossing else p[:1] for p, (_, crossing) in zip(points, measured, strict=True)]
            inside = [k for k, (_, crossing) in enumerate(measured) if not crossing and query.inside(points[k]).any()]
            for k in inside:  # wholly inside: all its points
                points[k] = self._shape_points(measured[k][0], pose)
                measured[k] = (measured[k][0], True)
            sets = [p if crossing else p[:0] for p, (_, crossing) in zip(points, measured, strict=True)]
            for (i, _), depth in zip(measured, query.depths_beyond(sets, self.object_tolerance), strict=True):
                if depth > self.object_tolerance:
                    link = self.shapes[i].link
                    depths[link] = max(depth, depths.get(link, 0.0))
        return depths

    def _shape_points(self, i: int, pose: np.ndarray) -> np.ndarray:
        """Link shape i's points (:func:`~graspnet_torch.collision.mesh.shape_points`) placed where
        the last :meth:`place` put it, in the frame ``pose`` (4, 4) of a mesh."""
        if i not in self._points:
            s = self.shapes[i]
            self._points[i] = shape_points(s.kind, s.size, s.mesh)
        tf = self.link_objects[i].getTransform()
        world = self._points[i] @ np.asarray(tf.getRotation()).T + np.asarray(tf.getTranslation())
        return (world - pose[:3, 3]) @ pose[:3, :3]

    def _inside(self, i: int, query, pose: np.ndarray, first: bool = False) -> bool:
        """Whether link shape i lies in a mesh (``first``: its first point, enough for a link that
        does not cross the surface)."""
        points = self._shape_points(i, pose)
        return bool(query.inside(points[:1] if first else points).any())

    def count(self, posture: Posture) -> int:
        return self.check(posture).count
