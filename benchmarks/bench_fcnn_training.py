"""Time to train the FCNN of all five fingers of the hand from scratch (default settings).

Trains into a temporary folder (the shipped checkpoint is untouched), prints the wall time per
finger and in total, and the closing accuracy table.

    python benchmarks/bench_fcnn_training.py [--threads 1] [--epochs N]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time

import torch
from hydra import compose, initialize_config_dir
from omegaconf import OmegaConf

import graspnet_torch as gt
from graspnet_torch.benchmarking import check_targets
from graspnet_torch.fcnn.train import FCNNTrainCfg
from graspnet_torch.jobs.train_fcnn import train_fcnn
from graspnet_torch.paths import configs_dir


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--epochs", type=int, default=None, help="override fcnn.epochs (default: configs/fcnn)")
    ap.add_argument("--check", action="store_true", help="exit 1 when training takes 5 min or more")
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    with initialize_config_dir(config_dir=str(configs_dir()), version_base="1.3"):
        cfg = compose(config_name="train_fcnn")
    fcnn = FCNNTrainCfg.from_mapping(OmegaConf.to_container(cfg.fcnn))
    if args.epochs:
        fcnn = FCNNTrainCfg(**{**fcnn.__dict__, "epochs": args.epochs})
    robot = gt.load_robot("hand")
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        train_fcnn(robot, fcnn, tmp, seed=cfg.seed, progress=False)
        total = time.perf_counter() - t0
    print(f"\ntrained {len(robot.finger_names)} fingers x {fcnn.epochs} epochs from scratch in {total:.0f} s "
          f"({total / 60:.1f} min, {args.threads} threads, including the 10,000-target evaluation); "
          f"target: under 5 min")
    return check_targets([(f"training {total:.0f} s < 300 s", total < 300)], args.check)


if __name__ == "__main__":
    sys.exit(main())
