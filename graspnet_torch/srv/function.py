"""Stochastic Real-Valued (SRV) units as a custom autograd Function (paper section 4.2-4.3).

For an input vector i, each SRV unit computes

    mu     = theta^T i                                      (9)
    r_hat  = phi^T i          (expected reinforcement)      (10)
    sigma  = s(r_hat)                                       (11)
    a      ~ N(mu, sigma)     (activation)                  (12)
    o      = logistic(a)      (output in [0, 1])

and learns from a scalar reinforcement r in [0, 1] (noisy in eq. 15) by

    theta += alpha ((r - r_hat)(a - mu) / sigma) i   if sigma > 0, unchanged if sigma = 0   (16)
    phi   += rho (r - r_hat) i                          (Widrow-Hoff LMS)                       (17)
    delta_SRV = (r - r_hat)(a - mu) / sigma                                                     (18)
    delta_BP  = Theta^T delta_SRV                       (error for the layers below)            (19)

There is no differentiable loss: the reinforcement takes the place of the incoming gradient.
``SRVFunction.apply(...)`` returns o (and a, mu, sigma, r_hat for logging); calling ``o.backward(r)``
with r broadcast to o's shape runs
the backward below, which returns the *negated* updates of eq. 16, 17 and 19 as gradients, so that
a plain SGD step with learning rates alpha (theta), rho (phi) and alpha_BP (the layers below, by
standard backpropagation of eq. 19's error) performs exactly the paper's updates. Biases are the
weights of a constant input 1.

The standard-deviation function s is left open by the paper (monotonically decreasing,
non-negative, s(1) = 0). Ours (:class:`SigmaCfg`): ``s(r_hat) = scale * max(1 - r_hat, 0)`` ('linear',
the default) or ``scale * max(1 - r_hat, 0)^2`` ('quadratic'), then ``max(., floor)``; a floor > 0
keeps exploring (and gives up s(1) = 0). The default scale 3 was chosen on the hand tasks: with
the paper's learning rates (0.01) and a = 1, scale 1 explores too little once r_hat nears 1
(mean errors 4-23 mm after the Table 2 budgets) and scale 10 so much that the trajectory never
settles; scale 3 gives mean errors of 0.2-1 mm (docs/hcnn.md).
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import Tensor

from graspnet_torch.settings import setting

__all__ = ["SRVFunction", "SigmaCfg", "sigma_of", "srv_errors", "srv_forward"]


@dataclass(frozen=True)
class SigmaCfg:
    """The SRV standard-deviation function s(r_hat) (eq. 11).

    Attributes:
        kind: 'linear' (``max(1 - r_hat, 0)``) or 'quadratic' (its square).
        scale: multiplies the above (activation units; o = logistic(a)); default 3, see above.
        floor: lower bound on sigma (0: none, so s(1) = 0 as in the paper).
    """

    kind: str = setting("linear", choices=("linear", "quadratic"))
    scale: float = setting(3.0, lo=0.0, lo_open=True, hi=1000.0)
    floor: float = setting(0.0, lo=0.0, hi=1000.0)

    def __post_init__(self):
        if self.kind not in ("linear", "quadratic"):
            raise ValueError(f"srv.sigma.kind must be 'linear' or 'quadratic', got '{self.kind}'")
        if not (self.scale > 0 and self.floor >= 0):
            raise ValueError(f"srv.sigma needs scale > 0 and floor >= 0, got {self.scale}, {self.floor}")


def sigma_of(r_hat: Tensor, cfg: SigmaCfg) -> Tensor:
    """s(r_hat) of eq. 11 (elementwise)."""
    d = torch.clamp(1.0 - r_hat, min=0.0)
    if cfg.kind == "quadratic":
        d = d * d
    s = d * cfg.scale
    return torch.clamp(s, min=cfg.floor) if cfg.floor > 0 else s


def srv_forward(i: Tensor, theta: Tensor, theta_b: Tensor, phi: Tensor, phi_b: Tensor, noise: Tensor,
                sigma_cfg: SigmaCfg) -> tuple[Tensor, Tensor, Tensor, Tensor, Tensor]:
    """Eq. 9-12 and o = logistic(a). Shapes as :class:`SRVFunction`; returns (o, a, mu, sigma, r_hat)."""
    mu = torch.baddbmm(theta_b, i, theta)  # (9)
    r_hat = torch.baddbmm(phi_b, i, phi)  # (10)
    sigma = sigma_of(r_hat, sigma_cfg)  # (11)
    a = torch.addcmul(mu, sigma, noise)  # (12)
    return torch.sigmoid(a), a, mu, sigma, r_hat


def srv_errors(noise: Tensor, sigma: Tensor, r_hat: Tensor, r: Tensor) -> tuple[Tensor, Tensor]:
    """The SRV error delta of eq. 16/18 and the LMS error of eq. 17 for reinforcement r.

    Since ``a - mu = sigma * noise`` (eq. 12), ``delta = (r - r_hat)(a - mu) / sigma`` equals
    ``(r - r_hat) * noise`` wherever sigma > 0, and 0 where sigma = 0 (no update, eq. 16): the same
    value without the division. All arguments (T, B, n_out). Returns (delta, lms).
    """
    lms = r - r_hat
    return lms * noise * torch.sign(sigma), lms  # sign(sigma) is 1 where sigma > 0 and 0 where it is 0


class SRVFunction(torch.autograd.Function):
    """A layer of SRV units, batched over independent learners (trials).

    forward(i, theta, theta_b, phi, phi_b, noise, sigma_cfg) -> (o, a, mu, sigma, r_hat), with
        i: (T, B, n_in) inputs; theta, phi: (T, n_in, n_out); theta_b, phi_b: (T, 1, n_out);
        noise: (T, B, n_out) standard normal draws (a = mu + sigma * noise);
        every output (T, B, n_out); only o carries the learning signal (the others are for logging).
    backward(r, ...): r (T, B, n_out) is the reinforcement of each sample, broadcast over the units;
        returns the negated updates of eq. 19 (input), 16 (theta) and 17 (phi), so that SGD applies
        them.
    """

    @staticmethod
    def forward(ctx, i: Tensor, theta: Tensor, theta_b: Tensor, phi: Tensor, phi_b: Tensor, noise: Tensor,
                sigma_cfg: SigmaCfg):
        o, a, mu, sigma, r_hat = srv_forward(i, theta, theta_b, phi, phi_b, noise, sigma_cfg)
        ctx.save_for_backward(i, theta, noise, sigma, r_hat)
        ctx.mark_non_differentiable(a, mu, sigma, r_hat)
        return o, a, mu, sigma, r_hat

    @staticmethod
    def backward(ctx, r: Tensor, *_unused: Tensor):
        i, theta, noise, sigma, r_hat = ctx.saved_tensors
        delta, lms = srv_errors(noise, sigma, r_hat, r)  # (16)-(18)
        it = i.transpose(1, 2)
        return (-(delta @ theta.transpose(1, 2)),  # (19) Theta^T delta, to the layers below
                -(it @ delta), -delta.sum(1, keepdim=True),  # (16)
                -(it @ lms), -lms.sum(1, keepdim=True),  # (17)
                None, None)
