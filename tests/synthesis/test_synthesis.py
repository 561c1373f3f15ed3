"""Pad contact sets and synthesize_grasps: independent re-checks of what they return."""

from __future__ import annotations

import numpy as np
import pytest
import torch

import graspnet_torch as gt
from graspnet_torch.collision.scene import CollisionScene
from graspnet_torch.collision.surface import pad_targets, surface_distance, surface_normals
from graspnet_torch.robot import load_robot_cfg
from graspnet_torch.robot.shape import Shape
from graspnet_torch.robot.transforms import pose_to_matrix_np
from graspnet_torch.solver.contact import surface_fields
from graspnet_torch.solver.postures import trial_posture
from graspnet_torch.synthesis import pad_contact_sets
from graspnet_torch.synthesis.candidates import placeholder_problem
from graspnet_torch.synthesis.closing import close_lines, closing_lines

FINGERS = ("thumb", "index", "middle")


@pytest.fixture(scope="module")
def robot() -> gt.Robot:
    return gt.load_robot("hand")


def cube() -> Shape:
    return Shape("box", (0.06, 0.06, 0.06), np.array([0.0, 0.0, 0.2, 0.0, 0.0, 0.0]))


def tip_pose(robot: gt.Robot, posture: gt.Posture, finger: str) -> np.ndarray:
    """The tip frame (4, 4) of a finger from the URDF link frames, tip offset applied."""
    T = robot.link_frames(posture)[robot.cfg.fingers[finger].tip].copy()
    offset = robot.cfg.fingers[finger].tip_offset
    if offset is not None:
        T[:3, 3] += T[:3, :3] @ np.asarray(offset)
    return T


@pytest.mark.parametrize("obj", [cube(), Shape("sphere", (0.04,), np.array([0.0, 0.0, 0.2, 0.0, 0.0, 0.0]))],
                         ids=["box", "sphere"])
def test_pad_contact_sets_touch_face_and_stay_out(robot: gt.Robot, obj: Shape) -> None:
    sets = pad_contact_sets(robot, obj, 4, FINGERS, seed=3)
    assert sets
    problem = placeholder_problem(robot, obj, FINGERS)
    scene = CollisionScene(robot, problem, object_tolerance=0.001, touching=False, fingers_apart=True)
    for s in sets:
        assert s.contacts.shape == (3, 3) and s.normals.shape == (3, 3)
        assert np.all(np.abs(surface_distance(obj, s.contacts)) < 1e-3)
        inward = -surface_normals(obj, s.contacts)
        for k, f in enumerate(FINGERS):
            T = tip_pose(robot, s.posture, f)
            pad = robot.pads[f]
            assert abs(np.linalg.norm(s.contacts[k] - T[:3, 3]) - pad.depth) < 1e-3  # the pad sphere touches
            angle = np.degrees(np.arccos(np.clip((T[:3, :3] @ pad.normal) @ inward[k], -1, 1)))
            assert angle <= 30.0 + 1e-6
        assert scene.check(s.posture).count == 0


@pytest.mark.parametrize("mesh", ["blob", "glass"])
def test_sampled_tips_sit_on_the_surface_models_targets(robot: gt.Robot, mesh: str, tmp_path) -> None:
    """On a mesh (edges where faces turn), every set's tips lie where the surface model's solver
    puts them for its contacts (pad_targets: the pad's depth out along the surface normal), the
    fingers not chosen at home: the sampled posture is a start the solver accepts."""
    import trimesh

    if mesh == "blob":  # a low-poly non-convex blob: sharp edges everywhere
        blob = trimesh.creation.icosphere(subdivisions=1, radius=0.035)
        blob.vertices *= np.random.default_rng(1).uniform(0.8, 1.2, (len(blob.vertices), 1))
        blob.export(tmp_path / "blob.stl")
        obj = Shape("mesh", (), np.array([0.0, 0.0, 0.2, 0.0, 0.0, 0.0]), tmp_path / "blob.stl", 1.0)
    else:
        obj = gt.GraspProblem.from_task("glass3").object
    sets = pad_contact_sets(robot, obj, 6, FINGERS, seed=2)
    assert sets
    home = robot.home_posture(torch.float64).fingers.numpy()
    others = [i for i, f in enumerate(robot.fingers) if f not in FINGERS]
    for s in sets:
        problem = placeholder_problem(robot, obj, FINGERS, s.contacts)
        tips = np.stack([tip_pose(robot, s.posture, f)[:3, 3] for f in FINGERS])
        assert np.linalg.norm(tips - pad_targets(robot, problem), axis=1).max() <= 1e-3
        np.testing.assert_array_equal(s.posture.fingers.numpy()[others], home[others])


@pytest.mark.slow
def test_sampled_starts_land_where_random_ones_search(robot: gt.Robot) -> None:
    """start="sampled" solves each set from its sampled posture (one trial) and stops at n_grasps
    successes; start="random" searches (``trials`` trials): both give grasps of the same cube."""
    obj = cube()
    stats: dict = {}
    warm = gt.synthesize_grasps(robot, obj, n_grasps=2, candidates=8, seed=0, stats=stats)
    assert len(warm) == 2 and stats["succeeded"] == 2 and stats["solved"] <= 8
    assert all(len(g.result.trials) == 1 and g.success for g in warm)
    cold = gt.synthesize_grasps(robot, obj, n_grasps=2, candidates=8, seed=0, start="random", trials=4)
    assert cold and all(len(g.result.trials) == 4 and g.success for g in cold)
    with pytest.raises(gt.ProblemError, match="start 'warm'"):
        gt.synthesize_grasps(robot, obj, start="warm")


def test_learned_proposals_seed_the_search(robot: gt.Robot) -> None:
    """start="proposal": the same sets searched with the trials started at the hand's learned
    posture proposals: grasps of the cube, other postures than the random starts reach."""
    obj = cube()
    cold = gt.synthesize_grasps(robot, obj, n_grasps=2, candidates=8, seed=0, start="random", trials=4)
    seeded = gt.synthesize_grasps(robot, obj, n_grasps=2, candidates=8, seed=0, start="proposal", trials=4)
    assert seeded and all(len(g.result.trials) == 4 and g.success for g in seeded)
    same = [(a, b) for a in cold for b in seeded if np.array_equal(a.contacts, b.contacts)]
    assert same  # the same contact sets, ranked alike
    for a, b in same:
        for ta, tb in zip(a.result.trials, b.result.trials, strict=True):
            assert not torch.allclose(trial_posture(robot, ta).fingers, trial_posture(robot, tb).fingers)


def test_a_warm_start_without_search_is_one_trial(robot: gt.Robot) -> None:
    """Solver.solve(start=..., search=False): a start far from the contacts that does not land is
    the result (one trial, not a success, not retried centred); with the search it gets the
    search's trials."""
    obj = cube()
    problem = placeholder_problem(robot, obj, FINGERS, np.array([[0.0, 0.0, 0.23], [0.0, 0.03, 0.2],
                                                                  [0.0, -0.03, 0.2]]))
    far = gt.Posture(palm_pose=torch.tensor([0.5, 0.5, 0.5, 0.0, 0.0, 0.0], dtype=torch.float64),
                     fingers=robot.home_posture(torch.float64).fingers, body=torch.zeros(0, dtype=torch.float64))
    solver = gt.Solver(robot, trials=2, solver={"contact_model": "surface", "max_iterations": 5})
    alone = solver.solve(problem, start=far, search=False)
    assert len(alone.trials) == 1 and not alone.success
    # not retried from the start centred either: as a solver without the centring leaves it
    plain = gt.Solver(robot, trials=2, solver={"contact_model": "surface", "max_iterations": 5,
                                               "polish": {"centre": None}}).solve(problem, start=far, search=False)
    searched = solver.solve(problem, start=far)
    assert len(searched.trials) == 3  # the warm trial (retried centred), then the search's two
    assert torch.equal(trial_posture(robot, alone.best).fingers, trial_posture(robot, plain.best).fingers)
    assert not torch.equal(trial_posture(robot, alone.best).fingers, trial_posture(robot, searched.trials[0]).fingers)


@pytest.mark.slow
def test_pad_contact_sets_deterministic(robot: gt.Robot) -> None:
    obj = gt.GraspProblem.from_task("glass3").object
    a = pad_contact_sets(robot, obj, 2, FINGERS, seed=5)
    b = pad_contact_sets(robot, obj, 2, FINGERS, seed=5)
    c = pad_contact_sets(robot, obj, 2, FINGERS, seed=6)
    assert len(a) == len(b) == 2
    for x, y in zip(a, b, strict=True):
        np.testing.assert_array_equal(x.contacts, y.contacts)
        np.testing.assert_array_equal(x.posture.fingers.numpy(), y.posture.fingers.numpy())
    assert not np.allclose(a[0].contacts, c[0].contacts)


def test_contact_problem_in_object_frame(robot: gt.Robot) -> None:
    obj = Shape("box", (0.06, 0.04, 0.08), np.array([0.05, -0.02, 0.2, 0.3, -0.2, 0.7]))
    pts = np.array([[0.05, -0.02, 0.24], [0.08, -0.02, 0.2], [0.02, -0.02, 0.2]])
    problem = placeholder_problem(robot, obj, FINGERS, pts)
    np.testing.assert_allclose(problem.contacts_world(), pts, atol=1e-9)
    assert np.allclose(pose_to_matrix_np(problem.object.pose), pose_to_matrix_np(obj.pose))


@pytest.mark.slow
def test_synthesize_grasps_box(robot: gt.Robot) -> None:
    obj = cube()
    grasps = gt.synthesize_grasps(robot, obj, n_grasps=2, candidates=8, seed=0)
    assert grasps
    for g in grasps:
        assert g.success and g.quality.min_singular_value > 0
        trial = g.result.best
        posture = trial_posture(robot, trial)
        fields = surface_fields(robot, g.problem, [posture])[0]  # re-measured from the reported posture
        assert max(fields["pad_distance_mm"].values()) < 1.0
        assert max(fields["normal_angle_deg"].values()) <= 30.0 + 1e-6
        assert fields["penetration_mm"] <= 1.0 + 1e-6
        np.testing.assert_allclose(g.problem.contacts_world(), g.contacts, atol=1e-9)


def test_a_force_closure_set_is_solved_before_one_that_is_not(robot: gt.Robot, monkeypatch) -> None:
    """A plate whose first batch of palm poses brings no force-closure set (seed 3): the search
    draws another batch before it solves (``LOOK_AHEAD``), and its first grasp is force closure;
    without the look-ahead it solves the first batch's best, which is not."""
    from graspnet_torch.synthesis import synthesize

    plate = Shape("box", (0.03, 0.09, 0.15), np.array([0.0, 0.0, 0.2, 0.0, 0.0, 0.0]))
    firsts, default = {}, synthesize.LOOK_AHEAD
    assert default > 0
    for ahead in (default, 0):
        monkeypatch.setattr(synthesize, "LOOK_AHEAD", ahead)
        stats: dict = {}
        grasps = gt.synthesize_grasps(robot, plate, n_grasps=1, candidates=8, seed=3, stats=stats)
        assert stats["solved"] == 1 and grasps
        firsts[ahead] = (grasps[0].quality.force_closure, stats["tried"])
    assert firsts[0] == (False, 64)  # one batch of palm poses drawn
    assert firsts[default][0] and firsts[default][1] > 64


def test_drafts_are_checked_as_they_come_up_and_every_solved_set_passed(robot: gt.Robot) -> None:
    """The search checks a draft (the solver's normals, the FCL scene) only when it comes to the top
    of the pool: far fewer checked than drafted; every grasp's set carries the normals the check
    gives, the surface model's at its contacts, and holds its pads within the cone."""
    stats: dict = {}
    obj = Shape("cylinder", (0.03, 0.1), np.array([0.0, 0.0, 0.2, 0.0, 0.0, 0.0]))
    grasps = gt.synthesize_grasps(robot, obj, n_grasps=1, candidates=4, seed=1, stats=stats)
    assert grasps and stats["drafts"] >= 20  # seed 1: two batches of palm poses
    assert stats["facing"] <= stats["drafts"] / 10
    for g in grasps:
        np.testing.assert_allclose(g.candidate.normals, -surface_normals(obj, g.contacts), atol=1e-12)
        assert np.all(g.candidate.angles_deg <= 30.0)


def test_closing_lines_move_each_pad_forward(robot: gt.Robot) -> None:
    """Every finger's closing line starts by pushing its pad along the pad normal, the thumb's too
    (its pad faces the fingers, off its flexion side); and a seed gives the same lines."""
    lo, hi = robot.finger_limits
    q0, q1 = closing_lines(robot, lo, hi - lo, np.random.default_rng(0), 32)
    again = closing_lines(robot, lo, hi - lo, np.random.default_rng(0), 32)
    np.testing.assert_array_equal(q0.numpy(), again[0].numpy())
    np.testing.assert_array_equal(q1.numpy(), again[1].numpy())
    assert np.all(q0.numpy() >= lo - 1e-12) and np.all(q1.numpy() <= hi + 1e-12)
    names, frames = robot.link_frames_of(None, q0, torch.zeros(len(q0), 6, dtype=torch.float64))
    R = frames[:, [names.index(robot.cfg.fingers[f].tip) for f in robot.fingers], :3, :3]
    normal = np.einsum("nfij,fj->nfi", R, np.stack([robot.pads[f].normal for f in robot.fingers]))
    step = robot.fingertips_palm(q0 + 0.05 * (q1 - q0)).numpy() - robot.fingertips_palm(q0).numpy()
    cos = np.sum(step * normal, axis=-1) / np.linalg.norm(step, axis=-1)
    assert cos.min() > 0.9


def test_closing_only_the_chosen_fingers_closes_them_as_closing_every_finger_does(robot: gt.Robot) -> None:
    """close_lines on some fingers: those fingers' touching joints and verdicts are those of
    closing every finger (each finger's pad moves with its own joints only); the others are left
    closed and not touching. And a touching pad lies on the surface (its sphere's gap under 1 mm)."""
    obj = cube()
    lo, hi = robot.finger_limits
    q0, q1 = closing_lines(robot, lo, hi - lo, np.random.default_rng(0), 64)
    head = pad_contact_sets(robot, obj, 1, FINGERS, seed=3)[0].posture.palm_pose.expand(64, 6)  # a palm that touches
    depth = np.array([robot.pads[f].depth for f in robot.fingers])
    q_all, touched_all = close_lines(robot, obj, head, q0, q1, depth)
    rows = [0, 2]
    q_some, touched_some = close_lines(robot, obj, head, q0, q1, depth, rows)
    assert touched_all[:, rows].any()
    np.testing.assert_array_equal(q_some[:, rows].numpy(), q_all[:, rows].numpy())
    np.testing.assert_array_equal(touched_some[:, rows], touched_all[:, rows])
    others = [i for i in range(len(robot.fingers)) if i not in rows]
    np.testing.assert_allclose(q_some[:, others].numpy(), q1[:, others].numpy(), atol=1e-12)
    assert not touched_some[:, others].any()
    tips = robot.fingertips_world(head, q_all).numpy()[touched_all]
    gaps = surface_distance(obj, tips) - np.broadcast_to(depth, touched_all.shape)[touched_all]
    assert np.all(np.abs(gaps) < 1e-3)


def test_a_robot_by_name_gives_what_the_built_robot_gives(robot: gt.Robot) -> None:
    """gt.synthesize_grasps and gt.baseline_grasps take a robot as gt.solve does (a shipped name,
    a config): the same grasps as from the built robot."""
    obj = cube()
    built = gt.synthesize_grasps(robot, obj, n_grasps=1, candidates=4, seed=1)
    named = gt.synthesize_grasps("hand", obj, n_grasps=1, candidates=4, seed=1)
    by_cfg = gt.synthesize_grasps(load_robot_cfg("hand"), obj, n_grasps=1, candidates=4, seed=1)
    assert built and len(named) == len(by_cfg) == len(built)
    for a, b, c in zip(built, named, by_cfg, strict=True):
        np.testing.assert_array_equal(a.contacts, b.contacts)
        np.testing.assert_array_equal(a.contacts, c.contacts)
    base = gt.baseline_grasps(robot, obj, n_grasps=1, candidates=4, seed=1)
    base_named = gt.baseline_grasps("hand", obj, n_grasps=1, candidates=4, seed=1)
    assert base and [g.touching for g in base] == [g.touching for g in base_named]


def test_a_table_under_the_object_is_kept_clear_of(robot: gt.Robot) -> None:
    """A 6 cm cube on a table: drawn without the table, some grasps put a link into it (FCL, the
    table as an obstacle); given the table, none does, and each still succeeds on the cube."""
    obj = cube()
    table = Shape("box", (0.4, 0.4, 0.1), np.array([0.0, 0.0, 0.12, 0.0, 0.0, 0.0]))  # its top at the cube's bottom
    on_table = placeholder_problem(robot, obj, FINGERS, None, (table,))
    scene = CollisionScene(robot, on_table, object_tolerance=0.001, touching=False, fingers_apart=True)

    def into_table(grasps) -> list[bool]:
        return [bool(scene.check(trial_posture(robot, g.result.best)).obstacle_pairs) for g in grasps]

    free = gt.synthesize_grasps(robot, obj, n_grasps=8, candidates=8, seed=0)
    assert any(into_table(free))
    kept = gt.synthesize_grasps(robot, obj, n_grasps=4, candidates=16, seed=0, obstacles=(table,))
    assert kept and not any(into_table(kept))
    assert all(g.success and g.result.best.collisions == 0 for g in kept)
    assert all(len(g.problem.obstacles) == 1 for g in kept)
