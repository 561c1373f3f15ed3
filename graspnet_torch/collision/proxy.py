"""A batched torch approximation of the collision count, for the closed loop.

FCL (``collision/scene.py``) is the engine of record, but it checks one posture at a time from
Python: for T = 1000 trials it would cost far more than the rest of an iteration. The loop
therefore counts collisions with this proxy, and every reported count still comes from FCL
(tests measure how often the two agree on random configurations).

The robot. Every collision primitive of the URDF becomes a few spheres fixed in its link:

- a sphere is itself;
- a cylinder (radius r, length L along z) becomes spheres of radius r whose centres run along
  the axis from -(L/2 - e) to (L/2 - e), e = min(r/4, L/2), at most r/2 apart: a capsule-like
  union whose waist is >= 0.97 r, which covers the rim (to within 3 % of r) and overshoots the
  flat ends by 3r/4 on the axis (the URDF's joint spheres sit there for most links);
- a box becomes spheres of radius rho (its smallest half-extent) on a grid over the box shrunk
  by rho, at most rho apart: a slab with rounded edges;
- a mesh becomes the spheres of its oriented bounding box, grown so that they cover the mesh
  (:func:`mesh_box`).

Each sphere hangs from one *frame*: a level of the body chain (the first k arm joints), the palm,
or a level of a finger chain (the first k finger joints), so that for a batch of configurations
all sphere centres come from a few batched matrix products:

    body level k:    P_k = F_0 M_0(q_0) F_1 M_1(q_1) ... F_{k-1} M_{k-1}(q_{k-1})    (chain.py)
    finger level k:  W_palm B_f F_0 M_0(q_0) ... F_{k-1} M_{k-1}(q_{k-1})
    M(q) = I + s(q) A + c(q) B:  revolute s = sin q, c = 1 - cos q, A = [a]x, B = [a]x^2 (Rodrigues);
                                 prismatic s = q, c = 0, A = the axis as a translation.

The environment. Signed distances of the sphere centres to the problem's primitives (exact for
box, cylinder and sphere; a mesh is approximated by its bounding box in its own frame):

    box (half-extents h):       d = |p| - h;  sd = |max(d, 0)| + min(max_i d_i, 0)
    cylinder (r, half-height):  d = (|p_xy| - r, |p_z| - h);  same formula in 2-D
    sphere (r):                 sd = |p| - r

    the floor (a half-space):   sd = p_z - top

A sphere (c, rho) intersects an obstacle when sd(c) < rho, and penetrates the object by more
than the tolerance tau when sd(c) < rho - tau. The count is INTERFACE.md's: distinct (link,
obstacle) pairs plus links penetrating the object, the touching fingers' distal links excepted.

The robot's own links (``self_collision: true``) are capsules (a segment and a radius: spheres,
cylinders, small boxes; :func:`self_collision_primitive`) and boxes (the rest), tested pair by
pair for every configuration at once:

    capsule-capsule:  |closest points of the two segments| < r_1 + r_2 + clearance  (exact)
    capsule-box:      the segment meets the box grown by r + clearance (slab test; conservative
                      by up to (sqrt(3) - 1) r at the box's corners)
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import torch
from torch import Tensor

from graspnet_torch.errors import ConfigError
from graspnet_torch.robot.geometry import Shape as LinkShape
from graspnet_torch.robot.geometry import link_shapes
from graspnet_torch.robot.robot import Posture, Robot
from graspnet_torch.tasks.problem import GraspProblem, Shape

__all__ = [
    "ChainLevels",
    "CollisionProxy",

    "mesh_box",
    "motion_terms",
    "self_collision_primitive",
    "shape_spheres",
]


SMALL_BOX_M = 0.1  # boxes whose longest half-extent is at most this are capsules for self-collision


def _axis_half(r: float, length: float) -> float:
    """How far along a cylinder's axis (r, length) its model reaches: L/2 - e, e = min(r/4, L/2)."""
    return length / 2 - min(r / 4, length / 2)


def mesh_box(shape: LinkShape) -> LinkShape:
    """A mesh link shape's conservative box, in the link frame: the mesh's oriented bounding box
    (trimesh; cached with the mesh), its half-extents h raised to at least max(h) / 8 (a thin
    plate would otherwise need thousands of spheres), then grown by rho / 2 on every side, rho =
    min(h): the box's sphere model (:func:`shape_spheres`) dimples its faces by up to 0.134 rho'
    and rounds its corners by up to 0.366 rho' / 2 along the diagonal (rho' = 1.5 rho, the grown
    box's), so the model of the grown box still covers the mesh. Other shapes are returned as
    they are."""
    if shape.kind != "mesh":
        return shape
    obb = shape.mesh.bounding_box_oriented
    half = np.asarray(obb.primitive.extents, dtype=np.float64) / 2
    half = np.maximum(half, half.max() / 8)
    half = half + half.min() / 2
    return LinkShape(shape.link, "box", tuple(float(2 * h) for h in half),
                     shape.origin @ np.asarray(obb.primitive.transform, dtype=np.float64), shape.rgba)


def shape_spheres(shape: LinkShape) -> tuple[np.ndarray, np.ndarray]:
    """A link shape as spheres in its link's frame: centres (k, 3), radii (k,); a mesh as its box
    (:func:`mesh_box`)."""
    shape = mesh_box(shape)
    if shape.kind == "sphere":
        local, radii = np.zeros((1, 3)), np.array([shape.size[0]])
    elif shape.kind == "cylinder":
        r, length = shape.size
        half = _axis_half(r, length)
        k = max(1, math.ceil(2 * half / (r / 2)) + 1)
        z = np.linspace(-half, half, k) if k > 1 else np.zeros(1)
        local, radii = np.stack([np.zeros(k), np.zeros(k), z], axis=1), np.full(k, r)
    elif shape.kind == "box":
        h = np.asarray(shape.size, dtype=np.float64) / 2
        rho = float(h.min())
        axes = []
        for hi in h - rho:
            k = max(1, math.ceil(2 * hi / rho) + 1)
            axes.append(np.linspace(-hi, hi, k) if k > 1 else np.zeros(1))
        local = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
        radii = np.full(len(local), rho)
        # the slab's rounded rim misses the box's edges: spheres of radius rho/2 along the rim,
        # rho/2 inside both faces that meet there, at most rho/2 apart
        a = int(np.argmin(h))
        b, c = [i for i in range(3) if i != a]
        hb, hc, r2 = h[b] - rho / 2, h[c] - rho / 2, rho / 2
        rim = []
        for u0, u1, v0, v1 in ((-hb, hb, -hc, -hc), (hb, hb, -hc, hc), (hb, -hb, hc, hc), (-hb, -hb, hc, -hc)):
            k = max(2, math.ceil(max(abs(u1 - u0), abs(v1 - v0)) / r2) + 1)
            rim += [(u, v) for u, v in zip(np.linspace(u0, u1, k)[:-1], np.linspace(v0, v1, k)[:-1], strict=True)]
        for side in (-1, 1):
            for u, v in rim:
                point = np.zeros(3)
                point[a], point[b], point[c] = side * (h[a] - r2), u, v
                local = np.vstack([local, point])
                radii = np.append(radii, r2)
    else:  # pragma: no cover - link_shapes makes no other kinds
        raise ConfigError(f"link '{shape.link}': no sphere model for {shape.kind}")
    centres = local @ shape.origin[:3, :3].T + shape.origin[:3, 3]
    return centres, radii


def motion_terms(axes: np.ndarray, types: tuple[str, ...]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(n, 4, 4) A and B of M(q) = I + s(q) A + c(q) B, and (n,) revolute mask."""
    n = len(types)
    A, B = np.zeros((n, 4, 4)), np.zeros((n, 4, 4))
    for i, (a, kind) in enumerate(zip(axes, types, strict=True)):
        if kind == "revolute":
            K = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
            A[i, :3, :3], B[i, :3, :3] = K, K @ K
        else:
            A[i, :3, 3] = a
    return A, B, np.array([t == "revolute" for t in types])


def _finger_chains(robot: Robot) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, tuple | None]:
    """Every finger's whole chain (mimic joints included) padded to the longest, m joints: A, B
    (F, m, 4, 4), revolute (F, m), offsets (F, m + 1, 4, 4), and the map from the free joints
    (F, n) to them, ``q_all = C q + c`` as (C (F, m, n), c (F, m)), or None when they are the same.
    A padding joint has no motion (A = B = 0) and an identity offset."""
    fingers = list(robot.fingers.values())
    m, n = max(f.chain.spec.n_joints for f in fingers), robot.joints_per_finger
    A, B = np.zeros((len(fingers), m, 4, 4)), np.zeros((len(fingers), m, 4, 4))
    rev = np.ones((len(fingers), m), dtype=bool)
    offsets = np.broadcast_to(np.eye(4), (len(fingers), m + 1, 4, 4)).copy()
    C, c = np.zeros((len(fingers), m, n)), np.zeros((len(fingers), m))
    for k, f in enumerate(fingers):
        spec, j = f.chain.spec, f.chain.spec.n_joints
        A[k, :j], B[k, :j], rev[k, :j] = motion_terms(spec.axes, spec.joint_types)
        offsets[k, :j] = spec.offsets[:j]
        offsets[k, m] = spec.offsets[j]
        C[k, :j, : f.n_joints], c[k, :j] = f.chain.coupling, f.chain.coupling_offset
    plain = m == n and all(f.chain.identity for f in fingers)
    return A, B, rev, offsets, None if plain else (C, c)


class ChainLevels:
    """Torch constants of one (batch of) serial chain(s). With M(q) = I + s(q) A + c(q) B,

        F_k M_k(q_k) = F_k + s(q_k) (F_k A_k) + c(q_k) (F_k B_k),

    so each joint's transform costs two fused multiply-adds on precomputed products, no matmul."""

    def __init__(self, A: np.ndarray, B: np.ndarray, revolute: np.ndarray, offsets: np.ndarray, kw: dict):
        F = offsets[..., :-1, :, :]
        self.F = torch.as_tensor(F, **kw)  # (..., n, 4, 4)
        self.FA = torch.as_tensor(F @ A, **kw)
        self.FB = torch.as_tensor(F @ B, **kw)
        self.all_revolute = bool(np.all(revolute))
        self.revolute = torch.as_tensor(revolute, device=kw["device"])

    def levels(self, q: Tensor, upto: int) -> list[Tensor]:
        """q (T, ..., n) -> [P_1, ..., P_upto], each (T, ..., 4, 4) (P_0 = identity is left out)."""
        if upto == 0:
            return []
        if self.all_revolute:
            s, c = torch.sin(q), 1 - torch.cos(q)
        else:
            s = torch.where(self.revolute, torch.sin(q), q)
            c = torch.where(self.revolute, 1 - torch.cos(q), torch.zeros_like(q))
        FM = torch.addcmul(torch.addcmul(self.F, s[..., None, None], self.FA), c[..., None, None], self.FB)
        lead = FM.shape[:-3]
        flat = FM.reshape(-1, *FM.shape[-3:])  # (B, n, 4, 4): products as bmm, the cheapest small matmul
        P = [flat[:, 0]]
        for k in range(1, upto):
            P.append(torch.bmm(P[-1], flat[:, k]))
        return [p.view(*lead, 4, 4) for p in P]


CLUSTER = 8  # spheres per cluster (a link's spheres are cut into clusters of at most this many)
DENSE_LIMIT = 1 << 13  # T x clusters x CLUSTER x elements below which every sphere is tested (no broad phase)


class CollisionProxy:
    """The collision count of a robot in a problem, batched over configurations, in torch.

    Args:
        robot: the robot (its URDF's collision primitives).
        problem: obstacles, object and contact fingers.
        object_tolerance: penetration of the object (m) that counts (INTERFACE.md: 2 mm).
        clearance: a safety margin (m): obstacles and the robot's own links count as hit from
            this distance on, and the object from ``clearance - object_tolerance`` (0: the
            count itself); the floor has none (the platform stands on it). A search that keeps
            the count at zero with a margin stays clear of
            the proxy's approximation error (FCL, with no margin, has the last word).

    Call :meth:`count` with the palm frame, the body joints (robots with an arm) and every
    finger's joints. Two phases, as FCL: each link's spheres are cut into clusters of at most
    ``CLUSTER`` neighbours, each with a bounding sphere; a cluster's spheres are placed and tested
    only where its bounding sphere meets an element (broad phase), so the cost follows the
    number of near (cluster, element) pairs, not T x spheres x elements. Small batches (T x
    clusters x ``CLUSTER`` x elements <= ``DENSE_LIMIT``, e.g. one trial) test every sphere at
    once: fewer operations, the same answer (tests compare the two).
    """

    def __init__(self, robot: Robot, problem: GraspProblem | Sequence[GraspProblem], object_tolerance: float = 0.002,
                 dtype: torch.dtype = torch.float32, device: torch.device | str = "cpu", clearance: float = 0.0):
        from graspnet_torch.collision.scene import CollisionScene, environment_obstacles, self_collision_pairs

        self.robot = robot
        problems = [problem] if isinstance(problem, GraspProblem) else list(problem)
        problem = problems[0]
        self.n_problems = len(problems)
        shapes = link_shapes(robot.urdf, "collision")
        touching = CollisionScene.distal_links(robot, shapes, problem.fingers)
        frames = self._frames_at_zero(robot)
        # the frame each link hangs from: ('body', k) | ('palm', 0) | ('finger', f, k)
        by_link: dict[str, list] = {}
        attach: dict[str, tuple] = {}
        self.link_spheres: dict[str, list[np.ndarray]] = {}
        for shape in shapes:
            where, G = self._attachment(robot, shape.link, frames)
            attach[shape.link] = where
            centres, radii_ = shape_spheres(shape)
            self.link_spheres.setdefault(shape.link, []).append(centres)  # in the link frame
            for c, r in zip(centres, radii_, strict=True):
                by_link.setdefault(shape.link, []).append((G[:3, :3] @ c + G[:3, 3], float(r)))
        self.links = list(by_link)
        self.n_spheres = sum(len(v) for v in by_link.values())
        self.body_levels = max((w[1] for w in attach.values() if w[0] == "body"), default=0)
        self.finger_levels = max((w[2] for w in attach.values() if w[0] == "finger"), default=0)
        # frames are stacked in a fixed order: body levels, palm, finger levels finger by finger
        n_body = self.body_levels + 1 if robot.body is not None else 0
        n_f = self.finger_levels + 1

        def frame_id(w: tuple) -> int:
            if w[0] == "body":
                return w[1]
            if w[0] == "palm":
                return n_body
            return n_body + 1 + w[1] * n_f + w[2]

        clusters = []  # (frame id, link index, centres (k, 3), radii (k,))
        for li, (link, spheres) in enumerate(by_link.items()):
            for start in range(0, len(spheres), CLUSTER):
                chunk = spheres[start:start + CLUSTER]
                clusters.append((frame_id(attach[link]), li, np.stack([c for c, _ in chunk]),
                                 np.array([r for _, r in chunk])))
        C = len(clusters)
        local = np.zeros((C, 4, CLUSTER))
        radii = np.full((C, CLUSTER), np.nan)
        bound = np.zeros((C, 4, 1))
        bound_r = np.zeros(C)
        for k, (_f, _l, c, r) in enumerate(clusters):
            local[k, :3, :len(r)], local[k, 3, :len(r)], radii[k, :len(r)] = c.T, 1.0, r
            centre = (c.min(0) + c.max(0)) / 2
            bound[k, :3, 0], bound[k, 3, 0] = centre, 1.0
            bound_r[k] = float(np.max(np.linalg.norm(c - centre, axis=1) + r))
        kw = {"dtype": dtype, "device": device}
        self._cluster_frame = torch.tensor([f for f, *_ in clusters], device=device)
        self._cluster_link = torch.tensor([li for _, li, *_ in clusters], device=device)
        one_hot = np.zeros((len(clusters), len(self.links)))
        one_hot[np.arange(len(clusters)), [li for _, li, *_ in clusters]] = 1
        self._link_of_cluster = torch.as_tensor(one_hot, **kw)  # (C, L)
        self._cluster_local = torch.as_tensor(local, **kw)  # (C, 4, CLUSTER) homogeneous sphere centres
        self._cluster_bound = torch.as_tensor(bound, **kw)  # (C, 4, 1) bounding-sphere centres
        if robot.body is not None:
            A, B, rev = motion_terms(robot.body.axes, robot.body.joint_types)
            self.body = ChainLevels(A, B, rev, robot.body.offsets, kw)
            self._palm_offset = torch.as_tensor(robot.body.offsets[-1], **kw)
        if robot.n_fingers:
            A, B, rev, offsets, self._finger_map = _finger_chains(robot)
            self.fingers = ChainLevels(A, B, rev, offsets, kw)
            if self._finger_map is not None:
                self._finger_map = tuple(torch.as_tensor(a, **kw) for a in self._finger_map)
            base = np.stack([f.base_in_palm for f in robot.fingers.values()])  # (F, 4, 4)
            self.n_f = len(base)
            self._base_cols = torch.as_tensor(base.transpose(1, 0, 2).reshape(4, -1), **kw)  # (4, 4F): W4 @ it
        self._bottom = torch.tensor([0.0, 0.0, 0.0, 1.0], **kw)
        self._eye34 = torch.eye(4, **kw)[:3]
        # the environment: obstacles, then the object (its own threshold; touching links exempt)
        elements = environment_obstacles(robot, problem)  # the problem's, then the robot's floor
        margin = [-clearance] * len(problem.obstacles) + [0.0] * (len(elements) - len(problem.obstacles))  # the
        # platform stands 1 mm above the floor slab: no margin there
        exempt: list[set] = [set()] * len(problem.obstacles)
        if robot.cfg.floor is not None:  # links that only ride the mobile base stand on the floor: never tested
            exempt.append(self._riding_base(robot, attach))
        if problem.object is not None:
            elements.append(problem.object)
            margin.append(object_tolerance - clearance)
            exempt.append(touching)
        self.n_elements = len(elements)
        batch = [elements] + [_elements_like(robot, p, elements, k) for k, p in enumerate(problems[1:], 1)]
        self._groups = _primitive_groups(batch, kw, len(problem.obstacles) if robot.cfg.floor is not None else None)
        for g in self._groups:
            # a sphere (c, rho) hits element o when sd_o(c) < rho - margin_o; padding never hits
            thr = radii[:, :, None] - np.array([margin[k] for k in g["index"]])  # (C, CLUSTER, O_g)
            for col, k in enumerate(g["index"]):
                for ci, (_f, li, *_r) in enumerate(clusters):
                    if self.links[li] in exempt[k]:
                        thr[ci, :, col] = -np.inf
            thr = np.nan_to_num(thr, nan=-np.inf)
            g["pos"] = torch.as_tensor(thr > 0, device=device)
            g["thr_sq"] = torch.as_tensor(np.where(thr > 0, thr, 0.0) ** 2, **kw)
            # broad phase: the cluster's bounding sphere within reach (of a convex piece's bounding sphere)
            bthr = np.broadcast_to(bound_r[:, None, None] - np.array([margin[k] for k in g["index"]]),
                                   (C, 1, len(g["index"])))[:, 0]  # (C, O_g)
            if g["kind"] == "convex":
                g["bound_r"] = torch.as_tensor(np.array(bthr), **kw)  # (C, O_g): + the piece's radius, per problem
                bthr = bthr + g["radius"].amax(0).cpu().numpy()[None]
            g["bound_pos"] = (torch.as_tensor(bthr > 0, device=device) & g["pos"].any(1)).unsqueeze(1)  # (C, 1, O_g)
            g["bound_thr_sq"] = torch.as_tensor(np.where(bthr > 0, bthr, 0.0) ** 2, **kw).unsqueeze(1)
            g["columns"] = torch.as_tensor(g["index"], device=device)
            P = g["R"].shape[0]
            g["R_cols"] = g["R"].permute(0, 2, 1, 3).reshape(P, 3, -1)  # per problem [R_1 .. R_O]
            g["Rt"] = torch.einsum("poji,poj->poi", g["R"], g["t"]).reshape(P, -1)  # per problem [R_o^T t_o]
        self._true = torch.ones((), dtype=torch.bool, device=device)
        # elementwise tests per sphere: one per primitive, one per plane of a convex piece
        self._dense_cost = sum(len(g["index"]) * (g["size"].shape[-2] if g["kind"] == "convex" else 1)
                               for g in self._groups)
        # the robot's own links (self_collision: true): capsules and boxes (self_collision_primitives),
        # every primitive of one link of a pair against every primitive of the other
        self.self_pairs = self_collision_pairs(robot)
        self._self_model(robot, shapes, attach, frame_id, clearance, kw)

    def _self_model(self, robot: Robot, shapes: list[LinkShape], attach: dict[str, tuple], frame_id,
                    clearance: float, kw: dict) -> None:
        """Tensors of the self-collision test: capsules (ends in their frame, radius), boxes (pose
        in their frame, half extents), and the primitive pairs of each link pair: capsule-capsule
        (exact: segment distance) and capsule-box (the segment against the box grown by the
        radius: conservative by up to (sqrt(3) - 1) r at the box's corners). A pair of two boxes
        has no test here: it is left to FCL (``proxy_unchecked``), as are pairs this model finds
        touching at the home posture (none for ``manus``)."""
        device = kw["device"]
        involved = set(link for pair in self.self_pairs for link in pair)
        caps, boxes = [], []  # (link, frame id, ...)
        frames = self._frames_at_zero(robot)
        for shape in shapes:
            if shape.link not in involved:
                continue
            _where, G = self._attachment(robot, shape.link, frames)
            kind, a, b = self_collision_primitive(shape)
            if kind == "capsule":
                ends = G[:3, :3] @ a.T + G[:3, 3:4]  # (3, 2)
                caps.append((shape.link, frame_id(attach[shape.link]), ends, float(b)))
            else:
                boxes.append((shape.link, frame_id(attach[shape.link]), G @ a, b))
        cc, cb, unchecked = [], [], []  # (i, j, link pair) index triples
        for p, (la, lb) in enumerate(self.self_pairs):
            ca = [i for i, c in enumerate(caps) if c[0] == la]
            cb_ = [i for i, c in enumerate(caps) if c[0] == lb]
            ba = [i for i, x in enumerate(boxes) if x[0] == la]
            bb = [i for i, x in enumerate(boxes) if x[0] == lb]
            cc += [(i, j, p) for i in ca for j in cb_]
            cb += [(i, j, p) for i in ca for j in bb] + [(i, j, p) for i in cb_ for j in ba]
            if ba and bb:
                unchecked.append(p)
        ends = np.zeros((len(caps), 4, 2))
        for k, (_l, _f, e, _r) in enumerate(caps):
            ends[k, :3], ends[k, 3] = e, 1.0
        radius = np.array([c[3] for c in caps])
        self._cap_frame = torch.tensor([c[1] for c in caps], dtype=torch.long, device=device)
        self._cap_ends = torch.as_tensor(ends, **kw)  # (N_cap, 4, 2): homogeneous end points
        self._box_frame = torch.tensor([x[1] for x in boxes], dtype=torch.long, device=device)
        self._box_pose = torch.as_tensor(np.stack([x[2] for x in boxes]) if boxes else np.zeros((0, 4, 4)), **kw)
        n_pairs = len(self.self_pairs)

        def index(rows: list[tuple[int, int, int]], col: int) -> Tensor:
            return torch.tensor([r[col] for r in rows], dtype=torch.long, device=device)

        self._cc_i, self._cc_j = index(cc, 0), index(cc, 1)
        self._cc_thr_sq = torch.as_tensor([(radius[i] + radius[j] + clearance) ** 2 for i, j, _p in cc], **kw)
        self._cb_cap, self._cb_box = index(cb, 0), index(cb, 1)
        grow = [boxes[j][3] + radius[i] + clearance for i, j, _p in cb]
        self._cb_grow = torch.as_tensor(np.array(grow).reshape(-1, 3), **kw)  # (N_cb, 3): grown half extents
        # (N, P) which link pair each primitive pair belongs to: hits (T, N) @ it > 0 -> (T, P)
        self._cc_pair = torch.zeros(len(cc), n_pairs, **kw)
        self._cc_pair[torch.arange(len(cc)), index(cc, 2)] = 1
        self._cb_pair = torch.zeros(len(cb), n_pairs, **kw)
        self._cb_pair[torch.arange(len(cb)), index(cb, 2)] = 1
        self.proxy_unchecked = [self.self_pairs[p] for p in unchecked]
        self._self_tested = bool(len(cc) or len(cb))
        if self.self_pairs:
            home = robot.home_posture(kw["dtype"]).body.to(device).unsqueeze(0)
            levels, palm_home = self.body_levels_and_palm(home)
            touching = self.self_hits(palm_home, torch.zeros(1, 0, 0, **kw), home, levels)[0]
            if bool(touching.any()):
                keep = (~touching).to(self._cc_pair.dtype)
                self._cc_pair, self._cb_pair = self._cc_pair * keep, self._cb_pair * keep
                self.proxy_unchecked += [pair for pair, t in zip(self.self_pairs, touching.tolist(), strict=True) if t]

    @staticmethod
    def _riding_base(robot: Robot, attach: dict[str, tuple]) -> set[str]:
        """Links that only the mobile base's joints move, when those joints keep them at their
        height and upright (a planar base: x, y, yaw; checked at random base configurations):
        they stand on the floor, so the floor is never tested against them (FCL still is)."""
        if robot.cfg.mobile_base is None or robot.body is None:
            return set()
        m = len(robot.urdf.chain_spec(robot.cfg.mobile_base.base, robot.cfg.mobile_base.tip, "mobile_base").joint_names)
        tip = robot.cfg.mobile_base.tip
        lo, hi = robot.body_limits
        rng = np.random.default_rng(0)
        rows = []
        for _ in range(4):
            q = np.zeros(len(lo))
            q[:m] = rng.uniform(lo[:m], hi[:m])
            posture = Posture(palm_pose=torch.zeros(6, dtype=torch.float64),
                              fingers=torch.zeros(robot.n_fingers, robot.joints_per_finger, dtype=torch.float64),
                              body=torch.as_tensor(q))
            rows.append(robot.link_frames(posture)[tip][2])  # the tip frame's z row: height and tilt
        if not np.allclose(rows, rows[0], atol=1e-9):
            return set()
        return {link for link, w in attach.items() if w[0] == "body" and w[1] <= m}

    @staticmethod
    def _frames_at_zero(robot: Robot) -> dict[str, np.ndarray]:
        zero = Posture(palm_pose=torch.zeros(6, dtype=torch.float64),
                       fingers=torch.zeros(robot.n_fingers, robot.joints_per_finger, dtype=torch.float64),
                       body=torch.zeros(len(robot.body_joint_names), dtype=torch.float64))
        return robot.link_frames(zero)

    @staticmethod
    def _attachment(robot: Robot, link: str, frames: dict[str, np.ndarray]) -> tuple[tuple, np.ndarray]:
        """Which frame a link hangs from and its (4, 4) pose in that frame (at any configuration)."""
        urdf = robot.urdf
        path = [link]  # link and its ancestors, up to the root
        while path[-1] in urdf.parent_joint:
            path.append(urdf.parent_joint[path[-1]].parent)

        def movable(upto: str) -> int:
            return sum(urdf.parent_joint[child].type != "fixed" for child in path[:path.index(upto)])

        palm = robot.cfg.palm_link
        for f, finger in enumerate(robot.fingers.values()):
            if finger.chain.root in path:
                k = movable(finger.chain.root)
                P = np.eye(4)
                for i in range(k):
                    P = P @ finger.chain.spec.offsets[i]
                frame = frames[palm] @ finger.base_in_palm @ P
                return ("finger", f, k), np.linalg.inv(frame) @ frames[link]
        if palm in path:
            if movable(palm):
                raise ConfigError(f"{robot.cfg.source}: link '{link}' moves with the palm but is on no finger chain")
            return ("palm", 0), np.linalg.inv(frames[palm]) @ frames[link]
        if robot.body is None:  # above the palm of a free hand: rigid with it
            return ("palm", 0), np.linalg.inv(frames[palm]) @ frames[link]
        joints = tuple(urdf.parent_joint[c].name for c in reversed(path[:-1]) if urdf.parent_joint[c].type != "fixed")
        k = len(joints)
        if robot.body.joint_names[:k] != joints:
            raise ConfigError(f"{robot.cfg.source}: link '{link}' moves but is on neither the arm nor a finger")
        P = np.eye(4)
        for i in range(k):
            P = P @ robot.body.offsets[i]
        return ("body", k), np.linalg.inv(P) @ frames[link]

    def body_levels_and_palm(self, body: Tensor) -> tuple[list[Tensor], tuple[Tensor, Tensor]]:
        """The body chain's frames P_1..P_m (T, 4, 4) and the palm frame R (T, 3, 3), t (T, 3) that
        its end gives (P_m F_m): the arm's forward kinematics as m small batched products, cheaper
        than the general kernel for a few trials."""
        levels = self.body.levels(body, len(self.robot.body_joint_names))
        end = torch.matmul(levels[-1], self._palm_offset) if levels else self._palm_offset.expand(body.shape[0], 4, 4)
        return levels, (end[:, :3, :3], end[:, :3, 3])

    def frames(self, palm: tuple[Tensor, Tensor], fingers: Tensor, body: Tensor | None = None,
               body_levels: list[Tensor] | None = None) -> Tensor:
        """Every frame spheres hang from. palm: R (T, 3, 3), t (T, 3); fingers: (T, F_all, j) every
        finger's joints; body: (T, m) the body joints (robots with an arm), or ``body_levels`` from
        :meth:`body_levels_and_palm` -> (n_frames, T, 3, 4)."""
        R, t = palm
        T = R.shape[0]
        W = torch.cat([R, t.unsqueeze(-1)], -1)  # (T, 3, 4)
        frames = []
        if self.robot.body is not None:
            frames.append(self._eye34.expand(T, 3, 4))
            if body_levels is None:
                body_levels = self.body.levels(body, self.body_levels)
            frames += [P[..., :3, :] for P in body_levels[:self.body_levels]]
        frames.append(W)
        stacked = torch.stack(frames)  # (n, T, 3, 4)
        if self.robot.n_fingers:
            if self._finger_map is not None:  # free joints (padded) -> every joint (mimic, padded)
                fingers = torch.einsum("fan,tfn->tfa", self._finger_map[0], fingers) + self._finger_map[1]
            # base_f = W B_f for every finger at once: (T, 3, 4) @ (4, 4F)
            base = (W @ self._base_cols).view(T, 3, self.n_f, 4).transpose(1, 2)  # (T, F, 3, 4)
            levels = [base]
            if self.finger_levels:
                base4 = torch.cat([base, self._bottom.expand(T, self.n_f, 1, 4)], -2).reshape(-1, 4, 4)
                for P in self.fingers.levels(fingers, self.finger_levels):
                    levels.append(torch.bmm(base4, P.reshape(-1, 4, 4))[:, :3].view(T, self.n_f, 3, 4))
            stacked = torch.cat([stacked, torch.stack(levels, dim=2).flatten(1, 2).transpose(0, 1)])
        return stacked

    def sphere_centres(self, palm: tuple[Tensor, Tensor], fingers: Tensor, body: Tensor | None = None) -> Tensor:
        """World centres of every cluster's spheres (padding included): (T, C, CLUSTER, 3)."""
        frames = self.frames(palm, fingers, body)[self._cluster_frame]  # (C, T, 3, 4)
        return (frames @ self._cluster_local.unsqueeze(1)).permute(1, 0, 3, 2)

    def pairs(self, palm: tuple[Tensor, Tensor], fingers: Tensor, body: Tensor | None = None,
              body_levels: list[Tensor] | None = None, problem_index: Tensor | None = None) -> Tensor:
        """(T, L, O) bool: link l (``self.links``) collides with element o (the obstacles in problem
        order, the floor, then the object). ``problem_index`` (T,): each configuration's problem
        when the proxy holds a batch of problems (None: the first)."""
        return self._pairs(self.frames(palm, fingers, body, body_levels), problem_index)

    def _pairs(self, every: Tensor, problem_index: Tensor | None) -> Tensor:
        """:meth:`pairs` from every frame (n_frames, T, 3, 4)."""
        frames = every[self._cluster_frame]  # (C, T, 3, 4)
        T = frames.shape[1]
        out = torch.zeros(T, len(self.links), self.n_elements, dtype=torch.bool, device=frames.device)
        C = frames.shape[0]
        flat = frames.reshape(C, T * 3, 4)
        pid = problem_index if self.n_problems > 1 else None
        if T * C * CLUSTER * self._dense_cost <= DENSE_LIMIT:  # small batches: every sphere, no gathers
            centres = torch.bmm(flat, self._cluster_local).view(C, T, 3, CLUSTER).transpose(2, 3)  # (C, T, K, 3)
            for g in self._groups:
                size = None if pid is None else g["size"][pid].unsqueeze(1)  # (T, 1, O_g, s)
                hit = _hit(g, _local(g, centres, pid), g["pos"].unsqueeze(1), g["thr_sq"].unsqueeze(1),
                           size).any(2)  # (C, T, O_g)
                per_link = torch.einsum("cto,cl->tlo", hit.to(self._link_of_cluster.dtype), self._link_of_cluster)
                if g["kind"] == "convex":  # the pieces of one mesh share its column
                    per_link = torch.zeros(T, len(self.links), self.n_elements, dtype=per_link.dtype,
                                           device=per_link.device).index_add_(2, g["columns"], per_link)
                    out |= per_link > 0
                else:
                    out[..., g["columns"]] |= per_link > 0
            return out
        bound = torch.bmm(flat, self._cluster_bound).view(C, T, 1, 3)  # bounding-sphere centres
        for g in self._groups:
            size = None if pid is None else g["size"][pid]  # (T, O_g, s)
            local = _local(g, bound, pid).squeeze(2)  # (C, T, O_g, 3)
            if g["kind"] == "convex":  # bounding spheres: the cluster's and the piece's
                gap = local - (g["centre"][0] if pid is None else g["centre"][pid])
                reach = g["bound_r"].unsqueeze(1) + (g["radius"][0] if pid is None else g["radius"][pid])
                near = g["bound_pos"] & (gap.square().sum(-1) < reach.clamp(min=0).square())  # (C, T, O_g)
            else:
                near = _hit(g, local, g["bound_pos"], g["bound_thr_sq"], size)
            c, t, o = near.nonzero(as_tuple=True)
            if c.numel() == 0:
                continue
            p_of = torch.zeros_like(t) if pid is None else pid[t]
            if g["kind"] == "convex":  # then the cluster's bounding sphere against the piece's planes
                from graspnet_torch.collision.convex import piece_distance

                planes = g["size"][p_of, o]  # (N, F, 4)
                keep = piece_distance(local[c, t, o].unsqueeze(1), planes).squeeze(1) < g["bound_r"][c, o]
                c, t, o, p_of = c[keep], t[keep], o[keep], p_of[keep]
                if c.numel() == 0:
                    continue
            centres = torch.bmm(frames[c, t], self._cluster_local[c]).transpose(1, 2)  # (N, CLUSTER, 3)
            if g["kind"] == "plane":  # the height above the floor's top
                p = centres[..., 2:3] - g["top"]
            else:
                p = torch.bmm(centres - g["t"][p_of, o].unsqueeze(1), g["R"][p_of, o])  # rows: R^T (x - t)
            if g["kind"] == "convex":  # every sphere of the cluster against the piece's planes
                from graspnet_torch.collision.convex import piece_distance

                d = piece_distance(p, planes[keep])  # (N, CLUSTER)
                thr_sq = g["thr_sq"][c, :, o]
                hit = (g["pos"][c, :, o] & ((d.clamp(min=0).square() < thr_sq) | (d <= 0))).any(-1)
            else:
                hit = _hit(g, p, g["pos"][c, :, o], g["thr_sq"][c, :, o], g["size"][p_of, o].unsqueeze(1)).any(-1)
            out.index_put_((t[hit], self._cluster_link[c[hit]], g["columns"][o[hit]]), self._true)
        return out

    def count(self, palm: tuple[Tensor, Tensor], fingers: Tensor, body: Tensor | None = None,
              body_levels: list[Tensor] | None = None, problem_index: Tensor | None = None) -> Tensor:
        """(T,) collision counts (long): distinct (link, obstacle) pairs + links in the object +
        colliding pairs of the robot's own links."""
        T = palm[0].shape[0]
        out = torch.zeros(T, dtype=torch.long, device=palm[0].device)
        if not self.n_elements and not self._self_tested:
            return out
        frames = self.frames(palm, fingers, body, body_levels)  # once for both tests
        if self.n_elements:
            out = self._pairs(frames, problem_index).sum(dim=(1, 2))
        if self._self_tested:
            out = out + self._self_hits(frames).sum(-1)
        return out

    def self_hits(self, palm: tuple[Tensor, Tensor], fingers: Tensor, body: Tensor | None = None,
                  body_levels: list[Tensor] | None = None) -> Tensor:
        """(T, P) bool: pair p of ``self.self_pairs`` collides (with the clearance): some capsule
        of one link within reach of a capsule of the other (segment distance < r_1 + r_2 +
        clearance), or of a box (the segment meets the box grown by r + clearance). Dense: every
        primitive pair of every configuration, a few elementwise operations each."""
        if not self._self_tested:
            return torch.zeros(palm[0].shape[0], len(self.self_pairs), dtype=torch.bool, device=palm[0].device)
        return self._self_hits(self.frames(palm, fingers, body, body_levels))

    def _self_hits(self, frames: Tensor) -> Tensor:
        """:meth:`self_hits` from every frame (n_frames, T, 3, 4)."""
        T = frames.shape[1]
        n = len(self._cap_frame)
        ends = torch.bmm(frames[self._cap_frame].reshape(n, T * 3, 4), self._cap_ends).view(n, T, 3, 2)
        start, end = ends[..., 0], ends[..., 1]  # (N_cap, T, 3)
        hits = torch.zeros(T, len(self.self_pairs), dtype=self._cc_pair.dtype, device=frames.device)
        if len(self._cc_i):
            i, j = self._cc_i, self._cc_j
            d2 = _segment_distance_sq(start[i], end[i], start[j], end[j])  # (N_cc, T)
            hits = hits + (d2 < self._cc_thr_sq.unsqueeze(1)).to(hits.dtype).T @ self._cc_pair
        if len(self._cb_cap):
            W = frames[self._box_frame]  # (N_box, T, 3, 4) each box's link frame -> its pose
            R = W[..., :3] @ self._box_pose[:, None, :3, :3]
            t = (W[..., :3] @ self._box_pose[:, None, :3, 3:]).squeeze(-1) + W[..., 3]
            Rb, tb = R[self._cb_box], t[self._cb_box]  # (N_cb, T, ...)
            c = self._cb_cap
            p0 = ((start[c] - tb).unsqueeze(-2) @ Rb).squeeze(-2)  # rows: R^T (x - t), in the box frame
            p1 = ((end[c] - tb).unsqueeze(-2) @ Rb).squeeze(-2)
            hit = _segment_meets_box(p0, p1, self._cb_grow.unsqueeze(1))  # (N_cb, T)
            hits = hits + hit.to(hits.dtype).T @ self._cb_pair
        return hits > 0


def _local(g: dict, points: Tensor, pid: Tensor | None = None) -> Tensor:
    """(..., T, K, 3) world points -> (..., T, K, O_g, 3) in each element's frame of a group:
    R_o^T (x - t_o) for every element at once as x @ [R_1 .. R_O] - [R_o^T t_o]; ``pid`` (T,)
    each trial's problem of a batch (None: the first). The floor (a half-space) needs only the
    height above its top: (..., T, K, 1, 1)."""
    if g["kind"] == "plane":
        return (points[..., 2:3] - g["top"]).unsqueeze(-2)  # the floor's top: one height for every problem
    if pid is None:
        return (points @ g["R_cols"][0] - g["Rt"][0]).view(*points.shape[:-1], -1, 3)
    return (points @ g["R_cols"][pid] - g["Rt"][pid].unsqueeze(-2)).view(*points.shape[:-1], -1, 3)


def _hit(g: dict, p: Tensor, positive: Tensor, thr_sq: Tensor, size: Tensor | None = None) -> Tensor:
    """sd(p) < thr for points p (..., 3) in their element's frame, with thr > 0 (``positive``;
    otherwise never) and ``thr_sq`` = thr^2: outside a primitive |max(d, 0)|^2 < thr^2, inside
    always. d: box |p| - h; cylinder (|p_xy| - r, |p_z| - h); sphere |p| - r; the floor (a
    half-space, p its height above the top) p."""
    if g["kind"] == "plane":
        d = p
    elif g["kind"] == "sphere":
        d = (torch.linalg.vector_norm(p, dim=-1) - _size(g, size)[..., 0]).unsqueeze(-1)
    elif g["kind"] == "convex":  # max over the piece's planes: (..., O_g, 3) against (..., O_g, F, 4)
        from graspnet_torch.collision.convex import pieces_distance

        d = pieces_distance(p, _size(g, size)).unsqueeze(-1)
    elif g["kind"] == "box":
        d = p.abs() - _size(g, size)
    else:
        d = torch.stack([torch.linalg.vector_norm(p[..., :2], dim=-1), p[..., 2].abs()], dim=-1) - _size(g, size)
    outside = d.clamp(min=0).square().sum(-1)
    return positive & ((outside < thr_sq) | (d.amax(-1) <= 0))



def self_collision_primitive(shape: LinkShape) -> tuple[str, np.ndarray, np.ndarray | float]:
    """A link primitive for the self-collision test, in its link's frame: ``("capsule", ends (2, 3),
    radius)`` or ``("box", pose (4, 4), half extents (3,))``. A sphere is a capsule of length 0; a
    cylinder (r, L) the capsule of radius r whose segment runs along its axis to (L/2 - e) of each
    end, e = min(r/4, L/2) (it overshoots the flat ends by 3r/4 on the axis, where the URDF's joints
    sit); a small box (longest half-extent <= ``SMALL_BOX_M``: a gripper, its jaws) the capsule
    along its longest axis with the half-diagonal of its cross-section as radius (it bulges by
    up to that radius beyond the box); any other box is itself; a mesh is its box (:func:`mesh_box`)."""
    shape = mesh_box(shape)
    R, t = shape.origin[:3, :3], shape.origin[:3, 3]
    if shape.kind == "sphere":
        return "capsule", np.stack([t, t]), float(shape.size[0])
    if shape.kind == "cylinder":
        r, length = shape.size
        half = _axis_half(r, length)
        return "capsule", np.stack([t - half * R[:, 2], t + half * R[:, 2]]), float(r)
    if shape.kind == "box":
        h = np.asarray(shape.size, dtype=np.float64) / 2
        if h.max() > SMALL_BOX_M:
            return "box", shape.origin.copy(), h
        k = int(np.argmax(h))
        radius = float(np.sqrt(np.sum(np.delete(h, k) ** 2)))
        return "capsule", np.stack([t - h[k] * R[:, k], t + h[k] * R[:, k]]), radius
    raise ConfigError(f"link '{shape.link}': no self-collision model for {shape.kind}")  # pragma: no cover


def _segment_distance_sq(p1: Tensor, q1: Tensor, p2: Tensor, q2: Tensor, eps: float = 1e-12) -> Tensor:
    """Squared distance between segments [p1, q1] and [p2, q2], all (..., 3) -> (...): the closest
    points p1 + s d1 and p2 + t d2 (Ericson, Real-Time Collision Detection, 5.1.9):

        s = clamp((b f - c e) / (a e - b^2)),  t = (b s + f) / e;  t < 0: t = 0, s = clamp(-c / a);
        t > 1: t = 1, s = clamp((b - c) / a)
        a = d1.d1, b = d1.d2, c = d1.r, e = d2.d2, f = d2.r, r = p1 - p2, clamp to [0, 1];

    a point (a or e ~ 0) takes the point-segment branch."""
    d1, d2, r = q1 - p1, q2 - p2, p1 - p2
    a, e = (d1 * d1).sum(-1), (d2 * d2).sum(-1)
    b, c, f = (d1 * d2).sum(-1), (d1 * r).sum(-1), (d2 * r).sum(-1)
    a_, e_ = a.clamp(min=eps), e.clamp(min=eps)
    denom = a * e - b * b
    s = torch.where(denom > eps, ((b * f - c * e) / denom.clamp(min=eps)).clamp(0, 1), torch.zeros_like(a))
    t = (b * s + f) / e_
    s = torch.where(t < 0, (-c / a_).clamp(0, 1), torch.where(t > 1, ((b - c) / a_).clamp(0, 1), s))
    t = t.clamp(0, 1)
    s = torch.where(e <= eps, (-c / a_).clamp(0, 1), s)  # the second is a point
    t = torch.where(e <= eps, torch.zeros_like(t), t)
    s = torch.where(a <= eps, torch.zeros_like(s), s)  # the first is a point
    t = torch.where(a <= eps, (f / e_).clamp(0, 1), t)
    return (r + d1 * s.unsqueeze(-1) - d2 * t.unsqueeze(-1)).square().sum(-1)


def _segment_meets_box(p0: Tensor, p1: Tensor, half: Tensor) -> Tensor:
    """Whether segments [p0, p1] (..., 3), in a box's frame, meet the box |x_i| <= half_i (..., 3):
    the slab test, t in [0, 1] within every slab -h_i <= p0_i + t (p1_i - p0_i) <= h_i."""
    d = p1 - p0
    d = torch.where(d.abs() < 1e-12, torch.full_like(d, 1e-12), d)  # parallel to a slab: +-inf-like bounds
    lo, hi = (-half - p0) / d, (half - p0) / d
    enter = torch.minimum(lo, hi).amax(-1).clamp(min=0)
    leave = torch.maximum(lo, hi).amin(-1).clamp(max=1)
    return enter <= leave

def _size(g: dict, size: Tensor | None) -> Tensor:
    return g["size"][0] if size is None else size


def _primitive_groups(batch: list[list[Shape]], kw: dict, floor: int | None = None) -> list[dict]:
    """Elements grouped by kind, stacked over the problems of a batch (the same kinds in the same
    order in each): rotations (P, O, 3, 3), origins (P, O, 3), half sizes (P, O, s). A mesh is its
    convex pieces (:func:`~graspnet_torch.collision.convex.convex_pieces`), one entry of kind
    ``convex`` each, in the mesh's frame: planes (P, O, F, 4) as its size, and bounding spheres
    ``centre`` (P, O, 3), ``radius`` (P, O); a problem whose mesh has fewer pieces is padded with
    pieces that never hit. Element ``floor`` (the robot's floor slab, the same in every problem)
    becomes a half-space, kind ``plane``: only a height is compared."""
    from graspnet_torch.collision.convex import FAR, convex_pieces
    from graspnet_torch.robot.chain import rpy_matrix_np

    groups: dict[str, dict] = {}
    slots: dict[tuple[int, int], int] = {}  # (element, piece) -> the convex group's entry
    for p, elements in enumerate(batch):
        for k, e in enumerate(elements):
            R, t = rpy_matrix_np(e.pose[3:]), np.asarray(e.pose[:3], dtype=np.float64)
            if e.kind == "mesh":
                pieces = convex_pieces(e.mesh, e.scale)
                entries = [("convex", pieces.planes[j], pieces.centres[j], pieces.radii[j])
                           for j in range(pieces.n_pieces)]
            elif k == floor:
                entries = [("plane", np.zeros(3), None, None)]
                t = t + R @ np.array([0.0, 0.0, e.size[2] / 2])  # the slab's top
            elif e.kind == "box":
                entries = [("box", np.asarray(e.size) / 2, None, None)]
            elif e.kind == "cylinder":
                entries = [("cylinder", np.array([e.size[0], e.size[1] / 2, 0.0]), None, None)]
            else:
                entries = [("sphere", np.array([e.size[0], 0.0, 0.0]), None, None)]
            for j, (kind, size, centre, radius) in enumerate(entries):
                g = groups.setdefault(kind, {"kind": kind, "index": [], "R": [], "t": [], "size": [], "centre": [],
                                             "radius": []})
                if (k, j) not in slots:
                    slots[k, j] = len(g["index"])
                    g["index"].append(k)
                    for key in ("R", "t", "size", "centre", "radius"):
                        g[key].append({})
                col = slots[k, j]
                g["R"][col][p], g["t"][col][p], g["size"][col][p] = R, t, size
                g["centre"][col][p], g["radius"][col][p] = centre, radius
    out = []
    P = len(batch)
    for kind in ("box", "cylinder", "sphere", "convex", "plane"):
        if kind not in groups:
            continue
        g = groups[kind]
        if kind == "convex":  # pad to one face count; a piece a problem lacks never hits
            F = max(s.shape[0] for col in g["size"] for s in col.values())
            never = np.zeros((F, 4))
            never[:, 3] = -FAR
            size = np.stack([np.stack([_pad_planes(col.get(p), F, never) for col in g["size"]]) for p in range(P)])
            first = [next(iter(col.values())) for col in g["R"]]
            R = np.stack([np.stack([col.get(p, first[c]) for c, col in enumerate(g["R"])]) for p in range(P)])
            t = np.stack([np.stack([col.get(p, np.zeros(3)) for col in g["t"]]) for p in range(P)])
            centre = np.stack([np.stack([col.get(p, np.zeros(3)) for col in g["centre"]]) for p in range(P)])
            radius = np.stack([np.array([col.get(p, 0.0) for col in g["radius"]]) for p in range(P)])
            entry = {"centre": torch.as_tensor(centre, **kw), "radius": torch.as_tensor(radius, **kw)}
        else:
            s = {"box": 3, "plane": 1}.get(kind, 2)
            size = np.stack([np.stack([col[p][:s] for col in g["size"]]) for p in range(P)])
            R = np.stack([np.stack([col[p] for col in g["R"]]) for p in range(P)])
            t = np.stack([np.stack([col[p] for col in g["t"]]) for p in range(P)])
            entry = {}
        out.append({"kind": kind, "index": g["index"], "R": torch.as_tensor(R, **kw), "t": torch.as_tensor(t, **kw),
                    "size": torch.as_tensor(size, **kw), **entry})
        if kind == "plane":
            out[-1]["top"] = float(t[0, 0, 2])
    return out


def _pad_planes(planes: np.ndarray | None, F: int, never: np.ndarray) -> np.ndarray:
    """(F, 4): a piece's planes padded with planes that are never the largest; a missing piece
    (None): ``never``, planes that put every point far outside."""
    from graspnet_torch.collision.convex import FAR

    if planes is None:
        return never
    out = np.zeros((F, 4))
    out[:, 3] = FAR
    out[: len(planes)] = planes
    return out


def _elements_like(robot: Robot, problem: GraspProblem, first: list[Shape], k: int) -> list[Shape]:
    """The elements of the k-th problem of a batch, checked to match the first's kinds and order."""
    from graspnet_torch.collision.scene import environment_obstacles
    from graspnet_torch.errors import ProblemError

    elements = environment_obstacles(robot, problem) + ([problem.object] if problem.object is not None else [])
    kinds = [e.kind for e in elements]
    if kinds != [e.kind for e in first]:
        raise ProblemError(f"{problem.source}: problem {k} of the batch has obstacles and object {kinds}; the "
                           f"batch's first has {[e.kind for e in first]} (one batch needs the same kinds in order)")
    return elements
