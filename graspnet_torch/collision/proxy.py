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
  by rho, at most rho apart: a slab with rounded edges.

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

A sphere (c, rho) intersects an obstacle when sd(c) < rho, and penetrates the object by more
than the tolerance tau when sd(c) < rho - tau. The count is INTERFACE.md's: distinct (link,
obstacle) pairs plus links penetrating the object, the touching fingers' distal links excepted.
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

__all__ = ["ChainLevels", "CollisionProxy", "motion_terms", "self_collision_spheres", "shape_spheres"]


SMALL_BOX_M = 0.1  # boxes whose longest half-extent is at most this get the covering model for self-collision


def self_collision_spheres(shape: LinkShape) -> tuple[np.ndarray, np.ndarray]:
    """The coarser model of a link primitive for self-collision: a small box (longest half-extent
    <= ``SMALL_BOX_M``: a gripper, its jaws) is covered by spheres along its longest axis, radius
    the half-diagonal of its cross-section, at most a radius apart (conservative: it bulges by up
    to that radius beyond the box), so that thin parts need a few spheres instead of hundreds;
    anything else as :func:`shape_spheres`."""
    if shape.kind != "box" or max(shape.size) / 2 > SMALL_BOX_M:
        return shape_spheres(shape)
    h = np.asarray(shape.size, dtype=np.float64) / 2
    a = int(np.argmax(h))
    r = float(np.sqrt(np.sum(np.delete(h, a) ** 2)))
    k = max(1, math.ceil(2 * h[a] / r) + 1)
    local = np.zeros((k, 3))
    local[:, a] = np.linspace(-h[a], h[a], k) if k > 1 else 0.0
    centres = local @ shape.origin[:3, :3].T + shape.origin[:3, 3]
    return centres, np.full(k, r)


def shape_spheres(shape: LinkShape) -> tuple[np.ndarray, np.ndarray]:
    """A link primitive as spheres in its link's frame: centres (k, 3), radii (k,)."""
    if shape.kind == "sphere":
        local, radii = np.zeros((1, 3)), np.array([shape.size[0]])
    elif shape.kind == "cylinder":
        r, length = shape.size
        half = length / 2 - min(r / 4, length / 2)
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
    else:  # pragma: no cover - link_shapes refuses other kinds
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
        self_by_link: dict[str, list] = {}  # the coarser model for the robot's own links
        for shape in shapes:
            where, G = self._attachment(robot, shape.link, frames)
            attach[shape.link] = where
            for c, r in zip(*self_collision_spheres(shape), strict=True):
                self_by_link.setdefault(shape.link, []).append((G[:3, :3] @ c + G[:3, 3], float(r)))
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
            terms = [motion_terms(f.chain.axes, f.chain.joint_types) for f in robot.fingers.values()]
            self.fingers = ChainLevels(np.stack([t[0] for t in terms]), np.stack([t[1] for t in terms]),
                                  np.stack([t[2] for t in terms]),
                                  np.stack([f.chain.offsets for f in robot.fingers.values()]), kw)
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
        self._groups = _primitive_groups(batch, kw)
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
            # broad phase: the cluster's bounding sphere within reach
            bthr = np.broadcast_to(bound_r[:, None, None] - np.array([margin[k] for k in g["index"]]),
                                   (C, 1, len(g["index"])))[:, 0]  # (C, O_g)
            g["bound_pos"] = (torch.as_tensor(bthr > 0, device=device) & g["pos"].any(1)).unsqueeze(1)  # (C, 1, O_g)
            g["bound_thr_sq"] = torch.as_tensor(np.where(bthr > 0, bthr, 0.0) ** 2, **kw).unsqueeze(1)
            g["columns"] = torch.as_tensor(g["index"], device=device)
            P = g["R"].shape[0]
            g["R_cols"] = g["R"].permute(0, 2, 1, 3).reshape(P, 3, -1)  # per problem [R_1 .. R_O]
            g["Rt"] = torch.einsum("poji,poj->poi", g["R"], g["t"]).reshape(P, -1)  # per problem [R_o^T t_o]
        self._true = torch.ones((), dtype=torch.bool, device=device)
        # the robot's own links (self_collision: true): their own clusters (self_collision_spheres),
        # every cluster of one link of a pair against every cluster of the other
        self.self_pairs = self_collision_pairs(robot)
        self.proxy_unchecked: list[tuple[str, str]] = []
        involved = list(dict.fromkeys(link for pair in self.self_pairs for link in pair))
        s_clusters, clusters_of = [], {}
        for link in involved:
            spheres = self_by_link[link]
            for start in range(0, len(spheres), CLUSTER):
                chunk = spheres[start:start + CLUSTER]
                clusters_of.setdefault(link, []).append(len(s_clusters))
                s_clusters.append((frame_id(attach[link]), np.stack([c for c, _ in chunk]),
                                   np.array([r for _, r in chunk])))
        S = len(s_clusters)
        s_local, s_radii = np.zeros((S, 4, CLUSTER)), np.full((S, CLUSTER), -np.inf)
        s_bound, s_bound_r = np.zeros((S, 4, 1)), np.zeros(S)
        for k, (_f, c, r) in enumerate(s_clusters):
            s_local[k, :3, :len(r)], s_local[k, 3, :len(r)], s_radii[k, :len(r)] = c.T, 1.0, r
            centre = (c.min(0) + c.max(0)) / 2
            s_bound[k, :3, 0], s_bound[k, 3, 0] = centre, 1.0
            s_bound_r[k] = float(np.max(np.linalg.norm(c - centre, axis=1) + r))
        ca, cb, pid = [], [], []
        for p, (a, b) in enumerate(self.self_pairs):
            for i in clusters_of[a]:
                for j in clusters_of[b]:
                    ca.append(i)
                    cb.append(j)
                    pid.append(p)
        self._self_frame = torch.tensor([f for f, *_ in s_clusters], dtype=torch.long, device=device)
        self._self_local = torch.as_tensor(s_local, **kw)
        self._self_bound = torch.as_tensor(s_bound, **kw)
        self._self_a = torch.tensor(ca, dtype=torch.long, device=device)
        self._self_b = torch.tensor(cb, dtype=torch.long, device=device)
        self._self_pair = torch.tensor(pid, dtype=torch.long, device=device)
        self._self_bound_sq = torch.as_tensor((s_bound_r[ca] + s_bound_r[cb] + clearance) ** 2, **kw)
        if ca:
            thr = s_radii[ca][:, :, None] + s_radii[cb][:, None, :] + clearance  # (N, K, K); padding: -inf
            self._self_thr_sq = torch.as_tensor(np.where(thr > 0, thr, 0.0) ** 2, **kw)
            # pairs that this coarser model (with its clearance) finds touching at the home posture
            # are joints' neighbours it cannot resolve (a wrist housing and the gripper): it leaves
            # them to FCL, which checks every pair of self_collision_pairs
            home = robot.home_posture(dtype).body.to(device).unsqueeze(0)
            levels, palm_home = self.body_levels_and_palm(home)
            touching_home = self.self_hits(palm_home, torch.zeros(1, 0, 0, **kw), home, levels)[0]
            keep = ~touching_home[self._self_pair]
            self._self_a, self._self_b = self._self_a[keep], self._self_b[keep]
            self._self_bound_sq, self._self_thr_sq = self._self_bound_sq[keep], self._self_thr_sq[keep]
            self._self_pair = self._self_pair[keep]
            self.proxy_unchecked = [pair for pair, t in zip(self.self_pairs, touching_home.tolist(), strict=True) if t]

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
                    P = P @ finger.chain.offsets[i]
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
        frames = self.frames(palm, fingers, body, body_levels)[self._cluster_frame]  # (C, T, 3, 4)
        T = frames.shape[1]
        out = torch.zeros(T, len(self.links), self.n_elements, dtype=torch.bool, device=frames.device)
        C = frames.shape[0]
        flat = frames.reshape(C, T * 3, 4)
        pid = problem_index if self.n_problems > 1 else None
        if T * C * CLUSTER * self.n_elements <= DENSE_LIMIT:  # small batches: every sphere, no gathers
            centres = torch.bmm(flat, self._cluster_local).view(C, T, 3, CLUSTER).transpose(2, 3)  # (C, T, K, 3)
            for g in self._groups:
                size = None if pid is None else g["size"][pid].unsqueeze(1)  # (T, 1, O_g, s)
                hit = _hit(g, _local(g, centres, pid), g["pos"].unsqueeze(1), g["thr_sq"].unsqueeze(1),
                           size).any(2)  # (C, T, O_g)
                per_link = torch.einsum("cto,cl->tlo", hit.to(self._link_of_cluster.dtype), self._link_of_cluster)
                out[..., g["columns"]] |= per_link > 0
            return out
        bound = torch.bmm(flat, self._cluster_bound).view(C, T, 1, 3)  # bounding-sphere centres
        for g in self._groups:
            size = None if pid is None else g["size"][pid]  # (T, O_g, s)
            near = _hit(g, _local(g, bound, pid).squeeze(2), g["bound_pos"], g["bound_thr_sq"], size)  # (C, T, O_g)
            c, t, o = near.nonzero(as_tuple=True)
            if c.numel() == 0:
                continue
            p_of = torch.zeros_like(t) if pid is None else pid[t]
            centres = torch.bmm(frames[c, t], self._cluster_local[c]).transpose(1, 2)  # (N, CLUSTER, 3)
            p = torch.bmm(centres - g["t"][p_of, o].unsqueeze(1), g["R"][p_of, o])  # rows: R^T (x - t)
            hit = _hit(g, p, g["pos"][c, :, o], g["thr_sq"][c, :, o], g["size"][p_of, o].unsqueeze(1)).any(-1)  # (N,)
            out.index_put_((t[hit], self._cluster_link[c[hit]], g["columns"][o[hit]]), self._true)
        return out

    def count(self, palm: tuple[Tensor, Tensor], fingers: Tensor, body: Tensor | None = None,
              body_levels: list[Tensor] | None = None, problem_index: Tensor | None = None) -> Tensor:
        """(T,) collision counts (long): distinct (link, obstacle) pairs + links in the object +
        colliding pairs of the robot's own links."""
        T = palm[0].shape[0]
        out = torch.zeros(T, dtype=torch.long, device=palm[0].device)
        if self.n_elements:
            out = self.pairs(palm, fingers, body, body_levels, problem_index).sum(dim=(1, 2))
        if self.self_pairs:
            out = out + self.self_hits(palm, fingers, body, body_levels).sum(-1)
        return out

    def self_hits(self, palm: tuple[Tensor, Tensor], fingers: Tensor, body: Tensor | None = None,
                  body_levels: list[Tensor] | None = None) -> Tensor:
        """(T, P) bool: pair p of ``self.self_pairs`` collides: some sphere of one link within reach
        of some sphere of the other, |c_i - c_j| < r_i + r_j + clearance. Broad phase on the
        clusters' bounding spheres, then every sphere of the near cluster pairs."""
        frames = self.frames(palm, fingers, body, body_levels)[self._self_frame]  # (S, T, 3, 4)
        C, T = frames.shape[:2]
        out = torch.zeros(T, len(self.self_pairs), dtype=torch.bool, device=frames.device)
        bound = torch.bmm(frames.reshape(C, T * 3, 4), self._self_bound).view(C, T, 3)
        near = (bound[self._self_a] - bound[self._self_b]).square().sum(-1) < self._self_bound_sq.unsqueeze(1)
        n, t = near.nonzero(as_tuple=True)  # (cluster pair, trial)
        if n.numel() == 0:
            return out
        a, b = self._self_a[n], self._self_b[n]
        pa = torch.bmm(frames[a, t], self._self_local[a])  # (N, 3, K)
        pb = torch.bmm(frames[b, t], self._self_local[b])
        # |a - b|^2 = |a|^2 + |b|^2 - 2 a.b: one batched product instead of an (N, K, K, 3) difference
        d2 = pa.square().sum(1).unsqueeze(2) + pb.square().sum(1).unsqueeze(1) - 2 * torch.bmm(pa.transpose(1, 2), pb)
        hit = (d2 < self._self_thr_sq[n]).flatten(1).any(-1)
        out.index_put_((t[hit], self._self_pair[n[hit]]), self._true)
        return out


def _local(g: dict, points: Tensor, pid: Tensor | None = None) -> Tensor:
    """(..., T, K, 3) world points -> (..., T, K, O_g, 3) in each element's frame of a group:
    R_o^T (x - t_o) for every element at once as x @ [R_1 .. R_O] - [R_o^T t_o]; ``pid`` (T,)
    each trial's problem of a batch (None: the first)."""
    if pid is None:
        return (points @ g["R_cols"][0] - g["Rt"][0]).view(*points.shape[:-1], -1, 3)
    return (points @ g["R_cols"][pid] - g["Rt"][pid].unsqueeze(-2)).view(*points.shape[:-1], -1, 3)


def _hit(g: dict, p: Tensor, positive: Tensor, thr_sq: Tensor, size: Tensor | None = None) -> Tensor:
    """sd(p) < thr for points p (..., 3) in their element's frame, with thr > 0 (``positive``;
    otherwise never) and ``thr_sq`` = thr^2: outside a primitive |max(d, 0)|^2 < thr^2, inside
    always. d: box |p| - h; cylinder (|p_xy| - r, |p_z| - h); sphere |p| - r."""
    size = g["size"][0] if size is None else size
    if g["kind"] == "sphere":
        d = (torch.linalg.vector_norm(p, dim=-1) - size[..., 0]).unsqueeze(-1)
    elif g["kind"] == "box":
        d = p.abs() - size
    else:
        d = torch.stack([torch.linalg.vector_norm(p[..., :2], dim=-1), p[..., 2].abs()], dim=-1) - size
    outside = d.clamp(min=0).square().sum(-1)
    return positive & ((outside < thr_sq) | (d.amax(-1) <= 0))


def _primitive_groups(batch: list[list[Shape]], kw: dict) -> list[dict]:
    """Elements grouped by kind, stacked over the problems of a batch (the same kinds in the same
    order in each): rotations (P, O, 3, 3), origins (P, O, 3), half sizes (P, O, s); a mesh becomes
    its bounding box in its own frame."""
    from graspnet_torch.robot.chain import rpy_matrix_np

    groups: dict[str, dict] = {}
    for p, elements in enumerate(batch):
        for k, e in enumerate(elements):
            R, t = rpy_matrix_np(e.pose[3:]), np.asarray(e.pose[:3], dtype=np.float64)
            if e.kind == "mesh":
                import trimesh

                mesh = trimesh.load(e.mesh, force="mesh")
                lo, hi = np.asarray(mesh.bounds[0]), np.asarray(mesh.bounds[1])
                kind, half = "box", (hi - lo) / 2
                t = t + R @ ((hi + lo) / 2)
            elif e.kind == "box":
                kind, half = "box", np.asarray(e.size) / 2
            elif e.kind == "cylinder":
                kind, half = "cylinder", np.array([e.size[0], e.size[1] / 2, 0.0])
            else:
                kind, half = "sphere", np.array([e.size[0], 0.0, 0.0])
            g = groups.setdefault(kind, {"kind": kind, "index": [], "R": [], "t": [], "size": []})
            if p == 0:
                g["index"].append(k)
                g["R"].append([])
                g["t"].append([])
                g["size"].append([])
            col = g["index"].index(k)
            g["R"][col].append(R)
            g["t"][col].append(t)
            g["size"][col].append(half)
    out = []
    for kind in ("box", "cylinder", "sphere"):
        if kind in groups:
            g = groups[kind]
            size = np.asarray(g["size"]).transpose(1, 0, 2)[..., :3 if kind == "box" else 2]
            out.append({"kind": kind, "index": g["index"],
                        "R": torch.as_tensor(np.asarray(g["R"]).transpose(1, 0, 2, 3), **kw),
                        "t": torch.as_tensor(np.asarray(g["t"]).transpose(1, 0, 2), **kw),
                        "size": torch.as_tensor(size, **kw)})
    return out


def _elements_like(robot: Robot, problem: GraspProblem, first: list[Shape], k: int) -> list[Shape]:
    """The elements of the k-th problem of a batch, checked to match the first's kinds and order."""
    from graspnet_torch.collision.scene import environment_obstacles
    from graspnet_torch.errors import ProblemError

    elements = environment_obstacles(robot, problem) + ([problem.object] if problem.object is not None else [])
    kinds = ["box" if e.kind == "mesh" else e.kind for e in elements]
    if kinds != ["box" if e.kind == "mesh" else e.kind for e in first]:
        raise ProblemError(f"{problem.source}: problem {k} of the batch has obstacles and object {kinds}; the "
                           f"batch's first has {[e.kind for e in first]} (one batch needs the same kinds in order)")
    return elements
