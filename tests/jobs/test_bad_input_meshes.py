"""Bad and hostile mesh files, as a problem's object and as a robot's link: each is refused before
any work with exit 2, one line naming the file (and the line of a bad OBJ vertex), no traceback and
nothing written; an archive that inflates to 1 GiB and a 2-million-face mesh are refused small.
An odd but usable mesh (a few degenerate faces) runs to a result."""

from __future__ import annotations

import json
import os
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest
import trimesh
import yaml

import graspnet_torch as gt
from graspnet_torch.meshes import FACES_VARIABLE, MAX_MESH_FACES, check_mesh_file
from graspnet_torch.paths import repo_root
from graspnet_torch.tasks.objects import REAL_OBJECTS, real_objects
from tests.in_process import run_script
from tests.mesh_robots import mesh_hand_urdf, write_robot
from tests.processes import run_measured
from tests.refusals import refused, refused_in_a_fresh_process, write_problem

GLASS3 = (repo_root() / "configs" / "task" / "glass3.yaml").read_text()
CYLINDER = "shape: cylinder\n  size: [0.0325, 0.12]"
BOX_OBJ = trimesh.exchange.obj.export_obj(trimesh.creation.box(extents=(0.065, 0.065, 0.12)))


@pytest.fixture(autouse=True)
def _cache(tmp_path, monkeypatch):
    """Convex pieces go to the test's own cache; the face limit is the default."""
    monkeypatch.setenv("GRASPNET_TORCH_CACHE", str(tmp_path / "cache"))
    monkeypatch.delenv(FACES_VARIABLE, raising=False)


def mesh_problem(tmp_path: Path, mesh: str, scale: float | None = None) -> Path:
    """glass3 with its object a mesh file of ``tmp_path``."""
    extra = f"\n  scale: {scale}" if scale is not None else ""
    return write_problem(tmp_path, GLASS3.replace(CYLINDER, f"shape: mesh\n  size: {mesh}{extra}"))


def bad_vertex_obj(value: str) -> str:
    """The box OBJ with its first vertex's x replaced by ``value``."""
    lines = BOX_OBJ.splitlines()
    k = next(i for i, line in enumerate(lines) if line.startswith("v "))
    lines[k] = f"v {value} 0 0"
    return "\n".join(lines) + "\n"


def vertex_line(text: str) -> int:
    return next(i for i, line in enumerate(text.splitlines()) if line.startswith("v ")) + 1


@pytest.fixture(scope="module")
def bombs(tmp_path_factory) -> dict[str, Path]:
    """A 1 MiB zip that inflates to 1 GiB (zeros) and a 38 MB binary PLY torus of 2,000,000
    triangles (non-convex), made at run time."""
    folder = tmp_path_factory.mktemp("bombs")
    zipped = folder / "cup.zip"
    with zipfile.ZipFile(zipped, "w", compression=zipfile.ZIP_DEFLATED) as z, \
            z.open("cup.stl", "w", force_zip64=True) as fh:
        chunk = bytes(1 << 24)
        for _ in range(64):
            fh.write(chunk)
    n = 1000  # a torus on an n x n grid: n^2 vertices, 2 n^2 triangles
    u, v = np.meshgrid(*[np.linspace(0, 2 * np.pi, n, endpoint=False)] * 2)
    r = 0.05 + 0.02 * np.cos(v)
    vertices = np.stack([r * np.cos(u), r * np.sin(u), 0.02 * np.sin(v)], -1).reshape(-1, 3).astype("<f4")
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    a, b = i * n + j, i * n + (j + 1) % n
    c, d = ((i + 1) % n) * n + j, ((i + 1) % n) * n + (j + 1) % n
    faces = np.zeros(2 * n * n, dtype=[("n", "u1"), ("i", "<i4", (3,))])
    faces["n"] = 3
    faces["i"] = np.concatenate([np.stack([a, b, d], -1).reshape(-1, 3), np.stack([a, d, c], -1).reshape(-1, 3)])
    ply = folder / "torus.ply"
    header = (f"ply\nformat binary_little_endian 1.0\nelement vertex {len(vertices)}\nproperty float x\n"
              f"property float y\nproperty float z\nelement face {len(faces)}\n"
              "property list uchar int vertex_indices\nend_header\n")
    with open(ply, "wb") as fh:
        fh.write(header.encode())
        fh.write(vertices.tobytes())
        fh.write(faces.tobytes())
    return {"zip": zipped, "ply": ply}


# ------------------------------------------------------------------ a problem's mesh
@pytest.mark.parametrize("value", ["nan", "inf", "-1e400"])
def test_an_obj_vertex_that_is_not_finite_is_refused_with_its_line(tmp_path, value):
    text = bad_vertex_obj(value)
    (tmp_path / "cup.obj").write_text(text)
    refused(tmp_path, "solve_grasp.py", f"problem={mesh_problem(tmp_path, 'cup.obj')}", f"out={tmp_path / 'r.json'}",
            message=f"object.size: cup.obj has a vertex that is not a finite number (line {vertex_line(text)})")
    assert not (tmp_path / "r.json").exists()


@pytest.mark.parametrize(("mesh", "scale", "message"), [
    ("v 0 0 0\nv 0.01 0 0\nv 0.02 0 0\nv 0 0.05 0\nf 1 2 3\nf 1 1 4\n", None,
     "cup.obj has no triangle with an area (every one is degenerate)"),
    ("v 0 0 0\nv 0.05 0 0\nv 0 0.05 0\nf 1 2 3\n", None,
     "cup.obj is 0 m thick across its thinnest direction at scale 1"),
    ("v 0 0 0\nv 0.05 0 0\nv 0 0.05 0\nv 0.05 0.05 0\nf 1 2 3\nf 2 4 3\n", None,
     "cup.obj is 0 m thick across its thinnest direction"),
    (BOX_OBJ, 1e-12, "cup.obj is 6.5e-14 m thick across its thinnest direction at scale 1e-12"),
    (BOX_OBJ, 200, "cup.obj has vertices beyond +-10 m at scale 200"),
    (BOX_OBJ + "f 1 2 99\n", None, "cup.obj is not a mesh trimesh can read"),
])
def test_meshes_that_enclose_no_volume_are_refused_before_the_decomposition(tmp_path, mesh, scale, message):
    (tmp_path / "cup.obj").write_text(mesh)
    refused(tmp_path, "solve_grasp.py", f"problem={mesh_problem(tmp_path, 'cup.obj', scale)}", message=message)
    assert not (tmp_path / "cache").exists()  # nothing decomposed


def test_a_zip_that_inflates_to_a_gibibyte_is_refused_small(tmp_path, bombs):
    os.link(bombs["zip"], tmp_path / "cup.zip")
    line = refused_in_a_fresh_process(tmp_path, "solve_grasp.py", f"problem={mesh_problem(tmp_path, 'cup.zip')}",
                                      message="object.size: cup.zip is an archive (.zip)", max_bytes=2 << 30)
    assert "name the mesh file itself" in line


@pytest.mark.parametrize("name", ["cup.tar.gz", "cup.3mf", "cup.bz2"])
def test_every_archive_trimesh_would_unpack_is_refused(tmp_path, name):
    (tmp_path / name).write_bytes(b"\x1f\x8b" + bytes(100))
    refused(tmp_path, "solve_grasp.py", f"problem={mesh_problem(tmp_path, name)}", message=f"{name} is an archive")


def test_an_archive_named_as_a_mesh_is_refused(tmp_path, bombs):
    os.link(bombs["zip"], tmp_path / "cup.stl")
    refused(tmp_path, "solve_grasp.py", f"problem={mesh_problem(tmp_path, 'cup.stl')}",
            message="object.size: cup.stl is a zip archive, not a mesh")


def test_a_two_million_face_mesh_is_refused_small_naming_the_setting(tmp_path, bombs):
    os.link(bombs["ply"], tmp_path / "cup.ply")
    refused_in_a_fresh_process(
        tmp_path, "solve_grasp.py", f"problem={mesh_problem(tmp_path, 'cup.ply')}", max_bytes=2 << 30,
        message=f"cup.ply has 2000000 triangles, more than the {MAX_MESH_FACES} allowed (set the environment "
                f"variable {FACES_VARIABLE} to raise it)")


def test_an_obj_with_too_many_faces_is_counted_before_it_is_parsed(tmp_path):
    (tmp_path / "cup.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\n" + "f 1 2 3\n" * 250_000)
    refused(tmp_path, "solve_grasp.py", f"problem={mesh_problem(tmp_path, 'cup.obj')}",
            message=f"cup.obj has 250000 triangles, more than the {MAX_MESH_FACES} allowed")
    (tmp_path / "fan.obj").write_text("v 0 0 0\n" * 3 + "f " + " ".join(["1"] * (MAX_MESH_FACES + 3)) + "\n")
    refused(tmp_path, "solve_grasp.py", f"problem={mesh_problem(tmp_path, 'fan.obj')}",
            message=f"fan.obj has {MAX_MESH_FACES + 1} triangles")  # one polygon, cut into a fan


def test_the_face_limit_is_raised_and_lowered_by_its_variable(tmp_path, monkeypatch):
    trimesh.creation.icosphere(subdivisions=5, radius=0.03).export(tmp_path / "ball.stl")  # 20480 faces
    path = mesh_problem(tmp_path, "ball.stl")
    assert gt.GraspProblem.from_file(path).object.kind == "mesh"
    monkeypatch.setenv(FACES_VARIABLE, "10000")
    refused(tmp_path, "solve_grasp.py", f"problem={path}", message="ball.stl has 20480 triangles, more than the 10000")
    monkeypatch.setenv(FACES_VARIABLE, "many")
    refused(tmp_path, "solve_grasp.py", f"problem={path}",
            message=f"{FACES_VARIABLE}=many: expected an integer in [1, 100000000]")


def test_a_side_file_is_read_only_when_small(tmp_path):
    """An OBJ's material file (mtllib) is read by trimesh; one of 1 GiB (sparse) is skipped."""
    with open(tmp_path / "big.mtl", "wb") as fh:
        fh.truncate(1 << 30)
    (tmp_path / "cup.obj").write_text("mtllib big.mtl\n" + BOX_OBJ)
    path = mesh_problem(tmp_path, "cup.obj")
    code = f"import graspnet_torch as gt; print(gt.GraspProblem.from_file({str(path)!r}).object.kind)"
    res, peak = run_measured([sys.executable, "-c", code], tmp_path / "peak.json", capture_output=True, text=True,
                             cwd=repo_root(), timeout=120)
    assert res.returncode == 0 and res.stdout.strip() == "mesh", res.stderr[-2000:]
    assert peak < 1 << 30, f"{peak / 2**20:.0f} MiB"


def test_a_mesh_with_a_few_degenerate_faces_runs_to_a_result(tmp_path):
    (tmp_path / "cup.obj").write_text(BOX_OBJ + "f 1 1 2\nf 3 3 3\n")
    out = tmp_path / "r.json"
    res = run_script("solve_grasp.py", f"problem={mesh_problem(tmp_path, 'cup.obj')}", "trials=1", "max_iterations=5",
                     f"out={out}", f"hydra.run.dir={tmp_path / 'run'}")
    assert res.returncode == 0, res.stderr[-2000:]
    assert len(json.loads(out.read_text())["trials"]) == 1


def test_the_meshes_the_repository_uses_pass_the_checks():
    """The real objects (solid) and pybullet_data's largest mesh (124,789 faces; a scene 140 m across,
    so scaled here to stay within +-10 m) are within the limits."""
    for name, (path, scale) in real_objects().items():
        check_mesh_file(path, name, gt.ProblemError, scale, solid=True)
    largest = real_objects()[next(iter(REAL_OBJECTS))][0].parent / "samurai_monastry.obj"
    if largest.is_file():
        check_mesh_file(largest, "samurai", gt.ConfigError, 0.1)


# ------------------------------------------------------------------ a robot's link mesh
def mesh_robot(tmp_path: Path, mesh: str) -> tuple[Path, Path]:
    """A two-finger hand whose palm is ``meshes/<mesh>``, and a problem for it: (robot, problem)."""
    robot = write_robot(tmp_path, mesh_hand_urdf(f'<mesh filename="meshes/{mesh}"/>'))
    problem = tmp_path / "p.yaml"
    problem.write_text(yaml.safe_dump({
        "robot": "meshhand.yaml", "object": {"shape": "box", "size": [0.04, 0.04, 0.04], "pose": [0, 0, 0.1, 0, 0, 0]},
        "contacts": [{"finger": "thumb", "position": [0.02, 0, 0]}, {"finger": "index", "position": [-0.02, 0, 0]}]}))
    return robot, problem


def test_a_zip_bomb_as_a_link_mesh_is_refused_small(tmp_path, bombs):
    (tmp_path / "meshes").mkdir()
    os.link(bombs["zip"], tmp_path / "meshes" / "palm.zip")
    robot, problem = mesh_robot(tmp_path, "palm.zip")
    refused_in_a_fresh_process(tmp_path, "solve_grasp.py", f"robot={robot}", f"problem={problem}", max_bytes=2 << 30,
                               message="meshhand.urdf: link 'palm' collision: mesh 'meshes/palm.zip': palm.zip is an "
                                       "archive (.zip)")


def test_a_link_mesh_with_a_nan_vertex_or_too_many_faces_is_refused(tmp_path, bombs):
    (tmp_path / "meshes").mkdir()
    text = bad_vertex_obj("nan")
    (tmp_path / "meshes" / "palm.obj").write_text(text)
    os.link(bombs["ply"], tmp_path / "meshes" / "palm.ply")
    robot, problem = mesh_robot(tmp_path, "palm.obj")
    refused(tmp_path, "solve_grasp.py", f"robot={robot}", f"problem={problem}",
            message=f"link 'palm' collision: mesh 'meshes/palm.obj': palm.obj has a vertex that is not a finite "
                    f"number (line {vertex_line(text)})")
    robot, problem = mesh_robot(tmp_path, "palm.ply")
    refused(tmp_path, "solve_grasp.py", f"robot={robot}", f"problem={problem}",
            message=f"mesh 'meshes/palm.ply': palm.ply has 2000000 triangles, more than the {MAX_MESH_FACES} allowed")


def test_a_flat_link_mesh_is_a_link_shape(tmp_path):
    """A link mesh is not cut into pieces (its proxy is a box's spheres): a single triangle loads."""
    (tmp_path / "meshes").mkdir()
    (tmp_path / "meshes" / "palm.obj").write_text("v 0 0 0\nv 0.05 0 0\nv 0 0.05 0\nf 1 2 3\n")
    robot, _ = mesh_robot(tmp_path, "palm.obj")
    assert gt.load_robot(robot).name == "meshhand"
