"""Reinforcement signals against the paper's formulas (eq. 3, 14, 15, 20-29)."""

from __future__ import annotations

import math

import torch

from graspnet_torch import rewards


def test_total_error_is_sum_of_fingertip_distances():
    d = torch.tensor([[0.0, 0, 0], [1, 1, 1]], dtype=torch.float64)
    a = torch.tensor([[0.003, 0.004, 0], [1, 1, 1.01]], dtype=torch.float64)
    assert math.isclose(float(rewards.total_error(d, a)), 0.005 + 0.01, rel_tol=1e-12)


def test_r1_to_r4():
    e = torch.tensor([0.0, 0.01, 0.5], dtype=torch.float64)
    r = rewards.r1(e, a=1.5)
    assert torch.allclose(r, 1 - torch.tanh(1.5 * e))
    c = torch.tensor([0, 1, 3])
    assert torch.allclose(rewards.r2(r, c), torch.stack([r[0], r[1] / 2, r[2] / 2]))
    assert torch.allclose(rewards.r3(r, c, 500, 2000), torch.stack([r[0], r[1] / 1.25, r[2] / 1.25]))
    r4 = rewards.r4(r, c, 500, 2000, beta=0.25)
    assert torch.allclose(r4, torch.stack([r[0], r[1] / (1 + 0.25), r[2] / (1 + 3**0.25 * 0.25)]))
    one = torch.tensor([1, 1, 1])
    assert torch.allclose(rewards.r4(r, one, 700, 2000), rewards.r3(r, one, 700, 2000))  # c = 1: R4 = R3
    assert torch.allclose(rewards.r3(r, c, 2000, 2000), rewards.r2(r, c))  # i = p: R3 = R2


def test_manus_reward():
    g = torch.tensor([[0.0, 0, 0], [0.07, 0, 0]], dtype=torch.float64)
    # swapped pairing: d takes the better of the two pairings (eq. 26-28)
    R, R1, _R2, d = rewards.manus_reward(g, g.flip(0))
    assert math.isclose(float(d), 0.0, abs_tol=1e-15) and math.isclose(float(R1), 1.0) and math.isclose(float(R), 1.0)
    t = torch.tensor([[0.0, 0.01, 0], [0.0, 0.08, 0]], dtype=torch.float64)  # orthogonal axis
    R, R1, _R2, d = rewards.manus_reward(g, t)
    d1 = 0.01 + math.hypot(0.07, 0.08)
    d2 = 0.08 + math.hypot(0.07, 0.01)
    assert math.isclose(float(R1), 0.0, abs_tol=1e-12) and math.isclose(float(d), min(d1, d2))
    assert math.isclose(float(R), (0.0 + 1 - math.tanh(min(d1, d2))) / 2)


def test_noise_is_zero_mean_with_given_sigma():
    gen = torch.Generator().manual_seed(0)
    r = torch.full((200_000,), 0.7, dtype=torch.float64)
    noisy = rewards.add_noise(r, 0.2, gen)
    assert abs(float(noisy.mean()) - 0.7) < 0.002 and abs(float(noisy.std()) - 0.2) < 0.002
    assert rewards.add_noise(r, 0.0) is r
