"""SRV units (eq. 9-19) against the formulas, and the configuration network."""

from __future__ import annotations

import math

import pytest
import torch

from graspnet_torch.srv import ConfigurationNetwork, SigmaCfg, SRVFunction, SRVNetCfg, sigma_of

D = torch.float64


def _layer(gen, T=3, n_in=5, n_out=4, B=1):
    i = torch.randn(T, B, n_in, generator=gen, dtype=D, requires_grad=True)
    params = [torch.randn(T, n_in, n_out, generator=gen, dtype=D) * 0.3,
              torch.randn(T, 1, n_out, generator=gen, dtype=D) * 0.3,
              torch.randn(T, n_in, n_out, generator=gen, dtype=D) * 0.1,
              torch.randn(T, 1, n_out, generator=gen, dtype=D) * 0.1]
    params = [p.requires_grad_() for p in params]
    noise = torch.randn(T, B, n_out, generator=gen, dtype=D)
    return i, params, noise


def test_forward_is_eq_9_to_12(gen):
    i, (theta, theta_b, phi, phi_b), noise = _layer(gen)
    cfg = SigmaCfg(scale=0.8)
    o, a, mu, sigma, r_hat = SRVFunction.apply(i, theta, theta_b, phi, phi_b, noise, cfg)
    mu_ref = torch.einsum("tbi,tio->tbo", i, theta) + theta_b
    r_ref = torch.einsum("tbi,tio->tbo", i, phi) + phi_b
    s_ref = 0.8 * torch.clamp(1 - r_ref, min=0)
    assert torch.allclose(mu, mu_ref) and torch.allclose(r_hat, r_ref) and torch.allclose(sigma, s_ref)
    assert torch.allclose(a, mu_ref + s_ref * noise)
    assert torch.allclose(o, 1 / (1 + torch.exp(-a)))


def test_backward_is_the_update_of_eq_16_to_19(gen):
    """The gradients the Function returns are minus the updates of eq. 16, 17 and the error of
    eq. 19, written out here unit by unit from the paper's formulas."""
    i, (theta, theta_b, phi, phi_b), noise = _layer(gen)
    cfg = SigmaCfg(scale=1.0)
    o, a, mu, sigma, r_hat = SRVFunction.apply(i, theta, theta_b, phi, phi_b, noise, cfg)
    r = torch.rand(3, generator=gen, dtype=D)
    o.backward(r.view(3, 1, 1).expand_as(o))
    T, _, n_in = i.shape
    n_out = theta.shape[2]
    for t in range(T):
        x = i[t, 0].detach()
        for k in range(n_out):
            s = float(sigma[t, 0, k])
            err = float(r[t] - r_hat[t, 0, k])
            delta = err * float(a[t, 0, k] - mu[t, 0, k]) / s if s > 0 else 0.0  # (18)
            assert torch.allclose(-theta.grad[t, :, k], delta * x)  # (16): theta += alpha * delta * i
            assert math.isclose(-float(theta_b.grad[t, 0, k]), delta, abs_tol=1e-12)
            assert torch.allclose(-phi.grad[t, :, k], err * x)  # (17): phi += rho (r - r_hat) i
            assert math.isclose(-float(phi_b.grad[t, 0, k]), err, abs_tol=1e-12)
        deltas = torch.stack([(r[t] - r_hat[t, 0, k]) * (a[t, 0, k] - mu[t, 0, k]) / sigma[t, 0, k]
                              for k in range(n_out)])
        assert torch.allclose(-i.grad[t, 0], theta[t].detach() @ deltas)  # (19): Theta^T delta
    assert i.grad.shape == (T, 1, n_in)


def test_no_theta_update_when_sigma_is_zero(gen):
    i, (theta, theta_b, phi, phi_b), noise = _layer(gen, T=1, n_out=2)
    with torch.no_grad():  # r_hat >= 1 for unit 0 -> sigma = 0; unit 1 explores
        phi.zero_()
        phi_b[0, 0, 0] = 1.3
        phi_b[0, 0, 1] = 0.2
    o, a, mu, sigma, _r_hat = SRVFunction.apply(i, theta, theta_b, phi, phi_b, noise, SigmaCfg())
    assert float(sigma[0, 0, 0]) == 0.0 and float(sigma[0, 0, 1]) > 0
    assert float(a[0, 0, 0]) == float(mu[0, 0, 0])
    o.backward(torch.full_like(o, 0.5))
    assert bool((theta.grad[0, :, 0] == 0).all()) and float(theta_b.grad[0, 0, 0]) == 0.0
    # only unit 1 sends an error down (eq. 19): delta_1 = (0.5 - 0.2) * (a - mu) / sigma = 0.3 * noise
    expected = -(theta[0, :, 1].detach() * 0.3 * float(noise[0, 0, 1]))
    assert torch.allclose(i.grad[0, 0], expected)
    # the LMS rule (17) still learns the expected reinforcement of the silent unit
    assert math.isclose(-float(phi_b.grad[0, 0, 0]), 0.5 - 1.3, rel_tol=1e-12)


def test_lms_rule_converges_to_the_mean_reinforcement(gen):
    """eq. 17 alone is Widrow-Hoff: r_hat tracks E[r] for a fixed input."""
    i = torch.ones(1, 1, 1, dtype=D)
    phi, phi_b = torch.zeros(1, 1, 1, dtype=D), torch.zeros(1, 1, 1, dtype=D)
    for _ in range(4000):
        r = 0.6 + 0.1 * torch.randn(1, generator=gen, dtype=D)
        r_hat = (i @ phi + phi_b)[0, 0, 0]
        phi += 0.01 * (r - r_hat) * i  # (17)
        phi_b += 0.01 * (r - r_hat)
    assert abs(float((i @ phi + phi_b)[0, 0, 0]) - 0.6) < 0.02


def test_sigma_function():
    r_hat = torch.tensor([-1.0, 0.0, 0.5, 1.0, 1.5])
    assert torch.allclose(sigma_of(r_hat, SigmaCfg(scale=2.0)), torch.tensor([4.0, 2.0, 1.0, 0.0, 0.0]))
    quadratic = sigma_of(r_hat, SigmaCfg(kind="quadratic", scale=1.0))
    assert torch.allclose(quadratic, torch.tensor([4.0, 1.0, 0.25, 0.0, 0.0]))
    assert torch.allclose(sigma_of(r_hat, SigmaCfg(scale=1.0, floor=0.1)), torch.tensor([2.0, 1.0, 0.5, 0.1, 0.1]))
    with pytest.raises(ValueError, match="linear"):
        SigmaCfg(kind="cubic")


@pytest.mark.slow
def test_one_srv_unit_learns_a_bandit():
    """A single SRV unit (bias input only) maximises a reward peaked at o = 0.7."""
    gen = torch.Generator().manual_seed(0)
    i = torch.ones(1, 1, 1)
    theta, theta_b = torch.zeros(1, 1, 1, requires_grad=True), torch.zeros(1, 1, 1, requires_grad=True)
    phi, phi_b = torch.zeros(1, 1, 1, requires_grad=True), torch.zeros(1, 1, 1, requires_grad=True)
    opt = torch.optim.SGD([{"params": [theta, theta_b], "lr": 0.2}, {"params": [phi, phi_b], "lr": 0.1}])
    for _ in range(3000):
        noise = torch.randn(1, 1, 1, generator=gen)
        o, *_ = SRVFunction.apply(i, theta, theta_b, phi, phi_b, noise, SigmaCfg(scale=1.0))
        r = torch.exp(-(((o.detach() - 0.7) / 0.15) ** 2))
        opt.zero_grad()
        o.backward(r)
        opt.step()
    mean_output = float(torch.sigmoid(theta + theta_b).detach().squeeze())
    assert abs(mean_output - 0.7) < 0.02


def test_fused_update_equals_autograd_update():
    """ConfigurationNetwork.reinforce (hand-fused) == SRV Function + autograd + SGD, float64."""
    cfg = SRVNetCfg(lr_bp=0.05, lr_srv=0.03, lr_lms=0.02)
    nets = [ConfigurationNetwork(6, 4, cfg, torch.Generator().manual_seed(3), dtype=D, autograd=ag)
            for ag in (False, True)]
    gen = torch.Generator().manual_seed(4)
    for step in range(5):
        x = torch.rand(4, 12, generator=gen, dtype=D)
        noise = torch.randn(4, 6, generator=gen, dtype=D)
        r = torch.rand(4, generator=gen, dtype=D)
        active = torch.tensor([True, True, step % 2 == 0, True])
        outs = [net(x, noise) for net in nets]
        assert torch.allclose(outs[0].o, outs[1].o, atol=1e-12)
        for net in nets:
            net.reinforce(r, active)
    for (name, p), (_, q) in zip(nets[0].named_parameters(), nets[1].named_parameters(), strict=True):
        assert torch.allclose(p, q, atol=1e-12), name


def test_inactive_trials_do_not_learn():
    net = ConfigurationNetwork(3, 2, SRVNetCfg(), torch.Generator().manual_seed(0))
    before = {k: v.clone() for k, v in net.state_dict().items()}
    net(torch.rand(2, 6), torch.randn(2, 3))
    net.reinforce(torch.tensor([0.9, 0.2]), active=torch.tensor([False, True]))
    for k, v in net.state_dict().items():
        assert torch.equal(v[0], before[k][0]), k
        assert not torch.equal(v[1], before[k][1]), k


def test_weights_start_in_paper_range_and_shapes():
    net = ConfigurationNetwork(7, 5, SRVNetCfg(), torch.Generator().manual_seed(0))
    assert net.W1.shape == (5, 14, 20) and net.W2.shape == (5, 20, 20) and net.theta.shape == (5, 20, 7)
    for p in net.parameters():
        assert float(p.abs().max()) <= 0.5
