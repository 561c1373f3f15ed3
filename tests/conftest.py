from __future__ import annotations

import os

import pytest
import torch

import graspnet_torch as gt

ROBOTS = ("hand", "arm_hand", "manus")

if os.environ.get("PYTEST_XDIST_WORKER"):  # pytest -n N: N processes share the cores, one torch thread each
    torch.set_num_threads(1)


@pytest.fixture(scope="session")
def robots() -> dict[str, gt.Robot]:
    return {name: gt.load_robot(name) for name in ROBOTS}


@pytest.fixture(scope="session")
def hand(robots) -> gt.Robot:
    return robots["hand"]


@pytest.fixture
def gen() -> torch.Generator:
    return torch.Generator().manual_seed(1234)


def uniform(lower, upper, n: int, gen: torch.Generator, dtype=torch.float64) -> torch.Tensor:
    """n samples uniform in the box [lower, upper] (array-likes of equal shape)."""
    lo = torch.as_tensor(lower, dtype=dtype)
    hi = torch.as_tensor(upper, dtype=dtype)
    return lo + (hi - lo) * torch.rand((n, *lo.shape), generator=gen, dtype=dtype)
