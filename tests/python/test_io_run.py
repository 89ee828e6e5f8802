"""Scene files at work (issue 6): ``wmo run scene.usda`` simulates a file and writes the
result, and a server hosts a scene read from a file."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("pxr", reason="usd-core (PyPI) is not installed")

import wmo  # noqa: E402
from pxr import Usd, UsdGeom, UsdPhysics  # noqa: E402
from wmo.cli import main  # noqa: E402

SHARED_USD = Path(__file__).resolve().parents[2].parent / "shared" / "assets" / "usd"


def _pose_at(stage, path, t):
    m = UsdGeom.Xformable(stage.GetPrimAtPath(path)).ComputeLocalToWorldTransform(Usd.TimeCode(t))
    return np.array(m.ExtractTranslation())


def test_wmo_run_records_the_same_run_as_simulating_in_python(tmp_path, capsys):
    w = wmo.scenes.mixed_pile(count=12, seed=4)
    wmo.save(w, tmp_path / "pile.usda")
    assert main(["run", str(tmp_path / "pile.usda"), "--steps", "90", "--out", str(tmp_path / "out.usdc")]) == 0
    printed = capsys.readouterr().out
    assert "13 bodies (12 dynamic)" in printed and "90 steps" in printed and "wrote" in printed
    st = Usd.Stage.Open(str(tmp_path / "out.usdc"))
    assert st.GetEndTimeCode() == 90
    w.step(90)  # the same run here: the file loads bit for bit, so the samples match exactly
    for k in (1, 6, 12):
        assert _pose_at(st, f"/World/body_{k}", 90).tolist() == w.positions[k].tolist()
        assert _pose_at(st, f"/World/body_{k}", 0).tolist() != w.positions[k].tolist()  # it moved


def test_wmo_run_takes_seconds_settings_and_obj_output(tmp_path, capsys):
    wmo.save(wmo.scenes.tower(3), tmp_path / "t.usda")
    out = tmp_path / "t.obj"
    assert main(["run", str(tmp_path / "t.usda"), "--seconds", "0.5", "--dt", "1/100", "--substeps", "2",
                 "--out", str(out)]) == 0
    assert "50 steps (0.5 s)" in capsys.readouterr().out
    mesh = wmo.io.obj.parse_obj(out)
    assert [name for name, _ in mesh.groups] == [f"body_{k}" for k in range(4)]


@pytest.mark.parametrize("args, message", [
    (["run", "missing.usda"], "no such file"),
    (["run", "{scene}", "--out", "x.stl"], "--out must end in"),
    (["run", "{scene}", "--steps", "-1"], "--steps must be >= 0"),
    (["run", "{scene}", "--substeps", "0"], "substeps"),
])
def test_wmo_run_bad_input_exits_2_with_a_message(tmp_path, capsys, args, message):
    wmo.save(wmo.scenes.tower(1), tmp_path / "t.usda")
    args = [a.format(scene=tmp_path / "t.usda") for a in args]
    assert main(args) == 2
    assert message in capsys.readouterr().err
    assert not (Path.cwd() / "x.stl").exists()


@pytest.mark.skipif(not SHARED_USD.is_dir(), reason="../shared/assets/usd is not here (CI clones may lack it)")
def test_wmo_run_on_pixars_box_on_box_lands_the_box(tmp_path):
    # The command as a user types it, in a fresh process: the box falls onto the ground
    # box and rests there (read from the written samples; the writer gives MassAPI to
    # dynamic bodies only, which finds the box among the two bodies).
    out = tmp_path / "run.usda"
    r = subprocess.run([sys.executable, "-m", "wmo", "run", str(SHARED_USD / "usdPhysicsBoxOnBox.usda"),
                        "--steps", "180", "--out", str(out)], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    st = Usd.Stage.Open(str(out))
    box = [p for p in ("/World/body_0", "/World/body_1") if st.GetPrimAtPath(p).HasAPI(UsdPhysics.MassAPI)]
    assert len(box) == 1
    up = "XYZ".index(UsdGeom.GetStageUpAxis(st))
    h = [_pose_at(st, box[0], t)[up] for t in (0, 120, 180)]
    assert h[0] - h[1] > 0.1 and abs(h[2] - h[1]) < 1e-3  # fell, then at rest


def test_a_server_hosts_a_scene_read_from_a_file(tmp_path):
    pytest.importorskip("msgpack")
    pytest.importorskip("websockets")
    from wmo.remote import SceneModel
    from wmo.remote.scene import SCENE_BUILDERS, register_file_scene

    w = wmo.scenes.mixed_pile(count=9, seed=2)
    # Given mass data, a collision group and a group filter travel with the file.
    given = w.add_body(wmo.Box((0.3, 0.2, 0.1)), position=(0, 9, 0), mass=3.0, center_of_mass=(0.05, 0, 0),
                       inertia=(0.1, 0.2, 0.25), collision_group=4)
    w.set_group_collision(4, 0, False)
    w.set_pair_collision(w.body(1), w.body(2), False)
    wmo.save(w, tmp_path / "pile.usda")
    name, warnings = register_file_scene(tmp_path / "pile.usda")
    try:
        assert name == f"file:{(tmp_path / 'pile.usda').resolve()}" and warnings == []
        model = SceneModel(name)
        assert model.world.body_count == 11
        assert np.array_equal(np.asarray(model.world.positions), np.asarray(w.positions))
        assert model.world.settings["gravity"].tolist() == w.settings["gravity"].tolist()
        b = model.world.body(given.index)
        assert b.collision_group == 4 and np.allclose(b.center_of_mass, given.center_of_mass)
        assert np.allclose(b.inertia, given.inertia) and b.mass == 3.0
        assert not model.world.group_collision(0, 4) and model.world.group_collision(1, 4)
        assert [(a.index, b.index) for a, b in model.world.filtered_pairs()] == [(1, 2)]
        model.apply("reset", {})  # the file is the scene a reset goes back to
        assert model.world.body_count == 11 and not model.world.group_collision(0, 4)
        # A compound body is hosted too: the same children, poses and mass.
        c = wmo.World()
        cb = c.add_body(wmo.Compound([(wmo.Sphere(0.2), wmo.Pose((0.3, 0, 0))),
                                      (wmo.Box((0.1, 0.2, 0.1)), wmo.Pose((0, 0.2, 0), (0, 0, 0.6, 0.8)))]),
                        position=(0, 2, 0))
        wmo.save(c, tmp_path / "compound.usda")
        name_c, warnings_c = register_file_scene(tmp_path / "compound.usda")
        model_c = SceneModel(name_c)
        hosted = model_c.world.body(cb.index)
        assert warnings_c == [] and hosted.shape.type == "compound" and hosted.mass == pytest.approx(cb.mass)
        assert [(type(s).__name__, p.position.tolist()) for s, p in hosted.shape.children] == \
            [(type(s).__name__, p.position.tolist()) for s, p in cb.shape.children]
    finally:
        SCENE_BUILDERS.pop(name, None)
        SCENE_BUILDERS.pop(f"file:{(tmp_path / 'compound.usda').resolve()}", None)


def test_wmo_serve_hosts_a_file_given_as_a_scene(tmp_path):
    pytest.importorskip("msgpack")
    pytest.importorskip("websockets")
    from wmo.remote.client import connect
    from wmo.remote.server import Server

    wmo.save(wmo.scenes.tower(4), tmp_path / "tower.usdc")
    srv = Server(port=0, scenes={"lab": str(tmp_path / "tower.usdc")}, data_dir=None).start()
    try:
        with connect(srv.url, scene="lab", mode="full") as c:
            snap = c.wait_snapshot()
            assert len(c.ids) == 5 and len(snap.positions) == 5
            assert sorted(np.round(c.positions[:, 1], 6).tolist())[1:] == pytest.approx([0.5, 1.5, 2.5, 3.5], abs=0.05)
    finally:
        srv.stop()
    with pytest.raises(ValueError, match="no such file"):
        Server(port=0, scenes={"lab": str(tmp_path / "missing.usda")}, data_dir=None)
