"""Two fingers through each other, as spheres: the surface contact model's finger-pair test.

The collision proxy (:mod:`graspnet_torch.collision.proxy`) holds every link's spheres; this
module finds, for a batch of sphere centres, the pairs of spheres of two different fingers' links
(the link pairs :func:`~graspnet_torch.collision.scene.finger_pairs` gives: apart at the home
posture) that overlap. Two phases: each link's spheres have a bounding sphere (its centre the mean
of the link's sphere centres, which moves rigidly with the link; its radius fixed), and a link
pair's spheres are compared only in the rows where the two bounding spheres meet. The cost then
follows the link pairs that come near (a hand's fingertips closing on an object), not the square
of every finger sphere (about 1400 on TriFinger's meshes). Both phases are batched: each link's
spheres are padded to one width, and the near (row, link pair) entries are measured in one call.
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
        members = {li: ((sphere_link == li) & valid).nonzero().squeeze(1) for p in pairs for li in p}
        self.pairs = [(a, b) for a, b in pairs if members[a].numel() and members[b].numel()]
        links = sorted({li for p in self.pairs for li in p})
        slot = {li: k for k, li in enumerate(links)}
        width = max((members[li].numel() for li in links), default=0)
        # each tested link's spheres, padded to one width: (L', K) indices (padding: sphere 0) and mask
        self._index = torch.zeros(len(links), width, dtype=torch.long, device=radii.device)
        self._mask = torch.zeros(len(links), width, dtype=torch.bool, device=radii.device)
        for k, li in enumerate(links):
            self._index[k, : members[li].numel()] = members[li]
            self._mask[k, : members[li].numel()] = True
        self._a = torch.tensor([slot[a] for a, _ in self.pairs], dtype=torch.long, device=radii.device)
        self._b = torch.tensor([slot[b] for _, b in self.pairs], dtype=torch.long, device=radii.device)
        self._r = torch.where(self._mask, radii[self._index], radii.new_zeros(()))  # (L', K)
        count = self._mask.sum(1, keepdim=True).clamp(min=1)
        mid = (local[self._index] * self._mask.unsqueeze(-1)).sum(1) / count  # (L', 3)
        reach = (local[self._index] - mid.unsqueeze(1)).norm(dim=-1) + self._r
        self.bound_r = torch.where(self._mask, reach, reach.new_zeros(())).amax(1)  # (L',)
        self._count = count

    def __bool__(self) -> bool:
        return bool(self.pairs)

    def overlapping(self, centres: Tensor) -> tuple[Tensor, Tensor, Tensor]:
        """centres (T, S, 3) of every sphere -> the (t, i, j) of each pair of spheres of a tested
        link pair that overlap (within :data:`FINGER_GAP_M`) in row t, each (N,)."""
        empty = torch.zeros(0, dtype=torch.long, device=centres.device)
        if not self.pairs:
            return empty, empty, empty
        grouped = centres[:, self._index]  # (T, L', K, 3)
        mids = (grouped * self._mask.unsqueeze(-1)).sum(2) / self._count  # (T, L', 3)
        a, b = self._a, self._b
        gap = (mids[:, a] - mids[:, b]).norm(dim=-1)  # (T, P)
        t, p = (gap < self.bound_r[a] + self.bound_r[b] + FINGER_GAP_M).nonzero(as_tuple=True)
        if t.numel() == 0:
            return empty, empty, empty
        la, lb = a[p], b[p]
        d = torch.cdist(grouped[t, la], grouped[t, lb], compute_mode="donot_use_mm_for_euclid_dist")  # (N, K, K)
        hit = d < self._r[la].unsqueeze(2) + self._r[lb].unsqueeze(1) + FINGER_GAP_M
        hit &= self._mask[la].unsqueeze(2) & self._mask[lb].unsqueeze(1)
        n, u, v = hit.nonzero(as_tuple=True)
        return t[n], self._index[la[n], u], self._index[lb[n], v]

    def overlaps(self, ci: Tensor, cj: Tensor, i: Tensor, j: Tensor) -> Tensor:
        """The overlap r_i + r_j + :data:`FINGER_GAP_M` - |c_i - c_j|, clamped at 0, of spheres i and
        j (N,) at centres ci, cj (N, ..., 3) -> (N, ...)."""
        shape = (-1,) + (1,) * (ci.dim() - 2)
        return ((self.radii[i] + self.radii[j] + FINGER_GAP_M).view(shape) - (ci - cj).norm(dim=-1)).clamp(min=0)
