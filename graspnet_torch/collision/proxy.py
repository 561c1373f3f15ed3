"""A batched torch approximation of the collision count, for the closed loop.

FCL (``collision/scene.py``) is the engine of record, but it checks one posture at a time from
Python: for T = 1000 trials it would cost far more than the rest of an iteration. The loop
therefore counts collisions with this proxy, and every reported count still comes from FCL
(tests measure how often the two agree on random configurations).

The proxy composes four parts:

- the robot's level frames (:mod:`graspnet_torch.robot.frames`): every frame a link hangs from
  (a level of the body chain, the palm, a level of a finger chain), for a batch of
  configurations from a few batched matrix products;
- each link's shapes as spheres in those frames (:mod:`graspnet_torch.collision.spheres`);
- signed distances of the sphere centres to the problem's obstacles, the floor and the object
  (:mod:`graspnet_torch.collision.primitives`): a sphere (c, rho) intersects an obstacle when
  sd(c) < rho, and penetrates the object by more than the tolerance tau when sd(c) < rho - tau;
- the robot's own links as capsules and boxes (:mod:`graspnet_torch.collision.self_collision`).

The count is INTERFACE.md's: distinct (link, obstacle) pairs plus links penetrating the object,
the touching fingers' distal links excepted, plus colliding pairs of the robot's own links.
"""

from __future__ import annotations

import weakref
from collections.abc import Callable, Sequence

import numpy as np
import torch
from torch import Tensor

from graspnet_torch.collision.convex import piece_distance
from graspnet_torch.collision.finger_overlaps import FINGER_GAP_M, FingerOverlaps
from graspnet_torch.collision.primitives import group_thresholds, primitive_groups
from graspnet_torch.collision.scene import CollisionScene, environment_obstacles, finger_pairs, self_collision_pairs
from graspnet_torch.collision.self_collision import SelfCollisionModel
from graspnet_torch.collision.spheres import CLUSTER, SphereClusters, sphere_clusters
from graspnet_torch.errors import ProblemError
from graspnet_torch.robot.frames import Attachment, RobotLevels, link_attachments, riding_base_links
from graspnet_torch.robot.geometry import link_shapes
from graspnet_torch.robot.robot import Robot
from graspnet_torch.robot.shape import Shape
from graspnet_torch.tasks.problem import GraspProblem

__all__ = ["FINGER_GAP_M", "CollisionProxy"]

PENETRATION_CHUNK = 1 << 21  # rows x spheres x elements that :meth:`CollisionProxy.penetrations` takes at once
DENSE_LIMIT = 1 << 13  # T x clusters x CLUSTER x elements below which every sphere is tested (no broad phase)


_ROBOT_PARTS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def _robot_parts(robot: Robot) -> tuple[list, dict, Callable[[Attachment], int], SphereClusters]:
    """What every proxy of a robot shares, built once per robot: its links' collision shapes, where
    each link hangs (its attachment), the frame each attachment's spheres ride (frames stacked in a
    fixed order: body levels, palm, finger levels finger by finger) and the links as sphere clusters."""
    parts = _ROBOT_PARTS.get(robot)
    if parts is None:
        shapes = link_shapes(robot.urdf, "collision")
        attach = link_attachments(robot, [shape.link for shape in shapes])
        body_levels = max((a.level for a in attach.values() if a.kind == "body"), default=0)
        n_body = body_levels + 1 if robot.body is not None else 0
        n_f = max((a.level for a in attach.values() if a.kind == "finger"), default=0) + 1

        def frame_id(a: Attachment) -> int:
            if a.kind == "body":
                return a.level
            if a.kind == "palm":
                return n_body
            return n_body + 1 + a.finger * n_f + a.level

        parts = _ROBOT_PARTS[robot] = (shapes, attach, frame_id, sphere_clusters(shapes, attach, frame_id))
    return parts


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

        touching: whether the contact fingers' distal links may touch the object at any depth
            (the point contact model); False: they count as every link does, beyond
            ``object_tolerance`` (the surface model).
        fingers_apart: :meth:`penetrations` also measures two fingers through each other (the
            surface model's rule; :meth:`count` does not count them: FCL does).

    Call :meth:`count` with the palm frame, the body joints (robots with an arm) and every
    finger's joints. Two phases, as FCL: each link's spheres are cut into clusters of at most
    ``CLUSTER`` neighbours, each with a bounding sphere; a cluster's spheres are placed and tested
    only where its bounding sphere meets an element (broad phase), so the cost follows the
    number of near (cluster, element) pairs, not T x spheres x elements. Small batches (T x
    clusters x ``CLUSTER`` x elements <= ``DENSE_LIMIT``, e.g. one trial) test every sphere at
    once: fewer operations, the same answer (tests compare the two).

    Attributes:
        links: the links with collision shapes; ``link_spheres`` their sphere centres in the link frame.
        clusters: the spheres in clusters (:class:`~graspnet_torch.collision.spheres.SphereClusters`).
        groups, thresholds: the elements by kind (:class:`~graspnet_torch.collision.primitives.PrimitiveGroup`)
            and the clusters' tests against them, one per group.
        self_pairs: the robot's link pairs tested against each other; ``proxy_unchecked`` those left to FCL.
        robot_levels: the robot's level frames (:class:`~graspnet_torch.robot.frames.RobotLevels`).
    """

    def __init__(self, robot: Robot, problem: GraspProblem | Sequence[GraspProblem], object_tolerance: float = 0.002,
                 dtype: torch.dtype = torch.float32, device: torch.device | str = "cpu", clearance: float = 0.0,
                 touching: bool = True, fingers_apart: bool = False):
        self.robot = robot
        self.fingers_apart = fingers_apart
        self._finger_overlaps: FingerOverlaps | None = None
        problems = [problem] if isinstance(problem, GraspProblem) else list(problem)
        problem = problems[0]
        self.n_problems = len(problems)
        shapes, attach, frame_id, cl = _robot_parts(robot)
        touching_links = CollisionScene.distal_links(robot, shapes, problem.fingers)
        self.body_levels = max((a.level for a in attach.values() if a.kind == "body"), default=0)
        self.finger_levels = max((a.level for a in attach.values() if a.kind == "finger"), default=0)
        self.clusters = cl
        self.links, self.link_spheres, self.n_spheres = cl.links, cl.link_spheres, cl.n_spheres
        kw = {"dtype": dtype, "device": device}
        self._cluster_frame = torch.tensor(cl.frame, device=device)
        self._cluster_link = torch.tensor(cl.link, device=device)
        one_hot = np.zeros((len(cl.link), len(self.links)))
        one_hot[np.arange(len(cl.link)), cl.link] = 1
        self._link_of_cluster = torch.as_tensor(one_hot, **kw)  # (C, L)
        self._cluster_local = torch.as_tensor(cl.local, **kw)  # (C, 4, CLUSTER) homogeneous sphere centres
        self._cluster_bound = torch.as_tensor(cl.bound, **kw)  # (C, 4, 1) bounding-sphere centres
        self.robot_levels = RobotLevels(robot, dtype, device)
        self._eye34 = torch.eye(4, **kw)[:3]
        # the environment: obstacles, then the object (its own threshold; touching links exempt)
        elements = environment_obstacles(robot, problem)  # the problem's, then the robot's floor
        margin = [-clearance] * len(problem.obstacles) + [0.0] * (len(elements) - len(problem.obstacles))  # the
        # platform stands 1 mm above the floor slab: no margin there
        exempt: list[set] = [set()] * len(problem.obstacles)
        if robot.cfg.floor is not None:  # links that only ride the mobile base stand on the floor: never tested
            exempt.append(riding_base_links(robot, attach))
        if problem.object is not None:
            elements.append(problem.object)
            margin.append(object_tolerance - clearance)
            exempt.append(touching_links if touching else set())
        self.n_elements = len(elements)
        batch = [elements] + [_elements_like(robot, p, elements, k) for k, p in enumerate(problems[1:], 1)]
        self.groups = primitive_groups(batch, kw, len(problem.obstacles) if robot.cfg.floor is not None else None)
        skip = np.zeros((len(cl.link), len(exempt)), dtype=bool)  # (C, elements): cluster never tested against it
        for k, links in enumerate(exempt):
            skip[:, k] = [self.links[li] in links for li in cl.link]
        self.thresholds = [group_thresholds(g, cl.radii, cl.bound_r, margin, skip, kw) for g in self.groups]
        self._true = torch.ones((), dtype=torch.bool, device=device)
        self._radii = torch.as_tensor(np.nan_to_num(cl.radii, nan=0.0), **kw)  # (C, K): padding 0 (never tested)
        # elementwise tests per sphere: one per primitive, one per plane of a convex piece
        self._dense_cost = sum(len(g.index) * (g.size.shape[-2] if g.kind == "convex" else 1) for g in self.groups)
        # the robot's own links (self_collision: true): capsules and boxes, every primitive of one
        # link of a pair against every primitive of the other; pairs this model finds touching at
        # the home posture (none for ``manus``) are left to FCL, as are pairs of two boxes
        self.self_pairs = self_collision_pairs(robot)
        self._self = SelfCollisionModel(shapes, self.self_pairs, attach, frame_id, clearance, kw)
        if self.self_pairs:
            home = robot.home_posture(dtype).body.to(device).unsqueeze(0)
            levels, palm_home = self.body_levels_and_palm(home)
            touching_home = self.self_hits(palm_home, torch.zeros(1, 0, 0, **kw), home, levels)[0]
            if bool(touching_home.any()):
                self._self.drop(touching_home)

    @property
    def proxy_unchecked(self) -> list[tuple[str, str]]:
        """The link pairs of ``self_pairs`` the proxy does not test (two boxes, or touching at home): FCL's."""
        return self._self.unchecked

    def body_levels_and_palm(self, body: Tensor) -> tuple[list[Tensor], tuple[Tensor, Tensor]]:
        """The body chain's frames P_1..P_m (T, 4, 4) and the palm frame R (T, 3, 3), t (T, 3)
        (:meth:`~graspnet_torch.robot.frames.RobotLevels.body_levels_and_palm`)."""
        return self.robot_levels.body_levels_and_palm(body)

    def frames(self, palm: tuple[Tensor, Tensor], fingers: Tensor, body: Tensor | None = None,
               body_levels: list[Tensor] | None = None, bases: tuple[Tensor, Tensor] | None = None) -> Tensor:
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
                body_levels = self.robot_levels.body_levels(body, self.body_levels)
            frames += [P[..., :3, :] for P in body_levels[:self.body_levels]]
        frames.append(W)
        stacked = torch.stack(frames)  # (n, T, 3, 4)
        if self.robot.n_fingers:
            levels = self.robot_levels.finger_levels(W, fingers, self.finger_levels, bases)
            stacked = torch.cat([stacked, torch.stack(levels, dim=2).flatten(1, 2).transpose(0, 1)])
        return stacked

    def sphere_centres(self, palm: tuple[Tensor, Tensor], fingers: Tensor, body: Tensor | None = None,
                       bases: tuple[Tensor, Tensor] | None = None) -> Tensor:
        """World centres of every cluster's spheres (padding included): (T, C, CLUSTER, 3)
        (arguments as :meth:`count`'s)."""
        T, C = palm[0].shape[0], self._cluster_local.shape[0]
        return self.centres(self.frames(palm, fingers, body, None, bases)).view(T, C, CLUSTER, 3)

    def centres(self, frames: Tensor, spheres: Tensor | None = None) -> Tensor:
        """World centres (T, S, 3) of the spheres ``spheres`` (S,) (indices into the C x ``CLUSTER``
        of :meth:`sphere_centres`, flattened; None: all) from every frame (n_frames, T, 3, 4) of
        :meth:`frames`."""
        C = self._cluster_local.shape[0]
        frame = self._cluster_frame.repeat_interleave(CLUSTER)
        local = self._cluster_local.transpose(1, 2).reshape(C * CLUSTER, 4)
        if spheres is not None:
            frame, local = frame[spheres], local[spheres]
        return (frames[frame] @ local[:, None, :, None]).squeeze(-1).transpose(0, 1)

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
            for g, th in zip(self.groups, self.thresholds, strict=True):
                size = None if pid is None else g.size[pid].unsqueeze(1)  # (T, 1, O_g, s)
                hit = g.hits(g.local(centres, pid), th.pos.unsqueeze(1), th.thr_sq.unsqueeze(1), size).any(2)
                per_link = torch.einsum("cto,cl->tlo", hit.to(self._link_of_cluster.dtype), self._link_of_cluster)
                if g.kind == "convex":  # the pieces of one mesh share its column
                    per_link = torch.zeros(T, len(self.links), self.n_elements, dtype=per_link.dtype,
                                           device=per_link.device).index_add_(2, g.columns, per_link)
                    out |= per_link > 0
                else:
                    out[..., g.columns] |= per_link > 0
            return out
        bound = torch.bmm(flat, self._cluster_bound).view(C, T, 1, 3)  # bounding-sphere centres
        for g, th in zip(self.groups, self.thresholds, strict=True):
            size = None if pid is None else g.size[pid]  # (T, O_g, s)
            local = g.local(bound, pid).squeeze(2)  # (C, T, O_g, 3)
            if g.kind == "convex":  # bounding spheres: the cluster's and the piece's
                gap = local - (g.centre[0] if pid is None else g.centre[pid])
                reach = th.bound_r.unsqueeze(1) + (g.radius[0] if pid is None else g.radius[pid])
                near = th.bound_pos & (gap.square().sum(-1) < reach.clamp(min=0).square())  # (C, T, O_g)
            else:
                near = g.hits(local, th.bound_pos, th.bound_thr_sq, size)
            c, t, o = near.nonzero(as_tuple=True)
            if c.numel() == 0:
                continue
            p_of = torch.zeros_like(t) if pid is None else pid[t]
            if g.kind == "convex":  # then the cluster's bounding sphere against the piece's planes
                planes = g.size[p_of, o]  # (N, F, 4)
                keep = piece_distance(local[c, t, o].unsqueeze(1), planes).squeeze(1) < th.bound_r[c, o]
                c, t, o, p_of = c[keep], t[keep], o[keep], p_of[keep]
                if c.numel() == 0:
                    continue
            centres = torch.bmm(frames[c, t], self._cluster_local[c]).transpose(1, 2)  # (N, CLUSTER, 3)
            if g.kind == "plane":  # the height above the floor's top
                p = centres[..., 2:3] - g.top
            else:
                p = torch.bmm(centres - g.t[p_of, o].unsqueeze(1), g.R[p_of, o])  # rows: R^T (x - t)
            if g.kind == "convex":  # every sphere of the cluster against the piece's planes
                d = piece_distance(p, planes[keep])  # (N, CLUSTER)
                thr_sq = th.thr_sq[c, :, o]
                hit = (th.pos[c, :, o] & ((d.clamp(min=0).square() < thr_sq) | (d <= 0))).any(-1)
            else:
                hit = g.hits(p, th.pos[c, :, o], th.thr_sq[c, :, o], g.size[p_of, o].unsqueeze(1)).any(-1)
            out.index_put_((t[hit], self._cluster_link[c[hit]], g.columns[o[hit]]), self._true)
        return out

    def count(self, palm: tuple[Tensor, Tensor], fingers: Tensor, body: Tensor | None = None,
              body_levels: list[Tensor] | None = None, problem_index: Tensor | None = None,
              bases: tuple[Tensor, Tensor] | None = None) -> Tensor:
        """(T,) collision counts (long): distinct (link, obstacle) pairs + links in the object +
        colliding pairs of the robot's own links. ``bases``: every finger's base in the palm per
        configuration (:meth:`Robot.base_frames <graspnet_torch.robot.robot.Robot.base_frames>`),
        where the joints the fingers share move them."""
        T = palm[0].shape[0]
        out = torch.zeros(T, dtype=torch.long, device=palm[0].device)
        if not self.n_elements and not self._self.tested:
            return out
        frames = self.frames(palm, fingers, body, body_levels, bases)  # once for both tests
        if self.n_elements:
            out = self._pairs(frames, problem_index).sum(dim=(1, 2))
        if self._self.tested:
            out = out + self._self.hits(frames).sum(-1)
        return out

    def penetrations(self, centres: Tensor, spheres: Tensor | None = None, problem_index: Tensor | None = None
                     ) -> Tensor:
        """How far spheres reach into the obstacles and the object: centres (T, S, 3) of the spheres
        ``spheres`` (S,) (indices into the C x ``CLUSTER`` of :meth:`sphere_centres`, flattened;
        None: all) -> (T, S) metres, per sphere the root sum of squares over the elements
        :meth:`count` tests it against (the floor left out) of max(0, rho - sd(c)); zero where it
        at most touches. ``problem_index`` as :meth:`count`'s."""
        pid = problem_index if self.n_problems > 1 else None
        T, S = centres.shape[:2]
        rows = max(1, PENETRATION_CHUNK // max(1, S * sum(len(g.index) for g in self.groups)))
        if T > rows:  # in chunks of rows: a batch's forward differences of a mesh's many pieces
            return torch.cat([self.penetrations(centres[a: a + rows], spheres,
                                                None if pid is None else pid[a: a + rows]) for a in range(0, T, rows)])
        radii = self._radii.reshape(-1) if spheres is None else self._radii.reshape(-1)[spheres]
        sq = centres.new_zeros(T, S)
        for g, th in zip(self.groups, self.thresholds, strict=True):
            if g.kind == "plane":
                continue
            pos = th.pos.flatten(0, 1) if spheres is None else th.pos.flatten(0, 1)[spheres]  # (S, O_g)
            local = g.local(centres, pid)  # (T, S, O_g, 3)
            if g.kind == "convex":  # the pieces' planes only where the sphere meets the piece's bounding sphere
                centre, reach = (g.centre[0], g.radius[0]) if pid is None else \
                    (g.centre[pid, None], g.radius[pid, None])
                near = pos & ((local - centre).norm(dim=-1) < radii[:, None] + reach)  # (T, S, O_g)
                t, k, o = near.nonzero(as_tuple=True)
                planes = g.size[0][o] if pid is None else g.size[pid[t], o]  # (N, F, 4)
                d = piece_distance(local[t, k, o].unsqueeze(1), planes).squeeze(1)
                sq = sq.index_put((t, k), (radii[k] - d).clamp(min=0).square(), accumulate=True)
                continue
            size = None if pid is None else g.size[pid].unsqueeze(1)  # (T, 1, O_g, s)
            sd = g.signed_distance(local, size)  # (T, S, O_g)
            sq = sq + ((radii[:, None] - sd).clamp(min=0) * pos).square().sum(-1)
        return sq.sqrt()

    def overlapping_pairs(self, centres: Tensor) -> tuple[Tensor, Tensor, Tensor]:
        """Two fingers through each other (where the proxy was built with ``fingers_apart``):
        centres (T, S, 3) of every sphere (flattened C x ``CLUSTER``) -> the (t, i, j) of each
        pair of spheres of two different fingers' links apart at home
        (:func:`~graspnet_torch.collision.scene.finger_pairs`) that overlap in row t, each (N,)
        (:class:`~graspnet_torch.collision.finger_overlaps.FingerOverlaps`: links first)."""
        return self._overlaps().overlapping(centres)

    def overlaps(self, ci: Tensor, cj: Tensor, i: Tensor, j: Tensor) -> Tensor:
        """The overlap r_i + r_j + :data:`FINGER_GAP_M` - |c_i - c_j|, clamped at 0, of spheres i and
        j (N,) at centres ci, cj (N, ..., 3) -> (N, ...)."""
        return self._overlaps().overlaps(ci, cj, i, j)

    def sphere_links(self) -> Tensor:
        """(S,) each sphere's link (index into ``self.links``), flattened C x ``CLUSTER``."""
        return self._cluster_link.repeat_interleave(CLUSTER)

    def sphere_radii(self) -> Tensor:
        """(S,) each sphere's radius, flattened C x ``CLUSTER`` (0: padding, never tested)."""
        return self._radii.reshape(-1)

    def _overlaps(self) -> FingerOverlaps:
        """The finger-pair test of :meth:`overlapping_pairs`; built once."""
        if self._finger_overlaps is None:
            pairs = []
            if self.fingers_apart:
                pairs = [(self.links.index(a), self.links.index(b)) for a, b in finger_pairs(self.robot)
                         if a in self.links and b in self.links]
            C = self._cluster_local.shape[0]
            local = self._cluster_local.transpose(1, 2).reshape(C * CLUSTER, 4)[:, :3]
            self._finger_overlaps = FingerOverlaps(self.sphere_links(), self._radii.reshape(-1), local, pairs,
                                                   CLUSTER)
        return self._finger_overlaps

    def link_depths(self, penetrations: Tensor, spheres: Tensor | None = None) -> Tensor:
        """(T, S) sphere penetrations (:meth:`penetrations`) -> (T, L) each link's (``self.links``):
        the root sum of squares over its spheres; a smooth residual for a least-squares solver
        to drive to zero."""
        of = self._link_of_cluster.repeat_interleave(CLUSTER, 0)  # (C K, L)
        return (penetrations.square() @ (of if spheres is None else of[spheres])).sqrt()

    def self_hits(self, palm: tuple[Tensor, Tensor], fingers: Tensor, body: Tensor | None = None,
                  body_levels: list[Tensor] | None = None) -> Tensor:
        """(T, P) bool: pair p of ``self.self_pairs`` collides (with the clearance): some capsule
        of one link within reach of a capsule of the other (segment distance < r_1 + r_2 +
        clearance), or of a box (the segment meets the box grown by r + clearance). Dense: every
        primitive pair of every configuration, a few elementwise operations each."""
        if not self._self.tested:
            return torch.zeros(palm[0].shape[0], len(self.self_pairs), dtype=torch.bool, device=palm[0].device)
        return self._self.hits(self.frames(palm, fingers, body, body_levels))


def _elements_like(robot: Robot, problem: GraspProblem, first: list[Shape], k: int) -> list[Shape]:
    """The elements of the k-th problem of a batch, checked to match the first's kinds and order."""
    elements = environment_obstacles(robot, problem) + ([problem.object] if problem.object is not None else [])
    kinds = [e.kind for e in elements]
    if kinds != [e.kind for e in first]:
        raise ProblemError(f"{problem.source}: problem {k} of the batch has obstacles and object {kinds}; the "
                           f"batch's first has {[e.kind for e in first]} (one batch needs the same kinds in order)")
    return elements
