"""Writing a :class:`wmo.World` as a UsdPhysics stage (``.usda`` text or ``.usdc`` binary),
through Pixar's ``usd-core``.

The stage holds what a UsdPhysics reader (Omniverse, Isaac Sim, usdview with a physics
plugin, :mod:`wmo.io.usd`) needs to simulate the same scene:

- ``/World/PhysicsScene``: gravity direction and magnitude; the stage's ``upAxis`` is
  the axis closest to -gravity (Y or Z), ``metersPerUnit`` 1 and ``kilogramsPerUnit`` 1
  (WMO's units: nothing is converted).
- one ``Xform`` per body, ``/World/body_<k>`` (k its row), with a double-precision
  ``translate`` and ``orient`` (the exact float64 pose), ``PhysicsRigidBodyAPI`` for
  dynamic and kinematic bodies (``kinematicEnabled``, ``velocity`` in m/s,
  ``angularVelocity`` in degrees per second, as the schema says), ``PhysicsMassAPI``
  (mass, centre of mass, principal moments and axes) and PhysX's ``PhysxRigidBodyAPI``
  damping (``physxRigidBody:linearDamping``, ``angularDamping``, 1/s) for dynamic ones;
- its collider, a child prim ``geom`` with ``PhysicsCollisionAPI``: ``Cube`` (size 2,
  scaled to the box's half-extents), ``Sphere``, ``Capsule`` and ``Cylinder`` (axis Y,
  as WMO's), ``Mesh`` with ``PhysicsMeshCollisionAPI`` approximation ``convexHull``
  (convex hulls: their vertices and faces) or ``none`` (triangle meshes), ``Plane``; a
  compound writes one child collider per part, ``geom_<j>``, at its local pose;
- physics materials (``PhysicsMaterialAPI``: static and dynamic friction both the
  body's friction, restitution), one per distinct pair of values, under
  ``/World/Materials``, bound with the ``physics`` purpose;
- collision groups (``PhysicsCollisionGroup`` under ``/World/CollisionGroups``, their
  colliders in the ``colliders`` collection, ``filteredGroups`` for each pair of groups
  the world does not let collide);
- filtered body pairs (``PhysicsFilteredPairsAPI`` on the first body of each pair);
- custom ``wmo:`` attributes with the exact float64 values (poses, shapes, masses,
  materials, velocities, the World's settings; see :mod:`wmo.io.usd_exact`), so that a
  world saved and loaded by WMO simulates bit for bit as the original; other readers
  ignore them.

A static body is a rigid body with ``rigidBodyEnabled = false`` (UsdPhysics' static
body), so that each WMO body is one prim, compound or not, in row order.

With ``steps``, the world is also simulated that many steps and each body's pose is
written as time samples (time codes are steps, ``timeCodesPerSecond`` = 1 / dt), so the
run plays back in usdview.
"""
from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np

from .. import _core
from . import usd_exact
from .obj import quat_from_matrix

__all__ = ["save_usd"]


def _up_axis(gravity: np.ndarray) -> str:
    g = np.asarray(gravity, dtype=float)
    if not g.any():
        return "Y"
    return "Z" if abs(g[2]) > abs(g[1]) else "Y"


def _principal_axes(inertia: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    moments, axes = np.linalg.eigh(inertia)
    if np.linalg.det(axes) < 0:
        axes[:, 2] = -axes[:, 2]
    return moments, np.array(quat_from_matrix(axes))


def _quatd(Gf, q) -> "Gf.Quatd":
    x, y, z, w = (float(v) for v in q)
    return Gf.Quatd(w, Gf.Vec3d(x, y, z))


def _write_collider(stage, path: str, shape, UsdGeom, UsdPhysics, Gf, Vt, local_pose=None):
    """A collider prim for a convex or concave shape; returns it."""
    if isinstance(shape, _core.Box):
        prim = UsdGeom.Cube.Define(stage, path)
        prim.CreateSizeAttr(2.0)
        xf = UsdGeom.Xformable(prim)
    elif isinstance(shape, _core.Sphere):
        prim = UsdGeom.Sphere.Define(stage, path)
        prim.CreateRadiusAttr(float(shape.radius))
        xf = UsdGeom.Xformable(prim)
    elif isinstance(shape, (_core.Capsule, _core.Cylinder)):
        cls = UsdGeom.Capsule if isinstance(shape, _core.Capsule) else UsdGeom.Cylinder
        prim = cls.Define(stage, path)
        prim.CreateRadiusAttr(float(shape.radius))
        prim.CreateHeightAttr(2.0 * float(shape.half_height))  # the cylinder part, without the caps
        prim.CreateAxisAttr("Y")
        xf = UsdGeom.Xformable(prim)
    elif isinstance(shape, (_core.ConvexHull, _core.TriangleMesh)):
        prim = UsdGeom.Mesh.Define(stage, path)
        v = np.asarray(shape.vertices, dtype=float)
        if isinstance(shape, _core.ConvexHull):
            faces = [np.asarray(f, dtype=int) for f in shape.faces]
            counts = [len(f) for f in faces]
            indices = np.concatenate(faces).tolist()
        else:
            tris = np.asarray(shape.triangles, dtype=int)
            counts, indices = [3] * len(tris), tris.ravel().tolist()
        prim.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(v.astype(np.float32)))
        prim.CreateFaceVertexCountsAttr(counts)
        prim.CreateFaceVertexIndicesAttr(indices)
        mesh_api = UsdPhysics.MeshCollisionAPI.Apply(prim.GetPrim())
        mesh_api.CreateApproximationAttr("convexHull" if isinstance(shape, _core.ConvexHull) else "none")
        xf = UsdGeom.Xformable(prim)
    elif isinstance(shape, _core.Plane):
        prim = UsdGeom.Plane.Define(stage, path)
        n = np.asarray(shape.normal, dtype=float)
        axis = "XYZ"[int(np.argmax(np.abs(n)))]
        if abs(abs(n["XYZ".index(axis)]) - 1) > 1e-12:
            raise ValueError(f"{path}: only axis-aligned planes are written to USD, got normal {n.tolist()}")
        prim.CreateAxisAttr(axis)
        xf = UsdGeom.Xformable(prim)
        offset = np.zeros(3)
        offset["XYZ".index(axis)] = float(shape.offset) * np.sign(n["XYZ".index(axis)])
        xf.AddTranslateOp(UsdGeom.XformOp.PrecisionDouble).Set(Gf.Vec3d(*offset.tolist()))
    else:
        raise TypeError(f"{path}: a {shape.type} shape cannot be written to USD")
    if local_pose is not None:
        p, q = local_pose
        xf.AddTranslateOp(UsdGeom.XformOp.PrecisionDouble, "local").Set(Gf.Vec3d(*map(float, p)))
        xf.AddOrientOp(UsdGeom.XformOp.PrecisionDouble, "local").Set(_quatd(Gf, q))
    if isinstance(shape, _core.Box):
        xf.AddScaleOp(UsdGeom.XformOp.PrecisionDouble).Set(Gf.Vec3d(*map(float, shape.half_extents)))
    UsdPhysics.CollisionAPI.Apply(prim.GetPrim())
    return prim.GetPrim()


def save_usd(world: _core.World, path: str | os.PathLike, *, steps: int = 0) -> None:
    """Writes `world` to `path` (.usda, .usdc or .usd) as a UsdPhysics stage (see the
    module docstring); with `steps` > 0, also simulates that many steps (the world
    moves on) and writes each body's pose per step as time samples. Raises ValueError
    for a path with another suffix, TypeError for a shape USD cannot hold."""
    from pxr import Gf, Sdf, Usd, UsdGeom, UsdPhysics, UsdShade, Vt

    path = Path(path)
    if path.suffix not in (".usda", ".usdc", ".usd"):
        raise ValueError(f"path must end in .usda, .usdc or .usd, got {str(path)!r}")
    if not (isinstance(steps, int) and steps >= 0):
        raise ValueError(f"steps must be an integer >= 0, got {steps!r}")
    stage = Usd.Stage.CreateNew(str(path))
    g = np.asarray(world.gravity, dtype=float)
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z if _up_axis(g) == "Z" else UsdGeom.Tokens.y)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    UsdPhysics.SetStageKilogramsPerUnit(stage, 1.0)
    root = UsdGeom.Xform.Define(stage, "/World")
    stage.SetDefaultPrim(root.GetPrim())
    scene = UsdPhysics.Scene.Define(stage, "/World/PhysicsScene")
    mag = float(np.linalg.norm(g))
    scene.CreateGravityDirectionAttr(Gf.Vec3f(*(g / mag if mag > 0 else np.array([0.0, -1.0, 0.0])).tolist()))
    scene.CreateGravityMagnitudeAttr(mag)
    usd_exact.write_scene(scene.GetPrim(), world)

    materials: dict[tuple[float, float], Sdf.Path] = {}
    group_members: dict[int, list[Sdf.Path]] = {}
    xform_ops = []
    for k in range(world.body_count):
        body = world.body(k)
        bpath = f"/World/body_{k}"
        xf = UsdGeom.Xform.Define(stage, bpath)
        t_op = xf.AddTranslateOp(UsdGeom.XformOp.PrecisionDouble)
        o_op = xf.AddOrientOp(UsdGeom.XformOp.PrecisionDouble)
        t_op.Set(Gf.Vec3d(*map(float, world.positions[k])))
        o_op.Set(_quatd(Gf, world.orientations[k]))
        xform_ops.append((t_op, o_op))
        prim = xf.GetPrim()
        rb = UsdPhysics.RigidBodyAPI.Apply(prim)
        if body.kind == "static":  # a disabled rigid body is static, and keeps the body one prim
            rb.CreateRigidBodyEnabledAttr(False)
        else:
            rb.CreateKinematicEnabledAttr(body.kind == "kinematic")
            rb.CreateVelocityAttr(Gf.Vec3f(*map(float, world.linear_velocities[k])))
            rb.CreateAngularVelocityAttr(Gf.Vec3f(*map(math.degrees, world.angular_velocities[k])))
        if body.kind == "dynamic":
            mass = UsdPhysics.MassAPI.Apply(prim)
            mass.CreateMassAttr(float(body.mass))
            mass.CreateCenterOfMassAttr(Gf.Vec3f(*map(float, body.center_of_mass)))
            moments, axes = _principal_axes(np.asarray(body.inertia))
            mass.CreateDiagonalInertiaAttr(Gf.Vec3f(*map(float, moments)))
            mass.CreatePrincipalAxesAttr(Gf.Quatf(float(axes[3]), Gf.Vec3f(*map(float, axes[:3]))))
            # Damping is PhysX's schema, not UsdPhysics'; written so PhysX-based readers
            # (and wmo.io.usd, which otherwise assumes PhysX's default 0.05 1/s) see it.
            prim.AddAppliedSchema("PhysxRigidBodyAPI")
            for name, value in (("linearDamping", body.linear_damping), ("angularDamping", body.angular_damping)):
                prim.CreateAttribute(f"physxRigidBody:{name}", Sdf.ValueTypeNames.Float).Set(float(value))
        shape = body.shape
        if isinstance(shape, _core.Compound):
            colliders = []
            for j, (child, pose) in enumerate(shape.children):
                colliders.append(_write_collider(stage, f"{bpath}/geom_{j}", child, UsdGeom, UsdPhysics, Gf, Vt,
                                                 (pose.position, pose.orientation)))
                usd_exact.write_collider(colliders[-1], child, pose)
        else:
            colliders = [_write_collider(stage, f"{bpath}/geom", shape, UsdGeom, UsdPhysics, Gf, Vt)]
            usd_exact.write_collider(colliders[0], shape)
        key = (float(body.friction), float(body.restitution))
        if key not in materials:
            mpath = Sdf.Path(f"/World/Materials/material_{len(materials)}")
            mat = UsdShade.Material.Define(stage, mpath)
            api = UsdPhysics.MaterialAPI.Apply(mat.GetPrim())
            api.CreateStaticFrictionAttr(key[0])
            api.CreateDynamicFrictionAttr(key[0])
            api.CreateRestitutionAttr(key[1])
            materials[key] = mpath
        mat = UsdShade.Material(stage.GetPrimAtPath(materials[key]))
        for c in colliders:
            UsdShade.MaterialBindingAPI.Apply(c).Bind(mat, UsdShade.Tokens.weakerThanDescendants, "physics")
        group_members.setdefault(int(body.collision_group), []).extend(c.GetPath() for c in colliders)
        usd_exact.write_body(prim, world, k)

    for a, b in world.filtered_pairs():
        api = UsdPhysics.FilteredPairsAPI.Apply(stage.GetPrimAtPath(f"/World/body_{a.index}"))
        api.CreateFilteredPairsRel().AddTarget(Sdf.Path(f"/World/body_{b.index}"))

    # Collision groups, only where the world filters some pair of groups.
    groups = sorted(group_members)
    filtered = [(a, b) for i, a in enumerate(groups) for b in groups[i:] if not world.group_collision(a, b)]
    if filtered:
        paths = {}
        for gi in groups:
            grp = UsdPhysics.CollisionGroup.Define(stage, f"/World/CollisionGroups/group_{gi}")
            grp.GetPrim().CreateAttribute("wmo:index", Sdf.ValueTypeNames.Int, custom=True).Set(gi)
            coll = Usd.CollectionAPI.Apply(grp.GetPrim(), "colliders")
            for p in group_members[gi]:
                coll.GetIncludesRel().AddTarget(p)
            paths[gi] = grp
        for a, b in filtered:
            paths[a].CreateFilteredGroupsRel().AddTarget(paths[b].GetPath())
            if a != b:
                paths[b].CreateFilteredGroupsRel().AddTarget(paths[a].GetPath())

    if steps:
        stage.SetTimeCodesPerSecond(1.0 / world.dt)
        stage.SetStartTimeCode(0)
        stage.SetEndTimeCode(steps)
        for k, (t_op, o_op) in enumerate(xform_ops):
            t_op.Set(Gf.Vec3d(*map(float, world.positions[k])), 0)
            o_op.Set(_quatd(Gf, world.orientations[k]), 0)
        for s in range(1, steps + 1):
            world.step()
            pos, ori = np.asarray(world.positions), np.asarray(world.orientations)
            for k, (t_op, o_op) in enumerate(xform_ops):
                t_op.Set(Gf.Vec3d(*map(float, pos[k])), s)
                o_op.Set(_quatd(Gf, ori[k]), s)
    stage.GetRootLayer().Save()
