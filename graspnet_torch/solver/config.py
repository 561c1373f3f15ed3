"""Typed settings of the closed loop (Hydra groups ``solver/``, ``reward/``, ``noise/``)."""

from __future__ import annotations

from dataclasses import dataclass

from graspnet_torch.settings import build, setting

__all__ = ["PAPER_PROTOCOL", "SOLVERS", "NoiseCfg", "RewardCfg", "SolverCfg"]


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


SOLVERS = ("srv", "cmaes", "dls")

# The paper's protocol (section 2.4, Tables 2-4): every trial runs to its own stop and only the
# fingers are refined after the loop (the palm pose is what the network chose).
PAPER_PROTOCOL = {"stop": None, "polish": "fingers", "polish_from": None, "stop_rule": "reinforcement"}


@dataclass(frozen=True)
class SolverCfg:
    """The solver of a problem (Hydra group ``solver/``: ``srv``, ``cmaes``, ``dls``, ``paper``).

    ``method`` picks the search; everything else (the problem, the result JSON, its float64
    verification, pictures, TensorBoard) is the same for all three:

    - 'srv': the closed loop of section 2.4 (the paper's system, the default), then a polish of
      the whole configuration and batch-level stopping (both beyond the paper; ``solver=paper``
      turns them off);
    - 'cmaes': CMA-ES (the ``cmaes`` package) over the same configuration, seeing the same
      (possibly noisy) reinforcement as a black box; one independent CMA-ES per trial, one
      evaluation = one iteration;
    - 'dls': damped least squares (Levenberg-Marquardt) over the whole configuration (palm pose or
      body joints together with the contact fingers' free joints) from ``trials`` random
      restarts; it minimises the model's error directly, so it never sees the reinforcement
      (refused with sensor noise); one step = one iteration.

    Attributes:
        method: 'srv', 'cmaes' or 'dls'.
        max_iterations: iteration budget per trial (srv: loop iterations; cmaes: evaluations;
            dls: Levenberg-Marquardt steps).
        threshold: with ``stop_rule: reinforcement`` (the paper), a trial stops once its observed
            reinforcement exceeds this (paper: 0.99, i.e. E < 10 mm at a = 1); ``None`` or > 1 (at
            most 2) never stops early, whatever the rule (fixed-length runs such as the noise study).
        tolerance_mm: a contact finger within this of its contact (a gripper: d of eq. 26) is on
            it. A result's ``success`` means the grasp: every contact finger within it and, where
            the problem has an object or obstacles, no collision (FCL).
        stop_rule: 'grasp' (default): a trial stops once its configuration is a grasp in the
            model (every contact finger within ``tolerance_mm``, a gripper aligned to
            ``gripper.ALIGNMENT_MIN``, and clear where the collision proxy counts collisions);
            'reinforcement': once its observed reinforcement exceeds ``threshold`` (the paper's
            rule, ``solver=paper``). With sensor noise the model's error is not observed, so the
            reinforcement rule applies (the noise presets run their whole budget). CMA-ES stops on
            the reinforcement rule either way (it has no in-loop polish).
        refine: steps inside the loop, per evaluation: FCNN refinement iterations (eq. 5) for a
            hand (0: the paper's FCNN, competition among experts only); for a gripper (MANUS),
            damped least-squares steps that settle each proposal before it is evaluated.
        final_refine: refinement iterations applied after the loop to the reported configuration's
            fingers (the palm pose is kept); the reported errors are those of the refined joints.
            Not used with ``polish: whole``, which moves the fingers too.
        polish: 'whole' (default) polishes the palm pose (or arm joints) together with the
            contact fingers' free joints after the loop (and inside it, ``polish_from``):
            ``polish_iterations`` Levenberg-Marquardt steps in float64 within bounds and limits,
            never worse, never into a collision the proxy sees; 'fingers' refines only the
            fingers (``final_refine``; the paper: the palm pose is what the network chose). A
            gripper (MANUS) always polishes its whole configuration (``final_refine``).
        polish_tolerance_mm: a polished (or ``dls``) trial stops once its error (E of eq. 3, or
            d of eq. 26) is below this.
        polish_from: with ``polish: whole``, no sensor noise and a threshold, a trial whose
            observed reinforcement first exceeds this (and each time it betters it) has its best
            configuration polished inside the loop; where the polish lands above the threshold,
            the trial has succeeded, else it learns on (``None``: the polish only after the loop).
            0.9 with a = 1: E < 100 mm, measured on random reachable hand problems (README, "Which
            solver?"): as sure as 0.95 and 0.99, and faster.
        candidates: FCNN experts whose answers are refined (1 = the paper's winner only).
        approach_m, approach_deg: a gripper problem with an ``approach`` configuration searches
            within +- these of it (prismatic joints in metres, revolute joints in degrees),
            clipped to the joint limits (section 7 automates the last phase only).
        time_budget: wall-clock seconds after which the loop stops (``None``: no limit).
        stop: a problem ends once this many of its trials have succeeded (srv, cmaes: r > threshold;
            dls: within the tolerance), the others reported as they stand (default 1: "give me a
            grasp", the trials are restarts of one search; ``None``: every trial runs to its own
            stop, the paper's independent runs).
        population: CMA-ES population per trial (``None``: the ``cmaes`` default, 4 + 3 ln n).
        step_size: CMA-ES initial step size, in units of the normalised bounds [0, 1].
        stop_clear: a trial stops only at a configuration the collision proxy finds clear (the
            paper stops on the reinforcement alone, so an early colliding configuration, weakly
            shaped by R3/R4 while i << p, can end a trial; the MANUS defaults to true: a grasp
            through the table is not a success). ``None``: true exactly when ``stop`` is set (a
            problem that ends at its first success ends at a clear one; measured on env1/env2: the
            best trial collision-free for 12/12 seeds against 7/12 without), false for the
            paper's protocol.
        report: 'best' (the configuration with the highest observed reinforcement; without
            noise, the smallest error) or 'final' (the last one).
        history: record per-iteration curves (reinforcement, expected reinforcement, sigma,
            errors, time) for logs and plots.
        dtype: 'float32' (hot path) or 'float64'.
    """

    method: str = setting("srv", choices=SOLVERS)
    max_iterations: int = setting(2000, lo=1, hi=10_000_000)
    threshold: float | None = setting(0.99, lo=-1.0, hi=2.0)
    tolerance_mm: float = setting(1.0, lo=0.0, lo_open=True, hi=1000.0)
    stop_rule: str = setting("grasp", choices=("grasp", "reinforcement"))
    time_budget: float | None = setting(None, lo=0.0, lo_open=True, hi=1e7)
    stop: int | None = setting(1, lo=1, hi=1_000_000)
    approach_m: float = setting(0.2, lo=0.0, lo_open=True, hi=10.0)
    approach_deg: float = setting(30.0, lo=0.0, lo_open=True, hi=360.0)
    refine: int = setting(0, lo=0, hi=1000)
    final_refine: int = setting(3, lo=0, hi=1000)
    polish: str = setting("whole", choices=("fingers", "whole"))
    polish_iterations: int = setting(30, lo=0, hi=10_000)
    polish_tolerance_mm: float = setting(0.001, lo=0.0, hi=1000.0)
    polish_from: float | None = setting(0.9, lo=-1.0, hi=1.0)
    candidates: int = setting(1, lo=1, hi=64)
    stop_clear: bool | None = None
    report: str = setting("best", choices=("best", "final"))
    history: bool = True
    dtype: str = setting("float32", choices=("float32", "float64"))
    population: int | None = setting(None, lo=2, hi=100_000)
    step_size: float = setting(0.25, lo=0.0, lo_open=True, hi=10.0)

    @classmethod
    def from_mapping(cls, d: dict | None, where: str = "solver") -> SolverCfg:
        return build(cls, d, where)

    @classmethod
    def paper(cls, **changes) -> SolverCfg:
        """The paper's protocol (every trial to its own stop, the fingers refined, the palm pose
        kept), with ``changes``: what the reproductions of its tables use."""
        return cls(**{**PAPER_PROTOCOL, **changes})

    @property
    def stops_clear(self) -> bool:
        """Whether a trial stops only where the collision proxy finds it clear: ``stop_clear``, or
        by default exactly when a problem ends at its first successes (``stop`` set)."""
        return self.stop_clear if self.stop_clear is not None else self.stop is not None

    @property
    def stop_threshold(self) -> float | None:
        """The threshold a trial stops at, or ``None`` when runs use their whole budget."""
        return self.threshold if self.threshold is not None and self.threshold <= 1 else None
