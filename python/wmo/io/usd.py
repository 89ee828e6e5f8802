"""USD stages with the UsdPhysics schema in, through Pixar's ``usd-core`` (``pxr``).

Supported (everything else with a Physics schema becomes a warning naming the prim):

- ``PhysicsScene``: ``gravityDirection`` and ``gravityMagnitude``. Unauthored (the
  schema's sentinels (0, 0, 0) and -inf) means earth gravity, 9.81 m/s^2 along -up.
  Several scenes: the first one is used, with a warning.
- ``PhysicsRigidBodyAPI``: a dynamic body; ``kinematicEnabled`` makes it kinematic,
  ``rigidBodyEnabled = false`` static. ``physics:velocity`` (stage units/s) and
  ``physics:angularVelocity`` (DEGREES/s in USD; converted to rad/s) are initial values,
  read in world axes (as the PhysX reference implementation does; for a body directly
  under the root they are also its parent's axes). ``startsAsleep`` and kinematic
  animation (time samples) are warned about, not used.
- ``PhysicsCollisionAPI`` on ``Cube`` (``size``), ``Sphere`` (``radius``), ``Capsule``
  and ``Cylinder`` (``radius``, ``height``, ``axis``; WMO's are along local Y, so they
  are rotated to the authored axis), ``Cone`` (a 32-sided hull, warned), ``Plane``
  (infinite ``wmo.Plane``, static only) and ``Mesh`` (points, ``faceVertexCounts``,
  ``faceVertexIndices``; polygons fan-triangulated). A collider's rigid body is its
  nearest ancestor-or-self with ``PhysicsRigidBodyAPI``; several colliders of one body
  become a ``wmo.Compound``. A collider without a rigid body becomes a static body of
  its own (keyed by the collider's path). ``collisionEnabled = false`` colliders are
  skipped (warned).
- ``PhysicsMeshCollisionAPI`` ``approximation``: ``none`` (the default) is a
  ``wmo.TriangleMesh`` on a static body and a convex hull (warned) on a moving one, as
  WMO triangle meshes are static; ``convexHull`` a ``wmo.ConvexHull`` (a flat one, like
  the ground quad of Pixar's ``usdPhysicsBoxOnQuad`` example, is thickened behind its
  face by 1% of its size, warned; pass ``flat_hulls="error"`` to refuse it instead);
  ``convexDecomposition`` a ``wmo.Compound`` of hulls from the ``coacd`` package (one
  hull, warned, without it); ``boundingSphere`` and ``boundingCube`` (axis-aligned in
  the prim's frame) are supported; ``meshSimplification`` and others fall back to
  ``none`` or a hull with a warning.
- ``PhysicsMassAPI``: ``mass`` (kg after ``kilogramsPerUnit``) and ``density`` on the
  body, then on its colliders, then the bound material's density, else WMO's 1000
  kg/m^3. A rigid body's own ``centerOfMass`` (its prim's frame, scaled), ``diagonalInertia``
  (kg m^2 after the stage's units) and ``principalAxes`` become ``add_body``'s
  ``center_of_mass``, ``inertia`` and ``inertia_axes`` (in the shape's frame); authored
  on a collider or a static body they are ignored with a warning.
- ``PhysicsMaterialAPI`` bound through ``material:binding:physics`` (or a plain
  ``material:binding``): ``dynamicFriction`` becomes WMO's single friction coefficient
  (WMO has no separate static coefficient; a different authored ``staticFriction`` is
  warned), ``restitution``, ``density``. Unauthored values are the schema's fallbacks
  (0). A body whose colliders bind different materials uses the first one (warned).
- Damping, which UsdPhysics leaves to the simulator: PhysX, the schema's reference
  runtime for which stages like Pixar's examples are authored, reads it from
  ``PhysxRigidBodyAPI``'s ``physxRigidBody:linearDamping`` and ``angularDamping`` (1/s)
  and defaults them to 0 and 0.05 1/s. A dynamic body takes its authored values and,
  where none is authored, PhysX's defaults, so a stage behaves as its authors saw it
  (Pixar's BoxOnQuad cube swings on its corner forever without the angular damping:
  a frictional point pivot does no work). ``physx_defaults=False`` leaves unauthored
  damping at WMO's 0. WMO damps as ``v *= 1 / (1 + dt c)`` per step, PhysX as ``v *=
  1 - dt c``: the same to first order in ``dt c``. Other authored ``physxRigidBody:``
  attributes are warned about, not used.
- ``PhysicsFilteredPairsAPI``: ``World.set_pair_collision(a, b, False)`` for every pair
  of bodies named (targets may be bodies or colliders).
- ``PhysicsCollisionGroup``: each group (groups sharing a ``mergeGroup`` name count as
  one) gets a WMO collision group index 1..63 (0 = no group; more than 63 groups raise
  SceneFormatError); ``filteredGroups`` become ``World.set_group_collision(a, b,
  False)``; ``invertFilteredGroups`` is honoured (the group then collides only with the
  listed groups). A body's group is that of its first collider in a group.

Units: all lengths are multiplied by the stage's ``metersPerUnit`` (USD's fallback is
0.01, centimetres, when unauthored; override with ``meters_per_unit=``), masses by
``kilogramsPerUnit``, densities by kilogramsPerUnit / metersPerUnit^3.

Axes: WMO has no fixed up axis (gravity is a World setting), so the stage's axes are kept
as they are: a Z-up stage gives a world whose gravity points along -Z.

Transforms: each prim's full local-to-world matrix (all xformOps, nested parents) is
split into translation, rotation and per-axis scale. The scale goes into the shape's
dimensions (a non-uniformly scaled Cube is a Box with scaled half extents; a
non-uniformly scaled Sphere becomes the convex hull of a scaled 162-vertex icosphere,
warned; a Capsule/Cylinder whose two radial scales differ uses the larger, warned). A
body's pose is its prim's rotation and translation; its colliders are placed relative to
it. Shear and mirroring are warned about (mirroring is applied to mesh points only).
"""
from __future__ import annotations

import math
import os
from pathlib import Path
from typing import Any, Dict, List, Optional, Sequence, Tuple, Union

import numpy as np

from .. import _core as wmo
from . import LoadResult, SceneFileNotFoundError, SceneFormatError, usd_exact
from .obj import convex_decomposition, drop_degenerate, make_hull, quat_from_matrix

try:  # pxr is optional for the package; load_usd says how to get it.
    from pxr import Sdf, Usd, UsdGeom, UsdPhysics, UsdShade  # type: ignore[import-not-found]
except ImportError:  # pragma: no cover - exercised only without usd-core
    Usd = None  # type: ignore[assignment]

__all__ = ["load_usd", "EARTH_GRAVITY", "MAX_MESH_TRIANGLES"]

EARTH_GRAVITY = 9.81  # m/s^2, used when the PhysicsScene does not author a magnitude
MAX_MESH_TRIANGLES = 20_000_000  # refuse absurd meshes before allocating triangle arrays
MAX_COLLISION_GROUPS = 63

# Schemas this reader understands; any other applied API or prim type whose name starts
# with "Physics" (joints, articulations, drives, limits, ...) or a vendor's "Physx" is
# reported as a warning.
_SUPPORTED_APIS = {"PhysicsRigidBodyAPI", "PhysicsCollisionAPI", "PhysicsMassAPI",
                   "PhysicsMeshCollisionAPI", "PhysicsMaterialAPI", "PhysicsFilteredPairsAPI",
                   "PhysxRigidBodyAPI"}  # only its damping is read; other attributes are warned about
# PhysX's defaults for PhysxRigidBodyAPI's damping (PhysxSchema; 1/s), used for dynamic
# bodies that author none unless load_usd(physx_defaults=False).
PHYSX_LINEAR_DAMPING = 0.0
PHYSX_ANGULAR_DAMPING = 0.05
_PHYSX_DAMPING_ATTRS = ("physxRigidBody:linearDamping", "physxRigidBody:angularDamping")
_SUPPORTED_TYPES = {"PhysicsScene", "PhysicsCollisionGroup"}

_Y = np.array([0.0, 1.0, 0.0])


def _warn_prim(warnings: List[str], prim: "Usd.Prim", what: str) -> None:
    warnings.append(f"{prim.GetPath()}: {what}")


def _fail(prim: "Usd.Prim", what: str) -> SceneFormatError:
    return SceneFormatError(f"{prim.GetPath()}: {what}")


class _Xf:
    """A prim's world transform split as x_world = R @ (s * x_local) + t (metres)."""

    def __init__(self, rotation: np.ndarray, translation: np.ndarray, scale: np.ndarray) -> None:
        self.rotation = rotation
        self.translation = translation
        self.scale = scale  # signed per-axis scale (negative: mirrored axis)


def _decompose(prim: "Usd.Prim", cache: "UsdGeom.XformCache", mpu: float,
               warnings: List[str]) -> _Xf:
    m = np.array(cache.GetLocalToWorldTransform(prim), dtype=np.float64)
    if not np.isfinite(m).all():
        raise _fail(prim, "transform is not finite")
    # Gf matrices act on row vectors (p' = p M); WMO uses columns: L = M[:3, :3]^T.
    lin = m[:3, :3].T
    t = m[3, :3] * mpu
    s = np.linalg.norm(lin, axis=0)
    if (s <= 0).any():
        raise _fail(prim, f"transform has a zero scale {tuple(s)}")
    r = lin / s
    if np.linalg.det(r) < 0:
        # A mirror: keep a proper rotation and carry the reflection in the scale.
        s[0] = -s[0]
        r[:, 0] = -r[:, 0]
        _warn_prim(warnings, prim, "mirrored transform: mirroring applied to mesh points only")
    if np.abs(r.T @ r - np.eye(3)).max() > 1e-6:
        _warn_prim(warnings, prim, "sheared transform: shear ignored (nearest rotation used)")
        u, _, vt = np.linalg.svd(r)
        r = u @ vt
    return _Xf(r, t, s)


def _rot_y_to(axis: str) -> np.ndarray:
    """Rotation taking WMO's local +Y (capsule/cylinder axis) onto USD ``axis``."""
    if axis == "X":  # -90 degrees about Z
        return np.array([[0.0, 1, 0], [-1, 0, 0], [0, 0, 1]])
    if axis == "Z":  # +90 degrees about X
        return np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]])
    return np.eye(3)


def _icosphere(subdivisions: int = 2) -> np.ndarray:
    """Unit-sphere points of a subdivided icosahedron (162 points for 2 subdivisions)."""
    p = (1 + 5 ** 0.5) / 2
    v = [(-1, p, 0), (1, p, 0), (-1, -p, 0), (1, -p, 0), (0, -1, p), (0, 1, p), (0, -1, -p),
         (0, 1, -p), (p, 0, -1), (p, 0, 1), (-p, 0, -1), (-p, 0, 1)]
    f = [(0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11), (1, 5, 9), (5, 11, 4),
         (11, 10, 2), (10, 7, 6), (7, 1, 8), (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8),
         (3, 8, 9), (4, 9, 5), (2, 4, 11), (6, 2, 10), (8, 6, 7), (9, 8, 1)]
    verts = [np.array(x, dtype=float) / np.linalg.norm(x) for x in v]
    for _ in range(subdivisions):
        mid: Dict[Tuple[int, int], int] = {}
        nf = []
        for a, b, c in f:
            ids = []
            for i, j in ((a, b), (b, c), (c, a)):
                key = (min(i, j), max(i, j))
                if key not in mid:
                    x = verts[i] + verts[j]
                    verts.append(x / np.linalg.norm(x))
                    mid[key] = len(verts) - 1
                ids.append(mid[key])
            nf += [(a, ids[0], ids[2]), (b, ids[1], ids[0]), (c, ids[2], ids[1]), tuple(ids)]
        f = nf
    return np.array(verts)


# A collider's geometry: convex parts with poses (rotation, translation) in the collider
# frame (rotation/translation of its prim, scale already applied), or one non-convex
# shape (TriangleMesh / Plane) at the collider frame.
_Part = Tuple["wmo.ConvexShape", np.ndarray, np.ndarray]


class _Geometry:
    def __init__(self, parts: List[_Part], concave: Optional["wmo.Shape"] = None) -> None:
        self.parts = parts
        self.concave = concave


def _get(attr: "Usd.Attribute", default: Any = None) -> Any:
    v = attr.Get() if attr and attr.IsValid() else None
    return default if v is None else v


def _finite_positive(prim: "Usd.Prim", name: str, value: float) -> float:
    if not (math.isfinite(value) and value > 0):
        raise _fail(prim, f"{name} must be a positive finite number, got {value!r}")
    return float(value)


def _mesh_arrays(prim: "Usd.Prim") -> Tuple[np.ndarray, np.ndarray]:
    """Points (stage units, prim frame) and fan-triangulated faces of a UsdGeom.Mesh,
    validated; SceneFormatError naming the prim on bad data."""
    mesh = UsdGeom.Mesh(prim)
    points = np.asarray(_get(mesh.GetPointsAttr(), []), dtype=np.float64).reshape(-1, 3)
    counts = np.asarray(_get(mesh.GetFaceVertexCountsAttr(), []), dtype=np.int64).reshape(-1)
    indices = np.asarray(_get(mesh.GetFaceVertexIndicesAttr(), []), dtype=np.int64).reshape(-1)
    if len(points) == 0 or len(counts) == 0:
        raise _fail(prim, "mesh has no points or no faces")
    if not np.isfinite(points).all():
        bad = int(np.argwhere(~np.isfinite(points))[0, 0])
        raise _fail(prim, f"points[{bad}] is not finite: {tuple(points[bad])}")
    if (counts < 3).any():
        bad = int(np.argmax(counts < 3))
        raise _fail(prim, f"faceVertexCounts[{bad}] = {int(counts[bad])}, a face needs at least 3 vertices")
    if int(counts.sum()) != len(indices):
        raise _fail(prim, f"faceVertexCounts sum to {int(counts.sum())} but faceVertexIndices has {len(indices)}")
    if ((indices < 0) | (indices >= len(points))).any():
        bad = int(np.argmax((indices < 0) | (indices >= len(points))))
        raise _fail(prim, f"faceVertexIndices[{bad}] = {int(indices[bad])} out of range 0..{len(points) - 1}")
    ntri = int((counts - 2).sum())
    if ntri > MAX_MESH_TRIANGLES:
        raise _fail(prim, f"{ntri} triangles is more than the {MAX_MESH_TRIANGLES} accepted")
    # Fan triangulation, vectorised: face f with start o and count c gives (o, o+k, o+k+1).
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    face_of_tri = np.repeat(np.arange(len(counts)), counts - 2)
    k = np.arange(ntri) - np.repeat(np.cumsum(counts - 2) - (counts - 2), counts - 2) + 1
    o = starts[face_of_tri]
    tris = np.stack([indices[o], indices[o + k], indices[o + k + 1]], axis=1)
    return points, tris


def _collider_geometry(prim: "Usd.Prim", xf: _Xf, mpu: float, static: bool, opts: Dict[str, Any],
                       warnings: List[str]) -> _Geometry:
    """The WMO shapes of one collider prim, in its frame (scale applied, metres); a
    shape WMO refuses (an infinite size after units and scale, ...) raises
    SceneFormatError naming the prim."""
    try:
        return _collider_shapes(prim, xf, mpu, static, opts, warnings)
    except SceneFormatError:
        raise
    except ValueError as e:
        raise _fail(prim, str(e)) from None


def _collider_shapes(prim: "Usd.Prim", xf: _Xf, mpu: float, static: bool, opts: Dict[str, Any],
                     warnings: List[str]) -> _Geometry:
    s = np.abs(xf.scale)
    path = str(prim.GetPath())
    eye, zero = np.eye(3), np.zeros(3)

    def nonuniform(a: Sequence[float]) -> bool:
        return max(a) - min(a) > 1e-6 * max(a)

    if prim.IsA(UsdGeom.Cube):
        size = _finite_positive(prim, "size", float(_get(UsdGeom.Cube(prim).GetSizeAttr(), 2.0)))
        return _Geometry([(wmo.Box(0.5 * size * s * mpu), eye, zero)])
    if prim.IsA(UsdGeom.Sphere):
        r = _finite_positive(prim, "radius", float(_get(UsdGeom.Sphere(prim).GetRadiusAttr(), 1.0)))
        if nonuniform(s):
            _warn_prim(warnings, prim, f"sphere scaled non-uniformly {tuple(s)}: "
                                       "approximated by the hull of a scaled 162-point icosphere")
            return _Geometry([(make_hull(_icosphere() * r * s * mpu, path, warnings), eye, zero)])
        return _Geometry([(wmo.Sphere(r * s[0] * mpu), eye, zero)])
    for schema, kind in ((getattr(UsdGeom, "Capsule", None), "capsule"),
                         (getattr(UsdGeom, "Cylinder", None), "cylinder"),
                         (getattr(UsdGeom, "Cone", None), "cone")):
        if schema is None or not prim.IsA(schema):
            continue
        g = schema(prim)
        r = _finite_positive(prim, "radius", float(_get(g.GetRadiusAttr(), 0.5 if kind == "capsule" else 1.0)))
        h = float(_get(g.GetHeightAttr(), 1.0 if kind == "capsule" else 2.0))
        if not (math.isfinite(h) and h >= 0):
            raise _fail(prim, f"height must be a non-negative finite number, got {h!r}")
        axis = str(_get(g.GetAxisAttr(), "Z"))
        ai = "XYZ".index(axis) if axis in ("X", "Y", "Z") else 2
        radial = [s[i] for i in range(3) if i != ai]
        if nonuniform(radial):
            _warn_prim(warnings, prim, f"{kind} scaled differently across its axis {tuple(s)}: larger radius used")
        rr, hh = r * max(radial) * mpu, 0.5 * h * s[ai] * mpu
        rot = _rot_y_to("XYZ"[ai])
        if kind == "capsule":
            return _Geometry([(wmo.Capsule(rr, hh), rot, zero)])
        if kind == "cylinder":
            if hh <= 0:
                raise _fail(prim, "cylinder height must be positive")
            return _Geometry([(wmo.Cylinder(rr, hh), rot, zero)])
        _warn_prim(warnings, prim, "cone approximated by a 32-sided convex hull")
        ang = np.linspace(0, 2 * np.pi, 32, endpoint=False)
        base = np.stack([rr * np.cos(ang), np.full(32, -hh), rr * np.sin(ang)], axis=1)
        pts = np.vstack([base, [[0.0, hh, 0.0]]])
        return _Geometry([(make_hull(pts, path, warnings), rot, zero)])
    if hasattr(UsdGeom, "Plane") and prim.IsA(UsdGeom.Plane):
        axis = str(_get(UsdGeom.Plane(prim).GetAxisAttr(), "Z"))
        n = np.eye(3)["XYZ".index(axis) if axis in ("X", "Y", "Z") else 2]
        if not static:
            _warn_prim(warnings, prim, "plane collider on a moving body ignored (WMO planes are static)")
            return _Geometry([])
        return _Geometry([], wmo.Plane(n, 0.0))
    if prim.IsA(UsdGeom.Mesh):
        points, tris = _mesh_arrays(prim)
        pts = points * xf.scale * mpu  # signed: mirroring applies to mesh points
        approx = "none"
        if prim.HasAPI(UsdPhysics.MeshCollisionAPI):
            approx = str(_get(UsdPhysics.MeshCollisionAPI(prim).GetApproximationAttr(), "none"))
        used = pts[np.unique(tris)]
        if approx == "meshSimplification":
            _warn_prim(warnings, prim, "approximation 'meshSimplification' not supported: mesh used as is")
            approx = "none"
        if approx == "none":
            if static:
                tris = drop_degenerate(pts, tris, path, warnings)
                try:
                    return _Geometry([], wmo.TriangleMesh(pts, tris))
                except ValueError as e:
                    raise _fail(prim, f"bad triangle mesh: {e}") from None
            _warn_prim(warnings, prim, "triangle mesh on a moving body: approximated by its convex hull "
                                       "(WMO triangle meshes are static)")
            approx = "convexHull"
        if approx == "convexHull":
            # The side a flat hull faces: the authored normals, else the face winding.
            normals = np.asarray(_get(UsdGeom.Mesh(prim).GetNormalsAttr(), []), dtype=np.float64).reshape(-1, 3)
            if len(normals):
                hint = normals.mean(axis=0) / np.where(xf.scale == 0, 1, xf.scale)
            else:
                a, b, c = pts[tris[:, 0]], pts[tris[:, 1]], pts[tris[:, 2]]
                hint = np.cross(b - a, c - a).sum(axis=0)
                if str(_get(UsdGeom.Mesh(prim).GetOrientationAttr(), "rightHanded")) == "leftHanded":
                    hint = -hint
            return _Geometry([(make_hull(used, path, warnings, flat=opts["flat_hulls"], normal_hint=hint),
                               eye, zero)])
        if approx == "convexDecomposition":
            tris = drop_degenerate(pts, tris, path, warnings)
            hulls = convex_decomposition(pts, tris, path, warnings, opts.get("coacd_options"))
            return _Geometry([(h, eye, zero) for h in hulls])
        if approx == "boundingSphere":
            lo, hi = used.min(axis=0), used.max(axis=0)
            c = 0.5 * (lo + hi)
            return _Geometry([(wmo.Sphere(float(np.linalg.norm(used - c, axis=1).max())), eye, c)])
        if approx == "boundingCube":
            lo, hi = used.min(axis=0), used.max(axis=0)
            _warn_prim(warnings, prim, "boundingCube approximated by the box aligned with the prim's axes")
            return _Geometry([(wmo.Box(np.maximum(0.5 * (hi - lo), 1e-6)), eye, 0.5 * (lo + hi))])
        _warn_prim(warnings, prim, f"approximation {approx!r} not supported: convex hull used")
        return _Geometry([(make_hull(used, path, warnings, flat=opts["flat_hulls"]), eye, zero)])
    _warn_prim(warnings, prim, f"PhysicsCollisionAPI on a {prim.GetTypeName() or 'typeless'} prim "
                               "(no geometry WMO can read): ignored")
    return _Geometry([])


def _material(prim: "Usd.Prim") -> Optional["Usd.Prim"]:
    """The material prim bound for physics to ``prim`` (or inherited from an ancestor),
    if it has PhysicsMaterialAPI."""
    mat = None
    try:
        mat, _ = UsdShade.MaterialBindingAPI(prim).ComputeBoundMaterial("physics")
    except Exception:  # noqa: BLE001 - older pxr without purposes: fall back below
        mat = None
    mprim = mat.GetPrim() if mat else None
    if mprim is None or not mprim.IsValid():
        # Bindings authored without applying MaterialBindingAPI may be ignored by newer
        # USD; walk the ancestors for the relationship itself.
        p = prim
        while p and p.IsValid() and not p.IsPseudoRoot():
            for name in ("material:binding:physics", "material:binding"):
                rel = p.GetRelationship(name)
                targets = rel.GetTargets() if rel else []
                if targets:
                    q = prim.GetStage().GetPrimAtPath(targets[0])
                    mprim = q if q and q.IsValid() else None
                    break
            if mprim is not None:
                break
            p = p.GetParent()
    if mprim is not None and mprim.IsValid() and mprim.HasAPI(UsdPhysics.MaterialAPI):
        return mprim
    return None


def _mass_api(prim: "Usd.Prim", kpu: float, mpu: float, warnings: List[str],
              given: Optional[Dict[str, Any]] = None) -> Tuple[Optional[float], Optional[float]]:
    """(mass kg, density kg/m^3) authored by PhysicsMassAPI on ``prim`` (None when not
    authored or zero, the schema's "unset"). The centre of mass (metres, the prim's
    scaled local frame), principal moments (kg m^2) and principal axes (x, y, z, w, the
    prim's local frame) go into ``given`` when the caller can use them (a rigid body's
    own MassAPI); elsewhere (colliders, static bodies) they are warned about."""
    if not prim.HasAPI(UsdPhysics.MassAPI):
        return None, None
    api = UsdPhysics.MassAPI(prim)
    mass = float(_get(api.GetMassAttr(), 0.0))
    density = float(_get(api.GetDensityAttr(), 0.0))
    for value, label in ((mass, "mass"), (density, "density")):
        if not math.isfinite(value) or value < 0:
            raise _fail(prim, f"physics:{label} must be a non-negative finite number, got {value!r}")
    com = _get(api.GetCenterOfMassAttr())
    # The schema's sentinel for "unset" is -inf in every component.
    if com is not None and all(math.isfinite(c) for c in com):
        if given is not None:
            given["center_of_mass"] = np.array(com, dtype=np.float64) * mpu
        else:
            _warn_prim(warnings, prim, f"physics:centerOfMass {tuple(com)} ignored: only a rigid body's own "
                                       "MassAPI sets its centre of mass")
    inertia = _get(api.GetDiagonalInertiaAttr())
    if inertia is not None and any(v != 0 for v in inertia):
        if given is not None:
            given["inertia"] = np.array(inertia, dtype=np.float64) * kpu * mpu ** 2
        else:
            _warn_prim(warnings, prim, f"physics:diagonalInertia {tuple(inertia)} ignored: only a rigid body's "
                                       "own MassAPI sets its inertia")
    axes = _get(api.GetPrincipalAxesAttr())
    if axes is not None and (axes.GetReal() != 0 or any(v != 0 for v in axes.GetImaginary())):
        q = np.array([*axes.GetImaginary(), axes.GetReal()], dtype=np.float64)
        if given is not None and "inertia" in given:
            given["inertia_axes"] = q / np.linalg.norm(q)
        elif given is None:
            _warn_prim(warnings, prim, "physics:principalAxes ignored: only a rigid body's own MassAPI sets them")
    return (mass * kpu if mass > 0 else None), (density * kpu / mpu ** 3 if density > 0 else None)


def _check_schemas(stage: "Usd.Stage", warnings: List[str]) -> None:
    for prim in stage.Traverse():
        tname = str(prim.GetTypeName())
        if (tname.startswith("Physics") or tname.startswith("Physx")) and tname not in _SUPPORTED_TYPES:
            _warn_prim(warnings, prim, f"{tname} is not supported by WMO yet: ignored")
        for api in prim.GetAppliedSchemas():
            base = str(api).split(":", 1)[0]
            if (base.startswith("Physics") or base.startswith("Physx")) and base not in _SUPPORTED_APIS:
                _warn_prim(warnings, prim, f"{api} is not supported by WMO yet: ignored")


def _gravity(stage: "Usd.Stage", up: str, mpu: float, warnings: List[str]) -> np.ndarray:
    scenes = [p for p in stage.Traverse() if p.IsA(UsdPhysics.Scene)]
    down = -np.eye(3)["XYZ".index(up)]
    if not scenes:
        warnings.append("stage has no PhysicsScene: earth gravity along -up used")
        return EARTH_GRAVITY * down
    if len(scenes) > 1:
        warnings.append(f"stage has {len(scenes)} PhysicsScenes: {scenes[0].GetPath()} used, the others ignored")
    sc = UsdPhysics.Scene(scenes[0])
    d = np.array(_get(sc.GetGravityDirectionAttr(), (0.0, 0.0, 0.0)), dtype=np.float64)
    mag = float(_get(sc.GetGravityMagnitudeAttr(), float("-inf")))
    if not np.isfinite(d).all() or (math.isnan(mag)):
        raise _fail(scenes[0], "gravity is not finite")
    n = float(np.linalg.norm(d))
    direction = d / n if n > 0 else down  # (0, 0, 0) is the schema's "use -up"
    magnitude = mag * mpu if math.isfinite(mag) and mag >= 0 else EARTH_GRAVITY  # -inf: earth
    return magnitude * direction


def _damping(prim: "Usd.Prim", physx_defaults: bool, warnings: List[str]) -> Dict[str, float]:
    """``add_body``'s ``linear_damping`` and ``angular_damping`` (1/s) for a dynamic body
    prim: the authored ``physxRigidBody:`` values, else PhysX's defaults (or nothing,
    WMO's 0, without ``physx_defaults``). Warns about the API's other authored attributes."""
    out: Dict[str, float] = {}
    defaults = (PHYSX_LINEAR_DAMPING, PHYSX_ANGULAR_DAMPING)
    for name, key, default in zip(_PHYSX_DAMPING_ATTRS, ("linear_damping", "angular_damping"), defaults):
        attr = prim.GetAttribute(name)
        if attr and attr.HasAuthoredValue():
            v = attr.Get()
            try:
                v = float(v)
            except (TypeError, ValueError):
                raise _fail(prim, f"{name} must be a number, got {v!r}") from None
            if not (math.isfinite(v) and v >= 0):
                raise _fail(prim, f"{name} must be a non-negative finite number (1/s), got {v!r}")
            out[key] = v
        elif physx_defaults:
            out[key] = default
    others = sorted(a.GetName() for a in prim.GetAttributes()
                    if a.GetName().startswith("physxRigidBody:") and a.GetName() not in _PHYSX_DAMPING_ATTRS
                    and a.HasAuthoredValue())
    if others:
        _warn_prim(warnings, prim, f"{', '.join(others)} not supported by WMO yet: ignored")
    return out


def load_usd(path: Union[str, "os.PathLike[str]"], *, meters_per_unit: Optional[float] = None,
             flat_hulls: str = "thicken", physx_defaults: bool = True, coacd_options: Optional[Dict[str, Any]] = None,
             world: Optional["wmo.World"] = None, **world_options: Any) -> LoadResult:
    """Reads the USD stage at ``path`` (.usd, .usda, .usdc, .usdz) into a World (see the
    module docstring for what is supported and how units, axes and scales convert).

    ``meters_per_unit``: overrides the stage's ``metersPerUnit``. ``flat_hulls``:
    ``"thicken"`` (default) or ``"error"`` for coplanar convexHull colliders.
    ``physx_defaults``: unauthored damping of dynamic bodies takes PhysX's defaults
    (linear 0, angular 0.05 1/s; see the module docstring); False keeps WMO's 0.
    ``coacd_options``: overrides of :data:`wmo.io.obj.DEFAULT_COACD_OPTIONS` for
    convexDecomposition. ``world``: add the bodies to this World (its gravity is left
    alone) instead of a new one; ``world_options`` (``dt``, ``substeps``, ...) go to the new
    World, whose gravity comes from the PhysicsScene.

    Returns a LoadResult: ``bodies`` keyed by prim path; ``info`` has ``meters_per_unit``,
    ``kilograms_per_unit``, ``up_axis``, ``gravity`` (m/s^2) and ``collision_groups``
    (group prim path -> WMO index). Raises SceneFileNotFoundError / SceneFormatError.
    """
    if Usd is None:
        raise ImportError("reading USD needs Pixar's usd-core: pip install usd-core")
    if flat_hulls not in ("thicken", "error"):
        raise ValueError(f"flat_hulls must be 'thicken' or 'error', got {flat_hulls!r}")
    if not isinstance(physx_defaults, bool):
        raise TypeError(f"physx_defaults must be True or False, got {physx_defaults!r}")
    name = os.fspath(path)
    if not Path(name).is_file():
        raise SceneFileNotFoundError(f"{name}: no such file")
    try:
        stage = Usd.Stage.Open(name, Usd.Stage.LoadAll)
    except Exception as e:  # Tf.ErrorException: parse errors, unknown format, ...
        msg = " ".join(str(e).split())
        raise SceneFormatError(f"{name}: cannot read USD: {msg[:500]}") from None
    if stage is None:
        raise SceneFormatError(f"{name}: cannot read USD")

    warnings: List[str] = []
    mpu = float(meters_per_unit) if meters_per_unit is not None else float(UsdGeom.GetStageMetersPerUnit(stage))
    if not (math.isfinite(mpu) and mpu > 0):
        raise SceneFormatError(f"{name}: metersPerUnit must be positive, got {mpu!r}")
    kpu = float(UsdPhysics.GetStageKilogramsPerUnit(stage))
    if not (math.isfinite(kpu) and kpu > 0):
        raise SceneFormatError(f"{name}: kilogramsPerUnit must be positive, got {kpu!r}")
    up = str(UsdGeom.GetStageUpAxis(stage))
    opts = {"flat_hulls": flat_hulls, "coacd_options": coacd_options}

    _check_schemas(stage, warnings)
    gravity = _gravity(stage, up, mpu, warnings)
    scenes = [p for p in stage.Traverse() if p.IsA(UsdPhysics.Scene)]
    if scenes:  # a stage WMO wrote: its exact gravity and World settings
        exact_g, settings = usd_exact.read_scene(scenes[0])
        if exact_g is not None:
            gravity = exact_g
        elif settings:
            warnings.append(f"{scenes[0].GetPath()}: gravity edited after WMO wrote it: the schema's used")
        world_options = {**settings, **world_options}
    cache = UsdGeom.XformCache(Usd.TimeCode.Default())

    # Rigid bodies and colliders; each collider belongs to its nearest rigid-body ancestor.
    body_prims: List[Usd.Prim] = []
    colliders: Dict[str, List[Usd.Prim]] = {}  # body path ("" for none) -> collider prims
    static_colliders: List[Usd.Prim] = []
    for prim in stage.Traverse():
        if prim.HasAPI(UsdPhysics.RigidBodyAPI):
            body_prims.append(prim)
            colliders.setdefault(str(prim.GetPath()), [])
        if prim.HasAPI(UsdPhysics.CollisionAPI):
            if not bool(_get(UsdPhysics.CollisionAPI(prim).GetCollisionEnabledAttr(), True)):
                _warn_prim(warnings, prim, "collisionEnabled = false: collider skipped")
                continue
            p = prim
            while p and p.IsValid() and not p.IsPseudoRoot() and not p.HasAPI(UsdPhysics.RigidBodyAPI):
                p = p.GetParent()
            if p and p.IsValid() and not p.IsPseudoRoot():
                colliders.setdefault(str(p.GetPath()), []).append(prim)
            else:
                static_colliders.append(prim)

    w = world if world is not None else wmo.World(gravity=gravity, **world_options)
    bodies: Dict[str, wmo.Body] = {}
    specs: Dict[str, Dict[str, Any]] = {}
    owner: Dict[str, wmo.Body] = {}  # body or collider path -> WMO body (for filtering)
    body_colliders: Dict[str, List[Usd.Prim]] = {}

    def material_props(prims: List["Usd.Prim"], where: "Usd.Prim") -> Dict[str, Optional[float]]:
        mats = [m for m in (_material(c) for c in prims) if m is not None]
        if not mats:
            return {"friction": 0.5, "restitution": 0.0, "density": None}
        if len({str(m.GetPath()) for m in mats}) > 1:
            _warn_prim(warnings, where, f"colliders bind different physics materials: {mats[0].GetPath()} used")
        api = UsdPhysics.MaterialAPI(mats[0])
        dyn = float(_get(api.GetDynamicFrictionAttr(), 0.0))
        sta = float(_get(api.GetStaticFrictionAttr(), 0.0))
        rest = float(_get(api.GetRestitutionAttr(), 0.0))
        dens = float(_get(api.GetDensityAttr(), 0.0))
        for v, label in ((dyn, "dynamicFriction"), (sta, "staticFriction"), (rest, "restitution"), (dens, "density")):
            if not (math.isfinite(v) and v >= 0):
                raise _fail(mats[0], f"physics:{label} must be a non-negative finite number, got {v!r}")
        if sta != dyn and api.GetStaticFrictionAttr().HasAuthoredValue():
            _warn_prim(warnings, mats[0], f"staticFriction {sta} differs from dynamicFriction {dyn}: "
                                          "WMO has one friction coefficient, dynamicFriction used")
        return {"friction": dyn, "restitution": rest, "density": dens * kpu / mpu ** 3 if dens > 0 else None}

    def assemble(parts: List[Tuple["wmo.ConvexShape", np.ndarray, np.ndarray]]) -> Tuple["wmo.Shape", np.ndarray, np.ndarray]:
        """One shape for convex parts given in the body frame; a lone part keeps its
        own pose folded into the body's (returned as an extra rotation/translation)."""
        if len(parts) == 1:
            return parts[0]
        return wmo.Compound([(sh, wmo.Pose(t, quat_from_matrix(r))) for sh, r, t in parts]), np.eye(3), np.zeros(3)

    def add(key: str, prim: "Usd.Prim", xf: _Xf, shape_parts, concave, kind: str, mass, density, mat,
            lin=None, ang=None, given=None, damping=None) -> Optional[wmo.Body]:
        if concave is not None:
            shape, r, t = concave
        elif shape_parts:
            shape, r, t = assemble(shape_parts)
        else:
            _warn_prim(warnings, prim, "body without any usable collider: not created")
            return None
        rot = xf.rotation @ r
        pos = xf.translation + xf.rotation @ t
        kwargs: Dict[str, Any] = dict(position=pos, orientation=quat_from_matrix(rot), kind=kind,
                                      friction=mat["friction"], restitution=mat["restitution"])
        if kind == "dynamic":
            if mass is not None:
                kwargs["mass"] = mass
            elif density is not None:
                kwargs["density"] = density
            if lin is not None:
                kwargs["linear_velocity"] = lin
            if ang is not None:
                kwargs["angular_velocity"] = ang
            kwargs.update(damping or {})
            given = given or {}
            # MassAPI values are in the body prim's frame; the shape's frame is that frame
            # turned by r and moved by t (a lone collider's own pose) and unscaled.
            if "center_of_mass" in given:
                kwargs["center_of_mass"] = r.T @ (xf.scale * given["center_of_mass"] - t)
            if "inertia" in given:
                kwargs["inertia"] = given["inertia"]
                axes = given.get("inertia_axes", np.array([0.0, 0.0, 0.0, 1.0]))
                kwargs["inertia_axes"] = quat_from_matrix(r.T @ wmo.Pose(orientation=axes).matrix())
        elif kind == "kinematic":
            if lin is not None:
                kwargs["linear_velocity"] = lin
            if ang is not None:
                kwargs["angular_velocity"] = ang
        try:
            b = w.add_body(shape, **kwargs)
        except ValueError as e:
            raise _fail(prim, f"cannot add the body: {e}") from None
        bodies[key] = b
        specs[key] = dict(kwargs, shape=shape)
        return b

    for prim in body_prims:
        key = str(prim.GetPath())
        api = UsdPhysics.RigidBodyAPI(prim)
        kind = "dynamic"
        if not bool(_get(api.GetRigidBodyEnabledAttr(), True)):
            kind = "static"
        elif bool(_get(api.GetKinematicEnabledAttr(), False)):
            kind = "kinematic"
            if UsdGeom.Xformable(prim).TransformMightBeTimeVarying():
                _warn_prim(warnings, prim, "kinematic animation (time samples) ignored: initial pose used")
        if bool(_get(api.GetStartsAsleepAttr(), False)):
            _warn_prim(warnings, prim, "startsAsleep ignored (bodies start awake)")
        cols = colliders.get(key, [])
        exact, has_exact = usd_exact.read_body(prim, cols, kind) if mpu == 1.0 else (None, False)
        if exact is not None:
            shape, kwargs = exact
            try:
                b = w.add_body(shape, **kwargs)
            except ValueError as e:
                raise _fail(prim, f"cannot add the body: {e}") from None
            bodies[key], specs[key], owner[key], body_colliders[key] = b, dict(kwargs, shape=shape), b, cols
            owner.update((str(c.GetPath()), b) for c in cols)
            continue
        if has_exact:
            _warn_prim(warnings, prim, "edited after WMO wrote it: its wmo: exact values are ignored, "
                                       "the schema's used")
        xf = _decompose(prim, cache, mpu, warnings)
        parts: List[_Part] = []
        concave = None
        for c in cols:
            cxf = _decompose(c, cache, mpu, warnings) if c != prim else xf
            geo = _collider_geometry(c, cxf, mpu, kind == "static", opts, warnings)
            rel_r = xf.rotation.T @ cxf.rotation
            rel_t = xf.rotation.T @ (cxf.translation - xf.translation)
            if geo.concave is not None:
                if len(cols) == 1 and kind == "static":
                    concave = (geo.concave, rel_r, rel_t)
                    break
                _warn_prim(warnings, c, "non-convex collider cannot join a compound body: ignored")
                continue
            for sh, r, t in geo.parts:
                parts.append((sh, rel_r @ r, rel_t + rel_r @ t))
        given: Dict[str, Any] = {}
        b_mass, b_density = _mass_api(prim, kpu, mpu, warnings, given)
        c_mass = c_density = None
        for c in cols:
            if c != prim:
                cm, cd = _mass_api(c, kpu, mpu, warnings)
                c_mass = (c_mass or 0.0) + cm if cm is not None else c_mass
                c_density = c_density if c_density is not None else cd
        mat = material_props(cols, prim)
        mass = b_mass if b_mass is not None else (None if b_density is not None else c_mass)
        density = b_density if b_density is not None else (c_density if c_density is not None else mat["density"])
        lin = ang = None
        v = _get(api.GetVelocityAttr())
        if v is not None:
            lin = np.array(v, dtype=np.float64) * mpu
        av = _get(api.GetAngularVelocityAttr())
        if av is not None:
            ang = np.radians(np.array(av, dtype=np.float64))  # USD: degrees per second
        for arr, label in ((lin, "velocity"), (ang, "angularVelocity")):
            if arr is not None and not np.isfinite(arr).all():
                raise _fail(prim, f"physics:{label} is not finite")
        damping = _damping(prim, physx_defaults, warnings) if kind == "dynamic" else None
        b = add(key, prim, xf, parts, concave, kind, mass, density, mat, lin, ang, given, damping)
        if b is not None:
            owner[key] = b
            for c in cols:
                owner[str(c.GetPath())] = b
            body_colliders[key] = cols

    for c in static_colliders:
        key = str(c.GetPath())
        xf = _decompose(c, cache, mpu, warnings)
        geo = _collider_geometry(c, xf, mpu, True, opts, warnings)
        _mass_api(c, kpu, mpu, warnings)  # warn about ignored mass properties; static bodies have no mass
        concave = (geo.concave, np.eye(3), np.zeros(3)) if geo.concave is not None else None
        b = add(key, c, xf, geo.parts, concave, "static", None, None, material_props([c], c))
        if b is not None:
            owner[key] = b
            body_colliders[key] = [c]

    def owner_of(path: "Sdf.Path") -> Optional[wmo.Body]:
        p = path
        while not p.isEmpty and p != Sdf.Path.absoluteRootPath:
            if str(p) in owner:
                return owner[str(p)]
            p = p.GetParentPath()
        return None

    # Pair filtering.
    has_pairs = hasattr(w, "set_pair_collision")
    for prim in stage.Traverse():
        if not prim.HasAPI(UsdPhysics.FilteredPairsAPI):
            continue
        me = owner_of(prim.GetPath())
        targets = UsdPhysics.FilteredPairsAPI(prim).GetFilteredPairsRel().GetTargets()
        for t in targets:
            other = owner_of(t)
            if me is None or other is None:
                _warn_prim(warnings, prim, f"filtered pair with {t}: no WMO body on one side, ignored")
                continue
            if me.index == other.index:
                continue
            if not has_pairs:
                _warn_prim(warnings, prim, f"filtered pair with {t} ignored: this WMO build has no "
                                           "World.set_pair_collision")
                continue
            w.set_pair_collision(me, other, False)

    # Collision groups.
    groups = [p for p in stage.Traverse() if p.IsA(UsdPhysics.CollisionGroup)]
    group_index: Dict[str, int] = {}
    if groups:
        merged: Dict[str, int] = {}
        # A stage WMO wrote names its groups' WMO numbers; used when they are all there,
        # distinct and in range (a group number decides nothing but filtering, so
        # otherwise the groups are simply numbered 1, 2, ...).
        wmo_index = [g.GetAttribute("wmo:index").Get() if g.HasAttribute("wmo:index") else None for g in groups]
        if (all(isinstance(i, int) and 0 <= i <= MAX_COLLISION_GROUPS for i in wmo_index)
                and len(set(wmo_index)) == len(groups)):
            group_index = {str(g.GetPath()): i for g, i in zip(groups, wmo_index)}
        for g in groups if not group_index else ():
            merge = str(_get(UsdPhysics.CollisionGroup(g).GetMergeGroupNameAttr(), "") or "")
            if merge and merge in merged:
                group_index[str(g.GetPath())] = merged[merge]
                continue
            idx = len(set(group_index.values())) + 1
            if idx > MAX_COLLISION_GROUPS:
                raise _fail(g, f"more than {MAX_COLLISION_GROUPS} collision groups: WMO has 63")
            group_index[str(g.GetPath())] = idx
            if merge:
                merged[merge] = idx
        has_groups = hasattr(w, "set_group_collision")
        if not has_groups:
            warnings.append("collision groups ignored: this WMO build has no World.set_group_collision")
        else:
            queries = [(g, UsdPhysics.CollisionGroup(g).GetCollidersCollectionAPI().ComputeMembershipQuery())
                       for g in groups]
            for key, cols in body_colliders.items():
                found = [group_index[str(g.GetPath())] for c in cols for g, q in queries
                         if q.IsPathIncluded(c.GetPath())]
                if not found:
                    continue
                if len(set(found)) > 1:
                    warnings.append(f"{key}: colliders in several collision groups: the first one used")
                bodies[key].collision_group = found[0]
            all_idx = sorted(set(group_index.values())) + [0]
            for g in groups:
                cg = UsdPhysics.CollisionGroup(g)
                me_idx = group_index[str(g.GetPath())]
                listed = set()
                for t in cg.GetFilteredGroupsRel().GetTargets():
                    if str(t) not in group_index:
                        _warn_prim(warnings, g, f"filteredGroups target {t} is not a collision group: ignored")
                        continue
                    listed.add(group_index[str(t)])
                if bool(_get(cg.GetInvertFilteredGroupsAttr(), False)):
                    # Inverted: collides only with the listed groups.
                    for other in all_idx:
                        if other not in listed:
                            w.set_group_collision(me_idx, other, False)
                else:
                    for other in listed:
                        w.set_group_collision(me_idx, other, False)

    info = {"meters_per_unit": mpu, "kilograms_per_unit": kpu, "up_axis": up,
            "gravity": np.asarray(w.gravity).copy(), "collision_groups": group_index}
    return LoadResult(world=w, bodies=bodies, warnings=warnings, specs=specs, info=info)
