"""Convex pieces of a never-seen mesh: the plane decomposition beside CoACD, time and accuracy.

    python benchmarks/decomposition.py [--objects 16] [--seed 11] [--check]

Objects: ``--objects`` of pybullet's random objects at the synthesis experiment's scale, drawn by
``--seed`` from those that neither the experiment ``synthesis`` (seed 2026) nor any tuning or test
uses, and pybullet's mug, duck, teddy bear and bunny. Each mesh is cut by both, uncached, in this process
(CoACD in its own process with its time limit and retries, as the package runs it): the seconds,
the pieces, and the verdicts of the pieces' union on 6000 points drawn in the mesh's box against the
mesh's own (its inside test, the distance to its triangles): the share of the points more than
``MARGIN_M`` inside the mesh the pieces hold, and of those more than ``MARGIN_M`` outside they leave
out. Targets (``--check``): the plane decomposition at most ``MEDIAN_S`` median and ``MAX_S`` at
worst; holding every deep point (``HELD``) and leaving out the far ones at least as well as
CoACD less ``LEFT_OUT_SLACK`` (pooled).
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path

import numpy as np
import torch

from graspnet_torch.benchmarking import check_targets
from graspnet_torch.collision.convex import _decompose, _pieces, pieces_distance
from graspnet_torch.collision.decompose import plane_pieces
from graspnet_torch.collision.mesh import MeshQuery, point_triangle_distance
from graspnet_torch.experiments.synthesis import SCALE, fresh_objects
from graspnet_torch.meshes import load_mesh
from graspnet_torch.table import format_table

MARGIN_M = 1.5e-3
MEDIAN_S, MAX_S = 0.3, 2.0
HELD, LEFT_OUT_SLACK = 0.995, 0.02


def _verdicts(mesh, vertices: list[np.ndarray]) -> tuple[int, int, int, int]:
    """(deep points held, deep points, far points left out, far points) of the pieces ``vertices``."""
    pieces = _pieces(vertices, False)
    lo, hi = mesh.bounds
    points = lo + (hi - lo) * np.random.default_rng(0).uniform(size=(6000, 3))
    depth = point_triangle_distance(points, np.asarray(mesh.triangles)).min(1)
    inside = MeshQuery(mesh).inside(points)
    sd = pieces_distance(torch.as_tensor(points)[:, None].expand(-1, pieces.n_pieces, 3),
                         torch.as_tensor(pieces.planes)).amin(-1).numpy()
    deep, far = inside & (depth > MARGIN_M), ~inside & (depth > MARGIN_M)
    return int((sd[deep] < 0).sum()), int(deep.sum()), int((sd[far] > 0).sum()), int(far.sum())


def _meshes(n: int, seed: int) -> list[tuple[str, Path, float]]:
    import pybullet_data

    root = Path(pybullet_data.getDataPath())
    household = [("mug", root / "objects" / "mug_col.obj", 1.0), ("duck", root / "duck.obj", 0.06),  # the
                 ("teddy", root / "teddy2_VHACD_CHs.obj", 0.12), ("bunny", root / "bunny.obj", 0.06)]  # hands' scales
    return [*((f"blob{k:03d}", root / "random_urdfs" / f"{k:03d}" / f"{k:03d}.obj", SCALE)
              for k in fresh_objects(n, seed)), *household]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--objects", type=int, default=16)
    ap.add_argument("--seed", type=int, default=11)
    ap.add_argument("--check", action="store_true")
    args = ap.parse_args()
    torch.set_num_threads(1)
    warnings.simplefilter("ignore")  # CoACD's "hull stands in" is counted in its row, not printed
    rows, totals = [], {"plane": np.zeros(4), "coacd": np.zeros(4)}
    seconds: dict[str, list[float]] = {"plane": [], "coacd": []}
    for name, path, scale in _meshes(args.objects, args.seed):
        mesh = load_mesh(path, scale)
        if mesh.is_convex:
            continue
        row = [name, len(mesh.faces), "yes" if mesh.is_watertight else "no"]
        for method in ("plane", "coacd"):
            t0 = time.perf_counter()
            if method == "plane":
                vertices = plane_pieces(mesh.vertices, mesh.faces, mesh.is_watertight)
            else:
                vertices = _decompose(mesh, name)[0]
            seconds[method].append(time.perf_counter() - t0)
            v = _verdicts(mesh, vertices)
            totals[method] += v
            row += [f"{seconds[method][-1]:.2f}", len(vertices), f"{v[0]}/{v[1]}", f"{v[2]}/{v[3]}"]
        rows.append(row)
        print(f"{name}: plane {seconds['plane'][-1]:.2f} s, CoACD {seconds['coacd'][-1]:.2f} s", file=sys.stderr)
    print(format_table(["mesh", "faces", "closed", "plane s", "pieces", "deep held", "far left out",
                        "CoACD s", "pieces", "deep held", "far left out"], rows))
    share = {m: (t[0] / max(t[1], 1), t[2] / max(t[3], 1)) for m, t in totals.items()}
    for method in ("plane", "coacd"):
        s = np.asarray(seconds[method])
        print(f"{method}: median {np.median(s):.2f} s, max {s.max():.2f} s; pooled deep held {share[method][0]:.4f}, "
              f"far left out {share[method][1]:.4f}")
    plane = np.asarray(seconds["plane"])
    return check_targets([
        (f"plane decomposition median {np.median(plane):.2f} s <= {MEDIAN_S} s "
         f"({np.median(seconds['coacd']) / np.median(plane):.0f}x faster than CoACD's median)",
         np.median(plane) <= MEDIAN_S),
        (f"plane decomposition at worst {plane.max():.2f} s <= {MAX_S} s (CoACD {max(seconds['coacd']):.1f} s)",
         plane.max() <= MAX_S),
        (f"deep points held {share['plane'][0]:.4f} >= {HELD}", share["plane"][0] >= HELD),
        (f"far points left out {share['plane'][1]:.4f} >= CoACD's {share['coacd'][1]:.4f} - {LEFT_OUT_SLACK}",
         share["plane"][1] >= share["coacd"][1] - LEFT_OUT_SLACK),
    ], args.check)


if __name__ == "__main__":
    sys.exit(main())
