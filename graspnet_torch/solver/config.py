"""Typed settings of the closed loop (Hydra groups ``solver/``, ``reward/``, ``noise/``)."""

from __future__ import annotations

from dataclasses import dataclass, replace
from functools import cache

from graspnet_torch.paths import configs_dir
from graspnet_torch.rewards import NoiseCfg, RewardCfg  # the reward's own settings, re-exported
from graspnet_torch.settings import build, setting

__all__ = ["DEFAULT_TRIALS", "RENAMED", "SOLVERS", "CmaesCfg", "FingersCfg", "GripperCfg", "NoiseCfg", "PolishCfg",
           "RewardCfg", "SolverCfg", "paper_protocol"]


SOLVERS = ("srv", "cmaes", "dls")
DEFAULT_TRIALS = 20  # learners per problem, run as one batch: gt.solve, gt.solve_many, gt.Solver, the solve_grasp job


@dataclass(frozen=True)
class PolishCfg:
    """The local polish (``solver.polish``): Levenberg-Marquardt in float64 over the whole
    configuration (palm pose or arm joints with the contact fingers' free joints), within bounds
    and limits, never worse, never into a collision the collision proxy sees. Beyond the paper.

    Attributes:
        mode: 'whole' (default): after the loop (and inside it, ``from_r``) polish the whole
            configuration; 'fingers': refine only the fingers after the loop
            (``fingers.final_refine``; the paper: the palm pose is what the network chose).
        iterations: steps of the whole polish.
        tolerance_mm: a polished (or ``dls``) trial stops once its error (E of eq. 3, or d of
            eq. 26) is below this.
        from_r: with ``mode: whole``, no sensor noise and a threshold, a trial whose observed
            reinforcement first exceeds this (and each time it betters it) has its best
            configuration polished inside the loop; where the polish lands, the trial has
            succeeded, else it learns on (``None``: the polish only after the loop). 0.9 with a = 1:
            E < 100 mm, measured on random reachable hand problems (docs/solvers.md).
        from_r_free: ``from_r`` where the search counts no collision (nothing to collide with, or
            a reward that ignores collisions): -1 polishes every trial from the first iteration
            on (the learner proposes, the polish lands), which on random reachable problems is
            about 3x faster than 0.9 at the same success (docs/python.md, "Many calls, and
            sequences"). None: ``from_r``.
            Near an object a polish from far lands against it, within tolerance but less exact:
            there ``from_r`` applies. With ``from_r: null`` (the polish after the loop only) neither.
        min_gain: a polished (or ``dls``) trial whose kept step lowers its error by less than this
            fraction has settled in a local minimum and stops (0: it runs its ``iterations``).
        warm_step_deg: a warm start (``gt.Solver.solve(problem, start=...)``, each frame of a
            sequence) moves no contact finger's joint more than this from the start's (degrees; a
            prismatic joint: mm): the polish from the start stays on its branch, so a frame's
            joints do not jump from the previous frame's (where it does not land within this,
            the full search runs). None: within the joint limits only.
        centre: a frame of a sequence that the full search solved (the first, or one where the
            warm start did not land) is moved, its contacts held, toward the middle of its
            fingers' joint ranges (a prior of this weight per range, faded out in six steps of five
            iterations), so the frames after it start away from the limits, where a warm start
            gets stuck (docs/python.md, "Many calls, and sequences", measures both settings). None: not moved.
    """

    mode: str = setting("whole", choices=("fingers", "whole"))
    iterations: int = setting(30, lo=0, hi=10_000)
    tolerance_mm: float = setting(0.001, lo=0.0, hi=1000.0)
    from_r: float | None = setting(0.9, lo=-1.0, hi=1.0)
    from_r_free: float | None = setting(-1.0, lo=-1.0, hi=1.0)
    min_gain: float = setting(1e-3, lo=0.0, hi=1.0)
    warm_step_deg: float | None = setting(19.5, lo=0.0, lo_open=True, hi=360.0)
    centre: float | None = setting(0.3, lo=0.0, lo_open=True, hi=1000.0)


@dataclass(frozen=True)
class CmaesCfg:
    """CMA-ES (``solver.cmaes``, with ``solver.method: cmaes``).

    Attributes:
        population: per trial (``None``: the ``cmaes`` default, 4 + 3 ln n).
        step_size: initial step size, in units of the normalised bounds [0, 1].
    """

    population: int | None = setting(None, lo=2, hi=100_000)
    step_size: float = setting(0.25, lo=0.0, lo_open=True, hi=10.0)


@dataclass(frozen=True)
class FingersCfg:
    """The FCNN's part (``solver.fingers``): robots whose fingers it places (hand, arm_hand).

    Attributes:
        refine: FCNN refinement iterations (eq. 5) inside the loop, per evaluation (0: the paper's
            FCNN, competition among experts only).
        final_refine: refinement iterations applied after the loop to the reported configuration's
            fingers (the palm pose kept) with ``polish.mode: fingers``; the whole polish moves the
            fingers too.
        candidates: FCNN experts whose answers are refined (1 = the paper's winner only).
    """

    refine: int = setting(0, lo=0, hi=1000)
    final_refine: int = setting(3, lo=0, hi=1000)
    candidates: int = setting(1, lo=1, hi=64)


@dataclass(frozen=True)
class GripperCfg:
    """A gripper with two marked points (``solver.gripper``; the MANUS, paper section 7).

    Attributes:
        settle: damped least-squares steps that settle each proposal before it is evaluated (the
            learner proposes, a few local steps settle it, the settled configuration is reported).
        polish_iterations: Levenberg-Marquardt steps of the body's joints after the loop (every
            trial, both pairings of eq. 26-28).
        approach_m, approach_deg: a problem with an ``approach`` configuration searches within
            +- these of it (prismatic joints in metres, revolute joints in degrees), clipped to the
            joint limits (section 7 automates the last phase only).
    """

    settle: int = setting(2, lo=0, hi=1000)
    polish_iterations: int = setting(200, lo=0, hi=10_000)
    approach_m: float = setting(0.2, lo=0.0, lo_open=True, hi=10.0)
    approach_deg: float = setting(30.0, lo=0.0, lo_open=True, hi=360.0)


# Flat keys of earlier versions -> where they live now (a one-line hint when one is given).
RENAMED = {"polish_iterations": "polish.iterations", "polish_tolerance_mm": "polish.tolerance_mm",
           "polish_from": "polish.from_r", "population": "cmaes.population", "step_size": "cmaes.step_size",
           "refine": "fingers.refine (a gripper: gripper.settle)",
           "final_refine": "fingers.final_refine (a gripper: gripper.polish_iterations)",
           "candidates": "fingers.candidates", "approach_m": "gripper.approach_m",
           "approach_deg": "gripper.approach_deg"}


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

    The search's settings are the top-level keys; the polish, CMA-ES and each kind of robot's
    environment have their own group (:class:`PolishCfg`, :class:`CmaesCfg`, :class:`FingersCfg`,
    :class:`GripperCfg`). Every default is defined here only: ``configs/solver/srv.yaml`` lists the
    same values, written from this class (``make sync-defaults``; ``tests/test_defaults_files.py``
    fails where they differ), and a robot config's ``solver_defaults`` may override them for that
    robot. ``trials`` is not a solver setting: its default is :data:`DEFAULT_TRIALS`.

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
        contact_model: how a contact finger touches its contact: 'surface' (its pad, a point and
            an outward normal on its distal link (:mod:`graspnet_torch.robot.pads`), on the
            contact, the pad facing into the object within ``normal_cone_deg``, no link deeper
            than ``penetration_mm`` in the object), 'point' (the paper's model: the finger's tip
            frame on the contact; ``solver=paper`` and the reproduction's experiments), or 'auto'
            (the default: 'surface' where the problem has an object and its contact fingers have
            pads, else 'point': without a surface there is nothing to touch; a gripper has no
            pads). The search sees the pads' normals (:mod:`graspnet_torch.solver.pad_term`) and
            the whole polish how deep each link reaches (docs/contact.md).
        penetration_mm: in the surface model, how deep a link of the robot (the contact
            fingers' distal links included) may lie inside the object.
        normal_cone_deg: in the surface model, the largest angle between a contact finger's pad
            normal and the object's inward normal at its contact.
        pregrasp_mm, squeeze_mm: in the surface model, the result's pre-grasp backs each contact
            finger's pad off its contact by ``pregrasp_mm`` along the object's normal, its
            squeeze presses it ``squeeze_mm`` further in (the fingers only; the palm and arm stay).
        stop_rule: 'grasp' (default): a trial stops once its configuration is a grasp in the
            model (every contact finger within ``tolerance_mm``, a gripper aligned, and clear
            where the collision proxy counts collisions); 'reinforcement': once its observed
            reinforcement exceeds ``threshold`` (the paper's rule, ``solver=paper``). With sensor
            noise the model's error is not observed, so the reinforcement rule applies (the noise
            presets run their whole budget). CMA-ES stops on the reinforcement rule either way.
        time_budget: wall-clock seconds after which the loop stops (``None``: no limit).
        stop: a problem ends once this many of its trials have succeeded (srv, cmaes: r > threshold;
            dls: within the tolerance), the others reported as they stand (default 1: "give me a
            grasp", the trials are restarts of one search; ``None``: every trial runs to its own
            stop, the paper's independent runs).
        stop_clear: a trial stops only at a configuration the collision proxy finds clear (the
            paper stops on the reinforcement alone, so an early colliding configuration, weakly
            shaped by R3/R4 while i << p, can end a trial; the MANUS's config sets true: a grasp
            through the table is not a success). ``None``: true exactly when ``stop`` is set
            (measured on env1/env2: the best trial collision-free for 12/12 seeds against 7/12
            without), false for the paper's protocol.
        restart_every: with a threshold, every this many iterations the trials still searching
            restart: new network weights and a new random start, their best so far kept (a learner
            stuck in a local minimum rarely leaves it; a fresh one often lands in tens of
            iterations). ``None``: never (the paper).
        report: 'best' (the configuration with the highest observed reinforcement; without
            noise, the smallest error) or 'final' (the last one).
        start: where the trials start: 'random' (uniform within the bounds, the paper),
            'proposal' (the robot's posture proposal model, :mod:`graspnet_torch.proposal`: each
            problem's K proposals ranked (by the model's score where nothing can collide, else by
            the environment's error, a collision as 1 m; with sensor noise by one noisy
            observation each), trial j at the j-th best, evaluated as the first iteration, the
            SRV network's mean output and expected reinforcement placed there (a colliding one:
            no expected reinforcement, or with ``stop: null`` a random start instead); a robot
            without a trained model starts at random, said once) or 'auto' (the default:
            'proposal' where the problem has no object and no obstacles, else 'random': a
            proposal does not see them, and near them its grasps pass through them or land less
            exactly; the arm's config sets 'proposal'). srv only.
        history: record per-iteration curves (reinforcement, expected reinforcement, sigma,
            errors, time) for logs and plots.
        history_postures: with ``history``, also every iteration's configurations and finger
            joints (the SRV loop): ``solve_grasp.py`` then writes ``replay.json``, which
            ``scripts/view.py`` replays over the iterations.
        dtype: 'float32' (hot path) or 'float64'.
        polish, cmaes, fingers, gripper: the groups above.
    """

    method: str = setting("srv", choices=SOLVERS)
    max_iterations: int = setting(2000, lo=1, hi=10_000_000)
    threshold: float | None = setting(0.99, lo=-1.0, hi=2.0)
    tolerance_mm: float = setting(1.0, lo=0.0, lo_open=True, hi=1000.0)
    contact_model: str = setting("auto", choices=("auto", "surface", "point"))
    penetration_mm: float = setting(1.0, lo=0.0, hi=100.0)
    normal_cone_deg: float = setting(30.0, lo=0.0, hi=90.0)
    pregrasp_mm: float = setting(10.0, lo=0.0, hi=200.0)
    squeeze_mm: float = setting(5.0, lo=0.0, hi=50.0)
    stop_rule: str = setting("grasp", choices=("grasp", "reinforcement"))
    time_budget: float | None = setting(None, lo=0.0, lo_open=True, hi=1e7)
    stop: int | None = setting(1, lo=1, hi=1_000_000)
    stop_clear: bool | None = None
    restart_every: int | None = setting(None, lo=1, hi=10_000_000)
    report: str = setting("best", choices=("best", "final"))
    start: str = setting("auto", choices=("auto", "random", "proposal"))
    history: bool = True
    history_postures: bool = False
    dtype: str = setting("float32", choices=("float32", "float64"))
    polish: PolishCfg = PolishCfg()
    cmaes: CmaesCfg = CmaesCfg()
    fingers: FingersCfg = FingersCfg()
    gripper: GripperCfg = GripperCfg()

    @classmethod
    def from_mapping(cls, d: dict | None, where: str = "solver") -> SolverCfg:
        return build(cls, d, where)

    @classmethod
    def paper(cls, **changes) -> SolverCfg:
        """The paper's protocol (``configs/solver/paper.yaml``: every trial to its own stop, the
        fingers refined, the palm pose kept), with ``changes`` (top-level keys, or whole groups):
        what the reproductions of its tables use."""
        return replace(build(cls, paper_protocol(), "solver=paper"), **changes)

    @property
    def stops_clear(self) -> bool:
        """Whether a trial stops only where the collision proxy finds it clear: ``stop_clear``, or
        by default exactly when a problem ends at its first successes (``stop`` set)."""
        return self.stop_clear if self.stop_clear is not None else self.stop is not None

    @property
    def stop_threshold(self) -> float | None:
        """The threshold a trial stops at, or ``None`` when runs use their whole budget."""
        return self.threshold if self.threshold is not None and self.threshold <= 1 else None


@cache
def _paper_yaml() -> str:
    return (configs_dir() / "solver" / "paper.yaml").read_text(encoding="utf-8")


def paper_protocol() -> dict:
    """The paper's protocol as ``configs/solver/paper.yaml`` states it over ``srv`` (its one
    definition): {key: value}, groups as mappings."""
    import yaml

    data = yaml.safe_load(_paper_yaml())
    return {k: v for k, v in data.items() if k != "defaults"}
