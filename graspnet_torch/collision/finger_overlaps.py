"""Two fingers through each other, as spheres: the surface contact model's finger-pair test.

The collision proxy (:mod:`graspnet_torch.collision.proxy`) holds every link's spheres; this
module finds, for a batch of sphere centres, the pairs of spheres of two different fingers' links
(the link pairs :func:`~graspnet_torch.collision.scene.finger_pairs` gives: apart at the home
posture) that overlap. Two phases: each link's spheres have a bounding sphere (its centre the mean
of the link's sphere centres, which moves rigidly with the link; its radius fixed), and a link
pair's spheres are compared only in the rows where the two bounding spheres meet. The cost then
follows the link pairs that come near (a hand's fingertips closing on an object), not the square
of every finger sphere (about 1400 on TriFinger's meshes). Within a link pair that meets, the same
again by groups of spheres (the collision proxy's clusters, ``group`` consecutive spheres of one
link, each with a bounding sphere): only the spheres of two groups that meet are compared. Every
phase is batched: each link's groups are padded to one width, and the near entries are measured in
one call.
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

    def __init__(self, sphere_link: Tensor, radii: Tensor, local: Tensor, pairs: Sequence[tuple[int, int]],
                 group: int = 1):
        self.radii, self.group = radii, group
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
        self._groups(sphere_link, local, links)

    def _groups(self, sphere_link: Tensor, local: Tensor, links: list[int]) -> None:
        """Each group of ``group`` consecutive spheres (one link's): its bounding sphere (centre the
        mean of its spheres' centres, radius fixed) and each tested link's groups, padded."""
        G, r = self.group, self.radii
        valid = (r > 0).view(-1, G)  # (C, G)
        count = valid.sum(1, keepdim=True).clamp(min=1)
        mid = (local.view(-1, G, 3) * valid.unsqueeze(-1)).sum(1) / count  # (C, 3)
        reach = (local.view(-1, G, 3) - mid.unsqueeze(1)).norm(dim=-1) + r.view(-1, G)
        self._group_r = torch.where(valid, reach, reach.new_zeros(())).amax(1)  # (C,)
        self._group_count, self._group_valid = count, valid
        owner = sphere_link.view(-1, G)[:, 0]
        members = [((owner == li) & valid.any(1)).nonzero().squeeze(1) for li in links]
        width = max((m.numel() for m in members), default=0)
        self._gindex = torch.zeros(len(links), max(width, 1), dtype=torch.long, device=r.device)
        self._gmask = torch.zeros(len(links), max(width, 1), dtype=torch.bool, device=r.device)
        for k, m in enumerate(members):
            self._gindex[k, : m.numel()], self._gmask[k, : m.numel()] = m, True

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
        G, S = self.group, centres.shape[1]
        gmid = (centres.view(len(centres), -1, G, 3) * self._group_valid.unsqueeze(-1)).sum(2) / self._group_count
        ga, gb = self._gindex[la], self._gindex[lb]  # (N, Ca), (N, Cb): the two links' groups
        d = torch.cdist(gmid[t.unsqueeze(1), ga], gmid[t.unsqueeze(1), gb], compute_mode="donot_use_mm_for_euclid_dist")
        near = d < self._group_r[ga].unsqueeze(2) + self._group_r[gb].unsqueeze(1) + FINGER_GAP_M
        n, u, v = (near & self._gmask[la].unsqueeze(2) & self._gmask[lb].unsqueeze(1)).nonzero(as_tuple=True)
        step = torch.arange(G, device=centres.device)
        sa, sb = ga[n, u].unsqueeze(1) * G + step, gb[n, v].unsqueeze(1) * G + step  # (M, G): their spheres
        d = torch.cdist(centres[t[n].unsqueeze(1), sa], centres[t[n].unsqueeze(1), sb],
                        compute_mode="donot_use_mm_for_euclid_dist")  # (M, G, G)
        ra, rb = self.radii[sa], self.radii[sb]
        hit = (d < ra.unsqueeze(2) + rb.unsqueeze(1) + FINGER_GAP_M) & (ra > 0).unsqueeze(2) & (rb > 0).unsqueeze(1)
        m, x, y = hit.nonzero(as_tuple=True)
        i, j, row = sa[m, x], sb[m, y], n[m]
        order = torch.argsort((row * S + i) * S + j)  # link pair, then each link's spheres in order
        return t[row[order]], i[order], j[order]

    def overlaps(self, ci: Tensor, cj: Tensor, i: Tensor, j: Tensor) -> Tensor:
        """The overlap r_i + r_j + :data:`FINGER_GAP_M` - |c_i - c_j|, clamped at 0, of spheres i and
        j (N,) at centres ci, cj (N, ..., 3) -> (N, ...)."""
        shape = (-1,) + (1,) * (ci.dim() - 2)
        return ((self.radii[i] + self.radii[j] + FINGER_GAP_M).view(shape) - (ci - cj).norm(dim=-1)).clamp(min=0)
