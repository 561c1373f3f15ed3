"""Fingertip FK and FK+Jacobian throughput: graspnet_torch's ChainKernel vs pytorch-kinematics.

Same chain, same joint values, float32, one run, timed side by side. Prints fingertips per second
for both and the ratio (ours / pytorch-kinematics).

    python benchmarks/bench_kinematics.py [--threads 1] [--batches 1 100 10000 100000]
"""

from __future__ import annotations

import argparse
import sys

import torch

import graspnet_torch as gt
from graspnet_torch.benchmarking import check_targets, time_interleaved
from graspnet_torch.robot import ChainKernel
from graspnet_torch.table import format_table


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--batches", type=int, nargs="+", default=[1, 100, 10_000, 100_000])
    ap.add_argument("--min-time", type=float, default=0.5, help="seconds of timing per function and batch")
    ap.add_argument("--check", action="store_true", help="exit 1 where pytorch-kinematics is faster")
    args = ap.parse_args()
    torch.set_num_threads(args.threads)

    hand, arm_hand = gt.load_robot("hand"), gt.load_robot("arm_hand")
    chains = [("index finger (base->tip, 4 joints)", hand, "index_base", "index_tip"),
              ("arm+index (world->tip, 11 joints)", arm_hand, "torso", "index_tip")]
    rows = []
    for label, robot, root, tip in chains:
        spec = robot.urdf.chain_spec(root, tip)
        ours = ChainKernel(spec)
        ref = robot.urdf.serial_chain(root, tip).to(dtype=torch.float32)
        lo, hi = torch.tensor(spec.lower, dtype=torch.float32), torch.tensor(spec.upper, dtype=torch.float32)
        for B in args.batches:
            q = lo + (hi - lo) * torch.rand(B, spec.n_joints, generator=torch.Generator().manual_seed(B))
            fns = [lambda q=q, k=ours: k.position(q),
                   lambda q=q, r=ref: r.forward_kinematics(q).get_matrix()[:, :3, 3],
                   lambda q=q, k=ours: k.position_jacobian(q),
                   lambda q=q, r=ref: r.jacobian(q, ret_eef_pose=True)]
            t_fk, t_fk_ref, t_j, t_j_ref = time_interleaved(fns, min_time=args.min_time)
            rows.append([label, B, B / t_fk / 1e6, B / t_fk_ref / 1e6, t_fk_ref / t_fk,
                         B / t_j / 1e6, B / t_j_ref / 1e6, t_j_ref / t_j])
            print(f"  {label} B={B}: FK+J ours {B / t_j / 1e6:.2f} M/s, pytorch-kinematics {B / t_j_ref / 1e6:.3f} M/s",
                  flush=True)
    # all five fingers in one stacked call vs five pytorch-kinematics chains
    specs = [f.chain.spec for f in hand.fingers.values()]
    stacked = ChainKernel(specs)
    refs = [hand.urdf.serial_chain(s.root, s.tip).to(dtype=torch.float32) for s in specs]
    lo, hi = (torch.tensor(a, dtype=torch.float32) for a in hand.finger_limits)
    for B in args.batches:
        q = lo + (hi - lo) * torch.rand(B, 5, 4, generator=torch.Generator().manual_seed(B))
        fns = [lambda q=q: stacked.position(q),
               lambda q=q: [r.forward_kinematics(q[:, k]).get_matrix() for k, r in enumerate(refs)],
               lambda q=q: stacked.position_jacobian(q),
               lambda q=q: [r.jacobian(q[:, k], ret_eef_pose=True) for k, r in enumerate(refs)]]
        t_fk, t_fk_ref, t_j, t_j_ref = time_interleaved(fns, min_time=args.min_time)
        n = 5 * B
        rows.append(["5 fingers stacked (one call)", B, n / t_fk / 1e6, n / t_fk_ref / 1e6, t_fk_ref / t_fk,
                     n / t_j / 1e6, n / t_j_ref / 1e6, t_j_ref / t_j])
    print()
    print(f"fingertips per second, millions (float32, {args.threads} threads); ratio = ours / pytorch-kinematics")
    print(format_table(["chain", "batch", "FK ours", "FK pk", "ratio", "FK+J ours", "FK+J pk", "ratio"], rows,
                       floatfmt=".3g"))
    # target: faster than pytorch-kinematics everywhere except one chain at batch 1, where the long
    # arm chain's traced program costs more than its loop (docs/robots.md, "Kinematics": about 0.7x)
    checks = [(f"{r[0]}, B={r[1]}: FK {r[4]:.3g}x, FK+J {r[7]:.3g}x pytorch-kinematics >= 1x",
               r[4] >= 1 and r[7] >= 1) for r in rows if not (r[1] == 1 and "11 joints" in r[0])]
    return check_targets(checks, args.check)


if __name__ == "__main__":
    sys.exit(main())
