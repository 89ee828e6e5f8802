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
    assert UsdPhysics.RigidBodyAPI(ground).GetRigidBodyEnabledAttr().Get() is False  # UsdPhysics' static body
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


def test_wmo_save_and_load_keep_every_body_by_prim_path(tmp_path):
    # Saved and read back: the same bodies, in the same rows, keyed by prim path, with
    # the same kinds, shapes, poses, masses and materials (bit for bit: the wmo: values).
    w = wmo.scenes.tower(5)
    wmo.save(w, tmp_path / "tower.usda")
    assert wmo.load(tmp_path / "tower.usda").body_count == w.body_count
    r = wmo.io.load(tmp_path / "tower.usda")
    assert r.warnings == []
    for k in range(w.body_count):
        a, b = w.body(k), r.bodies[f"/World/body_{k}"]
        assert b.index == k and a.kind == b.kind
        assert np.array_equal(b.position, a.position) and np.array_equal(b.orientation, a.orientation)
        assert b.mass == a.mass and b.friction == a.friction
        assert np.array_equal(b.shape.half_extents, a.shape.half_extents)
    assert np.array_equal(r.world.gravity, w.gravity)


CANONICAL = {"boxes3000": lambda: wmo.scenes.boxes3000(), "pyramid": lambda: wmo.scenes.pyramid(),
             "tower": lambda: wmo.scenes.tower(), "mixed_pile": lambda: wmo.scenes.mixed_pile()}


# Both formats for the quick scenes; one each for the two that take ~10 s to simulate.
@pytest.mark.parametrize("scene, suffix", [("boxes3000", ".usdc"), ("pyramid", ".usda"), ("tower", ".usda"),
                                           ("tower", ".usdc"), ("mixed_pile", ".usda"), ("mixed_pile", ".usdc")])
def test_every_canonical_scene_round_trips_to_the_same_state_hash(tmp_path, scene, suffix):
    # The round trip: saved, loaded back, both simulated 600 steps: the same
    # final state, bit for bit (boxes, spheres, capsules and hulls; settings included).
    w = CANONICAL[scene]()
    wmo.save(w, tmp_path / f"s{suffix}")
    w2 = wmo.load(tmp_path / f"s{suffix}")
    assert w2.settings.keys() == w.settings.keys()
    assert all(np.array_equal(w2.settings[k], v) for k, v in w.settings.items())
    assert wmo.state_hash(w2) == wmo.state_hash(w)
    w.step(600)
    w2.step(600)
    assert wmo.state_hash(w2) == wmo.state_hash(w)


def _strip_wmo_attributes(path):
    st = Usd.Stage.Open(str(path))
    for prim in st.Traverse():
        for a in prim.GetAuthoredAttributes():
            if a.GetName().startswith("wmo:"):
                prim.RemoveProperty(a.GetName())
    st.GetRootLayer().Save()


def test_without_the_exact_values_the_round_trip_drifts(tmp_path):
    # Why the wmo: attributes exist: the schema alone (float masses, velocities and
    # materials) gives a world that starts within float precision of the original and
    # ends elsewhere, so the hash test above would catch a reader that ignored them.
    w = wmo.scenes.mixed_pile(count=60, seed=3)
    for k in range(1, w.body_count):
        w.linear_velocities[k] = (0.1 * k, -1.0, 0.3)
    wmo.save(w, tmp_path / "p.usda")
    _strip_wmo_attributes(tmp_path / "p.usda")
    r = wmo.io.load(tmp_path / "p.usda")
    np.testing.assert_allclose(r.world.positions, w.positions, atol=1e-9)
    np.testing.assert_allclose(r.world.linear_velocities, w.linear_velocities, rtol=1e-6)
    w.step(300)
    r.world.step(300)
    assert wmo.state_hash(r.world) != wmo.state_hash(w)


def test_an_edit_made_elsewhere_wins_over_the_exact_values(tmp_path):
    # A body moved in another tool (its translate changed, its wmo:position not): the
    # reader sees the digest no longer matches, reads the schema and warns; the other
    # bodies keep their exact values.
    w = wmo.scenes.tower(3)
    wmo.save(w, tmp_path / "t.usda")
    st = Usd.Stage.Open(str(tmp_path / "t.usda"))
    xf = UsdGeom.Xformable(st.GetPrimAtPath("/World/body_2"))
    translate = [op for op in xf.GetOrderedXformOps() if op.GetOpType() == UsdGeom.XformOp.TypeTranslate][0]
    translate.Set((4.0, 7.0, 0.0))
    UsdPhysics.MaterialAPI(st.GetPrimAtPath("/World/Materials/material_0")).GetDynamicFrictionAttr().Set(0.25)
    st.GetRootLayer().Save()
    r = wmo.io.load(tmp_path / "t.usda")
    assert r.bodies["/World/body_2"].position.tolist() == [4.0, 7.0, 0.0]
    assert r.bodies["/World/body_2"].friction == 0.25
    assert sum("edited after WMO wrote it" in m for m in r.warnings) == r.world.body_count  # one material for all
    # Damping comes from the physxRigidBody: attributes the writer adds, so the schema
    # path keeps WMO's 0 instead of taking PhysX's default 0.05 1/s.
    assert [r.world.body(k).angular_damping for k in range(w.body_count)] == \
        [w.body(k).angular_damping for k in range(w.body_count)]
    # Edit nothing: exact again.
    wmo.save(w, tmp_path / "u.usda")
    assert wmo.io.load(tmp_path / "u.usda").warnings == []


def test_filtering_groups_compounds_and_settings_round_trip(tmp_path):
    w = wmo.World(gravity=(0.5, 0, -9.7), dt=1 / 120, substeps=2, iterations=3, friction_combine="max",
                  sleeping=False, ccd_motion_threshold=0.25)
    ground = w.add_body(wmo.Box((5, 5, 0.5)), position=(0, 0, -0.5), kind="static", collision_group=7)
    a = w.add_body(wmo.Compound([(wmo.Box((0.2, 0.1, 0.1)), wmo.Pose((0.3, 0, 0))),
                                 (wmo.Sphere(0.15), wmo.Pose((-0.3, 0, 0.05), (0, 0, math.sin(0.3), math.cos(0.3))))]),
                   position=(0, 0, 1), linear_damping=0.1, angular_damping=0.2, gravity_scale=0.5, ccd=True,
                   collision_group=2, center_of_mass=(0.01, 0.02, 0.0))
    b = w.add_body(wmo.Box((0.3, 0.3, 0.3), rounding=0.05), position=(0, 0, 2), collision_group=2)
    c = w.add_body(wmo.Cylinder(0.2, 0.3), position=(1, 0, 1), kind="kinematic", angular_velocity=(0, 0, 1))
    w.add_body(wmo.TriangleMesh([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]], one_sided=True), position=(3, 3, 0),
               kind="static")
    w.set_pair_collision(a, b, False)
    w.set_pair_collision(b, c, False)
    w.set_group_collision(2, 7, False)
    wmo.save(w, tmp_path / "f.usda")
    r = wmo.io.load(tmp_path / "f.usda")
    w2 = r.world
    assert r.warnings == [] and w2.body_count == w.body_count
    assert w2.settings["friction_combine"] == "max" and w2.settings["substeps"] == 2 and w2.dt == 1 / 120
    assert [(p.index, q.index) for p, q in w2.filtered_pairs()] == [(1, 2), (2, 3)]
    assert [w2.body(k).collision_group for k in range(4)] == [7, 2, 2, 0]
    assert not w2.group_collision(2, 7) and w2.group_collision(2, 2) and w2.group_collision(0, 7)
    assert w2.body(1).ccd and w2.body(1).gravity_scale == 0.5 and w2.body(1).angular_damping == 0.2
    assert np.array_equal(w2.body(1).center_of_mass, a.center_of_mass)
    assert w2.body(2).shape.rounding == 0.05 and w2.body(3).kind == "kinematic"
    assert len(w2.body(1).shape.children) == 2
    assert w2.body(4).shape.one_sided
    assert wmo.state_hash(w2) == wmo.state_hash(w)
    w.step(120)
    w2.step(120)
    assert wmo.state_hash(w2) == wmo.state_hash(w)
    with pytest.raises(ValueError, match="suffix"):
        wmo.save(w, tmp_path / "tower.stl")
