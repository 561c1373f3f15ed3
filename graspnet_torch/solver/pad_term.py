"""The pads' normals in the search (the surface contact model): how far each contact finger's pad
faces away from the object, as an error the search sees and a residual the whole polish lands.

A contact finger's pad normal in the world is ``m = R_palm B_R R_f(q) n`` (R_palm: the palm frame,
B_R: the finger's base in the palm, R_f(q): its chain's tip frame at the finger's joints (mimic
joints through their coupling), n: the pad normal in the tip frame, :mod:`graspnet_torch.robot.pads`).
It faces into the object where ``miss = m + o`` vanishes (o: the object's outward normal at the
contact); ``|miss| = 2 sin(theta / 2)`` for theta the angle between m and the inward normal. The
term is a hinge on that chord:

    penalty = w max(0, |miss| - c)                (metres, added to the finger's tip error)
    residual = penalty miss / |miss|              (3 rows per finger, goal 0; |residual| = penalty)

with c = 2 sin(theta_0 / 2), theta_0 = :data:`PAD_MARGIN` of ``solver.normal_cone_deg``: inside
it the pad is free, and the search aims a little inside the cone. The grasp test (the loop's stop,
a polish's landing: :meth:`PadTerm.contact_errors`) reads the cone itself: each pad within the
tolerance of its contact and within the cone. (At 0.9 of the cone, the pads' hinge and the tips
pulled against each other on glass4, whose pads come no nearer than 28 degrees: its tips ended
about 1 mm off, no trial landed and every problem ran the whole budget.) :data:`PAD_WEIGHT`
makes a pad turned 90 degrees away weigh as much as a tip some 50 mm off its target.

What the shipped hand can reach: its thumb has no axial rotation, so the side its flexion closes
towards (+y of its tip frame) faces across the palm, not the fingers; its pad is given in the
robot config on the distal sphere's side that faces them (-z; :mod:`graspnet_torch.robot.pads`).
With the closing side as the pad, no posture put the thumb's pad within 39, 56, 84 and 67 degrees
of the inward normal on glass3, glass4, videotape5 and block5 with no link deeper than 1 mm
(1,000 least-squares starts each); with the given pad, postures within 30 degrees and 1 mm exist
on glass3, videotape5 and block5 (worst pad 19, 23, 14 degrees), and glass4 came no nearer than
about 32 degrees (its index and ring pads, side by side on the glass).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import torch
from torch import Tensor

from graspnet_torch.collision.surface import surface_normals
from graspnet_torch.robot.robot import Robot
from graspnet_torch.solver.contact import ContactRule
from graspnet_torch.tasks.problem import GraspProblem

__all__ = ["PAD_MARGIN", "PAD_WEIGHT", "PadTerm", "skew"]

PAD_WEIGHT = 0.05  # metres per unit of |miss| beyond the margin
PAD_MARGIN = 0.97  # the hinge starts at this share of the cone


def skew(v: Tensor) -> Tensor:
    """(..., 3) -> (..., 3, 3) the cross-product matrix [v]_x."""
    x, y, z = v.unbind(-1)
    o = torch.zeros_like(x)
    return torch.stack([o, -z, y, z, o, -x, -y, x, o], -1).reshape(*v.shape, 3)


class PadTerm:
    """The pad-normal term of an environment's contact fingers (module docstring).

    Args:
        robot: the robot (its fingers' chains and pads).
        problems: the environment's problems, in its frame (one, or a batch's); a problem whose
            rule is not the surface model's gets weight 0 (its fingers are free to face anywhere).
        rules: each problem's contact rule.
        fingers: the environment's contact fingers (columns F).
        runs: trials per problem (a batch: trial t on problem t // runs).
        width: the finger joint slots j (padding slots: zero columns).

    Attributes:
        outward: (F, 3), or (T, F, 3) for a batch: the object's outward normal at each contact.
        weight: (F,) or (T, F): :data:`PAD_WEIGHT` where the finger has a surface contact, else 0.
        margin: c, the chord of the margin's angle.
        cone: the chord of the cone's angle (the grasp test's: :meth:`contact_errors`).
    """

    def __init__(self, robot: Robot, problems: Sequence[GraspProblem], rules: Sequence[ContactRule],
                 fingers: Sequence[str], runs: int, width: int):
        column = {f: k for k, f in enumerate(fingers)}
        outward = np.zeros((len(problems), len(fingers), 3))
        weight = np.zeros((len(problems), len(fingers)))
        for i, (p, rule) in enumerate(zip(problems, rules, strict=True)):
            if rule.surface:
                normals = surface_normals(p.object, np.asarray(p.contacts_world(), dtype=np.float64).reshape(-1, 3))
                for f, n in zip(p.fingers, normals, strict=True):
                    outward[i, column[f]], weight[i, column[f]] = n, PAD_WEIGHT
        if len(problems) > 1:
            outward, weight = np.repeat(outward, runs, axis=0), np.repeat(weight, runs, axis=0)
        else:
            outward, weight = outward[0], weight[0]
        self.outward64 = torch.as_tensor(outward, dtype=torch.float64)
        self.weight64 = torch.as_tensor(weight, dtype=torch.float64)
        cone = max(r.cone_deg for r in rules if r.surface)
        self.margin = 2 * math.sin(math.radians(cone * PAD_MARGIN) / 2)
        self.cone = 2 * math.sin(math.radians(cone) / 2)  # the chord of the cone itself
        self.batch = len(problems) > 1
        pads = robot.pads
        self.normals64 = torch.as_tensor(np.stack([pads[f].normal for f in fingers]), dtype=torch.float64)  # (F, 3)
        chains = [robot.fingers[f].chain for f in fingers]
        by_types: dict[tuple[str, ...], list[int]] = {}
        for k, c in enumerate(chains):
            by_types.setdefault(c.spec.joint_types, []).append(k)
        self.groups = []  # (fingers' columns, stacked kernel, A (K, n_all, j), c (K, n_all))
        for idx in by_types.values():
            A = np.zeros((len(idx), chains[idx[0]].spec.n_joints, width))
            for g, k in enumerate(idx):
                A[g, :, : chains[k].n_joints] = chains[k].coupling
            c = np.stack([chains[k].coupling_offset for k in idx])
            kernel = robot.finger_kernel.chain_kernel([robot.finger_index(fingers[k]) for k in idx])
            self.groups.append((idx, kernel, torch.as_tensor(A), torch.as_tensor(c)))
        self._cast: dict[tuple, tuple[Tensor, ...]] = {}

    def _consts(self, like: Tensor) -> tuple[Tensor, Tensor, Tensor, list[tuple[Tensor, Tensor]]]:
        """outward, weight, pad normals and the groups' couplings in the dtype/device of ``like``."""
        key = (like.dtype, like.device)
        if key not in self._cast:
            kw = {"dtype": like.dtype, "device": like.device}
            self._cast[key] = (self.outward64.to(**kw), self.weight64.to(**kw), self.normals64.to(**kw),
                               [(A.to(**kw), c.to(**kw)) for _, _, A, c in self.groups])
        return self._cast[key]

    def _rows(self, value: Tensor, rows: Tensor | None) -> Tensor:
        return value[rows.to(value.device)] if self.batch and rows is not None else value

    def local(self, q: Tensor, jacobian: bool = False) -> tuple[Tensor, Tensor | None]:
        """The pad normals in each finger's base frame at joints q (B, F, j): (B, F, 3) and, with
        ``jacobian``, d normal / d q (B, F, 3, j) (the chains' angular Jacobians: d(R n) = w x R n)."""
        _, _, normals, couplings = self._consts(q)
        B, F, j = q.shape
        n = q.new_empty(B, F, 3)
        J = q.new_zeros(B, F, 3, j) if jacobian else None
        for (idx, kernel, _, _), (A, c) in zip(self.groups, couplings, strict=True):
            cols = torch.as_tensor(idx, device=q.device)
            qa = torch.einsum("kaj,bkj->bka", A, q.index_select(1, cols)) + c
            if jacobian:
                R, _, J6 = kernel.pose_jacobian(qa)
            else:
                R, _ = kernel.pose(qa)
            m = (R @ normals[cols].unsqueeze(-1)).squeeze(-1)  # (B, K, 3)
            n[:, cols] = m
            if jacobian:
                J[:, cols] = -skew(m) @ J6[..., 3:, :] @ A  # w x m = -[m]_x w, free joints through A
        return n, J

    def penalty(self, world: Tensor, rows: Tensor | None = None) -> Tensor:
        """Pad normals in the world (B, F, 3) of the trials ``rows`` -> the penalty (B, F), metres."""
        outward, weight, _, _ = self._consts(world)
        miss = world + self._rows(outward, rows)
        return self._rows(weight, rows) * (miss.norm(dim=-1) - self.margin).clamp_min(0)

    def contact_errors(self, tip: Tensor, penalty: Tensor, rows: Tensor | None = None) -> Tensor:
        """The grasp test's errors (B, F) of the trials ``rows``: the tips' (pads') distances
        ``tip`` (B, F), infinite where the pad faces outside the cone, read from its ``penalty``
        (B, F) (:meth:`penalty`; the hinge exceeds w (cone - c) exactly there)."""
        _, weight, _, _ = self._consts(penalty)
        slack = self._rows(weight, rows) * (self.cone - self.margin)
        return torch.where(penalty <= slack * (1 + 1e-6), tip, torch.full_like(tip, float("inf")))

    def residual(self, world: Tensor, rows: Tensor | None = None, margin: float | None = None
                 ) -> tuple[Tensor, Tensor]:
        """Pad normals in the world (B, F, 3) -> the residual (B, F, 3) and its derivative with
        respect to the normals (B, F, 3, 3); ``margin``: the hinge's chord (None: :attr:`margin`)."""
        outward, weight, _, _ = self._consts(world)
        c = self.margin if margin is None else margin
        miss = world + self._rows(outward, rows)
        s = miss.norm(dim=-1, keepdim=True).clamp_min(1e-12)
        u = miss / s
        h = (s - c).clamp_min(0)
        w = self._rows(weight, rows).unsqueeze(-1)
        uu = u.unsqueeze(-1) * u.unsqueeze(-2)
        eye = torch.eye(3, dtype=world.dtype, device=world.device)
        D = (w * (s > c)).unsqueeze(-1) * uu + (w * h / s).unsqueeze(-1) * (eye - uu)
        return w * h * u, D
