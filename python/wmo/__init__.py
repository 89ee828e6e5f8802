"""WMO: a 3D rigid-body collision and physics engine.

Conventions (stated once in ``cpp/include/wmo/types.h``): metres, kilograms, seconds,
radians; a pose is a position ``(3,)`` and a unit quaternion ``(4,)`` in ``(x, y, z, w)``
order (as SciPy and PyBullet); contact normals point from A to B; depth is positive when
shapes overlap. Capsules and cylinders are aligned with their local Y axis.

Errors: a bad value (NaN, negative size, non-unit quaternion) raises ``ValueError``
(``wmo.InvalidArgument``), naming the field and the value; an argument of the wrong type
or array shape raises ``TypeError`` naming the expected shape.

>>> import wmo
>>> box, ball = wmo.Box(half_extents=(1, 1, 1)), wmo.Sphere(radius=0.5)
>>> d = wmo.geometry.distance(box, wmo.Pose(), ball, wmo.Pose(position=(3, 0, 0)))
>>> round(d.distance, 9)
1.5
"""
from . import _core
from ._core import (
    Body,
    Box,
    Capsule,
    Compound,
    ConvexHull,
    ConvexShape,
    Cylinder,
    InvalidArgument,
    MassProperties,
    Plane,
    Pose,
    Shape,
    Sphere,
    TriangleMesh,
    World,
)
from . import geometry, scenes

__version__ = "0.1.0"


def load(path, **options) -> World:
    """The World a scene file describes (.usda/.usdc/.usd: UsdPhysics; .obj: a mesh),
    through :func:`wmo.io.load`; each thing in the file WMO does not support yet is
    reported as a Python warning (``wmo.io.load`` returns them, with the bodies by prim
    path)."""
    import warnings

    from . import io

    result = io.load(path, **options)
    for w in result.warnings:
        warnings.warn(w, stacklevel=2)
    return result.world


def save(world: World, path, **options) -> None:
    """Writes a World to a scene file (see :func:`wmo.io.save`)."""
    from . import io

    io.save(world, path, **options)


def state_hash(world: World) -> str:
    """SHA-256 (hex) of the world's state bits: positions, orientations, linear and
    angular velocities of every body, in row order. Two worlds with the same hash are
    in the same state bit for bit; WMO's determinism tests (same run twice, 1 or 2
    threads, a scene saved to USD and loaded back) compare it."""
    import hashlib

    import numpy as np

    h = hashlib.sha256()
    for a in (world.positions, world.orientations, world.linear_velocities, world.angular_velocities):
        h.update(np.ascontiguousarray(a).tobytes())
    return h.hexdigest()


__all__ = [
    "Body",
    "Box",
    "Capsule",
    "Compound",
    "ConvexHull",
    "ConvexShape",
    "Cylinder",
    "InvalidArgument",
    "MassProperties",
    "Plane",
    "Pose",
    "Shape",
    "Sphere",
    "TriangleMesh",
    "World",
    "geometry",
    "load",
    "save",
    "state_hash",
    "scenes",
]
