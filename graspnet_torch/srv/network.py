"""The generic configuration network (paper sections 4.1, 4.3): two hidden backpropagation layers
of tanh units and an output layer of SRV units, trained by reinforcement.

Inputs: the current configuration and its change since the previous step (2n numbers); outputs:
n values o in [0, 1], scaled to the search bounds by eq. 13, ``c = c_min + (c_max - c_min) o``.
The same class serves the hand (HCNN, n = 6: the palm pose), the arm (ACNN, n = 7) and the MANUS
on its base (n = 9). ``trials`` independent networks (own weights, own random start) are held in
stacked tensors and run as one batch.

The configuration fed back as input is the network's previous output o (the configuration
normalised to [0, 1] by its bounds) and its change (in [-1, 1]); normalised inputs keep the same
learning rates meaningful for every robot.

Two equivalent ways to learn: ``reinforce`` (the default) computes the updates of eq. 16-19 with
the same functions as :class:`~graspnet_torch.srv.function.SRVFunction` and backpropagates eq. 19's
error through the tanh layers by hand, in one fused step; ``autograd=True`` runs the SRV Function
through ``torch.autograd`` and a ``torch.optim.SGD`` step. The tests check that they agree; the
fused step is about 4x faster for one trial, where framework overhead dominates the arithmetic.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import Tensor, nn

from graspnet_torch.settings import build, setting
from graspnet_torch.srv.function import SigmaCfg, SRVFunction, srv_errors, srv_forward

__all__ = ["ConfigurationNetwork", "SRVNetCfg", "SRVStep"]


@dataclass(frozen=True)
class SRVNetCfg:
    """Configuration network settings (Hydra group ``srv/``); the paper's section 5.1 defaults.

    Attributes:
        hidden: units of the two hidden backpropagation layers (paper: 20, 20).
        init_range: weights and biases start uniform in [-init_range, init_range] (paper: 0.5).
        lr_bp: alpha_BP, learning rate of the backpropagation layers (paper: 0.01).
        lr_srv: alpha, learning rate of the SRV means, eq. 16 (paper: 0.01).
        lr_lms: rho, learning rate of the expected reinforcement, eq. 17 (paper: 0.01).
        sigma: the standard-deviation function s(r_hat) of eq. 11 (left open by the paper).
    """

    hidden: tuple[int, int] = setting((20, 20), lo=1, hi=1024)
    init_range: float = setting(0.5, lo=0.0, lo_open=True, hi=100.0)
    lr_bp: float = setting(0.01, lo=0.0, hi=100.0)
    lr_srv: float = setting(0.01, lo=0.0, hi=100.0)
    lr_lms: float = setting(0.01, lo=0.0, hi=100.0)
    sigma: SigmaCfg = setting(factory=SigmaCfg)

    @classmethod
    def from_mapping(cls, d: dict | None, where: str = "srv") -> SRVNetCfg:
        """Checked against the ranges above (:func:`graspnet_torch.settings.build`)."""
        return build(cls, d, where)


@dataclass
class SRVStep:
    """One forward pass of T networks; every field (T, n)."""

    o: Tensor  # outputs in [0, 1]
    a: Tensor  # activations
    mu: Tensor  # means (eq. 9)
    sigma: Tensor  # standard deviations (eq. 11)
    r_hat: Tensor  # expected reinforcements (eq. 10)


class ConfigurationNetwork(nn.Module):
    """T independent networks 2n -> H1 -> H2 -> n (SRV).

    Args:
        n: outputs (configuration size).
        trials: number of independent learners T.
        cfg: sizes and learning rates.
        generator: draws the initial weights.
    """

    def __init__(self, n: int, trials: int, cfg: SRVNetCfg = SRVNetCfg(), generator: torch.Generator | None = None,
                 dtype: torch.dtype = torch.float32, device: torch.device | str = "cpu", autograd: bool = False):
        super().__init__()
        self.n, self.trials, self.cfg, self.autograd = n, trials, cfg, autograd
        h1, h2 = cfg.hidden
        shapes = {"W1": (2 * n, h1), "b1": (1, h1), "W2": (h1, h2), "b2": (1, h2),
                  "theta": (h2, n), "theta_b": (1, n), "phi": (h2, n), "phi_b": (1, n)}
        g = cfg.init_range
        for name, shape in shapes.items():
            w = (torch.rand((trials, *shape), generator=generator, dtype=torch.float64) * 2 - 1) * g
            setattr(self, name, nn.Parameter(w.to(dtype=dtype, device=device), requires_grad=autograd))
        self._bp = [self.W1, self.b1, self.W2, self.b2]
        self._srv = [self.theta, self.theta_b, self.phi, self.phi_b]
        if autograd:
            self.optimizer = torch.optim.SGD(
                [{"params": self._bp, "lr": cfg.lr_bp},
                 {"params": [self.theta, self.theta_b], "lr": cfg.lr_srv},
                 {"params": [self.phi, self.phi_b], "lr": cfg.lr_lms}], lr=cfg.lr_bp, foreach=True)
        self._cache: tuple | None = None

    def select(self, rows: Tensor) -> ConfigurationNetwork:
        """The networks of the trials ``rows`` (B,), copied: what a loop whose other trials have
        stopped still runs (each trial's network is independent: its steps are unchanged, up to the
        last unit of float32 where an elementwise op takes its scalar path on the shorter tensor)."""
        if self.autograd:
            raise ValueError("select() needs the fused updates (autograd=False)")
        out = ConfigurationNetwork.__new__(ConfigurationNetwork)
        nn.Module.__init__(out)
        out.n, out.trials, out.cfg, out.autograd = self.n, int(rows.numel()), self.cfg, False
        for name in ("W1", "b1", "W2", "b2", "theta", "theta_b", "phi", "phi_b"):
            setattr(out, name, nn.Parameter(getattr(self, name)[rows].clone(), requires_grad=False))
        out._bp = [out.W1, out.b1, out.W2, out.b2]
        out._srv = [out.theta, out.theta_b, out.phi, out.phi_b]
        out._cache = None
        return out

    def place(self, o: Tensor, expected: Tensor | None = None, rows: Tensor | None = None) -> None:
        """Shift the output layer's biases so that, fed its start ``o`` (T, n) in (0, 1) with no
        change (the input of the first iterations), each network's mean output is ``o`` and,
        given ``expected`` (T,), its expected reinforcement is that (the start's own: a start near
        a grasp is explored narrowly, eq. 11): the search starts at a given configuration (a
        posture proposal) instead of wherever its random weights put it. The weights and
        learning rules are unchanged. ``rows`` (T,) bool: only those networks (None: all)."""
        with torch.no_grad():
            x = torch.cat([o, torch.zeros_like(o)], 1).unsqueeze(1).to(self.W1)
            h1 = torch.tanh(torch.baddbmm(self.b1, x, self.W1))
            h2 = torch.tanh(torch.baddbmm(self.b2, h1, self.W2))
            logit = torch.logit(o.to(self.W1)).unsqueeze(1)
            keep = None if rows is None else rows.to(self.W1.device).view(-1, 1, 1)
            self.theta_b.copy_(logit - h2 @ self.theta if keep is None else
                               torch.where(keep, logit - h2 @ self.theta, self.theta_b))
            if expected is not None:
                phi_b = expected.to(self.W1).view(-1, 1, 1) - h2 @ self.phi
                self.phi_b.copy_(phi_b if keep is None else torch.where(keep, phi_b, self.phi_b))

    def restart(self, rows: Tensor, generator: torch.Generator | None = None) -> None:
        """New initial weights for the networks of the trials ``rows`` (B,), drawn as at construction."""
        g = self.cfg.init_range
        with torch.no_grad():
            for p in (*self._bp, *self._srv):
                u = torch.rand((int(rows.numel()), *p.shape[1:]), generator=generator, dtype=torch.float64)
                w = (u * 2 - 1) * g
                p[rows.to(p.device)] = w.to(p)

    def forward(self, x: Tensor, noise: Tensor) -> SRVStep:
        """x: (T, 2n) current configuration and its change; noise: (T, n) standard normal draws."""
        x = x.unsqueeze(1)
        h1 = torch.tanh(torch.baddbmm(self.b1, x, self.W1))
        h2 = torch.tanh(torch.baddbmm(self.b2, h1, self.W2))
        if self.autograd:
            out = SRVFunction.apply(h2, *self._srv, noise.unsqueeze(1), self.cfg.sigma)
        else:
            out = srv_forward(h2, *self._srv, noise.unsqueeze(1), self.cfg.sigma)
        self._cache = (x, h1, h2, noise.unsqueeze(1), *out)
        o, a, mu, sigma, r_hat = (t.squeeze(1) for t in out)
        return SRVStep(o, a, mu, sigma, r_hat)

    def reinforce(self, r: Tensor, active: Tensor | None = None) -> None:
        """Learn from the reinforcement of the last forward pass (eq. 16-19).

        r: (T,) reinforcement (possibly noisy, eq. 15); active: (T,) bool, trials that learn
        (the others get r = r_hat, which makes every update zero).
        """
        if self._cache is None:
            raise RuntimeError("reinforce() needs a forward() first")
        x, h1, h2, noise, o, _a, _mu, sigma, r_hat = self._cache
        self._cache = None
        r_b = r.to(o.dtype).reshape(-1, 1, 1).expand_as(o)
        if active is not None:
            r_b = torch.where(active.reshape(-1, 1, 1), r_b, r_hat)
        if self.autograd:
            self.optimizer.zero_grad(set_to_none=True)
            torch.autograd.backward(o, r_b)
            self.optimizer.step()
            return
        cfg = self.cfg
        with torch.no_grad():
            delta, lms = srv_errors(noise, sigma, r_hat, r_b)  # (16)-(18)
            d2 = (delta @ self.theta.transpose(1, 2)) * (1 - h2 * h2)  # (19), then through tanh
            d1 = (d2 @ self.W2.transpose(1, 2)) * (1 - h1 * h1)
            # one sample per trial: the weight updates are outer products (input^T error)
            h2t, h1t, xt = h2.transpose(1, 2), h1.transpose(1, 2), x.transpose(1, 2)
            if x.shape[1] != 1:  # several samples per trial: sum their outer products
                self.theta.baddbmm_(h2t, delta, alpha=cfg.lr_srv)
                self.phi.baddbmm_(h2t, lms, alpha=cfg.lr_lms)
                self.W2.baddbmm_(h1t, d2, alpha=cfg.lr_bp)
                self.W1.baddbmm_(xt, d1, alpha=cfg.lr_bp)
                delta, lms, d2, d1 = (t.sum(1, keepdim=True) for t in (delta, lms, d2, d1))
            else:
                self.theta.addcmul_(h2t, delta, value=cfg.lr_srv)  # (16)
                self.phi.addcmul_(h2t, lms, value=cfg.lr_lms)  # (17)
                self.W2.addcmul_(h1t, d2, value=cfg.lr_bp)
                self.W1.addcmul_(xt, d1, value=cfg.lr_bp)
            self.theta_b.add_(delta, alpha=cfg.lr_srv)
            self.phi_b.add_(lms, alpha=cfg.lr_lms)
            self.b2.add_(d2, alpha=cfg.lr_bp)
            self.b1.add_(d1, alpha=cfg.lr_bp)
