"""wmo.io.usd_writer: a World written as a UsdPhysics stage, read back with Pixar's own
API (not with WMO's reader, so the writer is checked against the schema)."""
from __future__ import annotations

import math

import numpy as np
import pytest

pxr = pytest.importorskip("pxr", reason="usd-core (PyPI) is not installed")

import wmo  # noqa: E402
from wmo.io.usd_writer import save_usd  # noqa: E402
from pxr import Usd, UsdGeom, UsdPhysics, UsdShade  # noqa: E402


def _world():
    w = wmo.World(gravity=(0, 0, -9.81))
    w.add_body(wmo.Box((5, 5, 0.5)), position=(0, 0, -0.5), kind="static", friction=0.8)
    w.add_body(wmo.Box((0.5, 0.25, 0.125)), position=(0, 0, 2), orientation=(0, 0, math.sin(0.2), math.cos(0.2)),
               mass=3.0, friction=0.3, restitution=0.5, linear_velocity=(1, 0, 0), angular_velocity=(0, 0, 2.0))
    w.add_body(wmo.Capsule(0.2, 0.4), position=(1, 0, 3), kind="kinematic", collision_group=4)
    w.add_body(wmo.ConvexHull(np.random.default_rng(1).normal(size=(16, 3))), position=(-2, 0, 2),
               center_of_mass=(0.1, 0, 0))
    w.set_group_collision(0, 4, False)
    return w


def test_the_stage_holds_the_worlds_physics(tmp_path):
    w = _world()
    save_usd(w, tmp_path / "w.usda")
    st = Usd.Stage.Open(str(tmp_path / "w.usda"))
    assert UsdGeom.GetStageUpAxis(st) == "Z" and UsdGeom.GetStageMetersPerUnit(st) == 1.0
    scene = UsdPhysics.Scene(st.GetPrimAtPath("/World/PhysicsScene"))
    assert scene.GetGravityMagnitudeAttr().Get() == pytest.approx(9.81, rel=1e-6)
    assert tuple(scene.GetGravityDirectionAttr().Get()) == (0, 0, -1)
    ground, box, cap, hull = (st.GetPrimAtPath(f"/World/body_{k}") for k in range(4))
    assert not ground.HasAPI(UsdPhysics.RigidBodyAPI)
    assert box.HasAPI(UsdPhysics.RigidBodyAPI) and box.HasAPI(UsdPhysics.MassAPI)
    # The pose, exact (double translate and orient) and as the schema composes it.
    m = UsdGeom.Xformable(box).ComputeLocalToWorldTransform(Usd.TimeCode.Default())
    np.testing.assert_allclose(np.array(m.ExtractTranslation()), [0, 0, 2], atol=1e-12)
    q = m.ExtractRotationQuat()
    np.testing.assert_allclose([*q.GetImaginary(), q.GetReal()], [0, 0, math.sin(0.2), math.cos(0.2)], atol=1e-12)
    rb = UsdPhysics.RigidBodyAPI(box)
    assert tuple(rb.GetVelocityAttr().Get()) == (1, 0, 0)
    assert rb.GetAngularVelocityAttr().Get()[2] == pytest.approx(math.degrees(2.0), rel=1e-6)  # deg/s
    assert UsdPhysics.MassAPI(box).GetMassAttr().Get() == 3.0
    # Its collider: a cube of size 2 scaled to the half-extents, with a physics material.
    geom = st.GetPrimAtPath("/World/body_1/geom")
    assert geom.IsA(UsdGeom.Cube) and geom.HasAPI(UsdPhysics.CollisionAPI)
    scale = UsdGeom.Xformable(geom).ComputeLocalToWorldTransform(Usd.TimeCode.Default()).ExtractRotationMatrix()
    assert scale is not None
    mat, _ = UsdShade.MaterialBindingAPI(geom).ComputeBoundMaterial("physics")
    api = UsdPhysics.MaterialAPI(mat.GetPrim())
    assert api.GetDynamicFrictionAttr().Get() == pytest.approx(0.3) and api.GetRestitutionAttr().Get() == 0.5
    assert box.GetAttribute("wmo:friction").Get() == 0.3  # the exact value
    assert UsdPhysics.RigidBodyAPI(cap).GetKinematicEnabledAttr().Get()
    c = st.GetPrimAtPath("/World/body_2/geom")
    assert c.IsA(UsdGeom.Capsule) and UsdGeom.Capsule(c).GetHeightAttr().Get() == pytest.approx(0.8)
    h = st.GetPrimAtPath("/World/body_3/geom")
    assert h.IsA(UsdGeom.Mesh) and UsdPhysics.MeshCollisionAPI(h).GetApproximationAttr().Get() == "convexHull"
    com = UsdPhysics.MassAPI(hull).GetCenterOfMassAttr().Get()
    assert com[0] == pytest.approx(0.1)
    # Collision groups: group 0 filters group 4 and back.
    g0 = UsdPhysics.CollisionGroup(st.GetPrimAtPath("/World/CollisionGroups/group_0"))
    assert [str(p) for p in g0.GetFilteredGroupsRel().GetTargets()] == ["/World/CollisionGroups/group_4"]


def test_a_run_is_written_as_time_samples(tmp_path):
    w = _world()
    z0 = w.positions[1][2]
    save_usd(w, tmp_path / "run.usdc", steps=30)
    st = Usd.Stage.Open(str(tmp_path / "run.usdc"))
    assert st.GetEndTimeCode() == 30 and st.GetTimeCodesPerSecond() == pytest.approx(60)
    xf = UsdGeom.Xformable(st.GetPrimAtPath("/World/body_1"))
    z = [xf.ComputeLocalToWorldTransform(Usd.TimeCode(t)).ExtractTranslation()[2] for t in (0, 15, 30)]
    assert z[0] == z0 and z[2] < z[1] < z[0]  # falling
    assert z[2] == w.positions[1][2]  # the last sample is where the world now is


def test_bad_paths_and_steps_raise(tmp_path):
    with pytest.raises(ValueError, match="usda"):
        save_usd(_world(), tmp_path / "w.txt")
    with pytest.raises(ValueError, match="steps"):
        save_usd(_world(), tmp_path / "w.usda", steps=-1)


def test_wmo_save_and_load_round_trip_a_canonical_scene(tmp_path):
    # Saved and read back: the same bodies (by prim path; a static body by its collider
    # prim; the reader puts rigid bodies
    # before static colliders), shapes, poses, masses and materials. The reader takes
    # the schema's float attributes, so masses and friction agree to float precision
    # (the writer's exact wmo: attributes are not read yet).
    w = wmo.scenes.tower(5)
    wmo.save(w, tmp_path / "tower.usda")
    assert wmo.load(tmp_path / "tower.usda").body_count == w.body_count
    r = wmo.io.load(tmp_path / "tower.usda")
    for k in range(w.body_count):
        key = f"/World/body_{k}"
        a, b = w.body(k), r.bodies.get(key) or r.bodies[key + "/geom"]  # a static body: its collider
        assert a.kind == b.kind
        np.testing.assert_allclose(b.position, a.position, atol=1e-12)
        np.testing.assert_allclose(b.orientation, a.orientation, atol=1e-12)
        assert b.mass == pytest.approx(a.mass, rel=1e-6)
        assert b.friction == pytest.approx(a.friction, rel=1e-6)
        np.testing.assert_allclose(b.shape.half_extents, a.shape.half_extents, rtol=1e-12)
    np.testing.assert_allclose(r.world.gravity, w.gravity, rtol=1e-6)
    with pytest.raises(ValueError, match="suffix"):
        wmo.save(w, tmp_path / "tower.obj")
