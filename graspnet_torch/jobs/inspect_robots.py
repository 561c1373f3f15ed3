"""Load every shipped robot, print a summary table and draw each at its home posture."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

import torch

from graspnet_torch.errors import ConfigError
from graspnet_torch.files import check_output_path
from graspnet_torch.jobs.configs import InspectRobotsJobCfg
from graspnet_torch.robot import ChainKernel, Posture, Robot, available_robots, load_robot
from graspnet_torch.robot.ik import refine
from graspnet_torch.settings import build
from graspnet_torch.table import format_table

__all__ = ["inspect_robots", "pinch_posture", "prepare_inspect", "robot_summary"]

# a tip-to-tip pinch: the finger's abduction, MCP, PIP, DIP (degrees)
PINCH_FLEXION_DEG = (0.0, 55.0, 60.0, 25.0)


def robot_summary(robot: Robot) -> dict[str, object]:
    """One row of the robot table."""
    return {"robot": robot.name, "links": len(robot.urdf.links), "movable joints": len(robot.urdf.movable_joint_names),
            "chains": robot.n_chains, "DOF": robot.dof}


def pinch_posture(robot: Robot, finger: str, start: Posture) -> tuple[Posture, float]:
    """Flex ``finger`` into a pinch and bring the thumb tip onto its tip (damped least squares).

    Returns the posture and the remaining thumb-to-fingertip distance (m).
    """
    k = robot.finger_index(finger)
    thumb = robot.finger_index("thumb")
    q = start.fingers.clone()
    q[k] = torch.tensor([math.radians(a) for a in PINCH_FLEXION_DEG], dtype=q.dtype)
    lo, hi = (torch.as_tensor(a, dtype=q.dtype) for a in robot.finger_limits)
    q = torch.clamp(q, lo, hi)
    target_palm = robot.fingertips_palm(q)[k]
    target = robot.palm_to_base(target_palm.expand(robot.n_fingers, 3))[thumb]
    kernel = ChainKernel(robot.fingers["thumb"].chain)
    starts = lo[thumb] + (hi[thumb] - lo[thumb]) * torch.rand(32, kernel.n_joints, dtype=q.dtype,
                                                               generator=torch.Generator().manual_seed(0))
    qt, err = refine(kernel.position_jacobian, starts, target.expand(32, 3), lo[thumb], hi[thumb], iterations=60)
    best = int(torch.argmin(err))
    q[thumb] = qt[best]
    return replace(start, fingers=q), float(err[best])


def prepare_inspect(cfg: Mapping[str, Any] | InspectRobotsJobCfg, run_dir: str | Path) -> tuple[list[str], Path]:
    """The checks of the job before any work: the settings, every robot (config and URDF) and the
    output folder; returns the robot names and the folder (``out_dir``, else the run folder)."""
    job = build(InspectRobotsJobCfg, cfg)
    out_dir = Path(job.out_dir) if job.out_dir else Path(run_dir)
    for name in job.robots:
        robot = load_robot(name)  # the config and its URDF
        check_output_path(str(out_dir / f"{robot.name}.png"), "out_dir", ConfigError)
    return job.robots, out_dir


def inspect_robots(names: Sequence[str] | None = None, out_dir: str | Path = "outputs/robots") -> list[dict]:
    """Print the robot table and write ``<out_dir>/<robot>.png``; returns the table rows."""
    names = list(names) if names else available_robots()
    out_dir = Path(out_dir)
    from graspnet_torch.viz import Panel, render_robot

    rows = []
    for name in names:
        robot = load_robot(name)
        row = robot_summary(robot)
        home = robot.home_posture()
        panels = [Panel(f"{name}: home posture", home, (15.0, -60.0) if robot.has_body else (10.0, -80.0))]
        if not robot.has_body and "thumb" in robot.fingers:
            panels.append(Panel(f"{name}: home, side view", home, (15.0, -15.0)))
            for finger in ("index", "middle"):
                if finger in robot.fingers:
                    pinch, gap = pinch_posture(robot, finger, home)
                    panels.append(Panel(f"thumb-{finger} opposition (gap {gap * 1000:.2f} mm)", pinch, (10.0, 20.0)))
                    row[f"thumb-{finger} gap (mm)"] = round(gap * 1000, 3)
        path = out_dir / f"{name}.png"
        render_robot(robot, panels, path)
        row["picture"] = str(path)
        rows.append(row)
    headers = ["robot", "links", "movable joints", "chains", "DOF", "picture"]
    print(format_table(headers, [[r[h] for h in headers] for r in rows]))
    gaps = [f"{k} {r[k]}" for r in rows for k in r if k.endswith("gap (mm)")]
    if gaps:
        print("opposition: " + ", ".join(gaps))
    return rows


