"""Grasp quality (graspnet_torch/quality.py): known answers, invariances, an independent recomputation."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
import torch
from scipy.optimize import linprog, minimize
from scipy.spatial.transform import Rotation

import graspnet_torch as gt
from graspnet_torch.errors import ProblemError
from graspnet_torch.quality import (
    GraspQuality,
    epsilon,
    ferrari_canny,
    force_closure,
    grasp_matrix,
    grasp_quality,
    min_singular_value,
    q1,
    torque_length,
)

TETRA = np.array([[1, 1, 1], [1, -1, -1], [-1, 1, -1], [-1, -1, 1]], dtype=np.float64) / math.sqrt(3)


def ring(k: int = 3, radius: float = 0.04) -> np.ndarray:
    """k contacts evenly around a cylinder's equator (axis z, centre at the origin): (k, 3)."""
    a = np.arange(k) * 2 * math.pi / k
    return radius * np.stack([np.cos(a), np.sin(a), np.zeros(k)], 1)


def inward(p: np.ndarray, c: np.ndarray | None = None) -> np.ndarray:
    """Unit normals from the contacts toward the centre (a sphere's or a cylinder's equator's)."""
    d = (np.zeros(3) if c is None else c) - p
    return d / np.linalg.norm(d, axis=-1, keepdims=True)


def perturbed_tetra(seed: int = 1) -> np.ndarray:
    """Four contacts near a tetrahedron on the unit sphere, no symmetry left: (4, 3)."""
    p = TETRA + 0.12 * np.random.default_rng(seed).normal(size=(4, 3))
    return p / np.linalg.norm(p, axis=1, keepdims=True)


def test_q1_of_known_wrench_sets():
    """The cross-polytope conv{+-e_i} has Q1 = 1 / sqrt(6) (facets x . s = 1, s in {+-1}^6) and the
    cube [-1, 1]^6 has Q1 = 1; moved off the origin it is 0 (signed: negative); flat (5-D) it is 0."""
    cross = np.concatenate([np.eye(6), -np.eye(6)], 1)
    assert q1(cross) == pytest.approx(1 / math.sqrt(6), abs=1e-12)
    cube = np.array(np.meshgrid(*[[-1.0, 1.0]] * 6)).reshape(6, -1)
    assert q1(cube) == pytest.approx(1.0, abs=1e-12)
    moved = cross + np.array([1.0, 0, 0, 0, 0, 0])[:, None] * 1.5
    assert q1(moved) == 0.0
    assert q1(moved, signed=True) < 0
    flat = cross.copy()
    flat[5] = 0.0
    assert q1(flat) == 0.0 and q1(flat, signed=True) == 0.0
    assert min_singular_value(flat) == pytest.approx(0.0, abs=1e-12)
    assert min_singular_value(cross) == pytest.approx(math.sqrt(2), abs=1e-12)
    assert min_singular_value(cross[:, :5]) == 0.0  # fewer than 6 columns


def test_an_antipodal_pinch_on_a_box_has_no_torque_about_its_axis():
    """Two point contacts on opposite faces of a box through its centre, mu = 0.6: the wrenches
    have no torque about the line joining them (rank 5), so Q1 = 0: no force closure (torsional
    friction is not modelled)."""
    p = np.array([[0.03, 0.0, 0.0], [-0.03, 0.0, 0.0]])
    n = np.array([[-1.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
    E = grasp_matrix(p, n, np.zeros(3), 0.6)
    assert E.shape == (6, 16)
    assert np.abs(E[3]).max() == 0.0  # torque about x
    assert np.linalg.matrix_rank(E) == 5
    assert epsilon(p, n, np.zeros(3), 0.6) == 0.0
    assert force_closure(p, n, np.zeros(3), 0.6) is False


def test_three_contacts_around_a_cylinder_close_with_friction_only():
    """Three contacts 120 degrees apart on a cylinder's equator: force closure at mu = 0.5 (Q1 > 0),
    none at mu = 0 (three normal forces span 3 of the 6 dimensions)."""
    p = ring(3)
    q = grasp_quality(p, inward(p), np.zeros(3), 0.5)
    assert isinstance(q, GraspQuality) and q.force_closure is True and q.epsilon > 0.1
    assert force_closure(p, inward(p), np.zeros(3), 0.5) is True
    q0 = grasp_quality(p, inward(p), np.zeros(3), 0.0)
    assert q0.epsilon == 0.0 and q0.force_closure is False
    assert q0.min_singular_value == pytest.approx(0.0, abs=1e-12)
    assert set(q.to_dict()) == {"epsilon", "min_singular_value"}
    assert q.to_dict()["epsilon"] == q.epsilon


def test_contacts_on_one_face_of_a_box_are_not_force_closure():
    """Three contacts on a box's top face, all pushing down (-z), mu = 0.5: nothing pulls up."""
    p = np.array([[0.02, 0.01, 0.05], [-0.02, 0.01, 0.05], [0.0, -0.015, 0.05]])
    n = np.tile([0.0, 0.0, -1.0], (3, 1))
    assert epsilon(p, n, np.zeros(3), 0.5) == 0.0
    assert force_closure(p, n, np.zeros(3), 0.5) is False


def test_a_tetrahedral_grasp_of_a_sphere_closes_and_epsilon_grows_with_friction():
    """Four contacts at a tetrahedron's vertices on a sphere: force closure with friction, and Q1
    strictly increasing over mu = 0.1, 0.3, 0.5, 0.8 (the cone edges at mu1 < mu2 lie in the hull
    of those at mu2, so the hull only grows); at mu = 0 it is 0 (no torque from normal forces)."""
    mus = [0.1, 0.3, 0.5, 0.8]
    eps = [epsilon(TETRA, inward(TETRA), np.zeros(3), mu) for mu in mus]
    assert all(e > 0 for e in eps)
    assert all(b > a + 1e-6 for a, b in itertools.pairwise(eps))
    assert epsilon(TETRA, inward(TETRA), np.zeros(3), 0.0) == 0.0
    batched = epsilon(np.stack([TETRA] * 4), np.stack([inward(TETRA)] * 4), np.zeros(3), np.array(mus))
    np.testing.assert_allclose(batched, eps, atol=1e-12)


def test_rigid_motion_and_scale_leave_epsilon_unchanged():
    """Rotating and translating contacts, normals, tangents and centre together: Q1 within 1e-9
    (the wrench set turns by diag(R, R)); translating alone with the default tangents: within 1e-9;
    scaling the object, contacts and torque length by s: within 1e-9 (default and given length)."""
    p, c = perturbed_tetra() * 0.05 + [0.01, -0.02, 0.03], np.array([0.01, -0.02, 0.03])
    n = inward(p, c)
    u = np.cross(n, np.random.default_rng(2).normal(size=(4, 3)))  # any tangents, turned with the set
    e0 = epsilon(p, n, c, 0.5, tangents=u)
    assert e0 > 0.05
    for seed in range(3):
        R = Rotation.random(random_state=seed).as_matrix()
        t = np.random.default_rng(seed).normal(size=3)
        e = epsilon(p @ R.T + t, n @ R.T, R @ c + t, 0.5, tangents=u @ R.T)
        assert abs(e - e0) < 1e-9
        e_default = epsilon(p @ R.T + t, n @ R.T, R @ c + t, 0.5)  # other edges: the linearisation moves
        assert abs(e_default - e0) < 0.1 * e0
    e1 = epsilon(p, n, c, 0.5)
    shift = np.array([0.3, -1.0, 2.0])
    assert abs(epsilon(p + shift, n, c + shift, 0.5) - e1) < 1e-9
    for s in (0.01, 7.0):
        assert abs(epsilon(s * p, n, s * c, 0.5) - e1) < 1e-9
        L = 0.08
        assert abs(epsilon(s * p, n, s * c, 0.5, length=s * L) - epsilon(p, n, c, 0.5, length=L)) < 1e-9


def test_epsilon_agrees_with_an_independent_support_function_search_and_a_linear_program():
    """Q1 = min over unit d of h(d) = max_ij d . w_ij, recomputed without Qhull: 200 000 sampled
    directions all have h(d) >= Q1; the epigraph problem min s, s >= d . w_ij, |d| = 1 (SLSQP from
    the 30 best samples) reaches Q1 to 1e-3; a linear program shooting a ray from the origin along
    that direction (max t: t d = sum lambda_ij w_ij, lambda >= 0, sum lambda = 1) leaves the hull
    at Q1 to 1e-3."""
    p = perturbed_tetra()
    W = grasp_matrix(p, inward(p), np.zeros(3), 0.5)
    eps = epsilon(p, inward(p), np.zeros(3), 0.5)
    assert eps > 0.1
    rng = np.random.default_rng(0)
    d = rng.normal(size=(200_000, 6))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    h = (d @ W).max(1)
    assert h.min() >= eps - 1e-12
    cons = [
        {"type": "ineq", "fun": lambda x: x[6] - x[:6] @ W, "jac": lambda x: np.c_[-W.T, np.ones(W.shape[1])]},
        {"type": "eq", "fun": lambda x: x[:6] @ x[:6] - 1, "jac": lambda x: np.r_[2 * x[:6], 0.0]},
    ]
    found = []
    for i in np.argsort(h)[:30]:
        r = minimize(
            lambda x: x[6],
            np.r_[d[i], h[i]],
            jac=lambda x: np.r_[np.zeros(6), 1.0],
            method="SLSQP",
            constraints=cons,
            options={"ftol": 1e-12, "maxiter": 500},
        )
        di = r.x[:6] / np.linalg.norm(r.x[:6])
        found.append(((di @ W).max(), di))
    h_min, d_min = min(found, key=lambda f: f[0])
    assert h_min >= eps - 1e-9 and abs(h_min - eps) < 1e-3
    N = W.shape[1]
    A_eq = np.c_[np.r_[W, np.ones((1, N))], np.r_[-d_min, 0.0]]
    lp = linprog(
        np.r_[np.zeros(N), -1.0],
        A_eq=A_eq,
        b_eq=np.r_[np.zeros(6), 1.0],
        bounds=[(0, None)] * N + [(None, None)],
        method="highs",
    )
    assert lp.status == 0 and abs(-lp.fun - eps) < 1e-3


def test_min_singular_value_is_the_cone_weighted_grasp_matrix_and_free_of_the_edge_count():
    """E E^T / m = G diag(n n^T + mu^2 / 2 (I - n n^T)) G^T with G = [I ; [p - c]x / L] (6, 3k), so
    sigma_min(E) / sqrt(m) is the same for m = 4, 8, 16 and equals that matrix's."""
    p, c = perturbed_tetra() * 0.05, np.array([0.001, 0.0, -0.002])
    n, mu = inward(p, c), 0.4
    L = torque_length(p, c)
    G = np.concatenate([np.concatenate([np.eye(3), np.cross(r, np.eye(3)).T / L], 0) for r in p - c], 1)
    M = np.zeros((12, 12))
    for i, ni in enumerate(n):
        M[3 * i : 3 * i + 3, 3 * i : 3 * i + 3] = np.outer(ni, ni) + mu**2 / 2 * (np.eye(3) - np.outer(ni, ni))
    ref = np.sqrt(np.linalg.eigvalsh(G @ M @ G.T)[0])
    for m in (4, 8, 16):
        E = grasp_matrix(p, n, c, mu, edges=m)
        np.testing.assert_allclose(E @ E.T / m, G @ M @ G.T, atol=1e-12)
        assert grasp_quality(p, n, c, mu, edges=m).min_singular_value == pytest.approx(ref, abs=1e-9)


def test_q1_equals_qhulls_default_hull_on_symmetric_and_random_sets():
    """Q1 is computed on Qhull's hull without pre-merged facets (the faster one); Qhull's default
    options (merged facets) give the same value, to 1e-12, on symmetric sets (a ring, a tetrahedron,
    evenly spaced cone edges: coplanar facets) and on 300 random ones, closed or not (signed)."""
    from scipy.spatial import ConvexHull

    rng = np.random.default_rng(5)
    p = rng.normal(size=(300, 3, 3)) * 0.03
    n = inward(p) + 0.4 * rng.normal(size=p.shape)
    sets = [(ring(3), inward(ring(3)), 0.5), (ring(4), inward(ring(4)), 0.3), (TETRA, inward(TETRA), 0.5)]
    sets += [(p[b], n[b], 0.6) for b in range(len(p))]
    closed = 0
    for c, nn, mu in sets:
        E = grasp_matrix(c, nn, np.zeros(3), mu)
        ref = float(np.min(-ConvexHull(E.T).equations[:, -1]))
        assert q1(E, signed=True) == pytest.approx(ref, abs=1e-12)
        closed += ref > 0
    assert 3 <= closed < len(sets)  # both kinds were compared


def test_torch_in_torch_out_batched_equals_one_at_a_time():
    """B sets in torch: (B,) float64 tensors, equal to the sets one at a time in numpy; to_dict lists."""
    sets = np.stack([TETRA, perturbed_tetra(1), perturbed_tetra(2), np.r_[ring(3, 1.0), [[0, 0, 1.0]]]])
    normals = np.stack([inward(s) for s in sets])
    q = grasp_quality(torch.tensor(sets), torch.tensor(normals), torch.zeros(3), 0.5)
    assert isinstance(q.epsilon, torch.Tensor) and q.epsilon.shape == (4,) and q.epsilon.dtype == torch.float64
    assert q.force_closure.dtype == torch.bool and q.force_closure.all()
    for b in range(4):
        one = grasp_quality(sets[b], normals[b], np.zeros(3), 0.5)
        assert abs(one.epsilon - float(q.epsilon[b])) < 1e-12
        assert abs(one.min_singular_value - float(q.min_singular_value[b])) < 1e-12
    d = q.to_dict()
    assert isinstance(d["epsilon"], list) and len(d["epsilon"]) == 4
    assert ferrari_canny is epsilon
    assert gt.grasp_quality is grasp_quality and GraspQuality is GraspQuality


def test_bad_inputs_say_what_is_wrong():
    p = ring(3)
    with pytest.raises(ProblemError, match="normals"):
        epsilon(p, inward(p)[:2], np.zeros(3), 0.5)
    with pytest.raises(ProblemError, match="friction"):
        epsilon(p, inward(p), np.zeros(3), -0.1)
    with pytest.raises(ProblemError, match="torque length"):
        epsilon(np.zeros((3, 3)), inward(p), np.zeros(3), 0.5)
