"""Stacked experts (batched == looped), training sets, reassignment."""

from __future__ import annotations

import pytest
import torch

from graspnet_torch.fcnn.dataset import TrainingSet
from graspnet_torch.fcnn.experts import ExpertSet, ExpertSetCfg


def _set(n_experts=3, max_experts=4, seed=0):
    es = ExpertSet(4, torch.tensor([0.05, 0.02, 0.0]), torch.tensor([0.03, 0.03, 0.01]),
                   torch.tensor([-0.3, -0.3, 0.0, -0.2]), torch.tensor([0.3, 1.5, 1.9, 1.4]),
                   ExpertSetCfg(hidden=35, max_experts=max_experts))
    g = torch.Generator().manual_seed(seed)
    for _ in range(n_experts):
        es.add_expert(torch.zeros(4), g)
    return es


def test_paper_architecture():
    es = _set()
    assert tuple(es.W1.shape[1:]) == (3, 35)
    assert tuple(es.W2.shape[1:]) == (35, 35)
    assert tuple(es.W3.shape[1:]) == (35, 4)


def test_batched_experts_equal_looped_mlps(gen):
    es = _set()
    x = torch.rand(50, 3, generator=gen) * 0.1
    out = es(x)
    assert out.shape == (3, 50, 4)
    for e in range(3):
        mlp = torch.nn.Sequential(torch.nn.Linear(3, 35), torch.nn.Tanh(), torch.nn.Linear(35, 35), torch.nn.Tanh(),
                                  torch.nn.Linear(35, 4))
        with torch.no_grad():
            for layer, W, b in zip(mlp[::2], (es.W1, es.W2, es.W3), (es.b1, es.b2, es.b3), strict=True):
                layer.weight.copy_(W[e].T)
                layer.bias.copy_(b[e, 0])
        expected = es.denormalize_q(mlp(es.normalize_x(x)))
        assert torch.allclose(out[e], expected, atol=1e-6)


def test_expert_creation_limit():
    es = _set(n_experts=4, max_experts=4)
    assert es.full
    with pytest.raises(RuntimeError, match="full"):
        es.add_expert(torch.zeros(4))


def test_training_set_sampling_respects_owners(gen):
    data = TrainingSet(4)
    data.add(torch.zeros(5, 3), torch.full((5, 4), 1.0), 0)
    data.add(torch.ones(7, 3), torch.full((7, 4), 2.0), torch.full((7,), 2))
    assert data.counts(3).tolist() == [5, 0, 7]
    _x, q, has = data.sample(3, 100, gen)
    assert has.tolist() == [True, False, True]
    assert bool((q[0] == 1.0).all()) and bool((q[2] == 2.0).all())
    for _ in range(3):  # growth beyond the initial capacity keeps everything
        data.add(torch.rand(3000, 3), torch.rand(3000, 4), 1)
    assert len(data) == 9012 and data.counts(3).tolist() == [5, 9000, 7]


def test_reassignment_moves_a_point_to_the_expert_that_fits_it_best(gen):
    es = _set(n_experts=2)
    x = torch.rand(20, 3, generator=gen) * 0.05
    with torch.no_grad():
        q_by_1 = es(x)[1]  # postures exactly as expert 1 maps these fingertips
    data = TrainingSet(4)
    data.add(x, q_by_1, 0)  # wrongly owned by expert 0
    moved = data.reassign(es)
    assert moved == 20 and data.owner.tolist() == [1] * 20
    assert data.reassign(es) == 0
