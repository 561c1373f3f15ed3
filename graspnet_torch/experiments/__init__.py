"""The paper's experiments, each a function of its settings that returns an :class:`ExperimentReport`.

===========  =============================================================  ======================
name         what (paper section)                                           settings
===========  =============================================================  ======================
table2       Table 2 and Fig. 4: the HCNN on three grasps (5.2)             :class:`Table2Cfg`
fig3         Fig. 3: learning with a noisy reinforcement (5.1)              :class:`NoiseStudyCfg`
table3       Tables 3-4, ANOVA + Bonferroni, Figs. 6, 8, 9 (6.3)            :class:`ObstaclesCfg`
fig10        Fig. 10: the arm among three obstacles (6.3)                   :class:`Fig10Cfg`
manus        the MANUS 64 x 30 protocol and Fig. 12 (7.2)                   :class:`ManusCfg`
solvers      every solver on the same problems (beyond the paper)           :class:`SolversCfg`
objects      moved tasks, meshes and real objects (beyond the paper)        :class:`ObjectsCfg`
arm          the arm as a product, random arm problems (beyond the paper)   :class:`ArmCfg`
random_hand  the HCNN on random reachable hand problems (beyond the paper)  :class:`RandomHandCfg`
tradeoff     the noise study against Table 2, open choices swept (5.1)      :class:`TradeoffCfg`
proxy        the collision proxy against FCL near meshes (beyond the paper) :class:`ProxyCfg`
proposal     posture proposals: what they cost and buy (beyond the paper)   :class:`ProposalExperimentCfg`
reach        reach motions to every arm and MANUS grasp (beyond the paper)  :class:`ReachExperimentCfg`
contact      pads on the surface beside the point model, in MuJoCo (beyond)  :class:`ContactCfg`
synthesis    grasps synthesized for objects, beside a baseline (beyond)     :class:`SynthesisExperimentCfg`
hands        synthesis on many public hands, everyday objects (beyond)      :class:`HandsCfg`
===========  =============================================================  ======================

Each is a Hydra experiment config, ``configs/experiment/<name>.yaml``::

    python scripts/reproduce.py +experiment=table3 experiments.table3.runs=10
    python scripts/reproduce.py                      # every experiment -> REPRODUCTION.md

and a plain function (``run_table2(Table2Cfg(trials=5), Path("out"))``).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from graspnet_torch.experiments.arm import ArmCfg, run_arm
from graspnet_torch.experiments.contact import ContactCfg, run_contact
from graspnet_torch.experiments.fig3 import NoiseStudyCfg, run_noise_study
from graspnet_torch.experiments.hands import HandsCfg, run_hands
from graspnet_torch.experiments.manus import ManusCfg, run_manus
from graspnet_torch.experiments.objects import ObjectsCfg, run_objects
from graspnet_torch.experiments.obstacles import Fig10Cfg, ObstaclesCfg, run_fig10, run_tables
from graspnet_torch.experiments.proposal import ProposalExperimentCfg, run_proposal
from graspnet_torch.experiments.proxy import ProxyCfg, run_proxy
from graspnet_torch.experiments.random_hand import RandomHandCfg, run_random_hand
from graspnet_torch.experiments.reach import ReachExperimentCfg, run_reach
from graspnet_torch.experiments.report import ExperimentReport, Figure
from graspnet_torch.experiments.solvers import SolversCfg, run_solvers
from graspnet_torch.experiments.synthesis import SynthesisExperimentCfg, run_synthesis
from graspnet_torch.experiments.table2 import Table2Cfg, run_table2
from graspnet_torch.experiments.tradeoff import TradeoffCfg, run_tradeoff
from graspnet_torch.settings import DefaultsFile

__all__ = ["DEFAULTS_FILES", "EXPERIMENTS", "ArmCfg", "ContactCfg", "Experiment", "ExperimentReport", "Fig10Cfg",
           "Figure", "HandsCfg", "ManusCfg", "NoiseStudyCfg", "ObjectsCfg", "ObstaclesCfg", "ProposalExperimentCfg",
           "ProxyCfg", "RandomHandCfg", "ReachExperimentCfg", "SolversCfg", "SynthesisExperimentCfg", "Table2Cfg",
           "TradeoffCfg", "run_arm", "run_contact", "run_fig10", "run_hands", "run_manus", "run_noise_study",
           "run_objects", "run_proposal", "run_proxy", "run_random_hand", "run_reach", "run_solvers",
           "run_synthesis", "run_table2", "run_tables", "run_tradeoff"]


@dataclass(frozen=True)
class Experiment:
    """One experiment: its settings class and the function that runs it into a folder."""

    name: str
    cfg: type
    run: Callable[[Any, Path], ExperimentReport]


_TABLE = (  # name, settings, run: in the order `make reproduce` runs them (the table above)
    ("table2", Table2Cfg, run_table2), ("fig3", NoiseStudyCfg, run_noise_study), ("table3", ObstaclesCfg, run_tables),
    ("fig10", Fig10Cfg, run_fig10), ("manus", ManusCfg, run_manus), ("solvers", SolversCfg, run_solvers),
    ("objects", ObjectsCfg, run_objects), ("arm", ArmCfg, run_arm), ("random_hand", RandomHandCfg, run_random_hand),
    ("tradeoff", TradeoffCfg, run_tradeoff), ("proxy", ProxyCfg, run_proxy),
    ("proposal", ProposalExperimentCfg, run_proposal), ("reach", ReachExperimentCfg, run_reach),
    ("contact", ContactCfg, run_contact), ("synthesis", SynthesisExperimentCfg, run_synthesis),
    ("hands", HandsCfg, run_hands))
EXPERIMENTS: dict[str, Experiment] = {name: Experiment(name, cfg, run) for name, cfg, run in _TABLE}

# configs/experiment/<name>.yaml lists its experiment's settings; their values are written from the
# dataclass's defaults (graspnet_torch.settings.DefaultsFile); `quick` is the reduced protocol on top.
DEFAULTS_FILES = tuple(DefaultsFile(f"experiment/{name}.yaml", e.cfg, under=("experiments", name), skip=("quick",))
                       for name, e in EXPERIMENTS.items())
