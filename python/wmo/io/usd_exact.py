"""WMO's exact values in a USD stage: the ``wmo:`` attributes that make a saved world load
back bit for bit.

UsdPhysics stores masses, velocities, materials and mesh points as 32-bit floats and
poses as matrices; read back, a world built from them differs from the saved one in the
last bits, and a simulation soon tells the difference. So :mod:`wmo.io.usd_writer`
also writes each value WMO needs as a custom ``wmo:`` attribute in double precision,
and :mod:`wmo.io.usd` uses them instead of the schema's values. Other readers ignore
them.

Exact values must never hide an edit made elsewhere: if a user moves a body in
usdview or Omniverse, its schema pose changes and its ``wmo:position`` does not. So
the writer also stores ``wmo:digest``, a hash of every schema attribute (not ``wmo:``)
of the body prim, its descendants and their bound materials, and the reader uses a
body's exact values only when the digest of what it reads still matches; otherwise
it reads the schema and says so in a warning.

Attributes (all custom, at the default time):

- the ``PhysicsScene`` prim: ``wmo:gravity`` (double3, m/s^2) and ``wmo:settings:<name>``
  for each entry of ``World.settings`` (dt, substeps, solver settings, ...), plus its
  digest (of gravityDirection / gravityMagnitude);
- a body prim: ``wmo:position`` (double3, m), ``wmo:orientation`` (double4, x y z w),
  ``wmo:linearVelocity`` (m/s) and ``wmo:angularVelocity`` (rad/s, world axes),
  ``wmo:friction``, ``wmo:restitution``, ``wmo:linearDamping``, ``wmo:angularDamping``,
  ``wmo:gravityScale``, ``wmo:collisionGroup``, ``wmo:ccd``, and for a dynamic body
  ``wmo:mass`` (kg), ``wmo:centerOfMass`` (m, shape frame) and ``wmo:inertia`` (matrix3d,
  kg m^2 about the centre of mass, shape frame);
- a collider prim: its shape's spec (the form remote scenes use, PROTOCOL.md), one
  ``wmo:shape:<field>`` attribute per field (``type``, ``half_extents``, ``radius``,
  ``points`` as double3[], ``triangles`` as int3[], ``one_sided`` as bool, ...), and for
  a part of a compound its ``wmo:localPosition`` / ``wmo:localOrientation`` in the
  body's shape frame;
- a ``PhysicsCollisionGroup``: ``wmo:index``, the WMO group number it stands for.
"""
from __future__ import annotations

import hashlib
from typing import Any, Dict, List, Optional, Tuple

import numpy as np

from .. import _core as wmo
from ..remote.scene import shape_from_spec, shape_to_spec

__all__ = ["schema_digest", "write_scene", "read_scene", "write_body", "write_collider", "read_body"]


def _value_bytes(value: Any) -> bytes:
    if value is None:
        return b"None"
    try:  # Vt arrays: their raw numbers (str would be slow on big meshes)
        return np.asarray(value).tobytes() if hasattr(value, "__len__") and not isinstance(value, str) else repr(value).encode()
    except (TypeError, ValueError):
        return repr(value).encode()


def schema_digest(prim, *, subtree: bool = True) -> str:
    """A hash of every authored non-``wmo:`` attribute value (default time) of ``prim``,
    of its descendants when ``subtree``, and of the physics materials they bind."""
    from pxr import Usd, UsdShade

    h = hashlib.sha256()
    prims = list(Usd.PrimRange(prim)) if subtree else [prim]
    materials = []
    for p in prims:
        mat, _ = UsdShade.MaterialBindingAPI(p).ComputeBoundMaterial("physics")
        if mat and mat.GetPrim().IsValid():
            materials.append(mat.GetPrim())
    for p in prims + materials:
        h.update(str(p.GetPath()).encode())
        for a in sorted(p.GetAuthoredAttributes(), key=lambda a: a.GetName()):
            if a.GetName().startswith("wmo:"):
                continue
            h.update(a.GetName().encode())
            h.update(_value_bytes(a.Get()))
    return h.hexdigest()


def _set(prim, name: str, type_name, value) -> None:
    prim.CreateAttribute(f"wmo:{name}", type_name, custom=True).Set(value)


def _get(prim, name: str) -> Any:
    a = prim.GetAttribute(f"wmo:{name}")
    return a.Get() if a and a.HasAuthoredValue() else None


def _vec(v) -> np.ndarray:
    return np.array(v, dtype=np.float64)


def write_scene(scene_prim, world: "wmo.World") -> None:
    """The world's exact gravity and settings on its PhysicsScene prim (after the schema
    attributes are written)."""
    from pxr import Gf, Sdf

    settings = world.settings
    _set(scene_prim, "gravity", Sdf.ValueTypeNames.Double3, Gf.Vec3d(*map(float, settings.pop("gravity"))))
    types = {bool: Sdf.ValueTypeNames.Bool, int: Sdf.ValueTypeNames.Int, float: Sdf.ValueTypeNames.Double,
             str: Sdf.ValueTypeNames.String}
    for name, value in settings.items():
        _set(scene_prim, f"settings:{name}", types[type(value)], value)
    _set(scene_prim, "digest", Sdf.ValueTypeNames.String, schema_digest(scene_prim, subtree=False))


def read_scene(scene_prim) -> Tuple[Optional[np.ndarray], Dict[str, Any]]:
    """(exact gravity, or None unless the digest still matches; the World settings
    found). The settings have no schema counterpart, so they are returned either way."""
    settings = {}
    for a in scene_prim.GetAuthoredAttributes():
        name = a.GetName()
        if name.startswith("wmo:settings:"):
            settings[name[len("wmo:settings:"):]] = a.Get()
    g = _get(scene_prim, "gravity")
    digest = _get(scene_prim, "digest")
    if g is None or digest is None or digest != schema_digest(scene_prim, subtree=False):
        return None, settings
    return _vec(g), settings


def write_collider(prim, shape: "wmo.Shape", local_pose: Optional["wmo.Pose"] = None) -> None:
    """The exact parameters of ``shape`` (its spec, :func:`wmo.remote.scene.shape_to_spec`,
    one ``wmo:shape:<field>`` attribute per field) and its pose in a compound on its
    collider prim."""
    from pxr import Gf, Sdf, Vt

    T = Sdf.ValueTypeNames
    for name, value in shape_to_spec(shape).items():
        if isinstance(value, bool):  # (before float: a bool is an int, not a float)
            type_name = T.Bool
        elif isinstance(value, (str, float)):
            type_name = T.String if isinstance(value, str) else T.Double
        elif not isinstance(value[0], list):
            type_name, value = T.Double3, Gf.Vec3d(*value)
        elif isinstance(value[0][0], int):  # rows: triangles (int) or points (float)
            type_name, value = T.Int3Array, Vt.Vec3iArray.FromNumpy(np.asarray(value, dtype=np.int32))
        else:
            type_name, value = T.Double3Array, Vt.Vec3dArray.FromNumpy(np.asarray(value, dtype=np.float64))
        _set(prim, f"shape:{name}", type_name, value)
    if local_pose is not None:
        _set(prim, "localPosition", T.Double3, Gf.Vec3d(*map(float, local_pose.position)))
        _set(prim, "localOrientation", T.Double4, Gf.Vec4d(*map(float, local_pose.orientation)))


def write_body(prim, world: "wmo.World", k: int) -> None:
    """Body row ``k``'s exact values on its prim, then the digest of its subtree (call it
    after the colliders, materials and schema attributes are written)."""
    from pxr import Gf, Sdf

    T = Sdf.ValueTypeNames
    body = world.body(k)
    _set(prim, "position", T.Double3, Gf.Vec3d(*map(float, world.positions[k])))
    _set(prim, "orientation", T.Double4, Gf.Vec4d(*map(float, world.orientations[k])))
    _set(prim, "linearVelocity", T.Double3, Gf.Vec3d(*map(float, world.linear_velocities[k])))
    _set(prim, "angularVelocity", T.Double3, Gf.Vec3d(*map(float, world.angular_velocities[k])))
    for name, value in (("friction", body.friction), ("restitution", body.restitution),
                        ("linearDamping", body.linear_damping), ("angularDamping", body.angular_damping),
                        ("gravityScale", body.gravity_scale)):
        _set(prim, name, T.Double, float(value))
    _set(prim, "collisionGroup", T.Int, int(body.collision_group))
    _set(prim, "ccd", T.Bool, bool(body.ccd))
    if body.kind == "dynamic":
        _set(prim, "mass", T.Double, float(body.mass))
        _set(prim, "centerOfMass", T.Double3, Gf.Vec3d(*map(float, body.center_of_mass)))
        _set(prim, "inertia", T.Matrix3d, Gf.Matrix3d(*np.asarray(body.inertia, dtype=float).ravel()))
    _set(prim, "digest", T.String, schema_digest(prim))


def _shape(prim) -> Optional["wmo.Shape"]:
    """The shape write_collider wrote on ``prim`` (None if it wrote none)."""
    spec = {}
    for a in prim.GetAuthoredAttributes():
        name = a.GetName()
        if name.startswith("wmo:shape:"):
            v = a.Get()
            spec[name[len("wmo:shape:"):]] = v if isinstance(v, (str, float, bool)) else np.asarray(v).tolist()
    return shape_from_spec(spec, limits=False) if spec else None


def read_body(prim, colliders: List[Any], kind: str) -> Tuple[Optional[Tuple["wmo.Shape", Dict[str, Any]]], bool]:
    """(shape and ``World.add_body`` keywords from the exact values, or None, and whether
    the prim had exact values at all). None with True: the prim was edited after WMO
    wrote it (its digest no longer matches) or a collider lacks its exact shape."""
    digest = _get(prim, "digest")
    if digest is None:
        return None, False
    if digest != schema_digest(prim) or not colliders:
        return None, True
    try:
        shapes = [_shape(c) for c in colliders]
    except (ValueError, TypeError):
        return None, True
    if any(s is None for s in shapes):
        return None, True
    if any(_get(c, "localPosition") is not None for c in colliders):
        shape: wmo.Shape = wmo.Compound([(s, wmo.Pose(_vec(_get(c, "localPosition")), _vec(_get(c, "localOrientation"))))
                                         for s, c in zip(shapes, colliders)])
    elif len(shapes) == 1:
        shape = shapes[0]
    else:
        return None, True
    kw: Dict[str, Any] = dict(kind=kind, position=_vec(_get(prim, "position")), orientation=_vec(_get(prim, "orientation")),
                              friction=float(_get(prim, "friction")), restitution=float(_get(prim, "restitution")),
                              linear_damping=float(_get(prim, "linearDamping")),
                              angular_damping=float(_get(prim, "angularDamping")),
                              gravity_scale=float(_get(prim, "gravityScale")),
                              collision_group=int(_get(prim, "collisionGroup")), ccd=bool(_get(prim, "ccd")))
    if kind != "static":
        kw["linear_velocity"] = _vec(_get(prim, "linearVelocity"))
        kw["angular_velocity"] = _vec(_get(prim, "angularVelocity"))
    if kind == "dynamic":
        kw["mass"] = float(_get(prim, "mass"))
        kw["center_of_mass"] = _vec(_get(prim, "centerOfMass"))
        kw["inertia"] = np.array(_get(prim, "inertia"), dtype=np.float64).reshape(3, 3)
    return (shape, kw), True
