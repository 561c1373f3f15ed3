"""Link shapes from URDF geometry: meshes found by package://, installed packages, relative and
file:// URIs, loaded with their scale; a missing or unreadable mesh is one clear line; large
meshes are decimated for pictures without optional libraries."""

from __future__ import annotations

import numpy as np
import pytest

import graspnet_torch as gt
import graspnet_torch.tasks
from graspnet_torch.robot import UrdfModel
from graspnet_torch.robot.geometry import LinkShape, link_shapes
from graspnet_torch.robot.meshes import decimate, mesh_candidates
from graspnet_torch.robot.shape import Shape
from graspnet_torch.robot.transforms import pose_to_matrix_np
from tests.mesh_robots import PALM_EXTENTS, mesh_hand_urdf, write_box_mesh


def _model(folder, geometry: str, name: str = "meshhand") -> UrdfModel:
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"{name}.urdf"
    path.write_text(mesh_hand_urdf(geometry, name))
    return UrdfModel(path)


def _palm(model, source="collision"):
    return next(s for s in link_shapes(model, source) if s.link == "palm")


def test_package_uri_against_a_folder_named_like_the_package_with_scale(tmp_path):
    write_box_mesh(tmp_path / "my_hand" / "meshes" / "palm.stl")
    geometry = '<mesh filename="package://my_hand/meshes/palm.stl" scale="2 1 0.5"/>'
    model = _model(tmp_path / "my_hand" / "urdf", geometry)
    shape = _palm(model)
    assert shape.kind == "mesh" and shape.size == () and shape.shape.scale == (2.0, 1.0, 0.5)
    assert shape.shape.mesh.resolve() == (tmp_path / "my_hand" / "meshes" / "palm.stl").resolve()
    np.testing.assert_array_equal(shape.shape.pose, np.zeros(6))
    np.testing.assert_allclose(shape.shape.trimesh().bounds, shape.mesh.bounds, atol=1e-12)  # the one Shape's mesh
    np.testing.assert_allclose(shape.mesh.extents, np.multiply(PALM_EXTENTS, (2, 1, 0.5)), atol=1e-9)
    np.testing.assert_allclose(shape.origin, np.eye(4))
    assert _palm(model).mesh is shape.mesh  # loaded once, cached
    cylinders = [s for s in link_shapes(model) if s.kind == "cylinder"]
    assert len(cylinders) == 4


def test_one_shape_class_for_problems_and_links():
    """gt.Shape, graspnet_torch.tasks.Shape and a link's shape are one class; a link shape's origin
    is its shape's pose as a matrix, exactly; a placed primitive keeps its origin exact."""
    assert gt.Shape is Shape and graspnet_torch.tasks.Shape is Shape
    shapes = link_shapes(gt.load_robot("arm_hand").urdf)
    assert shapes and all(isinstance(s.shape, Shape) and s.kind == s.shape.kind for s in shapes)
    assert any(np.any(s.shape.pose) for s in shapes)
    for s in shapes:
        np.testing.assert_array_equal(s.origin, pose_to_matrix_np(s.shape.pose))
    origin = pose_to_matrix_np([0.1, -0.2, 0.3, 0.4, -0.5, 0.6]) @ pose_to_matrix_np([0, 0, 0, 0.7, 0.2, -0.1])
    placed = LinkShape.placed("l", "box", (0.1, 0.2, 0.3), origin)
    assert np.array_equal(placed.origin, origin) and placed.size == (0.1, 0.2, 0.3)
    np.testing.assert_allclose(pose_to_matrix_np(placed.shape.pose), origin, atol=1e-12)


def test_package_uri_against_an_installed_python_package(tmp_path, monkeypatch):
    package = tmp_path / "site" / "my_robot_description"
    (package / "__init__.py").parent.mkdir(parents=True)
    (package / "__init__.py").write_text("")
    write_box_mesh(package / "meshes" / "palm.obj", extents=(0.01, 0.02, 0.03))
    monkeypatch.syspath_prepend(str(tmp_path / "site"))
    model = _model(tmp_path / "elsewhere", '<mesh filename="package://my-robot-description/meshes/palm.obj"/>')
    np.testing.assert_allclose(_palm(model).mesh.extents, (0.01, 0.02, 0.03), atol=1e-6)


@pytest.mark.parametrize("uri", ["meshes/palm.stl", "file://{folder}/meshes/palm.stl", "{folder}/meshes/palm.stl",
                                 "package://unknown_pkg/meshes/palm.stl"])
def test_relative_absolute_file_and_stripped_package_uris(tmp_path, uri):
    write_box_mesh(tmp_path / "meshes" / "palm.stl")
    model = _model(tmp_path, f'<mesh filename="{uri.format(folder=tmp_path)}"/>')
    np.testing.assert_allclose(_palm(model).mesh.extents, PALM_EXTENTS, atol=1e-9)


def test_a_visual_mesh_with_a_material_colour(tmp_path):
    write_box_mesh(tmp_path / "palm.stl")
    path = tmp_path / "v.urdf"
    path.write_text(mesh_hand_urdf(None, "v", visual='<mesh filename="palm.stl"/>').replace(
        "</geometry></visual>", '</geometry><material name="red"><color rgba="1 0 0 1"/></material></visual>'))
    shape = _palm(UrdfModel(path), "visual")
    assert shape.kind == "mesh" and shape.rgba == (1.0, 0.0, 0.0, 1.0)


def test_a_missing_mesh_is_one_line_naming_the_link_the_uri_and_where_it_looked(tmp_path):
    model = _model(tmp_path / "robot", '<mesh filename="package://robot/meshes/nope.stl"/>')
    with pytest.raises(gt.ConfigError) as info:
        link_shapes(model)
    message = str(info.value)
    assert "\n" not in message
    assert "link 'palm'" in message and "package://robot/meshes/nope.stl" in message
    assert f"looked in {tmp_path / 'robot' / 'meshes'}" in message and "not found" in message
    errors: list[str] = []
    shapes = link_shapes(model, "collision", errors)  # pictures: skipped, reported
    assert errors == [message] and "palm" not in {s.link for s in shapes} and len(shapes) == 4


def test_an_unreadable_mesh_is_one_line(tmp_path):
    (tmp_path / "palm.stl").write_bytes(b"\x00garbage" * 10)
    model = _model(tmp_path, '<mesh filename="palm.stl"/>')
    with pytest.raises(gt.ConfigError, match=r"link 'palm' collision: mesh 'palm.stl': palm.stl holds no triangles"):
        link_shapes(model)


def test_candidates_try_package_folders_then_the_urdf_folder(tmp_path):
    urdf = tmp_path / "pkg" / "urdf" / "r.urdf"
    assert mesh_candidates("package://pkg/m/a.stl", urdf) == [tmp_path / "pkg" / "m" / "a.stl",
                                                              tmp_path / "pkg" / "urdf" / "m" / "a.stl"]


def test_decimation_never_fails_without_fast_simplification(monkeypatch):
    import trimesh

    sphere = trimesh.creation.icosphere(subdivisions=5)  # 20480 faces

    def unavailable(*args, **kwargs):
        raise ImportError("fast_simplification")

    monkeypatch.setattr(trimesh.Trimesh, "simplify_quadric_decimation", unavailable)
    small = decimate(sphere, 2000)
    assert 100 < len(small.faces) <= 2000
    np.testing.assert_allclose(small.bounds, sphere.bounds, atol=0.1)
    box = trimesh.creation.box()
    assert decimate(box, 2000) is box
    assert len(decimate(sphere, 10).faces) <= 10  # clustering cannot go that low: subsampled


def test_palm_shapes_include_links_fixed_to_the_palm(tmp_path):
    """A wrist frame without geometry whose hand base hangs from it by a fixed joint: the palm's
    shapes are the base's, placed as the URDF's fixed transform puts them (checked against
    pytorch-kinematics); a link behind a movable joint is not the palm's."""
    import pytorch_kinematics as pk

    from graspnet_torch.robot.geometry import palm_shapes

    path = tmp_path / "wrist.urdf"
    path.write_text("""<robot name="wrist">
  <link name="wrist"/>
  <link name="base"><collision><origin xyz="0.01 0 0.02" rpy="0 0.3 0"/>
    <geometry><box size="0.08 0.02 0.09"/></geometry></collision></link>
  <link name="finger"><collision><geometry><sphere radius="0.01"/></geometry></collision>
  </link>
  <joint name="mount" type="fixed"><parent link="wrist"/><child link="base"/>
    <origin xyz="0 0 0.05" rpy="0.2 0 0.1"/></joint>
  <joint name="knuckle" type="revolute"><parent link="base"/><child link="finger"/><origin xyz="0 0 0.1"/>
    <axis xyz="1 0 0"/><limit lower="0" upper="1.5" effort="1" velocity="1"/></joint>
</robot>""")
    model = UrdfModel(path)
    shapes = palm_shapes(model, "wrist")
    assert [s.link for s, _ in shapes] == ["base"]
    chain = pk.build_chain_from_urdf(path.read_bytes())
    base = chain.forward_kinematics({"knuckle": 0.0})["base"].get_matrix()[0].double().numpy()
    np.testing.assert_allclose(shapes[0][1], base @ shapes[0][0].origin, atol=1e-12)
    assert [s.link for s, _ in palm_shapes(model, "base")] == ["base"]
