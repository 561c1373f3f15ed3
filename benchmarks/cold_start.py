"""A new object, cold: from a mesh never seen (an empty cache) to its first verified grasp.

    python benchmarks/cold_start.py [--objects 50] [--seed 7] [--jobs 2] [--report FILE] [--check]

Objects: ``--objects`` of pybullet's random objects at the synthesis experiment's scale, drawn by
``--seed`` from those that neither the experiment ``synthesis`` (seed 2026) nor any tuning or test
uses. Each object runs in a fresh Python process with its own empty cache folder
(``GRASPNET_TORCH_CACHE``), the shipped hand built first; timed from there: the mesh read
(``gt.Shape``), its preparation (the signed distance grid, the FCL model and the convex pieces of
the collision proxy and the physics model: ``prep``), then ``gt.synthesize_grasps`` (one grasp,
checked with ``gt.check_until_failure``) to the first check that holds 6/6 (``first``: from the
mesh read). Then a second fresh process with the same, now warm, cache (``warm``), and the peer:
``gt.baseline_grasps`` (random palm poses, fingers closed until they touch, the same check), cold,
in a third. ``--jobs`` objects at a time, one torch thread each. Targets (``--check``): median first
at most 1.5 s, 95th percentile at most 4 s, none over 10 s; preparation median at most 0.5 s, none
over 3 s. ``--report FILE``: the tables and the targets as markdown, with the command, the commit
and the machine (``make bench-cold-start`` writes ``reports/cold_start.md``).
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import tempfile
import time

import numpy as np

FIRST_MEDIAN_S, FIRST_P95_S, FIRST_MAX_S = 1.5, 4.0, 10.0
PREP_MEDIAN_S, PREP_MAX_S = 0.5, 3.0


def one(number: int, method: str) -> dict:
    """In this (fresh) process: object ``number`` by ``method`` ('synthesis' or 'baseline'), timed."""
    import torch

    import graspnet_torch as gt
    from graspnet_torch.collision.convex import convex_pieces
    from graspnet_torch.collision.mesh import mesh_query
    from graspnet_torch.collision.sdf import distance_grid
    from graspnet_torch.experiments.synthesis import object_mesh

    torch.set_num_threads(1)
    robot = gt.load_robot("hand")
    t0 = time.perf_counter()
    obj = object_mesh(number)
    distance_grid(obj)
    mesh_query(obj)
    convex_pieces(obj.mesh, obj.scale)
    prep = time.perf_counter() - t0
    first: list[float] = []

    def physics(problem, result, robot):  # the check, timed: the first that holds every push
        report = gt.check_until_failure(problem, result, robot=robot)
        if report.held_all and not first:
            first.append(time.perf_counter() - t0)
        return report

    kwargs = {"n_grasps": 1, "seed": 2026 + number, "physics": physics}
    grasps = (gt.synthesize_grasps if method == "synthesis" else gt.baseline_grasps)(robot, obj, **kwargs)
    return {"prep": prep, "first": first[0] if first else None, "wall": time.perf_counter() - t0,
            "held": bool(grasps) and grasps[0].holds == 6}


def _run(number: int, method: str, cache: str) -> dict:
    env = dict(os.environ, GRASPNET_TORCH_CACHE=cache)
    out = subprocess.run([sys.executable, __file__, "--one", str(number), method], env=env, capture_output=True,
                         text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def _object(number: int) -> dict:
    with tempfile.TemporaryDirectory(prefix="graspnet_cold_") as cache:
        cold = _run(number, "synthesis", cache)
        warm = _run(number, "synthesis", cache)
    with tempfile.TemporaryDirectory(prefix="graspnet_cold_") as cache:
        peer = _run(number, "baseline", cache)
    print(f"object {number:03d}: prep {cold['prep']:.2f} s, first verified {cold['first']} s cold, "
          f"{warm['first']} s warm, baseline {peer['first']} s", file=sys.stderr, flush=True)
    return {"number": number, "cold": cold, "warm": warm, "peer": peer}


def _stats(values: list[float | None]) -> tuple[float, float, float, int]:
    """Median, 95th percentile and largest of the times (an object with none counts as never), and
    how many have one."""
    found = [v for v in values if v is not None]
    x = np.array([math.inf if v is None else v for v in values])
    return float(np.median(x)), float(np.percentile(x, 95, method="higher")), float(x.max()), len(found)


def _s(seconds: float) -> str:
    return "never" if math.isinf(seconds) else f"{seconds:.2f}"


def _tables(rows: list[dict], wall: float) -> tuple[list[str], list[tuple[str, bool]]]:
    """The report's lines (per object, then per run, then the ratio to the peer) and the targets."""
    shown = lambda v: "never" if v is None else f"{v:.2f}"  # noqa: E731
    lines = ["| object | prep s | first verified s, cold | warm | baseline, cold |", "|---|---|---|---|---|"]
    lines += [f"| {r['number']:03d} | {r['cold']['prep']:.2f} | {shown(r['cold']['first'])} | "
              f"{shown(r['warm']['first'])} | {shown(r['peer']['first'])} |" for r in rows]
    lines += ["", "| run | objects with a verified grasp | median s to the first | 95th percentile | largest | "
              "median prep s | largest prep s |", "|---|---|---|---|---|---|---|"]
    summary = {}
    for run, name in (("cold", "synthesis, cold"), ("warm", "synthesis, warm"), ("peer", "baseline, cold")):
        med, p95, top, found = _stats([r[run]["first"] for r in rows])
        preps = [r[run]["prep"] for r in rows]
        summary[run] = (med, p95, top)
        lines.append(f"| {name} | {found}/{len(rows)} | {_s(med)} | {_s(p95)} | {_s(top)} | {np.median(preps):.2f} | "
                     f"{max(preps):.2f} |")
    med, p95, top = summary["cold"]
    peer = summary["peer"][0]
    ratio = (f"{med / peer:.2f}x the baseline's median time to the first verified grasp" if math.isfinite(peer)
             else "the baseline's median: never (half its objects or more have no verified grasp)")
    lines += ["", f"synthesis, cold: {ratio}; all processes: {wall:.0f} s"]
    preps = [r["cold"]["prep"] for r in rows]
    return lines, [(f"cold: median first verified {med:.2f} s <= {FIRST_MEDIAN_S:g} s", med <= FIRST_MEDIAN_S),
                   (f"cold: 95th percentile {p95:.2f} s <= {FIRST_P95_S:g} s", p95 <= FIRST_P95_S),
                   (f"cold: largest {top:.2f} s <= {FIRST_MAX_S:g} s", top <= FIRST_MAX_S),
                   (f"mesh preparation: median {np.median(preps):.2f} s <= {PREP_MEDIAN_S:g} s",
                    float(np.median(preps)) <= PREP_MEDIAN_S),
                   (f"mesh preparation: largest {max(preps):.2f} s <= {PREP_MAX_S:g} s", max(preps) <= PREP_MAX_S)]


def _write_report(path: str, head: str, lines: list[str], targets: list[tuple[str, bool]]) -> None:
    """``lines`` and the targets as a markdown report naming the command, the commit and the machine."""
    from graspnet_torch.experiments.report import machine
    from graspnet_torch.io import atomic_write_text

    text = ["# A new object, cold: the first verified grasp of never-seen meshes", "",
            f"Written by `python {' '.join(sys.argv)}` on {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}. "
            + (__doc__ or "").split("\n\n", 2)[2].replace("\n", " ").strip(), "", head, "", *lines, "",
            "Targets:", "", *(f"- {'met' if ok else 'MISSED'}: {t}" for t, ok in targets), "",
            "| machine | |", "|---|---|", *(f"| {k} | {v} |" for k, v in machine().items()), ""]
    atomic_write_text(path, "\n".join(text))


def main() -> int:
    from graspnet_torch.benchmarking import bench_args, check_targets
    from graspnet_torch.experiments.report import python_speed_ms
    from graspnet_torch.experiments.synthesis import fresh_objects

    args = bench_args(__doc__, [("--objects", int, 50), ("--seed", int, 7), ("--jobs", int, 2), ("--report", str, "")])
    numbers = fresh_objects(args.objects, args.seed)
    head = (f"{len(numbers)} objects never seen (seed {args.seed}): {', '.join(f'{k:03d}' for k in numbers)}; "
            f"{args.jobs} at a time, each in fresh processes, 1 torch thread; this machine: sum(range(10**6)) in "
            f"{python_speed_ms():.1f} ms")
    print(head)
    from joblib import Parallel, delayed

    t0 = time.perf_counter()
    rows = Parallel(n_jobs=args.jobs, backend="threading")(delayed(_object)(k) for k in numbers)
    lines, targets = _tables(rows, time.perf_counter() - t0)
    print("", *lines, sep="\n")
    if args.report:
        _write_report(args.report, head, lines, targets)
    return check_targets(targets, args.check)


if __name__ == "__main__":
    if len(sys.argv) == 4 and sys.argv[1] == "--one":
        print(json.dumps(one(int(sys.argv[2]), sys.argv[3])))
        sys.exit(0)
    sys.exit(main())
