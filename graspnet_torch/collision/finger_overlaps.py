"""Two fingers through each other, as spheres: the surface contact model's finger-pair test.

The collision proxy (:mod:`graspnet_torch.collision.proxy`) holds every link's spheres; this
module finds, for a batch of sphere centres, the pairs of spheres of two different fingers' links
(the link pairs :func:`~graspnet_torch.collision.scene.finger_pairs` gives: apart at the home
posture) that overlap. Two phases: each link's spheres have a bounding sphere (its centre the mean
of the link's sphere centres, which moves rigidly with the link; its radius fixed), and a link
pair's spheres are compared only in the rows where the two bounding spheres meet. The cost then
follows the link pairs that come near (a hand's fingertips closing on an object), not the square
of every finger sphere (about 1400 on TriFinger's meshes).
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import Tensor

__all__ = ["FINGER_GAP_M", "FingerOverlaps"]

FINGER_GAP_M = 0.001  # two fingers' spheres overlap from this gap on: the spheres lie inside a link's
# box and miss its edges, where FCL finds two side-by-side fingers touching


class FingerOverlaps:
    """The finger-pair test of a proxy's spheres.

    Args:
        sphere_link: (S,) each sphere's link (an index into the proxy's links), flattened clusters.
        radii: (S,) the spheres' radii (0: padding, never tested).
        local: (S, 3) each sphere's centre in its link's frame (any frame rigid with the link).
        pairs: the (link, link) index pairs tested.
    """

    def __init__(self, sphere_link: Tensor, radii: Tensor, local: Tensor, pairs: Sequence[tuple[int, int]]):
        self.radii = radii
        valid = radii > 0
        self.members: dict[int, Tensor] = {}
        for a, b in pairs:
            for li in (a, b):
                if li not in self.members:
                    self.members[li] = ((sphere_link == li) & valid).nonzero().squeeze(1)
        self.pairs = [(a, b) for a, b in pairs if self.members[a].numel() and self.members[b].numel()]
        self.links = sorted({li for p in self.pairs for li in p})
        slot = {li: k for k, li in enumerate(self.links)}
        self._slot_pairs = torch.tensor([[slot[a], slot[b]] for a, b in self.pairs], dtype=torch.long).reshape(-1, 2)
        bound = []
        for li in self.links:
            idx = self.members[li]
            mid = local[idx].mean(0)
            bound.append(float(((local[idx] - mid).norm(dim=-1) + radii[idx]).max()))
        self.bound_r = torch.tensor(bound, dtype=radii.dtype, device=radii.device)  # (L',)

    def __bool__(self) -> bool:
        return bool(self.pairs)

    def overlapping(self, centres: Tensor) -> tuple[Tensor, Tensor, Tensor]:
        """centres (T, S, 3) of every sphere -> the (t, i, j) of each pair of spheres of a tested
        link pair that overlap (within :data:`FINGER_GAP_M`) in row t, each (N,)."""
        empty = torch.zeros(0, dtype=torch.long, device=centres.device)
        if not self.pairs:
            return empty, empty, empty
        mids = torch.stack([centres[:, self.members[li]].mean(1) for li in self.links], 1)  # (T, L', 3)
        a, b = self._slot_pairs[:, 0], self._slot_pairs[:, 1]
        gap = (mids[:, a] - mids[:, b]).norm(dim=-1)  # (T, P)
        near = gap < (self.bound_r[a] + self.bound_r[b] + FINGER_GAP_M)
        found = [(empty, empty, empty)]
        for p in near.any(0).nonzero().squeeze(1).tolist():
            rows = near[:, p].nonzero().squeeze(1)
            i, j = self.members[self.pairs[p][0]], self.members[self.pairs[p][1]]
            d = torch.cdist(centres[rows][:, i], centres[rows][:, j], compute_mode="donot_use_mm_for_euclid_dist")
            t, u, v = (d < self.radii[i][:, None] + self.radii[j][None, :] + FINGER_GAP_M).nonzero(as_tuple=True)
            found.append((rows[t], i[u], j[v]))
        t, i, j = (torch.cat(x) for x in zip(*found, strict=True))
        return t, i, j

    def overlaps(self, ci: Tensor, cj: Tensor, i: Tensor, j: Tensor) -> Tensor:
        """The overlap r_i + r_j + :data:`FINGER_GAP_M` - |c_i - c_j|, clamped at 0, of spheres i and
        j (N,) at centres ci, cj (N, ..., 3) -> (N, ...)."""
        shape = (-1,) + (1,) * (ci.dim() - 2)
        return ((self.radii[i] + self.radii[j] + FINGER_GAP_M).view(shape) - (ci - cj).norm(dim=-1)).clamp(min=0)
