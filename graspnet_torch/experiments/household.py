"""Everyday objects at real scale, built offline (the experiment ``hands``): primitives at household
sizes (cylinders, boxes, spheres; ellipsoids and capsules as meshes written once into a folder) and
pybullet_data meshes scaled to the size of the thing they stand for. Each is placed as the synthesis
experiment places an object: its bounding box centred at
:data:`~graspnet_torch.tasks.objects.OBJECT_CENTRE`, unturned (its longest side along z).

*Long*: at least 120 mm long and at most 60 mm across (its two shorter extents). Not here, nor
anything near them: the six objects the synthesis was tuned on (bottle: cylinder r 27.5 x 160 mm;
can: r 25 x 80; carton: box 40 x 40 x 140; cereal box: 100 x 30 x 150; lemon: ellipsoid radii
29, 29, 35; bread roll: ellipsoid 50, 35, 28).

Sizes in mm: cylinder radius x height; capsule radius x total length; ellipsoid its three radii;
box its extents; a mesh its pybullet_data file at a scale (extents measured, rounded).

==============  =========  =========================  ====  ==================================
name            kind       size (mm)                  long  extents (mm)
==============  =========  =========================  ====  ==================================
marker          cylinder   r 9 x 135                  yes   18 x 18 x 135
candle          cylinder   r 11 x 200                 yes   22 x 22 x 200
flashlight      cylinder   r 19 x 170                 yes   38 x 38 x 170
thin_bottle     cylinder   r 21 x 225                 yes   42 x 42 x 225
spray_can       cylinder   r 24 x 195                 yes   48 x 48 x 195
rolling_pin     cylinder   r 26 x 280                 yes   52 x 52 x 280
screwdriver     capsule    r 15 x 125                 yes   30 x 30 x 125
salami          capsule    r 24 x 210                 yes   48 x 48 x 210
toothbrush_box  box        28 x 22 x 195              yes   28 x 22 x 195
glasses_case    box        58 x 38 x 160              yes   58 x 38 x 160
cucumber        ellipsoid  22, 22, 105                yes   44 x 44 x 210
banana          ellipsoid  20, 17, 92                 yes   40 x 34 x 184
carrot          ellipsoid  16, 16, 85                 yes   32 x 32 x 170
apple           sphere     r 38                       no    76 x 76 x 76
orange          sphere     r 42                       no    84 x 84 x 84
tennis_ball     sphere     r 33                       no    66 x 66 x 66
golf_ball       sphere     r 21                       no    42 x 42 x 42
egg             ellipsoid  22, 22, 29                 no    44 x 44 x 58
avocado         ellipsoid  35, 35, 52                 no    70 x 70 x 104
onion           ellipsoid  38, 38, 33                 no    76 x 76 x 66
computer_mouse  ellipsoid  55, 31, 19                 no    110 x 62 x 38
highlighter     capsule    r 12 x 110                 no    24 x 24 x 110
soap_bar        box        90 x 58 x 28               no    90 x 58 x 28
matchbox        box        52 x 36 x 16               no    52 x 36 x 16
puzzle_cube     box        57 x 57 x 57               no    57 x 57 x 57
juice_box       box        63 x 40 x 105              no    63 x 40 x 105
smartphone      box        72 x 8 x 147               no    72 x 8 x 147
yogurt_cup      cylinder   r 34 x 70                  no    68 x 68 x 70
tuna_can        cylinder   r 42 x 38                  no    84 x 84 x 38
jam_jar         cylinder   r 36 x 85                  no    72 x 72 x 85
d_battery       cylinder   r 17 x 61                  no    34 x 34 x 61
pill_bottle     cylinder   r 20 x 75                  no    40 x 40 x 75
mug             mesh       objects/mug_col.obj x 1    no    82 x 122 x 100
rubber_duck     mesh       duck.obj x 0.06            no    99 x 92 x 69
teddy_bear      mesh       teddy2_VHACD_CHs x 0.12    no    91 x 112 x 75
bunny           mesh       bunny.obj x 0.06           no    56 x 87 x 118
bagel           mesh       torus_textured x 0.065     no    98 x 32 x 98
baseball        mesh       soccerball.obj x 0.074     no    74 x 74 x 75
toy_block       mesh       toys/cube.obj x 0.6        no    52 x 52 x 39
door_wedge      mesh       toys/prism.obj x 1         no    84 x 64 x 118
==============  =========  =========================  ====  ==================================
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from graspnet_torch.collision.convex import cache_dir
from graspnet_torch.errors import ConfigError
from graspnet_torch.io import atomic_path
from graspnet_torch.robot.shape import Shape
from graspnet_torch.tasks.objects import OBJECT_CENTRE, centred_mesh

__all__ = ["LONG_ACROSS_M", "LONG_LENGTH_M", "OBJECTS", "Household", "household_objects", "object_names"]

LONG_LENGTH_M, LONG_ACROSS_M = 0.12, 0.06  # long: at least this long, at most this across


@dataclass(frozen=True)
class Household:
    """One everyday object: ``kind`` cylinder (radius, height), box (x, y, z), sphere (radius,),
    ellipsoid (three radii), capsule (radius, total length) in metres, or mesh (``size`` empty;
    ``mesh``: its file under pybullet_data at ``scale``); ``long``: at least 120 mm long and at most
    60 mm across."""

    name: str
    kind: str
    size: tuple[float, ...]
    long: bool
    mesh: str = ""
    scale: float = 1.0


def _mm(*values: float) -> tuple[float, ...]:
    return tuple(v / 1000 for v in values)


OBJECTS: tuple[Household, ...] = (
    Household("marker", "cylinder", _mm(9, 135), True), Household("candle", "cylinder", _mm(11, 200), True),
    Household("flashlight", "cylinder", _mm(19, 170), True), Household("thin_bottle", "cylinder", _mm(21, 225), True),
    Household("spray_can", "cylinder", _mm(24, 195), True), Household("rolling_pin", "cylinder", _mm(26, 280), True),
    Household("screwdriver", "capsule", _mm(15, 125), True), Household("salami", "capsule", _mm(24, 210), True),
    Household("toothbrush_box", "box", _mm(28, 22, 195), True),
    Household("glasses_case", "box", _mm(58, 38, 160), True),
    Household("cucumber", "ellipsoid", _mm(22, 22, 105), True), Household("banana", "ellipsoid", _mm(20, 17, 92), True),
    Household("carrot", "ellipsoid", _mm(16, 16, 85), True),
    Household("apple", "sphere", _mm(38), False), Household("orange", "sphere", _mm(42), False),
    Household("tennis_ball", "sphere", _mm(33), False), Household("golf_ball", "sphere", _mm(21), False),
    Household("egg", "ellipsoid", _mm(22, 22, 29), False), Household("avocado", "ellipsoid", _mm(35, 35, 52), False),
    Household("onion", "ellipsoid", _mm(38, 38, 33), False),
    Household("computer_mouse", "ellipsoid", _mm(55, 31, 19), False),
    Household("highlighter", "capsule", _mm(12, 110), False), Household("soap_bar", "box", _mm(90, 58, 28), False),
    Household("matchbox", "box", _mm(52, 36, 16), False), Household("puzzle_cube", "box", _mm(57, 57, 57), False),
    Household("juice_box", "box", _mm(63, 40, 105), False), Household("smartphone", "box", _mm(72, 8, 147), False),
    Household("yogurt_cup", "cylinder", _mm(34, 70), False), Household("tuna_can", "cylinder", _mm(42, 38), False),
    Household("jam_jar", "cylinder", _mm(36, 85), False), Household("d_battery", "cylinder", _mm(17, 61), False),
    Household("pill_bottle", "cylinder", _mm(20, 75), False),
    Household("mug", "mesh", (), False, "objects/mug_col.obj", 1.0),
    Household("rubber_duck", "mesh", (), False, "duck.obj", 0.06),
    Household("teddy_bear", "mesh", (), False, "teddy2_VHACD_CHs.obj", 0.12),
    Household("bunny", "mesh", (), False, "bunny.obj", 0.06),
    Household("bagel", "mesh", (), False, "torus/torus_textured.obj", 0.065),
    Household("baseball", "mesh", (), False, "soccerball.obj", 0.074),
    Household("toy_block", "mesh", (), False, "toys/cube.obj", 0.6),
    Household("door_wedge", "mesh", (), False, "toys/prism.obj", 1.0))
_BY_NAME = {o.name: o for o in OBJECTS}


def object_names() -> tuple[str, ...]:
    return tuple(_BY_NAME)


def _written(obj: Household, folder: Path) -> Path:
    """An ellipsoid's or capsule's mesh (its long axis along z), written once into ``folder``."""
    import trimesh

    if obj.kind == "ellipsoid":
        mesh = trimesh.creation.icosphere(subdivisions=3, radius=1.0)
        mesh.vertices = mesh.vertices * np.asarray(obj.size)
    else:
        radius, length = obj.size
        mesh = trimesh.creation.capsule(height=length - 2 * radius, radius=radius, count=[32, 32])
    data = mesh.export(file_type="stl")
    path = folder / f"{obj.name}.stl"
    if not path.is_file() or path.read_bytes() != data:
        with atomic_path(path, ".stl") as tmp:
            tmp.write_bytes(data)
    return path


def _shape(obj: Household, folder: Path) -> Shape:
    pose = np.array([*OBJECT_CENTRE, 0.0, 0.0, 0.0])
    if obj.kind in ("cylinder", "box", "sphere"):
        return Shape(obj.kind, obj.size, pose)
    if obj.kind in ("ellipsoid", "capsule"):
        return centred_mesh(_written(obj, folder))
    import pybullet_data

    return centred_mesh(Path(pybullet_data.getDataPath()) / obj.mesh, obj.scale)


def household_objects(objects: int | Sequence[str] | None = None, folder: Path | None = None
                      ) -> list[tuple[Household, Shape]]:
    """The objects (``objects``: n of :data:`OBJECTS` spread evenly over it, or names; None: all), each with its
    shape placed (module docstring); the ellipsoids' and capsules' meshes are written into
    ``folder`` (default: ``<cache>/household``, the convex pieces' cache folder)."""
    if objects is None:
        chosen = list(OBJECTS)
    elif isinstance(objects, int):  # spread over the table: long and not, primitives and meshes
        chosen = [OBJECTS[k] for k in np.unique(np.linspace(0, len(OBJECTS) - 1, objects).round().astype(int))]
    else:
        unknown = [n for n in objects if n not in _BY_NAME]
        if unknown:
            raise ConfigError(f"unknown object '{unknown[0]}': expected one of {', '.join(_BY_NAME)}")
        chosen = [_BY_NAME[n] for n in objects]
    folder = folder or cache_dir() / "household"
    return [(obj, _shape(obj, folder)) for obj in chosen]
