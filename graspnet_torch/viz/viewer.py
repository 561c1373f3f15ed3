"""An interactive 3D view of a result in the browser (viser): the robot at any trial's posture,
the object, the obstacles, the contacts (a gripper: the object's points and its own), colliding
links red, a slider that replays a trial over its iterations when the run kept them
(``solver.history_postures=true``: ``replay.json``), and one that replays the reach motion when
the result has one. A result whose contacts were chosen on the object (``contacts: auto``, or
one object's result of ``synthesize_grasps.py``) shows its grasps instead of trials, each with its
contacts and friction cones (:mod:`graspnet_torch.viz.grasp_view`).

``python scripts/view.py outputs/demo`` (a run folder, or a result JSON) serves the page on
localhost and runs until stopped. The robot is drawn from the same shapes as ``posture.png``
(collision geometry, else visual); what a link collides with is FCL's verdict on the posture
shown (:class:`~graspnet_torch.collision.CollisionScene`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from types import SimpleNamespace
from typing import TYPE_CHECKING, Any

import numpy as np

from graspnet_torch.collision import CollisionScene
from graspnet_torch.collision.scene import has_environment
from graspnet_torch.errors import ProblemError
from graspnet_torch.files import read_document
from graspnet_torch.io import json_digest
from graspnet_torch.motion.trajectory import Trajectory
from graspnet_torch.motion.validity import StateLayout, state_postures
from graspnet_torch.robot.geometry import LinkShape
from graspnet_torch.robot.meshes import decimate
from graspnet_torch.robot.robot import Posture, Robot
from graspnet_torch.settings import clip
from graspnet_torch.solver.api import as_problem, robot_of
from graspnet_torch.solver.environments import environment_class
from graspnet_torch.solver.postures import trial_posture
from graspnet_torch.solver.result import GraspResult, TrialResult
from graspnet_torch.tasks.problem import GraspProblem
from graspnet_torch.viz.grasp_view import FRICTION, cone_mesh, grasp_contacts, grasp_problem
from graspnet_torch.viz.robot import drawable_shapes

if TYPE_CHECKING:
    import viser

__all__ = ["ResultView", "load_view", "serve"]

MAX_RESULT_BYTES = 64 << 20  # a result (or replay) the viewer reads: a reach motion of 50,000 rows of 27 joints
ROBOT_RGB, RED, OBJECT_RGB, OBSTACLE_RGB, MARK_RGB = (170, 180, 200), (230, 40, 40), (90, 150, 230), (150, 150, 150), \
    (240, 30, 30)
CONE_RGB = (250, 170, 40)


@dataclass
class ResultView:
    """What the viewer shows: a result (its JSON), its problem, robot, every trial's posture, the
    index of the reported (best) trial and, when the result has one, its reach motion; with a
    ``replay.json`` beside the result (``solver.history_postures=true``), every trial's posture
    over the iterations (``iterations``, and ``trials``: per iteration, per trial, its fields).
    A result of grasps on chosen contacts: its grasps are the trials (``result["trials"]``) and
    ``cones`` holds each one's contacts (k, 3) and the object's inward normals there (k, 3)."""

    path: Path
    result: dict[str, Any]
    problem: GraspProblem
    robot: Robot
    postures: list[Posture]
    best: int
    motion: Trajectory | None
    replay: dict[str, Any] | None = None
    cones: list[tuple[np.ndarray, np.ndarray]] | None = None


def load_view(path: str | Path) -> ResultView:
    """A run folder (its ``result.json``) or a result JSON -> :class:`ResultView`. Refuses
    (:class:`ProblemError`, one line) a missing file, one that is not a result, a result without
    its problem."""
    path = Path(path)
    file = path / "result.json" if path.is_dir() else path
    if not file.is_file():
        raise ProblemError(f"{path}: no result here (a run folder with result.json, or a result JSON file)")
    result = read_document(file, "result", ProblemError, max_bytes=MAX_RESULT_BYTES)
    if isinstance(result, dict) and isinstance(result.get("grasps"), list) and "trials" not in result:
        return _grasps_view(file, result)
    if not isinstance(result, dict) or not isinstance(result.get("trials"), list) or not result["trials"]:
        raise ProblemError(f"{file}: not a result of solve_grasp.py (no 'trials')")
    bad = next((k for k, t in enumerate(result["trials"]) if not isinstance(t, dict)), None)
    if bad is not None:
        raise ProblemError(f"{file}: trials[{bad}] is not a trial (a mapping of its palm pose or arm joints and "
                           f"finger joints)")
    if not result.get("problem") or not isinstance(result["problem"], str):
        raise ProblemError(f"{file}: the result does not name its problem ('problem'), so there is nothing to place")
    source = result["problem"]
    candidate = file.parent / source
    problem = as_problem(candidate if not Path(source).is_absolute() and candidate.is_file() else source)
    robot = robot_of(problem.robot_cfg or problem.robot)
    try:
        grasp = GraspResult.from_dict(result)
        postures = [trial_posture(robot, t) for t in grasp.trials]
    except (KeyError, TypeError, ValueError, AttributeError, IndexError) as exc:
        raise ProblemError(f"{file}: a trial does not fit robot '{robot.name}' ({clip(str(exc), 120)})") from None
    best = grasp.chosen if grasp.chosen is not None else 0  # the trial whose fields the top level reports
    motion = _motion(file, result.get("trajectory"), robot)
    replay = None
    if (file.parent / "replay.json").is_file():
        replay = read_document(file.parent / "replay.json", "replay", ProblemError, max_bytes=MAX_RESULT_BYTES)
        if not isinstance(replay, dict) or replay.get("problem") != result["problem"] or \
                replay.get("result") != json_digest(result["trials"]):
            raise ProblemError(f"{file.parent / 'replay.json'}: not the replay of this result (another problem or "
                               f"run; solve again with solver.history_postures=true)")
        if not isinstance(replay.get("iterations"), list) or not isinstance(replay.get("trials"), list) or \
                len(replay["iterations"]) != len(replay["trials"]) or \
                any(not isinstance(row, list) or len(row) != len(postures) for row in replay["trials"]):
            raise ProblemError(f"{file.parent / 'replay.json'}: not the replay of this result (iterations x "
                               f"{len(postures)} trials)")
    return ResultView(file, result, problem, robot, postures, best, motion, replay)


def _grasps_view(file: Path, result: dict[str, Any]) -> ResultView:
    """The view of a result of grasps on chosen contacts (module docstring); refused in one line
    when it has none or one does not fit its robot."""
    grasps = result["grasps"]
    if not grasps:
        raise ProblemError(f"{file}: no grasps to show ({clip(str(result.get('reason') or 'none found'), 160)})")
    bad = next((k for k, g in enumerate(grasps) if not isinstance(g, dict)), None)
    if bad is not None:
        raise ProblemError(f"{file}: grasps[{bad}] is not a grasp (a mapping of its result's fields)")
    problem = grasp_problem(file, result)
    robot = robot_of(problem.robot_cfg or problem.robot)
    try:
        postures = [trial_posture(robot, TrialResult.from_dict(g)) for g in grasps]
    except (KeyError, TypeError, ValueError, AttributeError, IndexError) as exc:
        raise ProblemError(f"{file}: a grasp does not fit robot '{robot.name}' ({clip(str(exc), 120)})") from None
    cones = [grasp_contacts(file, problem, g, k) for k, g in enumerate(grasps)]
    return ResultView(file, {**result, "trials": grasps}, problem, robot, postures, 0, None, None, cones)


def _motion(file: Path, data: Any, robot: Robot) -> Trajectory | None:
    """The result's reach motion (``trajectory`` when ``found``), refused in one line where it is
    not a motion of ``robot``."""
    if not isinstance(data, dict) or data.get("found") is not True:
        return None
    layout = StateLayout.of(robot)
    if data.get("joint_names") != list(layout.names):
        raise ProblemError(f"{file}: the trajectory's joint_names are not the planned joints of robot '{robot.name}'")
    try:
        motion = Trajectory.from_dict(data, layout.revolute)
    except (KeyError, TypeError, ValueError) as exc:
        raise ProblemError(f"{file}: the trajectory is not a motion ({clip(str(exc), 120)})") from None
    if len(motion.times) != len(motion.positions) or not np.all(np.isfinite(motion.positions)):
        raise ProblemError(f"{file}: the trajectory is not a motion (times and positions differ in length, or a "
                           f"position is not finite)")
    return motion


def _shape_mesh(shape: LinkShape):
    """A link shape as a trimesh in its own frame."""
    import trimesh

    if shape.kind == "box":
        return trimesh.creation.box(extents=shape.size)
    if shape.kind == "cylinder":
        return trimesh.creation.cylinder(radius=shape.size[0], height=shape.size[1], sections=24)
    if shape.kind == "sphere":
        return trimesh.creation.icosphere(subdivisions=2, radius=shape.size[0])

    return decimate(shape.mesh)  # as the pictures draw it


def _wxyz(R: np.ndarray) -> np.ndarray:
    from scipy.spatial.transform import Rotation

    x, y, z, w = Rotation.from_matrix(R).as_quat()
    return np.array([w, x, y, z])


class _Scene:
    """The viser scene of one view: one mesh per link shape, moved per posture."""

    def __init__(self, server: viser.ViserServer, view: ResultView):
        self.server, self.view = server, view
        self.shapes, _errors = drawable_shapes(view.robot)
        self.handles = []
        for i, shape in enumerate(self.shapes):
            mesh = _shape_mesh(shape)
            self.handles.append(server.scene.add_mesh_simple(
                f"/robot/{i:03d}_{shape.link}", np.asarray(mesh.vertices, dtype=np.float32),
                np.asarray(mesh.faces, dtype=np.uint32), color=ROBOT_RGB))
        problem = view.problem
        if problem.object is not None:
            mesh = problem.object.trimesh()
            server.scene.add_mesh_simple("/object", np.asarray(mesh.vertices, dtype=np.float32),
                                         np.asarray(mesh.faces, dtype=np.uint32), color=OBJECT_RGB, opacity=0.85)
        for k, obstacle in enumerate(problem.obstacles):
            mesh = obstacle.trimesh()
            server.scene.add_mesh_simple(f"/obstacles/{k}", np.asarray(mesh.vertices, dtype=np.float32),
                                         np.asarray(mesh.faces, dtype=np.uint32), color=OBSTACLE_RGB, opacity=0.8)
        self.marks: list = []
        self.cones: list = []  # a grasp's friction cones
        self.collisions = None
        if has_environment(view.robot, problem):
            self.collisions = CollisionScene(view.robot, problem)

    def show(self, posture: Posture, trial: dict[str, Any] | None,
             cones: tuple[np.ndarray, np.ndarray] | None = None) -> list[str]:
        """Place every link at the posture, its contacts marked (``cones``: a grasp's contacts and
        inward normals, with their friction cones); returns the colliding links (red)."""
        frames = self.view.robot.link_frames(posture)
        red: set[str] = set()
        if self.collisions is not None:
            report = self.collisions.check(posture)
            red = {link for link, _ in report.obstacle_pairs} | set(report.object_links) | \
                {link for pair in report.self_pairs for link in pair}
        for shape, handle in zip(self.shapes, self.handles, strict=True):
            T = frames[shape.link] @ shape.origin
            handle.position, handle.wxyz = T[:3, 3], _wxyz(T[:3, :3])
            handle.color = RED if shape.link in red else ROBOT_RGB
        if trial is not None:
            marks = environment_class(self.view.robot).marks(self.view.problem, SimpleNamespace(**trial)) \
                if cones is None else cones[0]
            for handle in self.marks + self.cones:
                handle.remove()
            self.marks = [self.server.scene.add_icosphere(f"/marks/{k}", radius=0.004, color=MARK_RGB, position=p)
                          for k, p in enumerate(np.asarray(marks))]
            self.cones = []
            for k, (contact, inward) in enumerate(zip(*cones, strict=True) if cones is not None else ()):
                vertices, faces = cone_mesh(contact, inward, FRICTION)  # in the world: the handle at the origin
                self.cones.append(self.server.scene.add_mesh_simple(
                    f"/cones/{k}", vertices.astype(np.float32), faces.astype(np.uint32), color=CONE_RGB,
                    opacity=0.45))
        return sorted(red)


def serve(view: ResultView, host: str = "127.0.0.1", port: int = 8080) -> viser.ViserServer:
    """Serve the view (module docstring) at http://host:port; returns the running server (stop it
    with ``server.stop()``)."""
    import viser

    server = viser.ViserServer(host=host, port=port, verbose=False)
    server.scene.set_up_direction("+z")
    scene = _Scene(server, view)
    result, trials = view.result, view.result["trials"]
    info = server.gui.add_markdown("")
    labels = [f"{k}{' (reported)' if k == view.best else ''}: {_summary(t)}" for k, t in enumerate(trials)]
    pick = server.gui.add_dropdown("trial" if view.cones is None else f"grasp (friction cones at mu {FRICTION:g})",
                                   labels, initial_value=labels[view.best])

    def show_trial(k: int) -> None:
        red = scene.show(view.postures[k], trials[k], None if view.cones is None else view.cones[k])
        info.content = (f"**{view.robot.name}** on **{result.get('problem')}** - trial {k} of {len(trials)}: "
                        f"{_summary(trials[k])}" + (f"; colliding (red): {', '.join(red)}" if red else ""))

    @pick.on_update
    def _(_event) -> None:
        show_trial(labels.index(pick.value))

    show_trial(view.best)
    _frame_camera(server, scene, view)
    if view.replay is not None:
        steps = view.replay["iterations"]
        iteration = server.gui.add_slider("iteration (replay)", 0, len(steps) - 1, 1, len(steps) - 1,
                                          hint=f"the search at {len(steps)} iterations, {steps[0]} to {steps[-1]}")

        @iteration.on_update
        def _(_event) -> None:
            k = labels.index(pick.value)
            fields = view.replay["trials"][int(iteration.value)][k]
            red = scene.show(trial_posture(view.robot, fields), None)
            info.content = (f"trial {k} at iteration {steps[int(iteration.value)]}: error "
                            f"{fields.get('total_error_mm', fields.get('distance_mm', float('nan'))):.3g} mm"
                            + (f"; colliding (red): {', '.join(red)}" if red else ""))
    if view.motion is not None:
        motion = view.motion

        layout = StateLayout.of(view.robot)
        slider = server.gui.add_slider("reach motion (s)", 0.0, float(motion.times[-1]), 0.02,
                                       float(motion.times[-1]))

        @slider.on_update
        def _(_event) -> None:
            row = int(np.clip(np.searchsorted(motion.times, slider.value), 0, len(motion.times) - 1))
            scene.show(state_postures(view.robot, layout, motion.positions[row: row + 1])[0], None)

    return server


def _frame_camera(server: viser.ViserServer, scene: _Scene, view: ResultView) -> None:
    """The first view: looking at the box around the robot's links, the object, the obstacles and
    the marks, from the front-left and above, far enough to hold it all."""
    points = [np.asarray(h.position, dtype=np.float64) for h in scene.handles + scene.marks]
    for shape in ((view.problem.object,) if view.problem.object is not None else ()) + view.problem.obstacles:
        points += list(np.asarray(shape.trimesh().bounds, dtype=np.float64))
    cloud = np.stack(points) if points else np.zeros((1, 3))
    lo, hi = cloud.min(0), cloud.max(0)
    centre, size = (lo + hi) / 2, max(float(np.linalg.norm(hi - lo)), 0.1)
    direction = np.array([1.0, -1.4, 0.8]) / np.linalg.norm([1.0, -1.4, 0.8])
    server.initial_camera.look_at = centre
    server.initial_camera.position = centre + 1.3 * size * direction
    server.initial_camera.up = (0.0, 0.0, 1.0)
    server.initial_camera.near = 0.005


def _summary(trial: dict[str, Any]) -> str:
    error = trial.get("total_error_mm", trial.get("distance_mm"))
    ok = "solved" if trial.get("success") else "not solved"
    text = f"{ok}, error {error:.3g} mm" if isinstance(error, (int, float)) and math.isfinite(error) else ok
    text += f", {trial.get('collisions', 0)} collision(s)"
    quality, holds = trial.get("quality"), trial.get("holds")
    if isinstance(quality, dict) and isinstance(quality.get("epsilon"), (int, float)):  # a grasp on chosen contacts
        text += f", epsilon {quality['epsilon']:.4f}"
    return text + (f", holds {holds}/6" if isinstance(holds, int) else "")

