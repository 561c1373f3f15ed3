"""The loop's collision proxy against FCL near mesh objects (beyond the paper).

A contact set on each real object mesh (``pybullet_data``; a collision-free closure at a random
pose, :func:`~graspnet_torch.collision.problems.closure_problem`) and the moved ``tasks`` with their
objects as meshes; ``configurations`` palm poses uniform in each problem's search space (the frame
and box the loop searches) with finger joints uniform in their limits; the share of configurations
whose collision-free verdict is the same for the proxy (convex pieces) and for FCL (the mesh
itself). Target (issue 22): agreement >= 99 % over all the objects. The loop's speed with a mesh
is a timing: ``make bench-meshes`` (``benchmarks/mesh_objects.py``).
"""

from __future__ import annotations

import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

import graspnet_torch as gt
from graspnet_torch.collision import CollisionScene
from graspnet_torch.collision.problems import real_mesh_problems
from graspnet_torch.collision.proxy import CollisionProxy
from graspnet_torch.experiments.report import ExperimentReport, progress
from graspnet_torch.robot.robot import Posture
from graspnet_torch.robot.transforms import pose_to_rt
from graspnet_torch.settings import setting
from graspnet_torch.solver.search_space import palm_search_space, sample_hand_configurations
from graspnet_torch.table import markdown_table
from graspnet_torch.tasks.objects import REAL_OBJECTS, as_mesh, random_pose
from graspnet_torch.tasks.problem import GraspProblem

__all__ = ["AGREEMENT", "ProxyCfg", "agreement", "agreement_problems", "run_proxy"]

AGREEMENT = 0.99
TASKS = ("glass3", "videotape5")


@dataclass(frozen=True)
class ProxyCfg:
    """``+experiment=proxy``."""

    configurations: int = setting(300, lo=1, hi=1_000_000)  # per problem
    objects: tuple[str, ...] = setting(tuple(REAL_OBJECTS), choices=tuple(REAL_OBJECTS))
    tasks: tuple[str, ...] = setting(TASKS, choices=TASKS)


def agreement_problems(folder: Path, objects: tuple[str, ...] = tuple(REAL_OBJECTS),
                       tasks: tuple[str, ...] = TASKS) -> dict[str, GraspProblem]:
    """name -> problem: a closure contact set on each real object at a random pose, then each task
    moved to a random pose with its object written as a mesh into ``folder`` (one generator, seed 0)."""
    rng = np.random.default_rng(0)
    out = dict(zip(objects, real_mesh_problems(gt.load_robot("hand"), objects, rng), strict=True))
    for task in tasks:
        out[f"{task} (mesh)"] = as_mesh(gt.GraspProblem.from_task(task).moved(random_pose(rng)), folder)
    return out


def agreement(problem: GraspProblem, n: int) -> tuple[int, int, int, int]:
    """(agreeing, proxy-only, FCL-only, colliding by FCL) over n configurations of the search space."""
    import torch

    hand = gt.load_robot("hand")
    g = torch.Generator().manual_seed(0)
    pose, q = sample_hand_configurations(hand, palm_search_space(hand, problem), n, g)
    proxy = CollisionProxy(hand, problem, dtype=torch.float64).count(pose_to_rt(pose), q) > 0
    scene = CollisionScene(hand, problem)
    fcl = torch.tensor([scene.count(Posture(pose[k], q[k], torch.zeros(0))) > 0 for k in range(n)])
    return int((proxy == fcl).sum()), int((proxy & ~fcl).sum()), int((~proxy & fcl).sum()), int(fcl.sum())


def run_proxy(cfg: ProxyCfg, out: Path) -> ExperimentReport:
    """The agreement of each problem and over all, with the target as a check."""
    n = cfg.configurations
    rows, total, numbers = [], np.zeros(4, dtype=int), {}
    with tempfile.TemporaryDirectory(prefix="graspnet_proxy_") as tmp:
        problems = agreement_problems(Path(tmp), cfg.objects, cfg.tasks)
        for name, problem in progress(list(problems.items()), desc="proxy vs FCL", unit="problem"):
            counts = agreement(problem, n)
            total += counts
            rows.append([name, f"{counts[0] / n:.3f}", counts[1], counts[2], f"{counts[3] / n:.2f}"])
            numbers[f"{name}/same verdict"] = counts[0] / n
    share = float(total[0] / (n * len(rows)))
    rows.append(["all", f"{share:.4f}", total[1], total[2], f"{total[3] / (n * len(problems)):.2f}"])
    numbers["all/same verdict"] = share
    body = (" ".join(__doc__.split("\n\n")[1].split()) + f"\n\nHere: {n} configurations per problem.\n\n"
            + markdown_table(["object", "same verdict", "proxy only", "FCL only", "colliding (FCL)"], rows))
    return ExperimentReport("proxy", "The collision proxy against FCL near mesh objects", body, numbers=numbers,
                            checks=[(f"proxy vs FCL verdict on mesh objects: {100 * share:.1f} % >= "
                                     f"{100 * AGREEMENT:g} %", share >= AGREEMENT)])
