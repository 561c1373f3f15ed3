"""Grasp quality of a contact set on an object: the grasp matrix, Ferrari-Canny's Q1, force closure.

Batched over B contact sets of k point contacts with Coulomb friction (soft-finger / torsional
friction is *not* modelled: a contact transmits a force, no moment). Inputs are torch tensors or
numpy arrays, with or without the leading batch dimension; outputs follow the input's library and
batch shape (the hull work is float64 numpy and scipy either way).

The wrenches (Ferrari & Canny 1992; Miller & Allen, GraspIt! 2004). Contact i at p_i (3,) with
unit inward normal n_i (the direction the finger pushes, into the object) and friction coefficient
mu; the cone linearised by m edges at angles t_j = 2 pi j / m around n_i, with orthonormal tangents
u_i, v_i (v_i = n_i x u_i)::

    f_ij = n_i + mu (cos t_j u_i + sin t_j v_i)                  the edge force, normal part 1
    w_ij = [f_ij ; (p_i - c) x f_ij / L]                          (6,), c: centre of mass

L, the torque length, makes force and torque commensurate. Default: the object's characteristic
radius taken as the largest contact distance from the centre, L = max_i |p_i - c| (GraspIt!'s
convention uses the object's largest radius; pass ``length`` for the object's own). With it, Q1
is unchanged when the object, contacts and L are scaled together, and under any rigid motion of
contacts and centre together (the wrench set turns by diag(R, R), an isometry of R^6) when the
tangents turn too (``tangents``: the first edge's direction u_i per contact; otherwise u_i comes
from the normal alone, n x (the coordinate axis least along n), so a rotated set gets other edges
and Q1 moves within the linearisation's error, of the order of 1 - cos(pi / m)).

Every edge's normal part is 1, so the convex hull W = conv{w_ij} is the wrench set of the contact
forces whose normal parts sum to at most 1 (Ferrari-Canny's L1 grasp)::

    Q1 = epsilon = min over unit d in R^6 of h_W(d),   h_W(d) = max_ij d . w_ij   (support function)
               = min over W's facets a . x + b = 0 (|a| = 1, a . x + b <= 0 inside) of -b

the radius of the largest ball about the origin inside W; 0 when the origin is not strictly inside
(no force closure), and 0 when the wrenches span fewer than 6 dimensions (a flat hull: e.g. two
point contacts, which cannot resist a torque about the line joining them, or frictionless contacts
fewer than 7). ``signed=True`` gives min(-b) instead, negative when the origin is outside.

The grasp matrix here is the edge matrix E = [w_ij] (6, k m). ``min_singular_value`` of a set is
sigma_min(E) / sqrt(m): for m >= 3 evenly spaced edges sum_j f_ij f_ij^T = m (n n^T + mu^2 / 2
(I - n n^T)), so E E^T / m = G diag_i(n_i n_i^T + mu^2 / 2 (I - n_i n_i^T)) G^T, with G (6, 3k) the
point-contact grasp matrix [I ; [p_i - c]x / L]: independent of m, and at mu = 0 the normal-force
map's sigma_min (0 for fewer than 6 contacts).

Cost: the edge matrix is one batched torch expression; Q1 is one 6-D scipy ConvexHull (Qhull) per
set (without pre-merged facets, ``FAST_QHULL``), a Python loop over B, growing with the hull's facet
count (``make bench-quality`` times sets of k = 3, 4, 5 contacts, 24-40 wrenches).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch
from scipy.spatial import ConvexHull, QhullError

from graspnet_torch.errors import ProblemError

__all__ = [
    "GraspQuality",
    "epsilon",
    "ferrari_canny",
    "force_closure",
    "grasp_matrix",
    "grasp_quality",
    "min_singular_value",
    "q1",
    "torque_length",
]

Array = Any  # a torch tensor or a numpy array
RANK_RTOL = 1e-9  # a singular value below this fraction of the largest: the wrenches are flat
FAST_QHULL = "Q0"  # no pre-merged facets: 3.5x faster than Qhull's default (Qx) on 6-D wrench sets; on 447
# sets a grasp search drew, the same Q1 to 1.4e-15 and 1 precision error (answered by the default instead)


def _batch(x: Array, name: str, dims: int) -> tuple[torch.Tensor, bool]:
    """``x`` as float64 torch with a batch dimension; whether it had one (``dims``: unbatched rank)."""
    t = torch.as_tensor(x, dtype=torch.float64)
    if t.dim() == dims:
        return t.unsqueeze(0), False
    if t.dim() != dims + 1:
        raise ProblemError(f"quality: {name} has shape {tuple(t.shape)}, expected {dims} or {dims + 1} dimensions")
    return t, True


def _like(values: np.ndarray | torch.Tensor, like: Array, batched: bool) -> Array:
    """``values`` (B, ...) in ``like``'s library (torch: on its device), without B when unbatched."""
    out = values if batched else values[0]
    if isinstance(like, torch.Tensor):
        return torch.as_tensor(out).to(like.device)
    return out.detach().cpu().numpy() if isinstance(out, torch.Tensor) else np.asarray(out)


def torque_length(contacts: Array, centre: Array) -> Array:
    """The default torque length L = max_i |p_i - c|: contacts (B, k, 3) or (k, 3), centre (B, 3) or (3,) -> (B,) or ().

    The object's characteristic radius as Ferrari & Canny and GraspIt! use it, taken from the contacts.
    """
    p, batched = _batch(contacts, "contacts", 2)
    c, _ = _batch(centre, "centre", 1)  # (B, 3) or (1, 3), broadcast
    return _like((p - c[:, None]).norm(dim=-1).amax(dim=-1), contacts, batched)


def _per_set(x: Array | float, B: int, name: str) -> torch.Tensor:
    """A scalar or (B,) value as (B,) float64."""
    t = torch.as_tensor(x, dtype=torch.float64)
    if t.dim() == 0:
        return t.expand(B)
    if t.shape != (B,):
        raise ProblemError(f"quality: {name} has shape {tuple(t.shape)}, expected a scalar or ({B},)")
    return t


def grasp_matrix(
    contacts: Array,
    normals: Array,
    centre: Array,
    friction: Array | float,
    edges: int = 8,
    length: Array | float | None = None,
    tangents: Array | None = None,
) -> Array:
    """The edge wrenches of the linearised friction cones, as columns: (B, 6, k m) or (6, k m).

    contacts: (B, k, 3) or (k, 3); normals: unit inward normals, same shape (normalised here);
    centre: (B, 3) or (3,), the object's centre of mass; friction: mu, scalar or (B,); edges: m;
    length: L, scalar or (B,), default max_i |p_i - c|; tangents: optional (B, k, 3) first edge
    directions u_i (projected off n_i and normalised). Column i m + j is contact i's edge j::

        f_ij = n_i + mu (cos t_j u_i + sin t_j v_i),   t_j = 2 pi j / m,   v_i = n_i x u_i
        w_ij = [f_ij ; (p_i - c) x f_ij / L]
    """
    p, batched = _batch(contacts, "contacts", 2)
    n, _ = _batch(normals, "normals", 2)
    c, _ = _batch(centre, "centre", 1)
    B, k = p.shape[:2]
    c = c.expand(B, -1) if c.shape[0] == 1 else c
    if n.shape != p.shape or c.shape != (B, 3) or p.shape[-1] != 3:
        raise ProblemError(f"quality: contacts {tuple(p.shape)}, normals {tuple(n.shape)}, centre {tuple(c.shape)}")
    if edges < 1:
        raise ProblemError(f"quality: edges must be at least 1, got {edges}")
    mu = _per_set(friction, B, "friction")
    if (mu < 0).any():
        raise ProblemError("quality: friction must be >= 0")
    r = p - c[:, None]  # (B, k, 3)
    L = r.norm(dim=-1).amax(dim=-1) if length is None else _per_set(length, B, "length")
    if not (L > 0).all():
        raise ProblemError("quality: the torque length must be > 0 (contacts all at the centre?)")
    n = n / n.norm(dim=-1, keepdim=True).clamp_min(1e-300)
    if tangents is None:  # n x (the coordinate axis least along n)
        axis = torch.nn.functional.one_hot(n.abs().argmin(dim=-1), 3).to(n)
        u = torch.linalg.cross(n, axis)
    else:
        t, _ = _batch(tangents, "tangents", 2)
        u = t.expand_as(n) - (t * n).sum(-1, keepdim=True) * n
    u = u / u.norm(dim=-1, keepdim=True)
    v = torch.linalg.cross(n, u)
    ang = torch.arange(edges, dtype=torch.float64) * (2 * math.pi / edges)
    tang = torch.cos(ang)[:, None] * u[:, :, None] + torch.sin(ang)[:, None] * v[:, :, None]  # (B, k, m, 3)
    f = n[:, :, None] + mu[:, None, None, None] * tang
    tau = torch.linalg.cross(r[:, :, None].expand_as(f), f) / L[:, None, None, None]
    w = torch.cat([f, tau], dim=-1).reshape(B, k * edges, 6).transpose(1, 2)
    return _like(w, contacts, batched)


def min_singular_value(G: Array) -> Array:
    """The smallest of the 6 singular values of G (B, 6, N) or (6, N) -> (B,) or (); 0 when N < 6.

    Of the edge matrix, divide by sqrt(m) for the edge-count-free value (the module docstring);
    :func:`grasp_quality` does.
    """
    g, batched = _batch(G, "G", 2)
    s = torch.linalg.svdvals(g)  # (B, min(6, N))
    out = s[:, -1] if g.shape[-1] >= g.shape[-2] else torch.zeros(g.shape[0], dtype=torch.float64)
    return _like(out, G, batched)


def _q1_one(w: np.ndarray, signed: bool) -> float:
    """Q1 of the wrench columns w (6, N): min over facets of -b, or 0 (module docstring)."""
    s = np.linalg.svd(w, compute_uv=False)
    if w.shape[1] < w.shape[0] + 1 or s[-1] <= RANK_RTOL * s[0]:
        return 0.0  # spans < 6 dimensions: the origin is not interior
    try:
        hull = ConvexHull(w.T, qhull_options=FAST_QHULL)
    except QhullError:  # what merging facets would have answered: Qhull's default
        try:
            hull = ConvexHull(w.T)
        except QhullError:  # affinely flat (a hyperplane missing the origin): the origin is outside
            return 0.0
    q = float(np.min(-hull.equations[:, -1]))
    return q if signed else max(q, 0.0)


def q1(G: Array, signed: bool = False) -> Array:
    """Ferrari-Canny's Q1 of any wrench set, columns of G (B, 6, N) or (6, N) -> (B,) or ().

    The distance from the origin to the nearest facet plane of conv(columns), 0 when the origin is
    not strictly inside or the columns span fewer than 6 dimensions; ``signed``: min over facets
    of -b, negative when the origin is outside a full-dimensional hull (0 for a flat one).
    One ConvexHull per set, a loop over B.
    """
    g, batched = _batch(G, "G", 2)
    if g.shape[1] != 6:
        raise ProblemError(f"quality: a wrench set has 6 rows, got {tuple(g.shape)}")
    w = g.detach().cpu().numpy()
    out = np.array([_q1_one(w[b], signed) for b in range(w.shape[0])], dtype=np.float64)
    return _like(out, G, batched)


def epsilon(contacts: Array, normals: Array, centre: Array, friction: Array | float, edges: int = 8,
            length: Array | float | None = None, tangents: Array | None = None, signed: bool = False) -> Array:
    """Q1 (epsilon) of contact sets: (B, k, 3) -> (B,), or (k, 3) -> (); arguments as :func:`grasp_matrix`.

    Q1 = min over unit d of max_ij d . w_ij: the largest ball about the origin inside the hull of
    the edge wrenches; 0 without force closure (``signed``: negative when the origin is outside).
    """
    return q1(grasp_matrix(contacts, normals, centre, friction, edges, length, tangents), signed)


ferrari_canny = epsilon


def force_closure(contacts: Array, normals: Array, centre: Array, friction: Array | float, edges: int = 8,
                  length: Array | float | None = None, tangents: Array | None = None, tol: float = 1e-9) -> Any:
    """Whether Q1 > tol (of the linearised cones): a bool for one set, a (B,) bool array / tensor for B."""
    eps = epsilon(contacts, normals, centre, friction, edges, length, tangents)
    closed = eps > tol
    return bool(closed) if closed.ndim == 0 else closed


@dataclass
class GraspQuality:
    """Quality of one contact set (floats) or of B (arrays / tensors of shape (B,)).

    epsilon: Q1; min_singular_value: sigma_min(E) / sqrt(m) of the edge matrix E; force_closure:
    epsilon > tol.
    """

    epsilon: Any
    min_singular_value: Any
    force_closure: Any

    def to_dict(self) -> dict[str, Any]:
        """{"epsilon": ..., "min_singular_value": ...}: floats for one set, lists for B."""

        def plain(x: Any) -> Any:
            return np.asarray(x.detach().cpu() if isinstance(x, torch.Tensor) else x).tolist()

        return {"epsilon": plain(self.epsilon), "min_singular_value": plain(self.min_singular_value)}


def grasp_quality(contacts: Array, normals: Array, centre: Array, friction: Array | float, edges: int = 8,
                  length: Array | float | None = None, tangents: Array | None = None, tol: float = 1e-9
                  ) -> GraspQuality:
    """All the metrics of B contact sets at once (B, k, 3), or of one (k, 3) as floats.

    One batched grasp matrix and SVD, then one 6-D ConvexHull per set (a Python loop; about
    1-4 ms a set at k = 3-5 and 8 edges). Arguments as :func:`grasp_matrix`.
    """
    E = grasp_matrix(contacts, normals, centre, friction, edges, length, tangents)
    eps = q1(E)
    sig = min_singular_value(E) / math.sqrt(edges)
    closed = eps > tol
    if closed.ndim == 0:
        return GraspQuality(float(eps), float(sig), bool(closed))
    return GraspQuality(eps, sig, closed)
