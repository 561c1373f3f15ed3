"""Mesh objects in the loop: the collision proxy's verdict against FCL's near real meshes, and the
loop's speed with a mesh object beside the same loop with the primitive it replaces.

    python benchmarks/mesh_objects.py [--threads 1] [--check] [--configurations 300]

1. Agreement: a contact set on each real object mesh (``pybullet_data``; a collision-free closure
   at a random pose) and the moved glass3 and videotape5 with their objects as meshes; palm poses
   uniform in each problem's search space (the frame and box the loop searches) and finger joints
   uniform in their limits; the share of configurations whose collision-free verdict is the same
   for the proxy (convex pieces) and for FCL (the mesh itself).
2. Speed: glass3 and videotape5 as shipped (palm_bounds: robot), R3 (the proxy every iteration),
   fixed budgets, no early stop: trial-iterations per second with the object as a mesh and as its
   primitive, measured side by side, for T = 1, 20 and 1000 trials.

Targets (issue 22): verdict agreement >= 99 % over all the objects; the loop with a mesh at least
half as fast as with the primitive at every T. ``--check`` exits 1 when one is missed.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import torch

import graspnet_torch as gt
from graspnet_torch.benchmarking import check_targets, loop_rate
from graspnet_torch.collision import CollisionScene
from graspnet_torch.collision.proxy import CollisionProxy
from graspnet_torch.robot.robot import Posture
from graspnet_torch.robot.transforms import matrix_to_pose, pose_to_rt
from graspnet_torch.solver.search_space import palm_search_space, sample_hand_configurations
from graspnet_torch.table import format_table
from graspnet_torch.tasks.objects import as_mesh, closure_problem, random_pose, real_objects
from graspnet_torch.tasks.problem import Shape

AGREEMENT = 0.99
SPEED_RATIO = 0.5


def problems(folder: Path) -> dict[str, gt.GraspProblem]:
    hand = gt.load_robot("hand")
    rng = np.random.default_rng(0)
    out = {}
    for name, (path, scale) in real_objects().items():
        pose = matrix_to_pose(torch.as_tensor(random_pose(rng))).numpy()
        out[name] = closure_problem(hand, Shape("mesh", (), pose, path, scale), seed=0)
    for task in ("glass3", "videotape5"):
        out[f"{task} (mesh)"] = as_mesh(gt.GraspProblem.from_task(task).moved(random_pose(rng)), folder)
    return out


def agreement(problem: gt.GraspProblem, n: int) -> tuple[int, int, int, int]:
    """(agreeing, proxy-only, FCL-only, colliding by FCL) over n configurations of the search space."""
    hand = gt.load_robot("hand")
    g = torch.Generator().manual_seed(0)
    pose, q = sample_hand_configurations(hand, palm_search_space(hand, problem), n, g)
    proxy = CollisionProxy(hand, problem, dtype=torch.float64).count(pose_to_rt(pose), q) > 0
    scene = CollisionScene(hand, problem)
    fcl = torch.tensor([scene.count(Posture(pose[k], q[k], torch.zeros(0))) > 0 for k in range(n)])
    return int((proxy == fcl).sum()), int((proxy & ~fcl).sum()), int((~proxy & fcl).sum()), int(fcl.sum())


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--check", action="store_true")
    ap.add_argument("--configurations", type=int, default=300)
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    print(f"torch threads: {torch.get_num_threads()}")
    checks = []
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        rows, total = [], np.zeros(4, dtype=int)
        for name, problem in problems(Path(tmp)).items():
            counts = agreement(problem, args.configurations)
            total += counts
            rows.append([name, f"{counts[0] / args.configurations:.3f}", counts[1], counts[2],
                         f"{counts[3] / args.configurations:.2f}"])
        n = args.configurations * len(rows)
        rows.append(["all", f"{total[0] / n:.4f}", total[1], total[2], f"{total[3] / n:.2f}"])
        print(f"\n1. proxy vs FCL, {args.configurations} configurations of each search space "
              f"({time.perf_counter() - t0:.0f} s)")
        print(format_table(["object", "same verdict", "proxy only", "FCL only", "colliding (FCL)"], rows))
        checks.append((f"proxy vs FCL verdict on mesh objects: {100 * total[0] / n:.1f} % >= {100 * AGREEMENT:g} %",
                       total[0] / n >= AGREEMENT))
        speed = []
        for task in ("glass3", "videotape5"):
            primitive = gt.GraspProblem.from_task(task)
            mesh = as_mesh(primitive, Path(tmp))
            reward = gt.RewardCfg(kind="r3")
            for T, iterations, repeats in ((1, 1000, 3), (20, 300, 3), (1000, 20, 2)):
                loop_rate(mesh, T, 3, 1, reward)  # warm-up (the pieces, the proxy's tensors)
                m = loop_rate(mesh, T, iterations, repeats, reward)
                p = loop_rate(primitive, T, iterations, repeats, reward)
                speed.append([task, T, m, p, m / p])
                checks.append((f"{task}, T = {T}: the loop with the mesh at {m / p:.2f}x the primitive's speed >= "
                               f"{SPEED_RATIO:g}x", m / p >= SPEED_RATIO))
        print("\n2. the loop's speed, trial-iterations per second (R3, fixed budget)")
        print(format_table(["task", "trials T", "mesh", "primitive", "ratio"], speed, floatfmt=".3g"))
    print()
    return check_targets(checks, args.check)


if __name__ == "__main__":
    sys.exit(main())
