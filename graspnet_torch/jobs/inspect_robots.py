"""Load robots (shipped or by path), print a summary table and draw each at its home posture, with
its fingers' pads (point and normal), and, for a robot with fingers, with its opposing finger (the
thumb of a human-like hand, found from its kinematics) opposed to one or two others."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import Tensor

from graspnet_torch.errors import ConfigError, say
from graspnet_torch.files import check_output_path
from graspnet_torch.jobs.configs import InspectRobotsJobCfg
from graspnet_torch.least_squares import LMOptions, levenberg_marquardt
from graspnet_torch.robot import Posture, Robot, available_robots, load_robot
from graspnet_torch.robot.opposition import hand_axes
from graspnet_torch.settings import build, clip
from graspnet_torch.table import format_table
from graspnet_torch.viz import Panel, render_robot

__all__ = [
    "inspect_robots",
    "opposing_fingers",
    "opposition_posture",
    "pad_arrows",
    "pinch_posture",
    "prepare_inspect",
    "robot_summary",
]

MAX_OPPOSITIONS = 2  # opposition panels per robot
PAD_ARROW_M = 0.025  # how long a pad's normal is drawn (m)


def robot_summary(robot: Robot) -> dict[str, object]:
    """One row of the robot table."""
    return {"robot": robot.name, "links": len(robot.urdf.links), "movable joints": len(robot.urdf.movable_joint_names),
            "chains": robot.n_chains, "DOF": robot.dof}


def opposing_fingers(robot: Robot) -> list[tuple[str, str]]:
    """(first, other) finger pairs to oppose: the opposing finger (:func:`~graspnet_torch.robot.opposition.hand_axes`;
    the first finger where none opposes) and its nearest others, at most ``MAX_OPPOSITIONS``; none
    for a robot with fewer than two fingers."""
    names = list(robot.finger_names)
    if len(names) < 2:
        return []
    try:
        order = list(hand_axes(robot).order)
    except ConfigError:
        order = names
    return [(order[0], other) for other in order[1:]][:MAX_OPPOSITIONS]


def pad_arrows(robot: Robot, posture: Posture, length: float = PAD_ARROW_M) -> tuple[np.ndarray, np.ndarray]:
    """Every finger's pad at ``posture``, world: its points (F, 3) and its normals as segments
    (F, 2, 3) ``length`` (m) long from the points; none for a robot without pads or whose pads
    cannot be derived (a finger without collision geometry: the synthesis says so)."""
    try:
        pads = robot.pads
    except ConfigError:
        pads = {}
    if not pads:
        return np.zeros((0, 3)), np.zeros((0, 2, 3))
    frames = robot.link_frames(posture)
    points, arrows = [], []
    for name, pad in pads.items():
        cfg = robot.cfg.fingers[name]
        T = frames[cfg.tip].copy()
        T[:3, 3] = T[:3, :3] @ np.asarray(cfg.tip_offset or (0.0, 0.0, 0.0)) + T[:3, 3]
        p = T[:3, :3] @ pad.point + T[:3, 3]
        points.append(p)
        arrows.append([p, p + length * (T[:3, :3] @ pad.normal)])
    return np.asarray(points), np.asarray(arrows)


def _base_rotations(robot: Robot, dtype: torch.dtype) -> torch.Tensor:
    """(F, 3, 3) each finger base's rotation in the palm frame, from ``palm_to_base``: the rows of
    R are R^T e_i = palm_to_base(e_i) - palm_to_base(0)."""
    F = robot.n_fingers
    unit = torch.eye(3, dtype=dtype)[:, None, :].expand(3, F, 3)
    rows = robot.palm_to_base(unit) - robot.palm_to_base(torch.zeros(F, 3, dtype=dtype))  # (3, F, 3)
    return rows.transpose(0, 1)


def opposition_posture(robot: Robot, a: str, b: str, start: Posture, restarts: int = 48, iterations: int = 150,
                       damping: float = 1e-3, tol: float = 1e-9, seed: int = 0) -> tuple[Posture, float]:
    """Bring the tips of fingers ``a`` and ``b`` together (their gap to zero) over both fingers'
    joints, within the joint limits, from ``start`` and ``restarts - 1`` random configurations:
    the gap's residual handed to the package's one Levenberg-Marquardt
    (:func:`~graspnet_torch.least_squares.levenberg_marquardt`; lambda starts at ``damping``). The
    other fingers stay as in ``start``; padded or fixed slots (lower == upper) do not move.

    Residual e = tip_a - tip_b (3,) in the palm frame, Jacobian [J_a, -J_b] (3, 2n); every start
    stops once one of them is within ``tol`` (m). Returns the posture of the start nearest to a
    closed gap and that gap (m)."""
    ia, ib = robot.finger_index(a), robot.finger_index(b)
    dtype = torch.float64
    lo, hi = (torch.as_tensor(x, dtype=dtype) for x in robot.finger_limits)  # (F, n)
    n = lo.shape[1]
    free = (hi > lo)[[ia, ib]]  # (2, n)
    gen = torch.Generator().manual_seed(seed)
    q = start.fingers.to(dtype).clone().expand(restarts, *lo.shape).clone()  # (S, F, n)
    rand = lo + (hi - lo) * torch.rand(restarts - 1, *lo.shape, generator=gen, dtype=dtype)
    q[1:, [ia, ib]] = rand[:, [ia, ib]]
    q = torch.minimum(torch.maximum(q, lo), hi)
    R = _base_rotations(robot, dtype)[[ia, ib]]  # (2, 3, 3)

    def gap(x: Tensor, rows: Tensor) -> tuple[Tensor, Tensor]:  # x (b, 2n) -> e (b, 3), J (b, 3, 2n)
        qq = q[rows].clone()
        qq[:, [ia, ib]] = x.view(-1, 2, n)
        tips = robot.fingertips_palm(qq)  # (b, F, 3)
        _, J = robot.fingertips_base_jacobian(qq)  # (b, F, 3, n) in each base frame
        Jp = (R @ J[:, [ia, ib]]) * free[:, None, :]  # (b, 2, 3, n) palm frame; fixed slots still
        return tips[:, ia] - tips[:, ib], torch.cat([Jp[:, 0], -Jp[:, 1]], dim=-1)

    def one_closed(converged: Tensor) -> Tensor:  # every start stops once one has closed the gap
        return converged.any().expand_as(converged)

    solved = levenberg_marquardt(gap, torch.zeros(3, dtype=dtype), q[:, [ia, ib]].reshape(restarts, 2 * n),
                                 lo[[ia, ib]].reshape(-1), hi[[ia, ib]].reshape(-1), iterations,
                                 LMOptions(lam=damping, tol=tol, done=one_closed))
    best = int(torch.argmin(solved.err))
    fingers = q[best].clone()
    fingers[[ia, ib]] = solved.x[best].view(2, n)
    return replace(start, fingers=fingers.to(start.fingers.dtype)), float(solved.err[best])


def pinch_posture(robot: Robot, finger: str, start: Posture) -> tuple[Posture, float]:
    """``finger`` opposed to the opposing finger (:func:`opposing_fingers`): :func:`opposition_posture`."""
    first = opposing_fingers(robot)[0][0]
    return opposition_posture(robot, first, finger, start)


def prepare_inspect(cfg: Mapping[str, Any] | InspectRobotsJobCfg, run_dir: str | Path) -> tuple[list[str], Path]:
    """The checks of the job before any work: the settings, every robot (config and URDF; a name
    or a path to a robot YAML) and the output folder; returns the robots and the folder
    (``out_dir``, else the run folder)."""
    job = build(InspectRobotsJobCfg, cfg)
    out_dir = Path(job.out_dir) if job.out_dir else Path(run_dir)
    for name in job.robots:
        robot = load_robot(name)  # the config and its URDF
        check_output_path(str(out_dir / f"{robot.name}.png"), "out_dir", ConfigError)
    return job.robots, out_dir


def _panels(robot: Robot, row: dict) -> list:
    """The home panels, then one per opposition (the gap goes into the row)."""
    home = robot.home_posture()
    name = robot.name
    panels = [Panel(f"{name}: home posture", home, (15.0, -60.0))]
    pairs = opposing_fingers(robot)
    focus = hand_links(robot)  # the palm and its fingers (the whole robot for a free hand)
    if pairs:
        points, arrows = pad_arrows(robot, home)
        panels.append(Panel(f"{name}: home, side view; pads (green: normals)", home, (15.0, -15.0), markers=points,
                            focus=focus, arrows=arrows))
    for a, b in pairs:
        posture, gap = opposition_posture(robot, a, b, home)
        panels.append(Panel(f"{a}-{b} opposition (gap {gap * 1000:.2f} mm)", posture, (10.0, 20.0), focus=focus))
        row[f"{a}-{b} gap (mm)"] = round(gap * 1000, 3)
    return panels


def hand_links(robot: Robot) -> frozenset[str]:
    """The palm link and every link below it."""
    below = {robot.cfg.palm_link}
    changed = True  # to a fixed point: the URDF's joints may come in any order
    while changed:
        changed = False
        for joint in robot.urdf.robot.joints:
            if joint.parent in below and joint.child not in below:
                below.add(joint.child)
                changed = True
    return frozenset(below)


def inspect_robots(names: Sequence[str] | None = None, out_dir: str | Path = "outputs/robots") -> list[dict]:
    """Print the robot table and write ``<out_dir>/<robot name>.png`` for each robot (a name or a
    path to a robot YAML); returns the table rows. A picture that fails is a warning on stderr
    (its row says ``-``), never an error."""
    names = list(names) if names else available_robots()
    out_dir = Path(out_dir)

    rows = []
    for name in names:
        robot = load_robot(name)
        row = robot_summary(robot)
        path = out_dir / f"{robot.name}.png"
        try:
            render_robot(robot, _panels(robot, row), path)
            row["picture"] = str(path)
        except Exception as exc:  # a picture must not stop the table
            row["picture"] = "-"
            say(f"warning: {robot.name}: picture not written: {type(exc).__name__}: "
                f"{clip(' '.join(str(exc).split()), 200)}")
        rows.append(row)
    headers = ["robot", "links", "movable joints", "chains", "DOF", "picture"]
    print(format_table(headers, [[r[h] for h in headers] for r in rows]))
    gaps = [f"{r['robot']} {k} {r[k]}" for r in rows for k in r if k.endswith("gap (mm)")]
    if gaps:
        print("opposition: " + ", ".join(gaps))
    return rows
