"""Typed settings of the closed loop (Hydra groups ``solver/``, ``reward/``, ``noise/``)."""

from __future__ import annotations

from dataclasses import dataclass

from graspnet_torch.settings import build, setting

__all__ = ["NoiseCfg", "RewardCfg", "SolverCfg"]


@dataclass(frozen=True)
class RewardCfg:
    """Reinforcement (Hydra group ``reward/``): R_1 = 1 - tanh(a E) (eq. 14 / 20), E the total
    fingertip error in metres, and its collision-shaped forms (eq. 21-23).

    Attributes:
        kind: 'r1' (no collision term), 'r2' (R_1 / 2 on a collision), 'r3' (shaping:
            R_1 / (1 + i / p) on a collision) or 'r4' (R_1 / (1 + c^beta i / p), c collisions).
        a: slope of the evaluation (the paper gives a = 1.5 for the arm, none for the hand; with
            a = 1 the default threshold r > 0.99 means E < 10 mm).
        beta: exponent of the collision count in R_4 (paper: 0.25).
        p: the iteration count at which R_3 reaches R_2 (paper: 2000, its iteration budget);
            ``None``: the solver's ``max_iterations``.
    """

    kind: str = setting("r1", choices=("r1", "r2", "r3", "r4"))
    a: float = setting(1.0, lo=0.0, lo_open=True, hi=1e4)
    beta: float = setting(0.25, lo=0.0, lo_open=True, hi=100.0)
    p: int | None = setting(None, lo=1, hi=10_000_000)

    @classmethod
    def from_mapping(cls, d: dict | None, where: str = "reward") -> RewardCfg:
        return build(cls, d, where)


@dataclass(frozen=True)
class NoiseCfg:
    """Sensor noise on the reinforcement: r + N(0, sigma) (eq. 15)."""

    sigma: float = setting(0.0, lo=0.0, hi=100.0)

    @classmethod
    def from_mapping(cls, d: dict | None, where: str = "noise") -> NoiseCfg:
        return build(cls, d, where)


@dataclass(frozen=True)
class SolverCfg:
    """The closed loop of section 2.4.

    Attributes:
        max_iterations: iteration budget per trial.
        threshold: a trial stops once its (noise-free) reinforcement exceeds this (paper: 0.99);
            ``None`` or > 1 (at most 2) never stops early (fixed-length runs such as the noise study).
        refine: steps inside the loop, per evaluation: FCNN refinement iterations (eq. 5) for a
            hand (0: the paper's FCNN, competition among experts only); for a gripper (MANUS),
            damped least-squares steps that settle each proposal before it is evaluated.
        final_refine: refinement iterations applied after the loop to the reported configuration's
            fingers (the palm pose is kept); the reported errors are those of the refined joints.
        polish: after ``final_refine``, 'fingers' stops there (the paper: the palm pose is what the
            network chose); 'whole' also polishes the palm pose (or arm joints) together with the
            contact fingers' free joints, ``polish_iterations`` Levenberg-Marquardt steps in float64
            within bounds and limits, never worse, never into a collision the proxy sees.
        candidates: FCNN experts whose answers are refined (1 = the paper's winner only).
        approach_m, approach_deg: a gripper problem with an ``approach`` configuration searches
            within +- these of it (prismatic joints in metres, revolute joints in degrees),
            clipped to the joint limits (section 7 automates the last phase only).
        time_budget: wall-clock seconds after which the loop stops (``None``: no limit).
        enough: stop the whole batch once this many trials have succeeded, the others reported as
            they stand (``None``: every trial runs to its own stop, the paper's independent runs;
            a number: "give me a grasp", when the trials are restarts of one search).
        stop_clear: a trial stops only at a configuration the collision proxy finds clear (the
            paper stops on the reinforcement alone, so an early colliding configuration, weakly
            shaped by R3/R4 while i << p, can end a trial; the MANUS defaults to true: a grasp
            through the table is not a success).
        report: 'best' (the configuration with the highest observed reinforcement; without
            noise, the smallest error) or 'final' (the last one).
        history: record per-iteration curves (reinforcement, expected reinforcement, sigma,
            errors, time) for logs and plots.
        dtype: 'float32' (hot path) or 'float64'.
    """

    max_iterations: int = setting(2000, lo=1, hi=10_000_000)
    threshold: float | None = setting(0.99, lo=-1.0, hi=2.0)
    time_budget: float | None = setting(None, lo=0.0, lo_open=True, hi=1e7)
    enough: int | None = setting(None, lo=1, hi=1_000_000)
    approach_m: float = setting(0.2, lo=0.0, lo_open=True, hi=10.0)
    approach_deg: float = setting(30.0, lo=0.0, lo_open=True, hi=360.0)
    refine: int = setting(0, lo=0, hi=1000)
    final_refine: int = setting(3, lo=0, hi=1000)
    polish: str = setting("fingers", choices=("fingers", "whole"))
    polish_iterations: int = setting(30, lo=0, hi=10_000)
    candidates: int = setting(1, lo=1, hi=64)
    stop_clear: bool = False
    report: str = setting("best", choices=("best", "final"))
    history: bool = True
    dtype: str = setting("float32", choices=("float32", "float64"))

    @classmethod
    def from_mapping(cls, d: dict | None, where: str = "solver") -> SolverCfg:
        return build(cls, d, where)

    @property
    def stop_threshold(self) -> float | None:
        """The threshold a trial stops at, or ``None`` when runs use their whole budget."""
        return self.threshold if self.threshold is not None and self.threshold <= 1 else None
