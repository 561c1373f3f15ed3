"""Small robots with mesh geometry, written into a test's tmp folder (URDF, meshes, robot YAML)."""

from __future__ import annotations

from pathlib import Path

import yaml

# the palm's mesh: a box 0.08 x 0.02 x 0.10 m (x, y, z) centred on the palm frame, 12 faces
PALM_EXTENTS = (0.08, 0.02, 0.10)

_FINGER = """
<link name="{f}_base"/>
<link name="{f}_l1"><collision><origin xyz="0 0 0.02"/><geometry><cylinder radius="0.007" length="0.04"/></geometry>
  </collision></link>
<link name="{f}_l2"><collision><origin xyz="0 0 0.015"/><geometry><cylinder radius="0.006" length="0.03"/></geometry>
  </collision></link>
<link name="{f}_tip"/>
<joint name="{f}_base_joint" type="fixed"><parent link="palm"/><child link="{f}_base"/><origin xyz="{x} 0 0.05"/>
</joint>
<joint name="{f}_j1" type="revolute"><parent link="{f}_base"/><child link="{f}_l1"/><axis xyz="0 {s} 0"/>
  <limit lower="-0.3" upper="1.6" effort="1" velocity="1"/></joint>
<joint name="{f}_j2" type="revolute"><parent link="{f}_l1"/><child link="{f}_l2"/><origin xyz="0 0 0.04"/>
  <axis xyz="0 {s} 0"/><limit lower="0" upper="1.6" effort="1" velocity="1"/></joint>
<joint name="{f}_tip_joint" type="fixed"><parent link="{f}_l2"/><child link="{f}_tip"/><origin xyz="0 0 0.03"/>
</joint>
"""


def write_box_mesh(path: Path, extents=PALM_EXTENTS, subdivisions: int = 0) -> Path:
    """A box mesh file (STL, OBJ, ... by the suffix); ``subdivisions`` > 0: a sphere of that
    many subdivisions scaled to the extents instead (20 * 4**k faces)."""
    import trimesh

    if subdivisions:
        mesh = trimesh.creation.icosphere(subdivisions=subdivisions)
        mesh.apply_scale([e / 2 for e in extents])
    else:
        mesh = trimesh.creation.box(extents=extents)
    path.parent.mkdir(parents=True, exist_ok=True)
    mesh.export(path)
    return path


def mesh_hand_urdf(palm_geometry: str | None, name: str = "meshhand", visual: str | None = None,
                   rpy: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> str:
    """A two-finger hand (thumb, index: 2 flexion joints each, cylinder links) whose palm has
    ``palm_geometry`` (e.g. ``<mesh filename="..."/>``; None: none) as collision geometry, turned
    by ``rpy`` (radians) in the palm frame, and ``visual`` as visual geometry."""
    palm = ""
    if palm_geometry:
        origin = f'<origin rpy="{rpy[0]} {rpy[1]} {rpy[2]}"/>'
        palm += f"<collision>{origin}<geometry>{palm_geometry}</geometry></collision>"
    if visual:
        palm += f"<visual><geometry>{visual}</geometry></visual>"
    fingers = _FINGER.format(f="thumb", x=0.03, s=-1) + _FINGER.format(f="index", x=-0.03, s=1)
    return f'<robot name="{name}"><link name="palm">{palm}</link>{fingers}</robot>'


def bare_hand_urdf(name: str = "barehand") -> str:
    """The same two-finger hand without any geometry."""
    import re

    text = mesh_hand_urdf(None, name)
    return re.sub(r"<collision>.*?</collision>", "", text, flags=re.S)


def write_robot(folder: Path, urdf_text: str, name: str = "meshhand", **extra) -> Path:
    """``<folder>/<name>.urdf`` and ``<folder>/<name>.yaml`` (a free hand); returns the YAML path."""
    folder.mkdir(parents=True, exist_ok=True)
    (folder / f"{name}.urdf").write_text(urdf_text)
    cfg = {"name": name, "urdf": f"{name}.urdf", "palm_link": "palm",
           "fingers": {"thumb": {"base": "thumb_base", "tip": "thumb_tip"},
                       "index": {"base": "index_base", "tip": "index_tip"}},
           "palm_bounds": {"min": [-0.1, -0.1, 0.1, -45, -45, -45], "max": [0.1, 0.1, 0.2, 45, 45, 45]},
           "home": {"thumb_j1": 10, "index_j1": 10}, **extra}
    path = folder / f"{name}.yaml"
    path.write_text(yaml.safe_dump(cfg, sort_keys=False))
    return path
