"""Grasp quality per contact set: ``gt.grasp_quality`` (Ferrari-Canny epsilon by one Qhull per set,
the grasp matrix's smallest singular value) beside a peer that only answers force closure, by a
linear program (scipy's HiGHS: is there a strictly positive combination of the edge wrenches
that sums to zero and spans the wrench space? the usual LP test), on the same random sets.

    python benchmarks/quality.py [--sets 200] [--check]

Random contact sets of k = 3, 4, 5 contacts on a unit sphere (inward normals), friction 0.5, 8
cone edges. Target: at most 10 ms per set for k = 5 (``--check``).
"""

from __future__ import annotations

import sys
import time

import numpy as np
import torch
from scipy.optimize import linprog

import graspnet_torch as gt
from graspnet_torch.benchmarking import bench_args, check_targets
from graspnet_torch.quality import grasp_matrix

TARGET_MS = 10.0


def lp_force_closure(G: np.ndarray) -> bool:
    """Force closure by LP: maximise t such that G l = 0, sum l = 1, l >= t (t > 0: the origin
    lies strictly inside the cone's convex hull), with G of rank 6."""
    n = G.shape[1]
    if np.linalg.matrix_rank(G) < 6:
        return False
    c = np.zeros(n + 1)
    c[-1] = -1.0  # maximise t
    A_eq = np.zeros((7, n + 1))
    A_eq[:6, :n], A_eq[6, :n] = G, 1.0
    b_eq = np.zeros(7)
    b_eq[6] = 1.0
    A_ub = np.hstack([-np.eye(n), np.ones((n, 1))])  # t - l_i <= 0
    res = linprog(c, A_ub=A_ub, b_ub=np.zeros(n), A_eq=A_eq, b_eq=b_eq, bounds=[(0, None)] * n + [(None, None)],
                  method="highs")
    return bool(res.status == 0 and -res.fun > 1e-9)


def main() -> int:
    args = bench_args(__doc__, [("--sets", int, 200)])
    print(f"torch threads: {torch.get_num_threads()}")
    rng = np.random.default_rng(0)
    rows, checks = [], []
    for k in (3, 4, 5):
        p = rng.normal(size=(args.sets, k, 3))
        p /= np.linalg.norm(p, axis=-1, keepdims=True)
        t0 = time.perf_counter()
        q = gt.grasp_quality(p, -p, np.zeros(3), 0.5)
        ours = (time.perf_counter() - t0) / args.sets * 1e3
        G = grasp_matrix(p, -p, np.zeros(3), 0.5)
        t0 = time.perf_counter()
        peer_fc = np.array([lp_force_closure(g) for g in G])
        peer = (time.perf_counter() - t0) / args.sets * 1e3
        agree = float(np.mean(peer_fc == np.asarray(q.force_closure))) * 100
        rows.append((k, ours, peer, agree))
        if k == 5:
            what = f"gt.grasp_quality {ours:.2f} ms per set of 5 contacts <= {TARGET_MS:g} ms"
            checks.append((what, ours <= TARGET_MS))
    print("\n| contacts | gt.grasp_quality ms/set (epsilon, sigma_min) | LP force closure ms/set (peer) | ratio "
          "| force-closure verdicts agree |")
    print("|---|---|---|---|---|")
    for k, ours, peer, agree in rows:
        print(f"| {k} | {ours:.2f} | {peer:.2f} | {ours / peer:.2f} | {agree:.1f} % |")
    return check_targets(checks, args.check)


if __name__ == "__main__":
    sys.exit(main())
