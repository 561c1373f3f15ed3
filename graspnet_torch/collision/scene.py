"""Collision counts with python-fcl, the engine of record (shared/INTERFACE.md, "Collisions").

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

with a broad phase (FCL's dynamic AABB tree over the links, one per environment element) and a
narrow phase (FCL's primitive-primitive tests; penetration depth by GJK/EPA).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from graspnet_torch.robot.geometry import link_shapes
from graspnet_torch.robot.robot import Posture, Robot
from graspnet_torch.tasks.problem import GraspProblem, Shape

__all__ = ["CollisionReport", "CollisionScene", "environment_obstacles", "fcl_geometry", "has_environment",
           "link_geometry", "self_collision_pairs"]

FLOOR_SIZE = (100.0, 100.0, 1.0)  # m: the floor slab (centred under the world origin)
FLOOR_GAP = 0.001  # m: its top lies this far below the robot's floor height


def environment_obstacles(robot: Robot, problem: GraspProblem) -> list[Shape]:
    """The problem's obstacles, then the robot's floor (when it has one) as a box obstacle."""
    obstacles = list(problem.obstacles)
    if robot.cfg.floor is not None:
        top = robot.cfg.floor - FLOOR_GAP
        pose = np.array([0.0, 0.0, top - FLOOR_SIZE[2] / 2, 0.0, 0.0, 0.0])
        obstacles.append(Shape("box", FLOOR_SIZE, pose))
    return obstacles


def _shape_extent(shape) -> np.ndarray:
    """(8 or V, 3) points bounding a link shape, in its link's frame (a box's or a cylinder's
    corners, a sphere's bounding box, a mesh's vertices)."""
    if shape.kind == "mesh":
        local = np.asarray(shape.mesh.vertices, dtype=np.float64)
    else:
        half = {"box": lambda d: np.asarray(d) / 2, "cylinder": lambda d: np.array([d[0], d[0], d[1] / 2]),
                "sphere": lambda d: np.array([d[0]] * 3)}[shape.kind](shape.size)
        local = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)]) * half
    return local @ shape.origin[:3, :3].T + shape.origin[:3, 3]


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
    pairs: list[tuple[str, str]] = []
    if robot.cfg.self_collision:
        import fcl

        shapes = link_shapes(robot.urdf, "collision")
        with_geometry = list(dict.fromkeys(s.link for s in shapes))

        def carrier(link: str) -> str | None:  # the nearest ancestor (or itself) with geometry
            while link not in with_geometry and link in robot.urdf.parent_joint:
                link = robot.urdf.parent_joint[link].parent
            return link if link in with_geometry else None

        def moved_by(link: str) -> frozenset:  # the movable joints between the root and the link
            joints = set()
            while link in robot.urdf.parent_joint:
                joint = robot.urdf.parent_joint[link]
                if joint.type != "fixed":
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
            placed = _transform(frames[shape.link] @ shape.origin)
            obj = fcl.CollisionObject(link_geometry(shape), placed)
            objects.setdefault(shape.link, []).append(obj)
        for i, a in enumerate(with_geometry):
            for b in with_geometry[i + 1:]:
                if frozenset((a, b)) in adjacent or moved_by(a) == moved_by(b):  # adjacent or rigidly joined
                    continue
                if any(fcl.collide(oa, ob, fcl.CollisionRequest(), fcl.CollisionResult())
                       for oa in objects[a] for ob in objects[b]):
                    continue
                pairs.append((a, b))
    robot._self_collision_pairs = pairs
    return pairs

OBJECT_TOLERANCE_M = 0.002


def fcl_geometry(kind: str, size: tuple[float, ...], mesh=None):
    """An FCL geometry: box (full extents), cylinder (radius, length along z), sphere (radius), or
    a triangle mesh (a ``trimesh.Trimesh`` in its own frame)."""
    import fcl

    if kind == "box":
        return fcl.Box(*size)
    if kind == "cylinder":
        return fcl.Cylinder(size[0], size[1])
    if kind == "sphere":
        return fcl.Sphere(size[0])
    model = fcl.BVHModel()
    model.beginModel(len(mesh.vertices), len(mesh.faces))
    model.addSubModel(np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.faces, dtype=np.int32))
    model.endModel()
    return model


def link_geometry(shape) -> object:
    """The FCL geometry of a link's shape (``robot.geometry.Shape``): a primitive, or a mesh as a
    ``BVHModel`` of its triangles (a surface: FCL finds where it crosses another geometry, not a
    geometry wholly inside a closed mesh)."""
    return fcl_geometry(shape.kind, shape.size, shape.mesh)


def _transform(T: np.ndarray):
    import fcl

    return fcl.Transform(T[:3, :3], T[:3, 3])


def _environment_object(shape: Shape):
    """An obstacle or the object as an FCL collision object at its pose in the world."""
    import fcl

    from graspnet_torch.robot.chain import rpy_matrix_np

    T = np.eye(4)
    T[:3, :3] = rpy_matrix_np(shape.pose[3:])
    T[:3, 3] = shape.pose[:3]
    if shape.kind == "mesh":
        from pathlib import Path

        from graspnet_torch.collision.mesh import mesh_bvh

        geometry = mesh_bvh(Path(shape.mesh).resolve(), shape.scale)
    else:
        geometry = fcl_geometry(shape.kind, shape.size)
    return fcl.CollisionObject(geometry, _transform(T))


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
    """

    def __init__(self, robot: Robot, problem: GraspProblem, object_tolerance: float = OBJECT_TOLERANCE_M,
                 touching: bool = True):
        import fcl

        self.robot, self.problem, self.object_tolerance = robot, problem, object_tolerance
        self.shapes = link_shapes(robot.urdf, "collision")
        self.link_objects = [fcl.CollisionObject(link_geometry(s), fcl.Transform()) for s in self.shapes]
        self.obstacles = [_environment_object(o) for o in environment_obstacles(robot, problem)]
        self.self_pairs = self_collision_pairs(robot)
        self.object = _environment_object(problem.object) if problem.object is not None else None
        self.touching = self.distal_links(robot, self.shapes, problem.fingers) if touching else set()
        # meshes: FCL finds where a link crosses the surface; inside and depth are measured (collision/mesh.py)
        from graspnet_torch.collision.mesh import mesh_query

        elements = environment_obstacles(robot, problem)
        self._mesh_obstacles = {k: mesh_query(o) for k, o in enumerate(elements) if o.kind == "mesh"}
        self._mesh_object = mesh_query(problem.object) if problem.object is not None and \
            problem.object.kind == "mesh" else None
        self._points: dict[int, np.ndarray] = {}  # link shape index -> its points (shape frame)
        self._objects_of: dict[str, list] | None = None  # link -> its collision objects (self-collision)
        self._spheres: tuple | None = None  # the self-collision links' bounding spheres (their frames)
        self._object_spheres: tuple | None = None  # the link shapes' and the object's bounding spheres
        self._frames: dict[str, np.ndarray] = {}
        self._owner = {id(o): k for k, o in enumerate(self.obstacles)}
        self._link_of = {id(o): s.link for o, s in zip(self.link_objects, self.shapes, strict=True)}
        self.links = fcl.DynamicAABBTreeCollisionManager()
        self.links.registerObjects(self.link_objects)
        self.links.setup()
        self.environment = fcl.DynamicAABBTreeCollisionManager()
        if self.obstacles:
            self.environment.registerObjects(self.obstacles)
        self.environment.setup()

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

    def place(self, posture: Posture) -> None:
        """Move every link's geometry to the posture (forward kinematics in float64)."""
        self._place(self.robot.link_frames(posture))

    def _place(self, frames: dict[str, np.ndarray]) -> None:
        for obj, shape in zip(self.link_objects, self.shapes, strict=True):
            obj.setTransform(_transform(frames[shape.link] @ shape.origin))
        self.links.update()
        self._frames = frames

    def _near_object(self) -> np.ndarray:
        """(S,) which link shapes' bounding spheres reach the object's (only those can cross it or
        lie inside it) where :meth:`place` put them."""
        if self._object_spheres is None:
            extents = [_shape_extent(s) for s in self.shapes]
            centres = np.stack([(e.min(0) + e.max(0)) / 2 for e in extents])
            radii = np.array([np.linalg.norm(e - c, axis=1).max() for e, c in zip(extents, centres, strict=True)])
            vertices = np.asarray(self.problem.object.trimesh().vertices, dtype=np.float64)
            middle = (vertices.min(0) + vertices.max(0)) / 2
            reach = float(np.linalg.norm(vertices - middle, axis=1).max()) + 1e-3
            self._object_spheres = (centres, radii + 1e-3, middle, reach)
        centres, radii, middle, reach = self._object_spheres
        frames = np.stack([self._frames[s.link] for s in self.shapes])
        world = np.einsum("sij,sj->si", frames[:, :3, :3], centres) + frames[:, :3, 3]
        return np.linalg.norm(world - middle, axis=1) <= radii + reach

    def _near_pairs(self) -> list[tuple[str, str]]:
        """The self-collision pairs whose links' bounding spheres (each link's shapes, in its
        frame) overlap where :meth:`place` put them: only those can collide."""
        if self._spheres is None:
            links = sorted({name for pair in self.self_pairs for name in pair})
            spheres = {}
            for link in links:
                points = [_shape_extent(s) for s in self.shapes if s.link == link]
                if points:
                    cloud = np.concatenate(points)
                    centre = (cloud.min(0) + cloud.max(0)) / 2
                    spheres[link] = (centre, float(np.linalg.norm(cloud - centre, axis=1).max()) + 1e-3)
            pairs = [(a, b) for a, b in self.self_pairs if a in spheres and b in spheres]
            names = sorted(spheres)
            index = {name: k for k, name in enumerate(names)}
            self._spheres = (names, np.stack([spheres[n][0] for n in names]) if names else np.zeros((0, 3)),
                             np.array([spheres[n][1] for n in names]), pairs,
                             np.array([index[a] for a, _ in pairs], dtype=int),
                             np.array([index[b] for _, b in pairs], dtype=int))
        names, centres, radii, pairs, ia, ib = self._spheres
        if not pairs:
            return []
        frames = np.stack([self._frames[n] for n in names])  # (L, 4, 4)
        world = np.einsum("lij,lj->li", frames[:, :3, :3], centres) + frames[:, :3, 3]
        near = np.linalg.norm(world[ia] - world[ib], axis=1) <= radii[ia] + radii[ib]
        return [pair for pair, ok in zip(pairs, near, strict=True) if ok]

    def check(self, posture: Posture) -> CollisionReport:
        """The collision count of a posture and what makes it up."""
        return self.check_many([posture])[0]

    def check_many(self, postures: Sequence[Posture]) -> list[CollisionReport]:
        """:meth:`check` of several postures (their forward kinematics in one pass)."""
        out = []
        for frames in self.robot.link_frames_many(postures):
            self._place(frames)
            out.append(self._check_placed())
        return out

    def _check_placed(self) -> CollisionReport:
        """The collision count of the posture :meth:`_place` put the links at."""
        import fcl

        pairs: set[tuple[str, int]] = set()
        if self.obstacles:
            data = fcl.CollisionData(request=fcl.CollisionRequest(num_max_contacts=100000, enable_contact=True))
            self.links.collide(self.environment, data, fcl.defaultCollisionCallback)
            for contact in data.result.contacts:
                a, b = contact.o1, contact.o2
                link = self._link_of.get(id(a)) or self._link_of.get(id(b))
                owner = self._owner.get(id(b), self._owner.get(id(a)))
                if link is not None and owner is not None:
                    pairs.add((link, owner))
            if not pairs and data.result.is_collision:  # contacts not reported: fall back to pairwise tests
                pairs = self._pairwise()
            for k, (query, pose) in self._mesh_obstacles.items():  # a link wholly inside a mesh obstacle
                for i, shape in enumerate(self.shapes):
                    if (shape.link, k) not in pairs and self._inside(i, query, pose, first=True):
                        pairs.add((shape.link, k))
        depths: dict[str, float] = {}
        if self.object is not None:
            request = fcl.CollisionRequest(num_max_contacts=8, enable_contact=True)
            measured = []  # a mesh object: the links that cross its surface or may lie wholly inside
            near = self._near_object()
            for i, (obj, shape) in enumerate(zip(self.link_objects, self.shapes, strict=True)):
                if shape.link in self.touching or not near[i]:
                    continue
                result = fcl.CollisionResult()
                crossing = fcl.collide(obj, self.object, request, result)
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
                inside = [k for k, (_, crossing) in enumerate(measured)
                          if not crossing and query.inside(points[k]).any()]
                for k in inside:  # wholly inside: all its points
                    points[k] = self._shape_points(measured[k][0], pose)
                    measured[k] = (measured[k][0], True)
                sets = [p if crossing else p[:0] for p, (_, crossing) in zip(points, measured, strict=True)]
                for (i, _), depth in zip(measured, query.depths_beyond(sets, self.object_tolerance), strict=True):
                    if depth > self.object_tolerance:
                        link = self.shapes[i].link
                        depths[link] = max(depth, depths.get(link, 0.0))
        own = [(a, b) for a, b in self._near_pairs() if self._links_collide(a, b)] if self.self_pairs else []
        return CollisionReport(len(pairs) + len(depths) + len(own), sorted(pairs), depths, own)

    def _shape_points(self, i: int, pose: np.ndarray) -> np.ndarray:
        """Link shape i's points (:func:`~graspnet_torch.collision.mesh.shape_points`) placed where
        the last :meth:`place` put it, in the frame ``pose`` (4, 4) of a mesh."""
        from graspnet_torch.collision.mesh import shape_points

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

    def _links_collide(self, a: str, b: str) -> bool:
        import fcl

        if self._objects_of is None:  # each link's collision objects, gathered once
            self._objects_of = {}
            for obj, shape in zip(self.link_objects, self.shapes, strict=True):
                self._objects_of.setdefault(shape.link, []).append(obj)
        request = fcl.CollisionRequest()
        return any(fcl.collide(oa, ob, request, fcl.CollisionResult())
                   for oa in self._objects_of.get(a, ()) for ob in self._objects_of.get(b, ()))

    def _pairwise(self) -> set[tuple[str, int]]:
        import fcl

        pairs = set()
        for obj, shape in zip(self.link_objects, self.shapes, strict=True):
            for k, obstacle in enumerate(self.obstacles):
                if fcl.collide(obj, obstacle, fcl.CollisionRequest(), fcl.CollisionResult()):
                    pairs.add((shape.link, k))
        return pairs

    def count(self, posture: Posture) -> int:
        return self.check(posture).count
