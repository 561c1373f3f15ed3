"""Accuracy of learned finger IK on held-out reachable targets."""

from __future__ import annotations

import torch
from torch import Tensor

from graspnet_torch.fcnn.ik import FingerIK
from graspnet_torch.robot.fingers import FingerKernel

__all__ = ["error_stats", "heldout_targets"]

HELDOUT_SEED = 987_654  # distinct from every training seed


def heldout_targets(ik: FingerIK, finger: str, n: int = 10_000, seed: int = HELDOUT_SEED,
                    dtype: torch.dtype = torch.float32) -> tuple[Tensor, Tensor]:
    """n targets from joint angles uniform within limits: (q (n, j), x (n, 3)) in the base frame."""
    chain = ik.robot.fingers[finger].chain
    lo = torch.tensor(chain.lower, dtype=dtype)
    hi = torch.tensor(chain.upper, dtype=dtype)
    gen = torch.Generator().manual_seed(seed + sum(map(ord, finger)))
    q = lo + (hi - lo) * torch.rand(n, chain.n_joints, generator=gen, dtype=dtype)
    return q, FingerKernel(chain).position(q)


def error_stats(error_m: Tensor) -> dict[str, float]:
    """Median / p95 / p99 / max in mm and the share within 1 mm (percent)."""
    e = error_m.double() * 1000
    return {"median_mm": float(e.median()), "p95_mm": float(torch.quantile(e, 0.95)),
            "p99_mm": float(torch.quantile(e, 0.99)), "max_mm": float(e.max()),
            "within_1mm_pct": float((e < 1.0).double().mean() * 100)}
