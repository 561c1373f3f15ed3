"""Pictures of a reach motion: a strip of moments (PNG) and an animation (GIF)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from graspnet_torch.io import atomic_path
from graspnet_torch.motion.trajectory import Trajectory
from graspnet_torch.motion.validity import StateLayout, state_postures
from graspnet_torch.robot.robot import Robot
from graspnet_torch.tasks.problem import GraspProblem
from graspnet_torch.viz.robot import Panel, render_robot

__all__ = ["motion_panels", "write_motion_frames", "write_reach_gif"]


def motion_panels(robot: Robot, problem: GraspProblem, motion: Trajectory, frames: int,
                  view: tuple[float, float] = (20.0, -135.0)) -> list[Panel]:
    """``frames`` panels at evenly spaced times of a motion (first and last included), with the
    object, the obstacles and the contacts."""
    rows = np.unique(np.searchsorted(motion.times, np.linspace(0.0, motion.times[-1], frames)).clip(
        0, len(motion.times) - 1))
    postures = state_postures(robot, StateLayout.of(robot), motion.positions[rows])
    meshes = tuple(s.trimesh() for s in ((problem.object,) if problem.object else ()) + problem.obstacles)
    marks = np.asarray(problem.contacts_world()) if problem.contacts else problem.points_world()
    return [Panel(f"t = {motion.times[k]:.2f} s", posture, view, marks, meshes)
            for k, posture in zip(rows, postures, strict=True)]


def write_motion_frames(robot: Robot, problem: GraspProblem, motion: Trajectory, path: str | Path,
                        frames: int = 4) -> Path:
    """A strip of ``frames`` moments of the motion (PNG, written atomically)."""
    return render_robot(robot, motion_panels(robot, problem, motion, frames), path)


def write_reach_gif(robot: Robot, problem: GraspProblem, motion: Trajectory, path: str | Path,
                    frames: int = 16, seconds_per_frame: float | None = None) -> Path:
    """An animated GIF of the motion: ``frames`` moments at evenly spaced times, played at the
    motion's own pace (or ``seconds_per_frame``), the last held; written atomically."""

    images = [_png(robot, panel) for panel in motion_panels(robot, problem, motion, frames)]
    pace = seconds_per_frame or max(0.05, float(motion.times[-1]) / max(1, len(images) - 1))
    durations = [int(pace * 1000)] * (len(images) - 1) + [1500]
    first, rest = images[0], images[1:]
    with atomic_path(path, suffix=".gif") as tmp:
        first.save(tmp, format="GIF", save_all=True, append_images=rest, duration=durations, loop=0)
    return Path(path)


def _png(robot: Robot, panel: Panel):
    """One panel drawn into a PIL image (through a temporary PNG)."""
    import tempfile

    from PIL import Image

    with tempfile.TemporaryDirectory() as folder:
        with Image.open(render_robot(robot, [panel], Path(folder) / "frame.png")) as image:
            return image.convert("P", palette=Image.ADAPTIVE)
