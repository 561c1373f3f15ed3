"""Contact-set drafts: sampled hand postures whose chosen fingers' pads rest on the object's
surface, facing into it (the sampler of :mod:`~graspnet_torch.synthesis.candidates`, which checks
each draft before it is a contact set).

Drafts are made in batches of ``BATCH`` palm poses, in three steps:

1. *Palm*: a uniformly random palm orientation; the object is put in front of the palm (the side
   its fingers close toward: :func:`~graspnet_torch.robot.opposition.hand_axes`; :func:`palm_front`)
   at a random point of the palm's plane within the fingertips' reach, at a random gap from the
   palm's face up to ``GAP_SHARE`` of the fingertips' reach beyond it (:func:`palm_gap`: the hand's
   own scale): the palm looks at the object from a random direction, at a random roll. Once some
   palm pose has touched (step 2), ``NEAR_SHARE`` of each batch are drawn near those that have
   (turned by ``NEAR_DEG``, moved by ``NEAR_M``, standard deviations): a palm pose near one that
   touches often touches too.
2. *Fingers*: each finger closes along ``LINES`` random straight lines in joint space
   (:func:`~graspnet_torch.synthesis.closing.closing_lines`) that move its pad forward, along the
   pad normal, and stops where its pad sphere (the tip frame's origin, radius the pad's depth)
   first touches the surface (:func:`~graspnet_torch.synthesis.closing.close_lines`, on the
   object's fast distance :func:`~graspnet_torch.collision.surface.surface_distance_near`). A line
   is *good* where its pad touches by the exact distance (its touch point on the surface, the tip
   the pad's depth out from it along the surface normal, as the surface model's target, both within
   ``TOUCH_M``), its pad normal (the tip rotation times the pad normal) lies within ``cone_deg`` of
   the inward normal at its touch point, and its finger's links, as spheres, lie no deeper than
   ``penetration_m`` in the object.
3. *Drafts*: a palm pose whose every chosen finger has a good line gives up to ``COMBOS`` drafts,
   one good line per finger each (the first draft's line of the opposing finger, the thumb of a
   human-like hand, the one whose inward normal best opposes the others' mean: force closure
   needs opposition; the others at random). The fingers
   not chosen stay at the robot's home posture, as the solver holds them (a palm pose where they
   enter the object gives no draft). A draft's normals are the inward normals at its touch points.

The contact is the touch point: the pad sphere's point nearest the surface. Everything is drawn
from one ``numpy`` generator seeded by ``seed``: the same call gives the same drafts.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass

import numpy as np
import torch
from scipy.spatial.transform import Rotation

from graspnet_torch.collision.spheres import shape_spheres
from graspnet_torch.collision.surface import surface_distance_near, touch_points
from graspnet_torch.errors import ProblemError
from graspnet_torch.robot.geometry import link_shapes, palm_shapes, support, surface_points
from graspnet_torch.robot.opposition import hand_axes
from graspnet_torch.robot.robot import Posture, Robot
from graspnet_torch.robot.shape import Shape
from graspnet_torch.robot.transforms import matrix_to_pose, place_points_np
from graspnet_torch.synthesis.closing import close_lines, closing_lines
from graspnet_torch.tasks.auto_contacts import contact_fingers

__all__ = ["BATCH", "COMBOS", "GAP_SHARE", "LINES", "TOUCH_M", "ContactSet", "check_pad_fingers",
           "iter_contact_drafts", "palm_front", "palm_gap", "palm_plane", "palm_poses"]

GAP_SHARE = 0.55  # the object's gap to the palm's face: up to this share of the fingertips' reach beyond it
TOUCH_M = 1e-3  # a pad touches within this of the surface
BATCH = 64  # palm poses drawn at once
LINES = 16  # closing lines tried per finger and palm pose
HOLDER_SPREAD = 0.2  # a palm without a box: the object's offset off the fingers' mean axis (share of the tips')
NEAR_SHARE = 0.5  # of each batch after a palm pose touched: palm poses near those that did
NEAR_DEG, NEAR_M = 10.0, 0.005  # how near (standard deviations of the turn and the shift)
PAD_POINTS = 128  # points spread over a pad link's mesh where the sampler measures its clearance
COMBOS = 4  # line choices (contact sets) tried per palm pose whose every chosen finger touches


@dataclass(frozen=True)
class ContactSet:
    """A contact set the hand touches with its pads.

    Attributes:
        fingers: the k chosen fingers.
        contacts: (k, 3) the touch points, world.
        normals: (k, 3) the object's inward unit normals there.
        posture: the hand posture that touches them.
        angles_deg: (k,) each pad normal's angle to its inward normal.
    """

    fingers: tuple[str, ...]
    contacts: np.ndarray
    normals: np.ndarray
    posture: Posture
    angles_deg: np.ndarray

    def __iter__(self):  # unpacks as (contacts, normals, posture)
        return iter((self.contacts, self.normals, self.posture))


def palm_front(robot: Robot, rows: list[int]) -> tuple[np.ndarray, float, np.ndarray, np.ndarray]:
    """The palm's front axis (palm frame, unit), its face's offset along it (m), where in the
    palm's plane the object's centre is drawn (2, 2: low and high corner, plane coordinates) and
    that plane (:func:`palm_plane`), for the fingers ``rows``. A palm with collision geometry (boxes,
    cylinders, spheres, meshes): the front is the side the fingers close toward
    (:func:`~graspnet_torch.robot.opposition.hand_axes`), the face the palm's surface farthest
    along it; the object within the fingertips' reach over their joint limits. A palm without
    any (a holder the fingers hang from, as TriFinger's): the axis
    from the palm origin to the home fingertips' mean, the face at the fingertips' median reach
    along it (over their joints' limits and midpoints), the object within ``HOLDER_SPREAD`` of the
    home fingertips' distance from their mean axis: it hangs among the fingers, where they close."""
    home = robot.home_posture()
    tips_all = robot.fingertips_palm(home.fingers).numpy()
    tips = tips_all.mean(axis=0)
    lo, hi = (np.asarray(a, dtype=np.float64) for a in robot.finger_limits)
    palm = palm_shapes(robot.urdf, robot.cfg.palm_link)
    if not palm:
        front = tips / np.linalg.norm(tips)
        grid = np.stack(np.meshgrid(*[[0.0, 0.5, 1.0]] * lo.shape[1], indexing="ij"), -1).reshape(-1, lo.shape[1])
        q = lo[None] + grid[:, None, :] * (hi - lo)[None]  # (G, F, n): every finger at each grid point
        face = float(np.median(robot.fingertips_palm(torch.as_tensor(q)).numpy() @ front))
        plane = palm_plane(front)
        mid = tips_all[rows].mean(axis=0) @ plane
        off_axis = (tips_all[rows] - tips_all[rows].mean(axis=0)) @ plane
        spread = HOLDER_SPREAD * float(np.linalg.norm(off_axis, axis=1).mean())
        return front, face, np.stack([mid - spread, mid + spread]), plane
    front = hand_axes(robot).front
    face = max(support(s, P, front) for s, P in palm)
    tips_at = np.concatenate([robot.fingertips_palm(torch.as_tensor(q)).numpy()[rows] for q in (lo, hi)])
    plane = palm_plane(front)
    reach = tips_at @ plane
    return front, face, np.stack([reach.min(axis=0), reach.max(axis=0)]), plane


def palm_gap(robot: Robot, rows: list[int], palm: tuple) -> tuple[float, float]:
    """The range (m) of the object's gap to the palm's face (``palm``: :func:`palm_front`'s): 0 to
    ``GAP_SHARE`` of the median over the fingers ``rows`` of how far each fingertip reaches past the
    face along the front, its joints at their lower limits, middles or upper limits (the farthest)."""
    front, face = palm[0], palm[1]
    lo, hi = (np.asarray(a, dtype=np.float64) for a in robot.finger_limits)
    tips = np.stack([robot.fingertips_palm(torch.as_tensor(q)).numpy()[rows] for q in (lo, (lo + hi) / 2, hi)])
    reach = float(np.median((tips @ front - face).max(axis=0)))
    return 0.0, GAP_SHARE * max(reach, 0.0)


def _leader(robot: Robot, fingers: Sequence[str]) -> tuple[int, list[int]]:
    """The column of ``fingers`` whose line a first draft picks to oppose the others' (the hand's
    opposing finger, :func:`~graspnet_torch.robot.opposition.hand_axes`, else the first) and the others'."""
    opposing = hand_axes(robot).opposing
    lead = list(fingers).index(opposing) if opposing in fingers else 0
    return lead, [i for i in range(len(fingers)) if i != lead]


def palm_plane(front: np.ndarray) -> np.ndarray:
    """(3, 2) two unit axes of the plane normal to ``front``."""
    return np.linalg.svd(np.eye(3) - np.outer(front, front))[0][:, :2]


def _support(vertices: np.ndarray, centre: np.ndarray, d: np.ndarray) -> np.ndarray:
    """How far the object reaches from its centre along directions d (B, 3): (B,)."""
    return ((vertices - centre) @ d.T).max(axis=0)


def _finger_spheres(robot: Robot) -> list[tuple[int, str, np.ndarray, np.ndarray, bool]]:
    """Every finger link's collision shapes as spheres: (finger row, link, centres (s, 3) in the
    link frame, radii (s,), whether they cover a mesh) (:func:`~graspnet_torch.collision.spheres.shape_spheres`;
    a mesh's spheres may stand out of it by a share of its thickness:
    :mod:`~graspnet_torch.collision.mesh_spheres`)."""
    owner = {}
    for i, finger in enumerate(robot.fingers.values()):
        for joint in robot.urdf.path_joints(finger.chain.root, finger.chain.tip):
            owner[joint.child] = i
    out = []
    for shape in link_shapes(robot.urdf):
        if shape.link in owner:
            centres, radii = shape_spheres(shape)
            out.append((owner[shape.link], shape.link, centres, radii, shape.kind == "mesh"))
    return out


def _line_spheres(robot: Robot, spheres: list[tuple[int, str, np.ndarray, np.ndarray, bool]],
                  fingers: Sequence[str], rows: list[int]) -> list[tuple[int, str, np.ndarray, np.ndarray, bool]]:
    """The spheres (:func:`_finger_spheres`) a closing line's clearance is measured on: the chosen
    fingers' (``rows``), but the links that carry their pads or tips as points spread over their
    collision surfaces (spheres of radius 0: up to ``PAD_POINTS`` vertices and ``PAD_POINTS`` more per shape):
    spheres bound a shape loosely (a mesh's stand out of it by a share of its thickness) or
    leave its corners out (a box's), and a pad's link touches the object by construction."""
    links = {robot.cfg.fingers[f].tip for f in fingers} | {robot.pads[f].link for f in fingers}
    row = {sp[1]: sp[0] for sp in spheres}
    out = [sp for sp in spheres if sp[0] in rows and sp[1] not in links]
    for shape in link_shapes(robot.urdf):
        if shape.link in links and shape.link in row:
            points = surface_points(shape, shape.origin, PAD_POINTS, PAD_POINTS)
            out.append((row[shape.link], shape.link, points, np.zeros(len(points)), shape.kind == "mesh"))
    return out


def _clearance(obj: Shape, names: list[str], frames: np.ndarray,
               spheres: list[tuple[int, str, np.ndarray, np.ndarray, bool]], F: int) -> np.ndarray:
    """(N, F) each of F fingers' least clearance (m, negative: how deep) from the object, its links
    as ``spheres`` (inf: none given); frames (N, L, 4, 4) of the links ``names``."""
    out = np.full((len(frames), F), np.inf)
    for row, link, centres, radii, _ in spheres:
        world = place_points_np(frames[:, names.index(link)], centres)  # (N, s, 3)
        gap = surface_distance_near(obj, world.reshape(-1, 3)).reshape(len(frames), -1) - radii
        out[:, row] = np.minimum(out[:, row], gap.min(axis=1))
    return out


def _pad_touch(robot: Robot, obj: Shape, head: torch.Tensor, q: torch.Tensor, names: list[str],
               frames: np.ndarray, fingers: Sequence[str], rows: list[int], measure: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Where each chosen pad touches: (N, k) its pad normal's angle (degrees) to the inward normal
    at its touch point, inf where it does not touch (the touch point off the surface by more than
    ``TOUCH_M``, e.g. a box's edge; the tip farther than ``TOUCH_M`` from where the surface model
    puts it for that contact, the pad's depth out along the surface normal, as on a mesh's edge
    whose faces turn away; the tip inside the object; a pad not measured, ``measure`` (N, k) False: its
    closing line touched nothing or cannot make a draft; its normal and point 0), those normals (N, k, 3) and the
    touch points (N, k, 3): head (N, 6), q (N, F, j), the link frames (N, L, 4, 4) of ``names``
    (:func:`~graspnet_torch.collision.surface.touch_points`: exact)."""
    R = frames[:, [names.index(robot.cfg.fingers[f].tip) for f in fingers], :3, :3]  # (N, k, 3, 3)
    t_all = robot.fingertips_world(head, q).numpy()[:, rows].reshape(-1, 3)
    measured = np.flatnonzero(measure.reshape(-1))
    t = t_all[measured]
    contacts_at, outward_at, off_by = touch_points(obj, t)
    depth = np.tile([robot.pads[f].depth for f in fingers], len(q))[measured]
    target = contacts_at + depth[:, None] * outward_at  # the surface model's tip target (pad_targets)
    miss = np.ones(len(t_all), dtype=bool)
    miss[measured] = ((off_by > TOUCH_M) | (np.linalg.norm(target - t, axis=1) > TOUCH_M)
                      | (surface_distance_near(obj, t) <= 0))
    contacts, outward = np.zeros_like(t_all), np.zeros_like(t_all)
    contacts[measured], outward[measured] = contacts_at, outward_at
    shape = (len(q), len(rows))
    inward = -outward.reshape(*shape, 3)
    pad = np.einsum("nkij,kj->nki", R, np.stack([robot.pads[f].normal for f in fingers]))
    angles = np.degrees(np.arccos(np.clip(np.sum(pad * inward, axis=-1), -1.0, 1.0)))
    return np.where(miss.reshape(shape), np.inf, angles), inward, contacts.reshape(*shape, 3)


def check_pad_fingers(robot: Robot, fingers: Sequence[str]) -> None:
    """What choosing contacts needs of the robot (:func:`pad_contact_sets`): a free hand (its palm is
    placed: no arm; joints that several fingers share held where the robot holds them,
    :attr:`~graspnet_torch.robot.robot.Robot.shared_reference`, as the solvers hold them) and a pad
    on each of ``fingers`` (checked by :func:`~graspnet_torch.tasks.auto_contacts.contact_fingers`);
    :class:`ProblemError` otherwise."""
    if robot.has_body:
        raise ProblemError(f"robot {robot.cfg.name}: contact sets are drawn with a free hand (no arm; a hand on an "
                           f"arm: its config's 'hand'); the shipped one is robot=hand")
    for f in fingers:
        if f not in robot.pads:
            raise ProblemError(f"fingers: {f} of robot {robot.cfg.name} has no pad (its config's fingers.{f}.pad), "
                               f"which choosing contacts needs")


def iter_contact_drafts(robot: Robot, obj: Shape, fingers: Sequence[str] = ("thumb", "index", "middle"),
                        seed: int = 0, cone_deg: float = 30.0, penetration_m: float = 1e-3, max_tries: int = 3200,
                        stats: dict | None = None,
                        orientations: Callable[[np.random.Generator, int], np.ndarray] | None = None,
                        reachable: Callable[[np.ndarray], np.ndarray] | None = None) -> Iterator[list[ContactSet]]:
    """The drafts of each batch of ``BATCH`` palm poses (module docstring), batch after batch, until
    ``max_tries`` palm poses were drawn. ``stats`` (updated after every batch) receives ``tried``,
    ``touching`` (palm poses whose every chosen pad reached the surface; with ``reachable``, ``reached``
    too) and ``drafts``. ``orientations(rng, B)``: (B, 3, 3) palm orientations in place of uniform ones;
    ``reachable(T)``: which palm poses (B, 4, 4) to keep (a hand on an arm: those the arm reaches).
    The robot and fingers are checked at the call (:func:`check_pad_fingers`), the drafts drawn as read."""
    check_pad_fingers(robot, contact_fingers(robot.finger_names, list(fingers), robot.cfg.name, "fingers"))
    rng = np.random.default_rng(seed)
    finger_names = list(robot.fingers)
    rows = [finger_names.index(f) for f in fingers]
    depth = np.array([robot.pads[f].depth if f in robot.pads else 0.0 for f in finger_names])
    lo, hi = (np.asarray(a, dtype=np.float64) for a in robot.finger_limits)
    lead, rest = _leader(robot, fingers)
    palm = palm_front(robot, rows)  # front, face, reach and the palm's plane
    gap = palm_gap(robot, rows, palm)
    verts = np.asarray(obj.trimesh().vertices, dtype=np.float64)
    centre = np.asarray(obj.pose[:3], dtype=np.float64)
    F = len(finger_names)
    spheres = _finger_spheres(robot)
    line_spheres = _line_spheres(robot, spheres, fingers, rows)
    home = robot.home_posture(torch.float64).fingers
    others_rows = [i for i in range(len(finger_names)) if i not in rows]
    counts = stats if stats is not None else {}
    counts.update(tried=0, touching=0, drafts=0, **({} if reachable is None else {"reached": 0}))
    def batches() -> Iterator[list[ContactSet]]:
        landed: list[np.ndarray] = []  # (4, 4) the palm poses whose every chosen finger touched
        while counts["tried"] < max_tries:
            B = min(BATCH, max_tries - counts["tried"])
            counts["tried"] += B
            T = _batch_palms(rng, B, (palm, gap), verts, centre, landed, orientations, reachable)
            if reachable is not None:
                B = len(T)
                counts["reached"] += B
                if not B:
                    yield []
                    continue
            head = matrix_to_pose(torch.as_tensor(T, dtype=torch.float64))  # (B, 6)
            heads = head.repeat_interleave(LINES, dim=0)  # (B M, 6): LINES closing lines per palm
            q_open, q_close = closing_lines(robot, lo, hi - lo, rng, B * LINES)
            q_touch, touched = close_lines(robot, obj, heads, q_open, q_close, depth, rows)
            k = len(rows)
            q = home.expand(B, -1, -1)  # (B, F, n): the fingers not chosen at home, as the solver holds them
            hit = touched[:, rows].reshape(B, LINES, k)
            # only a palm pose whose every chosen finger touched on some line can make a draft (the others' lines
            v = np.flatnonzero(hit.any(axis=1).all(axis=1))  # are not measured further: clearance, exact touch)
            lines = (v[:, None] * LINES + np.arange(LINES)).reshape(-1)  # their lines' rows
            sel = torch.as_tensor(lines)
            clear, home_clear = np.zeros((B, LINES, F), dtype=bool), np.zeros((B, F), dtype=bool)
            angles = np.full((B * LINES, k), np.inf)
            inward, points = np.zeros((B * LINES, k, 3)), np.zeros((B * LINES, k, 3))
            if len(v):
                names, frames = robot.link_frames_of(None, q_touch[sel], heads[sel])
                clear[v] = (_clearance(obj, names, frames, line_spheres, F) >= -penetration_m).reshape(len(v), LINES, F)
                at_home = robot.link_frames_of(None, q[v], head[v])
                home_clear[v] = _clearance(obj, *at_home, spheres, F) >= -penetration_m
                # the exact touch is measured only where it can make a draft: a clear line that touched, of a
                # palm pose whose every chosen finger has one and whose other fingers are clear
                maybe = hit & clear[:, :, rows]
                maybe &= (maybe.any(axis=1).all(axis=1) & home_clear[:, others_rows].all(axis=1))[:, None, None]
                angles[lines], inward[lines], points[lines] = _pad_touch(robot, obj, heads[sel], q_touch[sel], names,
                                                                         frames, fingers, rows,
                                                                         maybe.reshape(B * LINES, k)[lines])
            angles, inward, points = (a.reshape(B, LINES, k, *a.shape[2:]) for a in (angles, inward, points))
            good = hit & clear[:, :, rows] & (angles <= cone_deg)
            picks = _picks(good, inward, rng, lead, rest)
            ok = good.any(axis=1).all(axis=1) & home_clear[:, others_rows].all(axis=1)
            counts["touching"] += int(ok.sum())
            landed.extend(T[ok])
            batch = _contact_sets(ok, picks, tuple(fingers), rows, head, q, q_touch.view(B, LINES, *lo.shape),
                                  (points, inward, angles))
            counts["drafts"] += len(batch)
            yield batch

    return batches()


def _batch_palms(rng: np.random.Generator, B: int, where: tuple, verts: np.ndarray, centre: np.ndarray,
                 landed: list[np.ndarray], orientations: Callable | None, reachable: Callable | None) -> np.ndarray:
    """Step 1 (module docstring): a batch's palm poses (B', 4, 4), placed by :func:`palm_poses`
    (``where``: :func:`palm_front`'s and :func:`palm_gap`'s), those ``reachable`` keeps if given."""
    R = Rotation.random(B, random_state=rng).as_matrix() if orientations is None else orientations(rng, B)
    T = palm_poses(R, rng, where[0], verts, centre, landed, where[1])
    return T if reachable is None else T[reachable(T)]


def palm_poses(R: np.ndarray, rng: np.random.Generator, palm: tuple, verts: np.ndarray, centre: np.ndarray,
               landed: list[np.ndarray], gap_m: tuple[float, float]) -> np.ndarray:
    """A batch's palm poses (B, 4, 4), world (module docstring, step 1): orientations R (B, 3, 3),
    the object's centre at a random point of the palm's plane within reach and a random gap from
    its face (uniform in ``gap_m``, m); a share near the palm poses ``landed`` that touched.
    ``palm``: (front, face, reach, plane) of :func:`palm_front`; the object's vertices (V, 3) and
    centre (3,)."""
    front, face, reach, plane = palm
    B = len(R)
    lateral = reach[0] + rng.random((B, 2)) * (reach[1] - reach[0])
    gap = gap_m[0] + rng.random(B) * (gap_m[1] - gap_m[0])
    d = -np.einsum("bij,j->bi", R, front)  # world: from the object toward the palm
    c_palm = lateral @ plane.T + (face + _support(verts, centre, d) + gap)[:, None] * front  # the centre, palm frame
    T = np.tile(np.eye(4), (B, 1, 1))
    T[:, :3, :3] = R
    T[:, :3, 3] = centre - np.einsum("bij,bj->bi", R, c_palm)
    if landed:  # a share of the batch near the palm poses that touched
        near = int(B * NEAR_SHARE)
        T[:near] = _near(np.stack(landed)[rng.integers(0, len(landed), near)], rng)
    return T


def _picks(good: np.ndarray, inward: np.ndarray, rng: np.random.Generator, lead: int, rest: list[int]
           ) -> list[np.ndarray]:
    """``COMBOS`` line choices (B, k) each among the good lines ``good`` (B, M, k): at random, the
    first's opposing finger (column ``lead``) on its good line whose inward normal (``inward``
    (B, M, k, 3)) best opposes the others' mean (force closure needs opposition)."""
    picks = [np.argmax(good + rng.random(good.shape), axis=1) for _ in range(COMBOS)]
    if rest:
        B = len(good)
        others = inward[np.arange(B)[:, None], picks[0][:, rest], rest].mean(axis=1)  # (B, 3)
        oppose = -np.einsum("bmi,bi->bm", inward[:, :, lead], others)
        picks[0][:, lead] = np.argmax(np.where(good[:, :, lead], oppose, -np.inf), axis=1)
    return picks


def _contact_sets(ok: np.ndarray, picks: list[np.ndarray], fingers: tuple[str, ...], rows: list[int],
                  head: torch.Tensor, q: torch.Tensor, q_touch: torch.Tensor, touch: tuple) -> list[ContactSet]:
    """The drafts of the palm poses ``ok`` (B,): one per distinct line choice of ``picks``, in order.
    head (B, 6), q (B, F, n) the fingers at home, q_touch (B, M, F, n) the touching joints; ``touch``:
    the lines' touch points, inward normals (B, M, k, 3) and pad angles (B, M, k)."""
    points, inward, angles = touch
    k = len(rows)
    out: list[ContactSet] = []
    for b in np.flatnonzero(ok):
        for pick in dict.fromkeys(tuple(p[b].tolist()) for p in picks):  # distinct line choices, in order
            fingers_q = q[b].clone()
            for i, row in enumerate(rows):
                fingers_q[row] = q_touch[b, pick[i], row]
            posture = Posture(palm_pose=head[b], fingers=fingers_q, body=torch.zeros(0, dtype=torch.float64))
            out.append(ContactSet(fingers, points[b, pick, range(k)], inward[b, pick, range(k)], posture,
                                  angles[b, pick, range(k)]))
    return out


def _near(T: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Palm poses (N, 4, 4) near the given ones: turned about a random axis by a normal angle (sd
    ``NEAR_DEG``) about the palm's origin and moved by a normal offset (sd ``NEAR_M`` per axis)."""
    N = len(T)
    turn = Rotation.from_rotvec(rng.normal(size=(N, 3)) * math.radians(NEAR_DEG) / math.sqrt(3)).as_matrix()
    out = T.copy()
    out[:, :3, :3] = turn @ T[:, :3, :3]
    out[:, :3, 3] += rng.normal(0.0, NEAR_M, (N, 3))
    return out
