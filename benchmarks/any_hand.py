"""Any hand by config, end to end: train its FCNN from scratch, solve random reachable problems,
check every result from the URDF alone.

    python benchmarks/any_hand.py [--robot PATH] [--threads 1] [--epochs N] [--problems 40] [--check]

1. Trains the FCNN of every finger of ``--robot`` (default: the Dexmate F5D6 right hand of
   examples/dexmate_f5d6/: a 3-joint thumb and four 2-joint fingers, one joint of each a <mimic>
   joint) into a temporary folder (the exported checkpoint goes there too, unless ``--export``
   writes it beside the config, where ``scripts/solve_grasp.py robot=PATH`` reads it); prints the
   wall time and the closing accuracy table (10,000 held-out reachable targets per finger).
2. Solves ``--problems`` random reachable problems (``gt.random_reachable_problem``: every joint
   drawn within its limits, the joints fingers share included; ``--fingers`` contact fingers,
   default 2 or 3) with 20 trials, side by side in one run: the default solver (SRV with the
   whole polish), the paper's protocol (``solver=paper``: the palm pose as the network chose it,
   the fingers refined) and the baselines CMA-ES and damped least squares (100 iterations);
   success = total error (E, eq. 3) < 1 mm, median error, median wall time per problem.
3. Checks every trial of every result independently: a float64 pytorch-kinematics chain built from
   the URDF's bytes, every joint read from the result JSON (mimic joints included), palm_link
   placed at the reported pose (R = Rz Ry Rx); the fingertips (tip link plus the config's offset)
   against the contacts must give the reported fingertip errors to 1e-6 m, each mimic joint must
   equal multiplier * leader + offset (1e-9 rad), and every joint must lie within its URDF limits.

Targets: training under 5 min (2 cores), >= 99.5 % of the held-out targets within 1 mm after
refinement for every finger, >= 95 % of the problems solved to < 1 mm by the default solver, no
verification failure; ``--check`` exits 1 when one is missed.
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import math
import sys
import tempfile
import time
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import torch
from hydra import compose, initialize_config_dir
from omegaconf import OmegaConf

import graspnet_torch as gt
from graspnet_torch.errors import ConfigError
from graspnet_torch.fcnn import FingerIK, load_finger_ik
from graspnet_torch.fcnn.train import FCNNTrainCfg
from graspnet_torch.files import read_document
from graspnet_torch.jobs.train_fcnn import train_fcnn
from graspnet_torch.paths import configs_dir, repo_root
from graspnet_torch.robot import RobotCfg
from graspnet_torch.solver.config import paper_protocol
from graspnet_torch.table import format_table

DEFAULT_ROBOT = repo_root() / "examples" / "dexmate_f5d6" / "dexmate_f5d6_right.yaml"
TRIALS = 20
TRAIN_TARGET_S, WITHIN_TARGET_PCT, SOLVED_TARGET_PCT = 300.0, 99.5, 95.0
TIP_TOL_M, MIMIC_TOL_RAD, LIMIT_TOL = 1e-6, 1e-9, 1e-9


# ---------------------------------------------------------------------------------------- robot
def load_robot(path: Path) -> gt.Robot:
    """The robot of a config file; when its ``urdf`` is not found (``package://<pkg>/...``, or a
    ``.../site-packages/<pkg>/...`` path of another Python), the file is looked up in the installed
    package ``<pkg>`` instead."""
    try:
        return gt.load_robot(str(path))
    except ConfigError as exc:
        data = read_document(path, "robot config", ConfigError)
        raw = str(data.get("urdf", ""))
        rel = raw[len("package://"):] if raw.startswith("package://") else raw.partition("site-packages/")[2]
        pkg, _, inner = rel.partition("/")
        spec = importlib.util.find_spec(pkg) if pkg and inner else None
        if spec is None or not spec.submodule_search_locations:
            hint = f" (is the package '{pkg}' installed? pip install -e '.[hands]')" if pkg and inner else ""
            raise SystemExit(f"{exc}{hint}") from None
        urdf = Path(next(iter(spec.submodule_search_locations))) / inner
        print(f"note: {raw} not found; using the installed package's {urdf}")
        cfg = RobotCfg.from_mapping({**data, "urdf": str(urdf)}, source=str(path), folder=path.resolve().parent)
        return gt.Robot(cfg)


# ---------------------------------------------------------------------------------------- training
def train(robot: gt.Robot, epochs: int | None, export: Path) -> tuple[FingerIK, list[dict], float, int]:
    with initialize_config_dir(config_dir=str(configs_dir()), version_base="1.3"):
        cfg = compose(config_name="train_fcnn")
    fcnn = FCNNTrainCfg.from_mapping(OmegaConf.to_container(cfg.fcnn))
    if epochs:
        fcnn = FCNNTrainCfg(**{**fcnn.__dict__, "epochs": epochs})
    with tempfile.TemporaryDirectory() as run_dir:
        t0 = time.perf_counter()
        _, rows = train_fcnn(robot, fcnn, run_dir, seed=cfg.seed, export=export, progress=False,
                             eval_targets=10_000)
        seconds = time.perf_counter() - t0
    ik = load_finger_ik(robot, export)  # what the solver reads, not the trainer's objects
    return ik, rows, seconds, fcnn.epochs


# ---------------------------------------------------------------------------------------- verification
def _rot(rx: float, ry: float, rz: float) -> np.ndarray:
    """Rz(rz) @ Ry(ry) @ Rx(rx), radians."""
    cx, sx, cy, sy, cz, sz = math.cos(rx), math.sin(rx), math.cos(ry), math.sin(ry), math.cos(rz), math.sin(rz)
    Rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    Ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    Rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return Rz @ Ry @ Rx


def _pose(xyz_deg: list[float]) -> np.ndarray:
    """4x4 of a pose (x, y, z in m, rx, ry, rz in degrees)."""
    T = np.eye(4)
    T[:3, :3] = _rot(*(math.radians(a) for a in xyz_deg[3:]))
    T[:3, 3] = xyz_deg[:3]
    return T


class UrdfChecker:
    """Checks results against the URDF alone: its XML (joints, limits, mimic couplings) and a
    float64 pytorch-kinematics chain built from its bytes; finger chains and tip offsets from the
    robot config file, nothing from the library's kinematics."""

    def __init__(self, urdf: Path, cfg: RobotCfg):
        import pytorch_kinematics as pk

        data = urdf.read_bytes()
        self.chain = pk.build_chain_from_urdf(data).to(dtype=torch.float64)
        self.names = self.chain.get_joint_parameter_names()
        root = ET.fromstring(data)
        self.joints = {}  # name -> (type, parent, child, lower, upper, mimic (leader, multiplier, offset) | None)
        for j in root.iter("joint"):
            lim, mim = j.find("limit"), j.find("mimic")
            lo = float(lim.get("lower", 0)) if lim is not None else -math.inf
            hi = float(lim.get("upper", 0)) if lim is not None else math.inf
            mimic = None if mim is None else (mim.get("joint"), float(mim.get("multiplier", 1)),
                                              float(mim.get("offset", 0)))
            self.joints[j.get("name")] = (j.get("type"), j.find("parent").get("link"), j.find("child").get("link"),
                                          lo, hi, mimic)
        parent_joint = {v[2]: k for k, v in self.joints.items()}
        self.palm = cfg.palm_link
        self.fingers = {}  # finger -> (tip link, offset (3,), movable joint names palm -> tip)
        for name, ch in cfg.fingers.items():
            path, link = [], ch.tip
            while link != self.palm:  # the finger's base hangs rigidly from the palm
                joint = parent_joint[link]
                path.append(joint)
                link = self.joints[joint][1]
            movable = [j for j in reversed(path) if self.joints[j][0] != "fixed"]
            self.fingers[name] = (ch.tip, np.array(ch.tip_offset or (0.0, 0.0, 0.0)), movable)

    def check(self, result: dict, contacts: dict[str, np.ndarray]) -> dict[str, int]:
        """Every trial of a result JSON: counts of trials with a fingertip error, mimic or limit
        failure, and the largest discrepancies seen."""
        trials = result["trials"]
        th = torch.zeros(len(trials), len(self.names), dtype=torch.float64)
        mimic_bad = limit_bad = shape_bad = 0
        for t, trial in enumerate(trials):
            values = {}
            for f, (_, _, movable) in self.fingers.items():
                row = trial["joints"][f]
                if len(row) != len(movable):
                    shape_bad += 1
                    continue
                for j, v in zip(movable, row, strict=True):
                    values[j] = math.radians(v) if self.joints[j][0] in ("revolute", "continuous") else v
            mimic_ok = all(abs(values[j] - (self.joints[j][5][1] * values[self.joints[j][5][0]] + self.joints[j][5][2]))
                           <= MIMIC_TOL_RAD for j in values if self.joints[j][5] is not None)
            limits_ok = all(self.joints[j][3] - LIMIT_TOL <= v <= self.joints[j][4] + LIMIT_TOL
                            for j, v in values.items())
            mimic_bad += int(not mimic_ok)
            limit_bad += int(not limits_ok)
            th[t] = torch.tensor([values.get(n, 0.0) for n in self.names], dtype=torch.float64)
        frames = self.chain.forward_kinematics(th)
        palm = frames[self.palm].get_matrix().numpy()
        tip_bad, worst = 0, 0.0
        for t, trial in enumerate(trials):
            world = _pose(trial["palm_pose"]) @ np.linalg.inv(palm[t])
            bad = False
            for f, target in contacts.items():
                tip, offset, _ = self.fingers[f]
                p = (world @ frames[tip].get_matrix()[t].numpy() @ np.append(offset, 1.0))[:3]
                diff = abs(np.linalg.norm(p - target) - trial["fingertip_error_mm"][f] / 1000.0)
                worst = max(worst, float(diff))
                bad |= diff > TIP_TOL_M
            tip_bad += int(bad)
        return {"trials": len(trials), "tip": tip_bad, "mimic": mimic_bad, "limits": limit_bad, "shape": shape_bad,
                "worst_tip_m": worst}


def contacts_world(problem: gt.GraspProblem) -> dict[str, np.ndarray]:
    """Contacts in the world: the object frame placed by the object's pose (none: the world)."""
    T = np.eye(4)
    if problem.object is not None:
        pose = np.asarray(problem.object.pose, dtype=np.float64)
        T[:3, :3], T[:3, 3] = _rot(*pose[3:]), pose[:3]
    return {c.finger: (T @ np.append(np.asarray(c.position, dtype=np.float64), 1.0))[:3] for c in problem.contacts}


# ---------------------------------------------------------------------------------------- main
def describe(robot) -> None:
    """Print each finger's joints (shared and mimic ones named) and tip."""
    for f in robot.fingers.values():
        every = robot.finger_all_joint_names(f.name)
        mimic = [n for n in f.chain.all_joint_names if n not in f.joint_names]
        shared = every[: len(every) - len(f.chain.all_joint_names)]
        print(f"  {f.name:>7s}: {len(every)} joints {', '.join(every)}"
              f"{' (shared: ' + ', '.join(shared) + ')' if shared else ''}"
              f"{' (mimic: ' + ', '.join(mimic) + ')' if mimic else ''}, tip {f.chain.tip}")
    if robot.shared.names:
        print(f"  shared joints searched with the palm pose: {', '.join(robot.shared.names)}")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--robot", type=Path, default=DEFAULT_ROBOT, help="robot config YAML")
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--epochs", type=int, default=None, help="override fcnn.epochs (default: configs/fcnn)")
    ap.add_argument("--problems", type=int, default=40)
    ap.add_argument("--fingers", type=int, nargs=2, default=(2, 3), metavar=("LO", "HI"),
                    help="contact fingers per problem, drawn uniformly from LO..HI (default 2 3)")
    ap.add_argument("--export", action="store_true",
                    help="write the trained checkpoint beside the config (default: a temporary folder)")
    ap.add_argument("--check", action="store_true")
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    robot = load_robot(args.robot)
    print(f"{robot!r} from {args.robot}; torch threads: {torch.get_num_threads()}")
    describe(robot)

    with tempfile.TemporaryDirectory() as tmp:
        export = robot.cfg.checkpoint if args.export and robot.cfg.checkpoint else Path(tmp) / "fcnn.pt"
        ik, rows, train_s, epochs = train(robot, args.epochs, export)
    within = {r["finger"]: r["refined"]["within_1mm_pct"] for r in rows}
    print(f"\ntrained {robot.n_fingers} fingers x {epochs} epochs from scratch in {train_s:.0f} s "
          f"({train_s / 60:.1f} min, {torch.get_num_threads()} threads, including the 10,000-target evaluation); "
          f"target: under {TRAIN_TARGET_S / 60:.0f} min")

    checker = UrdfChecker(robot.cfg.urdf, robot.cfg)
    variants = {"default": None, "solver=paper": paper_protocol(), "cmaes": {"method": "cmaes"},
                "dls": {"method": "dls", "max_iterations": 100}}  # the baselines beside, on the same problems
    problems = [gt.random_reachable_problem(robot, seed, n_fingers=tuple(args.fingers))
                for seed in range(args.problems)]
    gt.solve(problems[0], trials=TRIALS, seed=0, robot=robot, finger_ik=ik)  # warm-up
    err = {v: [] for v in variants}
    wall = {v: [] for v in variants}
    verify = {v: {"trials": 0, "tip": 0, "mimic": 0, "limits": 0, "shape": 0, "worst_tip_m": 0.0} for v in variants}
    for k, problem in enumerate(problems):
        for v, solver in variants.items():  # side by side, same seed
            t0 = time.perf_counter()
            res = gt.solve(problem, trials=TRIALS, seed=k, solver=solver, robot=robot, finger_ik=ik)
            wall[v].append(time.perf_counter() - t0)
            out = json.loads(res.to_json())
            err[v].append(out["total_error_mm"])
            c = checker.check(out, contacts_world(problem))
            for key in ("trials", "tip", "mimic", "limits", "shape"):
                verify[v][key] += c[key]
            verify[v]["worst_tip_m"] = max(verify[v]["worst_tip_m"], c["worst_tip_m"])
    n_contacts = [len(p.contacts) for p in problems]
    counts = ", ".join(f"{n_contacts.count(k)} with {k}" for k in range(args.fingers[0], args.fingers[1] + 1))
    print(f"\n{args.problems} random reachable problems ({counts} contact fingers), {TRIALS} trials each, "
          f"side by side:")
    table = []
    for v in variants:
        e, w, c = np.asarray(err[v]), np.asarray(wall[v]), verify[v]
        table.append([v, round(float(np.mean(e < 1.0) * 100), 1), float(np.median(e)), float(np.percentile(e, 90)),
                      float(np.median(w)), float(np.max(w)), c["trials"], c["tip"], c["mimic"], c["limits"],
                      c["shape"], f"{c['worst_tip_m']:.1e}"])
    print(format_table(["solver", "E < 1 mm %", "median E mm", "p90 E mm", "median s", "max s", "trials checked",
                        "tip fail", "mimic fail", "limit fail", "joint count fail", "worst |d err| m"], table,
                       floatfmt=".4g"))
    ratio = np.median(wall["default"]) / np.median(wall["solver=paper"])
    print(f"\nwall time default / solver=paper (medians): {ratio:.2f}; default / dls: "
          f"{np.median(wall['default']) / np.median(wall['dls']):.2f}; default / cmaes: "
          f"{np.median(wall['default']) / np.median(wall['cmaes']):.2f}")

    solved = table[0][1]
    failures = sum(verify[v][k] for v in variants for k in ("tip", "mimic", "limits", "shape"))
    checks = [(f"training {train_s:.0f} s < {TRAIN_TARGET_S:.0f} s", train_s < TRAIN_TARGET_S),
              *((f"{f}: {p:.2f} % of held-out targets within 1 mm >= {WITHIN_TARGET_PCT} %", p >= WITHIN_TARGET_PCT)
                for f, p in within.items()),
              (f"default solver: {solved:.1f} % solved to < 1 mm >= {SOLVED_TARGET_PCT:.0f} %",
               solved >= SOLVED_TARGET_PCT),
              (f"verification: {failures} failures", failures == 0)]
    print()
    for text, ok in checks:
        print(f"{'met   ' if ok else 'MISSED'}  {text}")
    return 1 if args.check and not all(ok for _, ok in checks) else 0


if __name__ == "__main__":
    sys.exit(main())
