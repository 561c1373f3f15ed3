"""The FCNN learning procedure (paper section 3.1), batched over many targets per epoch.

One epoch of one finger draws ``targets_per_epoch`` reachable fingertip targets X_D and, for all
of them at once:

1. every expert predicts; the posture of the expert with the smallest fingertip error is the start
   of a reaching motion (eq. 6-8, or iterative improvement eq. 5 when e(0) < r_st);
2. targets whose motion was rejected (joint limits, singularity) retry from the next expert in
   order of predicted error, until all experts are tried;
3. targets still unsolved start from the representative postures of the experts, in random order;
4. targets still unsolved start from random postures; the end posture of the first such success
   founds a new expert (at most ``new_experts_per_epoch``, up to ``max_experts``); the other
   successes of this step join the expert whose representative posture is nearest (joint space).

Every accepted motion is stored in the training set of the expert it started from (all motions
are kept), then every expert trains on its own set for ``train_steps`` steps of backpropagation,
and every ``reassign_every`` epochs each stored point moves to the expert that fits it best.

The paper processed one target per epoch in MATLAB; processing a batch per epoch is what makes
training take minutes. Within an epoch the order of the steps is the paper's.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import Tensor

from graspnet_torch.fcnn.dataset import TrainingSet
from graspnet_torch.fcnn.experts import ExpertSet, ExpertSetCfg
from graspnet_torch.fcnn.reach import ReachCfg, ReachResult, reach_motion
from graspnet_torch.robot.chain import ChainSpec
from graspnet_torch.robot.fingers import FingerChain, FingerKernel
from graspnet_torch.settings import build, setting

__all__ = ["FCNNTrainCfg", "FingerTrainer", "sample_reachable"]


@dataclass(frozen=True)
class FCNNTrainCfg:
    """Training settings (Hydra group ``fcnn/``); defaults are the paper's where it gives them.

    Attributes:
        experts: network sizes (paper: 35 hidden units; 4-6 experts emerged).
        reach: reaching-motion thresholds r_st, r_e (not given in the paper; see ReachCfg).
        epochs: epochs per finger.
        targets_per_epoch: targets processed together in one epoch (the paper: 1).
        train_steps: backpropagation steps per epoch ("a predefined number of steps").
        batch_size: points per expert per step.
        lr: learning rate; optimizer: 'adam' (default, for speed) or 'sgd' (plain backprop).
        reassign_every: epochs between reassignments of points (paper: 5).
        random_restarts: random postures tried per unsolved target in step 4 (per round).
        random_rounds: rounds of step 4 before a target is given up for this epoch.
        new_experts_per_epoch: experts step 4 may found in one epoch.
        val_targets: held-out targets for validation; val_every: epochs between validations.
    """

    experts: ExpertSetCfg = setting(factory=ExpertSetCfg)
    reach: ReachCfg = setting(factory=ReachCfg)
    epochs: int = setting(300, lo=1, hi=10_000_000)
    targets_per_epoch: int = setting(256, lo=1, hi=100_000)
    train_steps: int = setting(40, lo=0, hi=1_000_000)
    batch_size: int = setting(256, lo=1, hi=100_000)
    lr: float = setting(3e-3, lo=0.0, hi=10.0)
    optimizer: str = setting("adam", choices=("adam", "sgd"))
    reassign_every: int = setting(5, lo=1, hi=1_000_000)
    random_restarts: int = setting(8, lo=0, hi=1000)
    random_rounds: int = setting(3, lo=0, hi=1000)
    new_experts_per_epoch: int = setting(1, lo=0, hi=1000)
    val_targets: int = setting(10_000, lo=1, hi=1_000_000)
    val_every: int = setting(20, lo=1, hi=10_000_000)

    @classmethod
    def from_mapping(cls, d: dict | None, where: str = "fcnn") -> FCNNTrainCfg:
        """Checked against the ranges above (:func:`graspnet_torch.settings.build`)."""
        return build(cls, d, where)


def sample_reachable(kernel: FingerKernel, lower: Tensor, upper: Tensor, n: int,
                     generator: torch.Generator) -> tuple[Tensor, Tensor]:
    """n fingertip targets from joint angles uniform within limits: (q (n, j), x (n, 3))."""
    q = lower + (upper - lower) * torch.rand(n, lower.shape[0], generator=generator, dtype=lower.dtype)
    return q, kernel.position(q)


class FingerTrainer:
    """Learns one finger's expert set. ``epoch()`` runs one epoch and returns its statistics."""

    def __init__(self, chain: FingerChain | ChainSpec, cfg: FCNNTrainCfg = FCNNTrainCfg(), seed: int = 0,
                 name: str | None = None):
        chain = chain if isinstance(chain, FingerChain) else FingerChain.from_spec(chain)
        self.cfg = cfg
        self.name = name or chain.tip
        self.chain = chain
        self.kernel = FingerKernel(chain)  # over the free joints (mimic joints follow)
        self.lower = torch.tensor(chain.lower, dtype=torch.float32)
        self.upper = torch.tensor(chain.upper, dtype=torch.float32)
        self.generator = torch.Generator().manual_seed(seed)
        _, ws = sample_reachable(self.kernel, self.lower, self.upper, 20_000, torch.Generator().manual_seed(seed + 1))
        self.experts = ExpertSet(chain.n_joints, ws.mean(0), ws.std(0).clamp(min=1e-3), self.lower, self.upper,
                                 cfg.experts)
        first = torch.clamp(torch.zeros(chain.n_joints), self.lower, self.upper)  # paper: [0, 0, 0, 0]
        self.experts.add_expert(first, self.generator)
        self.data = TrainingSet(chain.n_joints)
        if cfg.optimizer == "adam":
            self.optimizer = torch.optim.Adam(self.experts.parameters(), lr=cfg.lr)
        elif cfg.optimizer == "sgd":
            self.optimizer = torch.optim.SGD(self.experts.parameters(), lr=cfg.lr)
        else:
            raise ValueError(f"fcnn.optimizer must be 'adam' or 'sgd', got '{cfg.optimizer}'")
        self.epochs_done = 0
        self.val_q, self.val_x = sample_reachable(self.kernel, self.lower, self.upper, cfg.val_targets,
                                                  torch.Generator().manual_seed(10_000 + seed))

    # ------------------------------------------------------------------ competition
    @torch.no_grad()
    def compete(self, x: Tensor) -> tuple[Tensor, Tensor, Tensor]:
        """All experts' clamped outputs, their fingertip errors and the winner per target.

        x: (B, 3) -> outputs (E, B, n), errors (E, B), winner (B,).
        """
        out = torch.clamp(self.experts(x), self.lower, self.upper)
        err = torch.linalg.vector_norm(self.kernel.position(out) - x, dim=-1)
        return out, err, torch.argmin(err, dim=0)

    def _reach(self, q0: Tensor, x: Tensor) -> ReachResult:
        return reach_motion(self.kernel.position_jacobian, q0, x, self.lower, self.upper, self.cfg.reach)

    def _store(self, res: ReachResult, owners: Tensor) -> int:
        target_idx, postures = res.stored_points()
        if postures.shape[0]:
            self.data.add(self.kernel.position(postures), postures, owners[target_idx])
        return int(postures.shape[0])

    # ------------------------------------------------------------------ one epoch
    @torch.no_grad()
    def collect(self, x: Tensor, stats: dict) -> None:
        """Learn from targets x (N, 3): each reached by the best expert, the next ones, a reaching
        motion, or a random start that founds a new expert (steps 1-4); counts go into ``stats``."""
        N = x.shape[0]
        E = self.experts.n_active
        out, err, _ = self.compete(x)
        order = torch.argsort(err, dim=0)  # (E, N) experts by predicted error
        pending = torch.ones(N, dtype=torch.bool)
        stats["start_error_mm"] = float(err.min(0).values.median()) * 1000
        # steps 1-2: the best expert's output, then the next ones
        for rank in range(E):
            idx = torch.nonzero(pending).squeeze(1)
            if idx.numel() == 0:
                break
            e = order[rank, idx]
            res = self._reach(out[e, idx], x[idx])
            stats["points"] += self._store(res, e)
            stats["step1" if rank == 0 else "step2"] += int(res.success.sum())
            stats["motions"] += int((res.success & (res.steps > 1)).sum())
            pending[idx[res.success]] = False
        # step 3: representative postures of the experts, in random order
        idx = torch.nonzero(pending).squeeze(1)
        if idx.numel():
            perm = torch.argsort(torch.rand(idx.numel(), E, generator=self.generator), dim=1)
            for a in range(E):
                alive = pending[idx]
                if not bool(alive.any()):
                    break
                sub, e = idx[alive], perm[alive, a]
                res = self._reach(self.experts.rep_postures[e], x[sub])
                stats["points"] += self._store(res, e)
                stats["step3"] += int(res.success.sum())
                pending[sub[res.success]] = False
        # step 4: random postures; the first success founds a new expert
        idx = torch.nonzero(pending).squeeze(1)
        if idx.numel():
            self._random_starts(x, idx, pending, stats)
        stats["unsolved"] += int(pending.sum())

    def _random_starts(self, x: Tensor, idx: Tensor, pending: Tensor, stats: dict) -> None:
        n = self.chain.n_joints
        R = self.cfg.random_restarts
        created = 0
        for _ in range(self.cfg.random_rounds):
            sub = idx[pending[idx]]
            if sub.numel() == 0:
                return
            starts = self.lower + (self.upper - self.lower) * torch.rand(sub.numel(), R, n, generator=self.generator)
            res = self._reach(starts.reshape(-1, n), x[sub].repeat_interleave(R, 0))
            ok = res.success.reshape(-1, R)
            solved = ok.any(1)
            if not bool(solved.any()):
                continue
            first = torch.argmax(ok.to(torch.uint8), dim=1)  # first successful restart per target
            pick = torch.arange(sub.numel()) * R + first
            keep = torch.zeros_like(res.success)
            keep[pick[solved]] = True
            res.success = keep
            finals = res.q  # (sub*R, n)
            owners = torch.full((res.q.shape[0],), -1, dtype=torch.long)
            # found new experts from the first successes
            for row in pick[solved].tolist():
                if created >= self.cfg.new_experts_per_epoch or self.experts.full:
                    break
                owners[row] = self.experts.add_expert(finals[row], self.generator)
                created += 1
                stats["new_experts"] += 1
            # the others join the expert whose representative posture is nearest
            rest = pick[solved][owners[pick[solved]] < 0]
            if rest.numel():
                reps = self.experts.normalize_q(self.experts.rep_postures[: self.experts.n_active])
                d = torch.cdist(self.experts.normalize_q(finals[rest]), reps)
                owners[rest] = torch.argmin(d, dim=1)
            stats["points"] += self._store(res, owners.clamp(min=0))
            stats["step4"] += int(solved.sum())
            pending[sub[solved]] = False

    def _train(self, stats: dict) -> None:
        E = self.experts.n_active
        losses = torch.zeros(E)
        for _ in range(self.cfg.train_steps):
            x, q, has = self.data.sample(E, self.cfg.batch_size, self.generator)
            if not bool(has.any()):
                return
            pred = self.experts.forward_each(x)
            per_expert = (pred - self.experts.normalize_q(q)).square().mean(dim=(1, 2))
            loss = (per_expert * has).sum() / has.sum()
            self.optimizer.zero_grad(set_to_none=True)
            loss.backward()
            self.optimizer.step()
            losses += per_expert.detach() * has
        stats["loss"] = (losses / self.cfg.train_steps).tolist()

    def epoch(self) -> dict:
        """One epoch; returns statistics (counts per step, losses per expert, ...)."""
        stats = {k: 0 for k in ("points", "motions", "step1", "step2", "step3", "step4", "unsolved", "new_experts")}
        _, x = sample_reachable(self.kernel, self.lower, self.upper, self.cfg.targets_per_epoch, self.generator)
        self.collect(x, stats)
        self._train(stats)
        self.epochs_done += 1
        stats["moved"] = 0
        if self.epochs_done % self.cfg.reassign_every == 0:
            stats["moved"] = self.data.reassign(self.experts)
        stats["experts"] = self.experts.n_active
        stats["points_per_expert"] = self.data.counts(self.experts.n_active).tolist()
        return stats

    @torch.no_grad()
    def validate(self) -> dict[str, float]:
        """Competition error on the held-out targets (no refinement), millimetres."""
        _, err, win = self.compete(self.val_x)
        best = err.gather(0, win.unsqueeze(0)).squeeze(0) * 1000
        return {"median_mm": float(best.median()), "p95_mm": float(torch.quantile(best, 0.95)),
                "max_mm": float(best.max())}

    # ------------------------------------------------------------------ resume
    def state_dict(self) -> dict:
        return {"experts": self.experts.state_dict(), "optimizer": self.optimizer.state_dict(),
                "data": self.data.state_dict(), "generator": self.generator.get_state(),
                "epochs_done": self.epochs_done}

    def load_state_dict(self, state: dict) -> None:
        self.experts.load_state_dict(state["experts"])
        self.optimizer.load_state_dict(state["optimizer"])
        self.data.load_state_dict(state["data"])
        self.generator.set_state(state["generator"])
        self.epochs_done = int(state["epochs_done"])
