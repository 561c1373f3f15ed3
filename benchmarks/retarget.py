"""Fingertip targets -> the whole hand, side by side with dex-retargeting's position retargeting.

    python benchmarks/retarget.py [--robot hand] [--sequences 10] [--frames 100] [--problems 200]
                                  [--fingers 4 5] [--threads 1] [--check]

Needs the ``retarget`` extra (``pip install -e '.[retarget]'``: dex-retargeting, pinocchio
(``pin``), nlopt). ``--robot`` is a shipped robot or a robot config YAML of a free hand, e.g.
``examples/dexmate_f5d6/dexmate_f5d6_right.yaml`` (the ``hands`` extra; train its FCNN first:
``python benchmarks/any_hand.py --export``).

Both methods get the same frames: (a) ``--sequences`` smooth sequences of ``--frames`` frames
(``random_sequence``: contact fingertips move <= 1 cm and the palm turns <= 5 deg per frame),
(b) ``--problems`` independent random reachable problems (one-frame ``random_sequence``: a
posture uniform in the search space, as ``gt.random_reachable_problem`` draws it, which also gives
the true palm pose), each with ``--fingers`` contact fingers. Methods:

* ours, cold: ``gt.Solver(robot).solve(problem)`` on every frame on its own;
* ours, track: ``gt.Solver(robot).track(frames)`` over each sequence (warm starts); and the same
  without centring the searched frames (``solver.polish.centre: null``) and also without the
  bound on a warm start's joint steps (``warm_step_deg: null``);
* dex-retargeting: its ``position`` optimizer (SLSQP, nlopt) on a free-floating hand
  (``add_dummy_free_joint``; target links: the fingertips, a fixed link added where the config
  gives the tip an offset; low-pass filter off), one retargeter per contact-finger set. On a
  sequence it starts from the middle of every joint range (its ``reset``) and then warm-starts from
  the previous frame, as it is used; on an independent problem it starts from the middle;
* dex-retargeting tuned: the same, with its regulariser towards the previous frame off
  (``normal_delta: 0``: as shipped it enters the gradient but not the objective, and SLSQP stops
  early) and a tighter stop (``ftol_abs`` 1e-9 instead of 1e-5, at most 300 evaluations);
* "true wrist at the start" (either): the same, but the first frame of a sequence (every independent
  problem) starts at the palm pose that made the frame (its ``warm_start``: in retargeting a human
  hand the wrist pose is known; here it is an oracle that ours does not get).

Every error is recomputed here, in float64, by this project's forward kinematics of each method's
output (for dex-retargeting its qpos: the dummy free joint and the palm link's pose from its own
model give the palm pose, the hand joints the finger joints): the sum over the contact fingers of
the fingertip-to-contact distance (mm). Time per frame: the call alone (the model building and
the conversion not counted); for ``track``, its wall time divided by the frames, the median over
sequences. Joint jumps: the largest change of a contact finger's free joint between consecutive
frames (degrees); a jump counts against the target only where the previous frame's posture still
puts every contact fingertip within 1 cm of the new contacts (no jump was needed).

Targets (ours; set for the shipped ``hand``, checked for any ``--robot``): on sequences (track)
>= 99 % of the frames below 1 mm and a median time per frame <= 3 ms; independent problems (cold)
>= 99.5 % below 1 mm and a median time <= 15 ms; no jump > 20 deg where the previous posture
still fits (track). ``--check`` exits
1 when one is missed.
"""

from __future__ import annotations

import argparse
import math
import sys
import tempfile
import time
import xml.etree.ElementTree as ET
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

import graspnet_torch as gt
from graspnet_torch.benchmarking import check_targets
from graspnet_torch.robot.transforms import matrix_to_pose, pose_from_degrees, pose_to_rt
from graspnet_torch.table import markdown_table
from graspnet_torch.tasks import random_sequence

SEQ_BELOW_PCT, SEQ_MS, ONE_BELOW_PCT, ONE_MS, JUMP_DEG, FITS_M = 99.0, 3.0, 99.5, 15.0, 20.0, 0.01
TUNED_FTOL, TUNED_MAXEVAL = 1e-9, 300
Posture = tuple[torch.Tensor, torch.Tensor]  # palm pose (6,) m/rad, free finger joints (F, n) rad


# ------------------------------------------------------------------------------ dex-retargeting
def kinematic_urdf(robot: gt.Robot, folder: Path) -> tuple[Path, dict[str, str]]:
    """A copy of the robot's URDF for dex-retargeting, under ``folder``: visuals and collisions
    dropped (kinematics only: no mesh paths to resolve) and, for each finger whose fingertip is its
    tip link plus an offset (robot config), a fixed link at that point.

    Returns the URDF's path and each finger's fingertip link.
    """
    tree = ET.parse(robot.cfg.urdf)
    root = tree.getroot()
    for link in root.iter("link"):
        for child in [c for c in link if c.tag in ("visual", "collision")]:
            link.remove(child)
    tips = {}
    for name, chain in robot.cfg.fingers.items():
        tips[name] = chain.tip
        if chain.tip_offset is not None:
            tips[name] = f"{name}_fingertip_point"
            ET.SubElement(root, "link", name=tips[name])
            joint = ET.SubElement(root, "joint", name=f"{tips[name]}_joint", type="fixed")
            ET.SubElement(joint, "parent", link=chain.tip)
            ET.SubElement(joint, "child", link=tips[name])
            ET.SubElement(joint, "origin", xyz=" ".join(map(str, chain.tip_offset)), rpy="0 0 0")
    path = folder / f"{robot.name}.urdf"
    tree.write(path)
    return path, tips


class DexRetargeter:
    """dex-retargeting's position retargeting of one contact-finger set on a free-floating hand."""

    def __init__(self, robot: gt.Robot, urdf: Path, tips: dict[str, str], fingers: tuple[str, ...], tuned: bool):
        from dex_retargeting.retargeting_config import RetargetingConfig

        cfg = RetargetingConfig.from_dict({
            "type": "position", "urdf_path": str(urdf), "add_dummy_free_joint": True,
            "target_link_names": [tips[f] for f in fingers],
            "target_joint_names": [j for f in robot.fingers.values() for j in f.joint_names],  # free: no mimic
            "target_link_human_indices": list(range(len(fingers))),
            "low_pass_alpha": -1,  # no filter: it would lag behind the targets
            **({"normal_delta": 0.0} if tuned else {}),
        })
        self.robot, self.fingers = robot, fingers
        self.retargeting = cfg.build()
        if tuned:
            self.retargeting.optimizer.opt.set_ftol_abs(TUNED_FTOL)
            self.retargeting.optimizer.opt.set_maxeval(TUNED_MAXEVAL)
        self.model = self.retargeting.optimizer.robot  # dex-retargeting's pinocchio wrapper
        self.palm = self.model.get_link_index(robot.cfg.palm_link)
        self.names = self.model.dof_joint_names

    def start(self, palm_pose: torch.Tensor | None) -> None:
        """The next frame starts from the middle of every joint range, or (``palm_pose`` (6,)) with
        the palm there (``warm_start``)."""
        from pytransform3d.rotations import quaternion_from_matrix

        self.retargeting.reset()
        if palm_pose is not None:
            R, t = pose_to_rt(palm_pose)
            self.retargeting.warm_start(t.numpy(), quaternion_from_matrix(R.numpy()))

    def __call__(self, targets: np.ndarray) -> tuple[np.ndarray, float]:
        """Targets (K, 3) -> qpos (pinocchio order) and the seconds the call took."""
        t0 = time.perf_counter()
        qpos = self.retargeting.retarget(targets)
        return qpos, time.perf_counter() - t0

    def posture(self, qpos: np.ndarray) -> Posture:
        """dex-retargeting's qpos -> this project's palm pose (the palm link's pose in its model)
        and free finger joints."""
        self.model.compute_forward_kinematics(qpos)
        pose = matrix_to_pose(torch.as_tensor(self.model.get_link_pose(self.palm), dtype=torch.float64))
        values = dict(zip(self.names, qpos.tolist(), strict=True))
        joints = {f: [values[j] for j in finger.chain.all_joint_names] for f, finger in self.robot.fingers.items()}
        return pose, self.robot.free_finger_joints(joints)


# ------------------------------------------------------------------------------ one method's frames
@dataclass
class Run:
    """One method on a list of sequences (an independent problem: a sequence of one frame).

    Attributes:
        postures: per sequence, per frame, the method's posture.
        seconds: the time per frame of each frame (or each sequence, for ``track``).
    """

    postures: list[list[Posture]]
    seconds: list[float]


def ours_posture(robot: gt.Robot, result: gt.GraspResult) -> Posture:
    best = result.best
    pose = pose_from_degrees(torch.tensor(best.palm_pose, dtype=torch.float64))
    return pose, robot.finger_joints_from_file(best.joints)


def run_ours_cold(robot: gt.Robot, sequences: list[list[gt.GraspProblem]]) -> Run:
    solver = gt.Solver(robot)
    solver.solve(sequences[0][0])  # warm-up: checkpoint, kernels
    postures, seconds = [], []
    for frames in sequences:
        row = []
        for p in frames:
            t0 = time.perf_counter()
            result = solver.solve(p)
            seconds.append(time.perf_counter() - t0)
            row.append(ours_posture(robot, result))
        postures.append(row)
    return Run(postures, seconds)


def run_ours_track(robot: gt.Robot, sequences: list[list[gt.GraspProblem]], **polish) -> Run:
    """``gt.Solver(robot).track`` over each sequence; ``polish``: settings of ``solver.polish``
    changed (the ablations of ``warm_step_deg`` and ``centre``)."""
    from dataclasses import replace

    solver = gt.Solver(robot)
    if polish:
        cfg = solver.solver_cfg
        solver = gt.Solver(robot, solver=replace(cfg, polish=replace(cfg.polish, **polish)))
    solver.track(sequences[0][:2])  # warm-up
    postures, seconds = [], []
    for frames in sequences:
        t0 = time.perf_counter()
        results = solver.track(frames)
        seconds.append((time.perf_counter() - t0) / len(frames))
        postures.append([ours_posture(robot, r) for r in results])
    return Run(postures, seconds)


def run_dex(robot: gt.Robot, sequences: list[list[gt.GraspProblem]], true_wrist: bool, tuned: bool) -> Run:
    with tempfile.TemporaryDirectory(prefix="retarget-") as folder:
        urdf, tips = kinematic_urdf(robot, Path(folder))
        retargeters: dict[tuple[str, ...], DexRetargeter] = {}
        postures, seconds = [], []
        for frames in sequences:
            fingers = frames[0].fingers
            if fingers not in retargeters:
                retargeters[fingers] = DexRetargeter(robot, urdf, tips, fingers, tuned)
            dex = retargeters[fingers]
            first = frames[0].reference
            dex.start(torch.as_tensor(first.palm_pose) if true_wrist else None)
            row = []
            for p in frames:
                qpos, s = dex(np.stack([c.position for c in p.contacts]))
                seconds.append(s)
                row.append(dex.posture(qpos))
            postures.append(row)
    return Run(postures, seconds)


# ------------------------------------------------------------------------------ measures
def contact_distances(robot: gt.Robot, problem: gt.GraspProblem, posture: Posture) -> np.ndarray:
    """(K,) distance (m) of each contact finger's fingertip to its contact."""
    tips = robot.fingertips_world(*posture)[[robot.finger_index(f) for f in problem.fingers]]
    contacts = torch.as_tensor(np.stack([c.position for c in problem.contacts]))
    return torch.linalg.vector_norm(tips - contacts, dim=-1).numpy()


def measure(robot: gt.Robot, sequences: list[list[gt.GraspProblem]], run: Run) -> dict[str, float]:
    errors, jumps, fitting_jumps = [], [], []
    for frames, postures in zip(sequences, run.postures, strict=True):
        idx = [robot.finger_index(f) for f in frames[0].fingers]
        for t, (p, posture) in enumerate(zip(frames, postures, strict=True)):
            errors.append(contact_distances(robot, p, posture).sum() * 1e3)
            if t:
                jump = math.degrees(float((posture[1][idx] - postures[t - 1][1][idx]).abs().max()))
                jumps.append(jump)
                if contact_distances(robot, p, postures[t - 1]).max() <= FITS_M:
                    fitting_jumps.append(jump)
    e = np.asarray(errors)
    out = {"frames": e.size, "median_mm": float(np.median(e)), "p90_mm": float(np.percentile(e, 90)),
           "below_pct": float((e < 1).mean() * 100), "median_ms": float(np.median(run.seconds) * 1e3)}
    if jumps:
        out |= {"max_jump": max(jumps), "jumps": sum(j > JUMP_DEG for j in jumps),
                "fitting_jumps": sum(j > JUMP_DEG for j in fitting_jumps)}
    return out


def table(rows: dict[str, dict[str, float]]) -> str:
    headers = ["method", "frames", "median mm", "p90 mm", "< 1 mm %", "median ms/frame", "max jump deg",
               f"jumps > {JUMP_DEG:g} deg", "of them, previous fits"]
    body = [[name, m["frames"], m["median_mm"], m["p90_mm"], f"{m['below_pct']:.1f}", f"{m['median_ms']:.2f}",
             f"{m['max_jump']:.1f}" if "max_jump" in m else "-", m.get("jumps", "-"), m.get("fitting_jumps", "-")]
            for name, m in rows.items()]
    return markdown_table(headers, body, floatfmt=".3g")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--robot", default="hand", help="a shipped robot or a robot config YAML (a free hand)")
    ap.add_argument("--sequences", type=int, default=10)
    ap.add_argument("--frames", type=int, default=100)
    ap.add_argument("--problems", type=int, default=200)
    ap.add_argument("--fingers", type=int, nargs=2, default=(4, 5), help="contact fingers: lowest, highest")
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--check", action="store_true")
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    print(f"torch.get_num_threads() = {torch.get_num_threads()}", flush=True)
    robot = gt.load_robot(args.robot)
    if robot.kind != "hand":
        ap.error(f"--robot {args.robot}: a free hand is needed (dex-retargeting's dummy free joint), got "
                 f"a robot of kind '{robot.kind}'")
    fingers = tuple(args.fingers)
    sequences = [random_sequence(robot, 30_000 + s, args.frames, fingers) for s in range(args.sequences)]
    # an independent problem: a sequence's first frame (a posture uniform in the search space, as
    # gt.random_reachable_problem draws it), which carries its posture (the true wrist)
    singles = [random_sequence(robot, 40_000 + k, 1, fingers) for k in range(args.problems)]

    methods: dict[str, Callable[[list[list[gt.GraspProblem]]], Run]] = {
        "ours, cold (Solver.solve)": lambda s: run_ours_cold(robot, s),
        "ours, track (Solver.track)": lambda s: run_ours_track(robot, s),
        "ours, track, centre: null": lambda s: run_ours_track(robot, s, centre=None),
        "ours, track, centre: null, warm_step_deg: null": lambda s: run_ours_track(robot, s, centre=None,
                                                                                   warm_step_deg=None),
        "dex-retargeting": lambda s: run_dex(robot, s, true_wrist=False, tuned=False),
        "dex-retargeting, true wrist at the start": lambda s: run_dex(robot, s, true_wrist=True, tuned=False),
        "dex-retargeting tuned": lambda s: run_dex(robot, s, true_wrist=False, tuned=True),
        "dex-retargeting tuned, true wrist at the start": lambda s: run_dex(robot, s, true_wrist=True, tuned=True),
    }
    results = {}
    for part, frames in (("sequences", sequences), ("independent problems", singles)):
        rows = {}
        for name, method in methods.items():
            if part != "sequences" and "track" in name:
                continue
            rows[name] = measure(robot, frames, method(frames))
            print(f"{part}: {name}: {rows[name]}", flush=True)
        results[part] = rows
        print(f"\n### {robot.name}: {part} ({len(frames)} x {len(frames[0])} frames, {fingers[0]}-{fingers[1]} "
              f"contact fingers)\n\n{table(rows)}\n", flush=True)

    track, cold = results["sequences"]["ours, track (Solver.track)"], results["independent problems"][
        "ours, cold (Solver.solve)"]
    checks = [
        (f"sequences, track: {track['below_pct']:.1f} % of frames < 1 mm >= {SEQ_BELOW_PCT:g} %",
         track["below_pct"] >= SEQ_BELOW_PCT),
        (f"sequences, track: median {track['median_ms']:.2f} ms per frame <= {SEQ_MS:g} ms",
         track["median_ms"] <= SEQ_MS),
        (f"sequences, track: {track['fitting_jumps']} jump(s) > {JUMP_DEG:g} deg where the previous posture fits "
         f"within {FITS_M * 100:g} cm == 0", track["fitting_jumps"] == 0),
        (f"independent problems, cold: {cold['below_pct']:.1f} % < 1 mm >= {ONE_BELOW_PCT:g} %",
         cold["below_pct"] >= ONE_BELOW_PCT),
        (f"independent problems, cold: median {cold['median_ms']:.2f} ms <= {ONE_MS:g} ms",
         cold["median_ms"] <= ONE_MS),
    ]
    return check_targets(checks, args.check)


if __name__ == "__main__":
    sys.exit(main())
