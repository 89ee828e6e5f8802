"""The remote server and its clients (issue 5): edits ordered, acknowledged, broadcast and
journaled; bad input answered with errors while everyone else is served; a SIGKILLed
server restores every acknowledged edit. Everything listens on loopback, with bounded
counts and timeouts."""
from __future__ import annotations

import asyncio
import os
import random
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

msgpack = pytest.importorskip("msgpack")
pytest.importorskip("websockets")

import wmo  # noqa: E402
from wmo.remote import EditError, SceneModel  # noqa: E402
from wmo.remote.scene import SCENE_SETTINGS, SETTINGS  # noqa: E402
from wmo.remote.client import RemoteError, connect, connect_async  # noqa: E402
from wmo.remote.experiment import _free_port, _wait_port  # noqa: E402
from wmo.remote.journal import SceneStore  # noqa: E402
from wmo.remote.server import Server, ServerLimits  # noqa: E402

BOX = {"type": "box", "half_extents": [0.5, 0.5, 0.5]}


def _state(model: SceneModel) -> dict:
    w, o = model.world, model.order
    return {"ids": model.ids().tolist(), "defs": [model.defs[int(r)] for r in model.ids()],
            "owner": dict(model.owner), "positions": np.asarray(w.positions)[o].copy(),
            "orientations": np.asarray(w.orientations)[o].copy(),
            "linear_velocities": np.asarray(w.linear_velocities)[o].copy()}


def _state_after_replay(doc: dict, records: list) -> dict:
    m = SceneModel.from_document(doc)
    for r in records:
        m.apply(r["op"], r["args"], r["client"])
    return _state(m)


def _assert_same_state(a: dict, b: dict) -> None:
    assert a["ids"] == b["ids"]
    assert a["defs"] == b["defs"]
    assert a["owner"] == b["owner"]
    for k in ("positions", "orientations", "linear_velocities"):
        np.testing.assert_array_equal(a[k], b[k], err_msg=k)


# ---- the scene model (no network) ----

def test_scene_model_ids_follow_the_worlds_swap_remove():
    # The world removes a body by moving its last body into the hole; the model's id
    # map must follow, or snapshots would pair ids with other bodies' poses.
    rng = random.Random(1)
    m = SceneModel("empty")
    live = []
    for k in range(400):
        if live and rng.random() < 0.4:
            rid = live.pop(rng.randrange(len(live)))
            m.apply("remove_body", {"id": rid})
        else:
            live.append(m.apply("add_body", {"shape": BOX, "position": [k * 2.0, 1, 0]})["id"])
        for rid, body in m.bodies.items():
            assert m._ids_by_index[body.index] == rid
    ids = m.ids()
    assert ids.tolist() == sorted([1] + live)
    # Rows of the snapshot order hold the right bodies: body k was placed at x = 2k.
    pos = np.asarray(m.world.positions)[m.order]
    for row, rid in enumerate(ids):
        if rid != 1:
            assert pos[row][0] == m.bodies[int(rid)].position[0]


@pytest.mark.parametrize("op,args,code", [
    ("add_body", {"shape": {"type": "box", "half_extents": [1, -1, 1]}}, "bad_args"),
    ("add_body", {"shape": BOX, "position": [0, float("nan"), 0]}, "bad_args"),
    ("add_body", {"shape": BOX, "orientation": [0, 0, 0, 2]}, "bad_args"),
    ("add_body", {"shape": BOX, "mass": -1}, "bad_args"),
    ("add_body", {"shape": BOX, "colour": "red"}, "bad_args"),
    ("add_body", {"shape": {"type": "convex_hull", "points": [[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]]}},
     "bad_args"),
    ("set_pose", {"id": 999, "position": [0, 0, 0]}, "unknown_body"),
    ("set_pose", {"id": 2, "position": [0, 1, 0], "orientation": [0, 0, 0.5, 0.5]}, "bad_args"),
    ("set_velocity", {"id": 2, "linear": [0, float("inf"), 0]}, "bad_args"),
    ("apply_impulse", {"id": 1, "impulse": [0, 1, 0]}, "bad_args"),
    ("remove_body", {"id": "2"}, "bad_args"),
    ("step", {"n": 1}, "not_paused"),
    ("load_scene", {"name": "nowhere"}, "bad_args"),
    ("set_settings", {"dt": 0}, "bad_args"),
    ("set_settings", {"substeps": 0}, "bad_args"),
    ("set_settings", {"relax_iterations": -1}, "bad_args"),
    ("set_settings", {"speculative_motion": -1.0}, "bad_args"),
    ("set_settings", {"friction_combine": "bogus"}, "bad_args"),
    ("set_settings", {"restitution_combine": 2}, "bad_args"),
    ("set_settings", {"time_to_sleep": float("nan")}, "bad_args"),
    ("set_settings", {"collision_groups_off": [[0, 64]]}, "bad_args"),
    ("set_settings", {"collision_pairs_off": [[1, 0]]}, "bad_args"),
    ("set_settings", {"collision_pairs_off": [[1, 1]]}, "bad_args"),
    ("add_body", {"shape": BOX, "collision_group": 64}, "bad_args"),
    ("add_body", {"shape": BOX, "inertia": [1, -2, 3]}, "bad_args"),
    ("add_body", {"shape": BOX, "center_of_mass": [0, "x", 0]}, "bad_args"),
    ("add_body", {"shape": {"type": "compound", "children": []}}, "bad_args"),
    ("add_body", {"shape": {"type": "compound", "children": [{"shape": {"type": "plane", "normal": [0, 1, 0]}}]}},
     "bad_args"),
    ("add_body", {"shape": {"type": "compound", "children": [
        {"shape": {"type": "compound", "children": [{"shape": {"type": "sphere", "radius": 1}}]}}]}}, "bad_args"),
    ("add_body", {"shape": {"type": "compound", "children": [{"shape": BOX, "position": [0, 1]}]}}, "bad_args"),
    ("add_body", {"shape": {"type": "compound", "children": [{"shape": BOX}] * 257}}, "limit"),
    ("add_body", {"shape": {"type": "triangle_mesh", "vertices": [[0, 0, 0], [1, 0, 0], [0, 0, 1]],
                            "triangles": [[0, 2, 1]], "one_sided": "yes"}, "kind": "static"}, "bad_args"),
    ("fly", {}, "unknown_op"),
])
def test_a_bad_edit_names_the_problem_and_leaves_the_scene_unchanged(op, args, code):
    m = SceneModel("tower")
    m.apply("add_body", {"shape": BOX, "position": [3, 1, 0]})
    before = _state(m)
    with pytest.raises(EditError) as e:
        m.apply(op, args)
    assert e.value.code == code
    _assert_same_state(before, _state(m))
    if op == "set_settings":  # the message names the setting
        assert next(iter(args)) in str(e.value)


def test_given_mass_data_and_collision_groups_survive_rebuilds_resets_and_restarts():
    # A body's given centre of mass and inertia and its collision group, and the scene's
    # group matrix (collision_groups_off), are carried through set_settings (a new
    # World), the scene document a restart reads, and describe(); a reset goes back to
    # the loaded scene (no filters).
    m = SceneModel("empty")
    rid = m.apply("add_body", {"shape": BOX, "position": [0, 3, 0], "mass": 2.0, "center_of_mass": [0.1, 0, 0],
                               "inertia": [1.0, 2.0, 3.0], "collision_group": 5})["id"]
    # Group 5 does not collide with the ground's group 0: the box falls through it.
    m.apply("set_settings", {"collision_groups_off": [[5, 0]]})
    m.apply("set_settings", {"dt": 1 / 120})  # another rebuild
    for model in (m, SceneModel.from_document(m.to_document())):
        b = model.bodies[rid]
        assert b.collision_group == 5 and b.center_of_mass.tolist() == [0.1, 0, 0]
        assert np.allclose(np.linalg.eigvalsh(b.inertia), [1, 2, 3])
        assert not model.world.group_collision(0, 5) and model.world.group_collision(0, 4)
        assert model.describe()["bodies"][rid]["collision_group"] == 5
    m.step(240)
    assert m.bodies[rid].position[1] < -1  # through the ground (its top is at y = 0)
    m.apply("reset", {})
    assert m.world.group_collision(0, 5)


def test_filtered_pairs_of_bodies_follow_grabs_restarts_and_removal():
    # collision_pairs_off: the box no longer collides with the ground (it falls through),
    # also after a grab and release (the body is re-created) and in the restart document;
    # removing the box removes its pairs from the setting.
    m = SceneModel("empty")  # the ground is body 1
    rid = m.apply("add_body", {"shape": BOX, "position": [0, 3, 0]})["id"]
    other = m.apply("add_body", {"shape": BOX, "position": [3, 3, 0]})["id"]
    with pytest.raises(EditError) as e:
        m.apply("set_settings", {"collision_pairs_off": [[1, 99]]})
    assert e.value.code == "unknown_body"
    m.apply("set_settings", {"collision_pairs_off": [[1, rid]]})
    m.apply("grab", {"id": rid}, client="c")
    m.apply("release", {"id": rid}, client="c")
    m = SceneModel.from_document(m.to_document())
    m.step(120)
    assert m.bodies[rid].position[1] < -1  # through the ground
    assert abs(m.bodies[other].position[1] - 0.5) < 0.01  # resting on it
    m.apply("remove_body", {"id": rid})
    assert m.settings["collision_pairs_off"] == []


def test_every_world_setting_can_be_set_remotely():
    # The remote settings are the World's keywords, all of them: a setting added to the
    # World and forgotten here fails this test. Values the old list refused (0 relax
    # passes, a zero margin) are the World's to judge.
    assert set(SETTINGS) == set(wmo.World().settings) | set(SCENE_SETTINGS)
    m = SceneModel("tower")
    new = {"relax_iterations": 0, "speculative_distance": 0.0, "speculative_motion": 0.5,
           "speculative_motion_static": 0.0, "manifold_reuse_angle": 0.01, "friction_combine": "max",
           "restitution_combine": "average", "sleep_linear_threshold": 0.1, "time_to_sleep": 1.5,
           "ccd_motion_threshold": 0.25, "ccd_penetration": 0.1, "energy_guard_passes": 8,
           "energy_guard_tolerance": 1e-5, "broadphase": "sweep_and_prune"}
    m.apply("set_settings", new)
    for k, v in new.items():
        assert m.world.settings[k] == v, k
    assert m.settings == {**m.settings, **new}


def test_scene_document_round_trip_is_bit_exact():
    m = SceneModel("tower")
    m.apply("add_body", {"shape": {"type": "capsule", "radius": 0.2, "half_height": 0.5}, "position": [2, 3, 0],
                         "orientation": [0, 0, np.sin(0.3), np.cos(0.3)], "friction": 0.3, "restitution": 0.5})
    m.apply("grab", {"id": 5}, "alice")
    m.step(37)
    doc = m.to_document()
    packed = msgpack.unpackb(msgpack.packb(doc, use_bin_type=True), raw=False, strict_map_key=False)
    back = SceneModel.from_document(packed)
    _assert_same_state(_state(m), _state(back))
    assert back.step_count == 37 and back.next_id == m.next_id
    # (The contact cache, the solver's warm start, is not in the document: the two go
    # on from the same state but not bit for bit; a restart is such a rebuild.)


def test_grab_turns_a_body_kinematic_owned_by_its_client_until_release():
    m = SceneModel("tower")
    m.apply("grab", {"id": 3}, "alice")
    assert m.bodies[3].kind == "kinematic" and m.owner[3] == "alice"
    with pytest.raises(EditError) as e:
        m.apply("set_pose", {"id": 3, "position": [0, 9, 0]}, "bob")
    assert e.value.code == "not_owner"
    m.apply("set_pose", {"id": 3, "position": [4, 9, 0]}, "alice")
    m.apply("release", {"id": 3, "linear_velocity": [1, 0, 0]}, "alice")
    assert m.bodies[3].kind == "dynamic" and 3 not in m.owner
    assert m.bodies[3].position.tolist() == [4, 9, 0]
    assert m.bodies[3].linear_velocity.tolist() == [1, 0, 0]


def test_journal_cuts_a_torn_tail(tmp_path):
    store = SceneStore(tmp_path / "s")
    store.checkpoint(SceneModel("empty").to_document())
    store.append([{"seq": 1, "op": "pause", "args": {}, "client": "a"},
                  {"seq": 2, "op": "resume", "args": {}, "client": "a"}])
    store.close()
    path = tmp_path / "s" / "journal.log"
    data = path.read_bytes()
    path.write_bytes(data[:-3])  # a write cut short by a crash
    doc, records = SceneStore(tmp_path / "s").load()
    assert [r["seq"] for r in records] == [1]
    assert path.stat().st_size < len(data) - 3  # the torn record is gone


# ---- the server ----

@pytest.fixture
def server(tmp_path):
    srv = Server(port=0, data_dir=tmp_path / "data", scenes={"lab": "tower"}, rate=120.0).start()
    yield srv
    srv.stop()


def test_clients_edit_and_watch_one_scene(server):
    with connect(server.url, scene="lab") as a, connect(server.url, scene="lab", mode="full") as b:
        assert len(a.ids) == 31  # ground + 30 boxes
        a.pause()
        h = a.add_body(wmo.Box((0.5, 0.5, 0.5)), position=(5, 5, 0), mass=2.0)
        seq = a.set_pose(h, position=(1.25, 5, 0.5))
        b.wait_edit(a.edit_seq)
        assert h in b.bodies and b.bodies[h]["mass"] == 2.0
        # Given mass data and a collision group travel with the edit (as numpy input too).
        g = a.add_body(wmo.Box((0.5, 0.5, 0.5)), position=(-5, 5, 0), mass=2.0, collision_group=2,
                       center_of_mass=np.array([0.1, 0.0, 0.0]), inertia=np.diag([0.5, 0.6, 0.7]))
        b.wait_edit(a.edit_seq)
        assert b.bodies[g]["collision_group"] == 2 and b.bodies[g]["center_of_mass"] == [0.1, 0, 0]
        assert b.bodies[g]["inertia"] == np.diag([0.5, 0.6, 0.7]).tolist()
        a.remove_body(g)
        # A compound travels as its children's specs and poses.
        shape = wmo.Compound([(wmo.Sphere(0.25), wmo.Pose((0.4, 0, 0))), (wmo.Box((0.2, 0.2, 0.2)), wmo.Pose())])
        k = a.add_body(shape, position=(-5, 5, 0))
        b.wait_edit(a.edit_seq)
        spec = b.bodies[k]["shape"]
        assert spec["type"] == "compound" and [c["shape"]["type"] for c in spec["children"]] == ["sphere", "box"]
        assert spec["children"][0]["position"] == [0.4, 0, 0]
        a.remove_body(k)
        snap = b.wait_snapshot()
        b.wait_snapshot(snap.seq)
        # Full mode is exact; compressed within its resolution (1 mm: half of it per axis).
        assert b.positions[b.index(h)].tolist() == [1.25, 5, 0.5]
        a.wait_snapshot()
        np.testing.assert_allclose(a.positions[a.index(h)], [1.25, 5, 0.5], atol=0.5e-3 + 1e-12)
        assert seq is None
        a.resume()
        y0 = a.wait_snapshot().positions[a.index(h)][1]
        for _ in range(20):
            a.wait_snapshot()
        assert a.positions[a.index(h)][1] < y0  # it falls
        st = a.stats()
        assert st["bodies"] == 32 and st["clients"] == 2


def test_async_client(server):
    async def main():
        scene = await connect_async(server.url, scene="lab")
        async with scene:
            h = await scene.add_body(wmo.Sphere(0.3), position=(0, 40, 0))
            n = 0
            async for snap in scene.snapshots():
                n += 1
                if h in snap.ids.tolist() and n >= 3:
                    break
            with pytest.raises(RemoteError) as e:
                await scene.remove_body(12345)
            assert e.value.code == "unknown_body"
            return h

    assert asyncio.run(main()) > 31


def test_eight_clients_with_1000_concurrent_edits_each_end_with_the_servers_scene(server, tmp_path):
    # Every edit is acknowledged; all clients' mirrors equal the server's scene, and
    # replaying the server's journal on the scene it started from gives that scene
    # again, bit for bit. Paused, so the state is the edits' alone.
    clients = [connect(server.url, scene="lab", mode="full") for _ in range(8)]
    clients[0].pause()
    host = server.scenes["lab"]
    n_edits = 1000
    errors = []

    def work(k: int, scene) -> None:
        rng = random.Random(k)
        mine: list[int] = []
        futures = []
        for i in range(n_edits):
            r = rng.random()
            if r < 0.3 or not mine:
                f = scene.add_body(BOX, position=[rng.uniform(-20, 20), rng.uniform(1, 20), k], wait=False)
                futures.append(("add", f))
                if len(futures) % 50 == 0:  # learn some ids
                    for kind, g in futures[-50:]:
                        if kind == "add":
                            try:
                                mine.append(g.result(30))
                            except RemoteError:
                                pass
            elif r < 0.7:
                # Anyone's body, including ones others are removing: conflicts are the point.
                target = rng.choice(mine) if rng.random() < 0.7 else rng.randrange(1, 40)
                futures.append(("pose", scene.set_pose(target, position=[rng.uniform(-5, 5), 3, 0],
                                                        orientation=[0, 0, 0, 1], wait=False)))
            elif r < 0.85:
                target = rng.choice(mine)
                futures.append(("vel", scene.set_velocity(target, linear=[0, rng.uniform(0, 1), 0], wait=False)))
            else:
                target = mine.pop(rng.randrange(len(mine)))
                futures.append(("remove", scene.remove_body(target, wait=False)))
        for kind, f in futures:
            try:
                f.result(60)
            except RemoteError as e:  # another client removed it first: a reply all the same
                if e.code not in ("unknown_body",):
                    errors.append(e)
            except Exception as e:
                errors.append(e)

    threads = [threading.Thread(target=work, args=(k, c)) for k, c in enumerate(clients)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(120)
    assert not errors
    final_seq = host.model.edit_seq
    assert final_seq >= 8 * n_edits * 0.7
    truth = None
    for c in clients:
        c.wait_edit(final_seq, timeout=30)
        c.wait_snapshot(timeout=10)
        c.wait_snapshot(timeout=10)  # one captured after the last edit's tick
    time.sleep(0.2)
    truth = _state(host.model)
    for c in clients:
        assert sorted(c.bodies) == truth["ids"]
        assert c.ids.tolist() == truth["ids"]
        np.testing.assert_array_equal(c.positions, truth["positions"])
        np.testing.assert_array_equal(c.orientations, truth["orientations"])
        assert [{k: v for k, v in c.bodies[r].items() if k != "owner"} for r in truth["ids"]] == truth["defs"]
        c.close()
    # The server's edit log (its last checkpoint and the journal after it, as fsync'd
    # before each acknowledgement) replayed gives the same scene: the same bodies and
    # definitions, and bit for bit the poses and velocities of every body the edits
    # made (the tower's own boxes also moved in the ticks before the pause, which no
    # journal records).
    doc, records = SceneStore(server.data_dir / "lab").load(repair=False)
    replayed = _state_after_replay(doc, records)
    assert replayed["ids"] == truth["ids"] and replayed["defs"] == truth["defs"]
    made = np.array(truth["ids"]) > 31
    for k in ("positions", "orientations", "linear_velocities"):
        np.testing.assert_array_equal(replayed[k][made], truth[k][made], err_msg=k)
    server.stop()
    store = SceneStore(server.data_dir / "lab")
    doc, records = store.load()
    assert doc["edit_seq"] == final_seq  # the shutdown checkpoint holds them all
    assert records == []


def test_replaying_the_journal_reproduces_the_scene(tmp_path):
    srv = Server(port=0, data_dir=tmp_path / "d", scenes={"lab": "empty"}, checkpoint_interval=1e9).start()
    try:
        with connect(srv.url, scene="lab", mode="full") as c:
            c.pause()
            rng = random.Random(5)
            ids = [c.add_body(BOX, position=[i, 2, 0]) for i in range(20)]
            for _ in range(200):
                c.set_pose(rng.choice(ids), position=[rng.uniform(-3, 3), 2, 0], wait=False)
            c.remove_body(ids[3])
            c.step(5)
            truth = _state(srv.scenes["lab"].model)
            # Read the journal while the server runs: what it fsync'd before acknowledging.
            store = SceneStore(tmp_path / "d" / "lab")
            doc, records = store.load(repair=False)
            _assert_same_state(truth, _state_after_replay(doc, records))
    finally:
        srv.stop()


def test_bad_messages_get_error_replies_and_everyone_else_is_served(server):
    from websockets.sync.client import connect as ws_connect

    good = connect(server.url, scene="lab")
    ws = ws_connect(server.url, max_size=None).__enter__()
    ws.send(msgpack.packb({"t": "hello", "v": 1, "scene": "lab"}))

    def replies(n_expected: int) -> list[dict]:
        out = []
        deadline = time.monotonic() + 10
        while len(out) < n_expected and time.monotonic() < deadline:
            raw = ws.recv(timeout=10)
            if raw[:2] == b"WS":
                continue
            msg = msgpack.unpackb(raw, raw=False, strict_map_key=False)
            if msg["t"] in ("error", "ok"):
                out.append(msg)
        return out

    bad = [
        b"\x00\x01garbage",                                   # not msgpack
        msgpack.packb({"t": "cmd", "id": 1, "op": "add_body", "args": {"shape": BOX}})[:-4],  # truncated
        b"\xdb\xff\xff\xff\xf0abc",                            # str32 claiming 4 GB
        b"\xdd\xff\xff\xff\xff",                               # array32 claiming 4 billion items
        msgpack.packb([1, 2, 3]),                              # not a map
        msgpack.packb({"t": "teleport"}),                      # unknown type
        msgpack.packb({"t": "cmd", "id": 2, "op": "set_pose", "args": {"id": 2, "position": [0, float("nan"), 0]}}),
        msgpack.packb({"t": "cmd", "id": 3, "op": "remove_body", "args": {"id": 99999}}),
        msgpack.packb({"t": "cmd", "id": 3, "op": "pause", "args": {}}),   # id not increasing
        msgpack.packb({"t": "cmd", "id": 4, "op": "warp", "args": {}}),
        msgpack.packb({"t": "ack", "snap": 10 ** 9}),          # a snapshot never sent
        msgpack.packb({"t": "hello", "v": 1}),                 # hello twice
    ]
    for b in bad:
        ws.send(b)
    ws.send("a text frame")
    ws.send(msgpack.packb({"t": "cmd", "id": 5, "op": "add_body", "args": {"shape": BOX, "position": [0, 30, 0]}})
            + b"")
    got = replies(14)
    codes = [m.get("code", "ok") for m in got]
    assert codes.count("ok") == 1, codes
    assert "bad_message" in codes and "out_of_order" in codes and "unknown_body" in codes
    assert "bad_args" in codes and "unknown_op" in codes
    # The other client was served all along, and the scene is intact.
    h = good.add_body(BOX, position=(2, 30, 0))
    assert h in good.bodies
    before = good.wait_snapshot().seq
    assert good.wait_snapshot(before).seq > before
    ws.close()
    good.close()


def test_a_client_that_keeps_sending_garbage_is_disconnected(server):
    from websockets.exceptions import ConnectionClosed
    from websockets.sync.client import connect as ws_connect

    ws = ws_connect(server.url, max_size=None).__enter__()
    ws.send(msgpack.packb({"t": "hello", "v": 1, "scene": "lab"}))
    with pytest.raises(ConnectionClosed):
        for _ in range(200):
            ws.send(b"\xc1")  # never valid msgpack
            time.sleep(0.001)
        deadline = time.monotonic() + 10
        while time.monotonic() < deadline:
            ws.recv(timeout=10)
    assert ws.close_code == 1008


def test_oversized_messages_are_refused(tmp_path):
    srv = Server(port=0, scenes={"lab": "empty"}, limits=ServerLimits(max_message_bytes=10_000)).start()
    try:
        with connect(srv.url, scene="lab") as c:
            pts = np.random.default_rng(0).normal(size=(700, 3)).tolist()  # ~20 KB of msgpack
            with pytest.raises(RemoteError) as e:
                c.add_body({"type": "convex_hull", "points": pts})
            assert e.value.code == "too_large"
            assert c.add_body(wmo.Sphere(0.5)) == 2  # and the connection goes on
            # Beyond 4x the cap the frame is not even read whole: the connection closes.
            with pytest.raises(ConnectionError, match="1009"):
                c.add_body({"type": "convex_hull", "points": np.zeros((3000, 3)).tolist()})
    finally:
        srv.stop()


def test_token_is_required_when_set_and_generated_beyond_loopback(tmp_path):
    srv = Server(port=0, token="s3cret", scenes={"lab": "empty"}).start()
    try:
        with pytest.raises(RemoteError) as e:
            connect(srv.url, scene="lab", token="wrong")
        assert e.value.code == "auth"
        with pytest.raises(RemoteError):
            connect(srv.url, scene="lab")
        with connect(srv.url, scene="lab", token="s3cret") as c:
            assert len(c.ids) == 1
    finally:
        srv.stop()
    assert Server("0.0.0.0", 0).token  # on by default beyond loopback (not started)
    assert Server("127.0.0.1", 0).token is None


def test_protocol_version_is_checked(server):
    from websockets.sync.client import connect as ws_connect

    ws = ws_connect(server.url).__enter__()
    ws.send(msgpack.packb({"t": "hello", "v": 99, "scene": "lab"}))
    msg = msgpack.unpackb(ws.recv(timeout=10), raw=False)
    assert msg["code"] == "version"


def test_a_dragged_body_is_released_when_its_client_leaves(server):
    with connect(server.url, scene="lab") as a, connect(server.url, scene="lab") as b:
        a.grab(10)
        b.wait_edit(a.edit_seq)
        assert b.bodies[10]["owner"] == a.client_id and b.bodies[10]["kind"] == "kinematic"
        with pytest.raises(RemoteError) as e:
            b.set_pose(10, position=(0, 50, 0))
        assert e.value.code == "not_owner"
        a.close()
        deadline = time.monotonic() + 10
        while b.bodies[10].get("owner") is not None and time.monotonic() < deadline:
            time.sleep(0.02)
        assert b.bodies[10]["owner"] is None and b.bodies[10]["kind"] == "dynamic"
        b.set_pose(10, position=(0, 50, 0))


def test_a_stalled_client_does_not_hold_up_the_others(tmp_path):
    # A client that stops reading: the server keeps only the newest snapshot for it
    # (and a bounded queue of replies), so the scene and the other clients go on.
    from websockets.sync.client import connect as ws_connect

    srv = Server(port=0, scenes={"big": "boxes3000"}, rate=60.0).start()
    try:
        # A small receive buffer, so that the kernel's buffers do not hide the stall.
        sock = socket.socket()
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
        sock.connect(("127.0.0.1", srv.port))
        stalled = ws_connect(srv.url, sock=sock, max_size=None).__enter__()
        stalled.send(msgpack.packb({"t": "hello", "v": 1, "scene": "big", "mode": "full"}))
        with connect(srv.url, scene="big") as c:
            t0, s0 = time.monotonic(), c.wait_snapshot().seq
            time.sleep(3.0)
            s1 = c.wait_snapshot().seq
            rate = (s1 - s0) / (time.monotonic() - t0)
            host = srv.scenes["big"]
            conn = [k for k in host.clients.values() if k.id != c.client_id][0]
            # What the server holds for it: a bounded reply queue and one snapshot slot
            # (the sender awaits the socket, so frames do not pile up in the server).
            assert conn.out.qsize() <= srv.limits.max_queue
            assert conn.acked is None
            # The watching client still gets most ticks (the scene steps at 60 Hz unless
            # a boxes3000 step takes longer on this machine: compare with the scene's rate).
            assert rate > 0.5 * min(60.0, host.steps_per_second + 1)
        stalled.close()
    finally:
        srv.stop()


def _start_server_process(port: int, data: Path) -> subprocess.Popen:
    proc = subprocess.Popen([sys.executable, "-m", "wmo", "serve", "--port", str(port), "--data", str(data),
                             "--scene", "lab=tower", "--rate", "60"],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        _wait_port(port, proc)
    except RuntimeError as e:
        proc.kill()
        raise RuntimeError(f"{e}: {proc.communicate(timeout=10)[0]}") from None
    return proc


def test_sigkill_mid_edit_loses_no_acknowledged_edit(tmp_path):
    port = _free_port()
    data = tmp_path / "data"
    proc = _start_server_process(port, data)
    acked: dict[int, list[float]] = {}   # body id -> position last acknowledged
    removed: set[int] = set()
    try:
        c = connect(f"ws://127.0.0.1:{port}", scene="lab", mode="full")
        c.pause()  # poses then stay as the edits left them
        stop = threading.Event()

        inflight: list = [None]  # the edit sent and not yet acknowledged when the server died

        def edit_loop():
            rng = random.Random(3)
            k = 0
            while not stop.is_set():
                k += 1
                try:
                    if k % 5 == 0 and len(acked) > 3:
                        rid = rng.choice(sorted(acked))
                        inflight[0] = ("remove", rid, None)
                        c.remove_body(rid)
                        acked.pop(rid)
                        removed.add(rid)
                    elif k % 2 == 0 and acked:
                        rid = rng.choice(sorted(acked))
                        pos = [rng.uniform(-9, 9), 2.0, float(k)]
                        inflight[0] = ("pose", rid, pos)
                        c.set_pose(rid, position=pos)
                        acked[rid] = pos
                    else:
                        pos = [float(k), 5.0, 0.0]
                        inflight[0] = ("add", None, pos)
                        acked[c.add_body(BOX, position=pos)] = pos
                    inflight[0] = None
                except Exception:
                    return  # the server is gone: the edit in flight was not acknowledged

        t = threading.Thread(target=edit_loop)
        t.start()
        time.sleep(1.5)
        proc.send_signal(signal.SIGKILL)  # mid-edit: the loop is sending as fast as acks come
        proc.wait(10)
        stop.set()
        t.join(30)
        c.close()
        assert len(acked) + len(removed) > 20
        proc = _start_server_process(port, data)
        c2 = c
        c2.reconnect()  # the same client object: a full description and a key frame
        assert c2.paused
        # An edit applied but not yet acknowledged may or may not have survived.
        kind, in_rid, in_pos = inflight[0] or (None, None, None)
        for rid, pos in acked.items():
            if kind == "remove" and rid == in_rid and rid not in c2.bodies:
                continue
            assert rid in c2.bodies, f"acknowledged body {rid} lost"
            got = c2.positions[c2.index(rid)].tolist()
            assert got == pos or (kind == "pose" and rid == in_rid and got == in_pos)
        for rid in removed:
            assert rid not in c2.bodies
        # And it goes on: a reconnecting client edits as before.
        h = c2.add_body(BOX, position=(0, 9, 0))
        assert h > max(list(acked) + list(removed))
        c2.close()
    finally:
        proc.kill()
        proc.wait(10)


def test_rate_limit_answers_and_keeps_the_connection(tmp_path):
    srv = Server(port=0, scenes={"lab": "empty"}, limits=ServerLimits(rate=200.0, burst=20.0)).start()
    try:
        with connect(srv.url, scene="lab") as c:
            futures = [c.set_settings(wait=False, dt=1 / 60) for _ in range(60)]
            codes = []
            for f in futures:
                try:
                    f.result(30)
                    codes.append("ok")
                except RemoteError as e:
                    codes.append(e.code)
            # A burst of 20 (snapshot acks count too, 60 a second): about 20 pass at once.
            assert codes.count("ok") >= 10 and "rate_limited" in codes
            time.sleep(0.5)  # the bucket refills at 200 per second
            assert c.add_body(BOX, position=(0, 3, 0)) == 2
    finally:
        srv.stop()


def test_a_client_that_does_not_acknowledge_gets_at_most_the_window(tmp_path):
    # At most max_unacked_snapshots beyond the newest ack: over a slow link the server
    # then sends the newest snapshot once the link has room, instead of queueing stale
    # ones in the socket (the mobile preset measured 3.5 s of delay without the window).
    from websockets.sync.client import connect as ws_connect

    from wmo.remote.snapshot import SnapshotDecoder

    srv = Server(port=0, scenes={"lab": "tower"}, rate=120.0,
                 limits=ServerLimits(max_unacked_snapshots=10)).start()
    try:
        ws = ws_connect(srv.url, max_size=None).__enter__()
        ws.send(msgpack.packb({"t": "hello", "v": 1, "scene": "lab"}))
        dec = SnapshotDecoder()

        def frames(seconds: float) -> list:
            out, end = [], time.monotonic() + seconds
            while time.monotonic() < end:
                try:
                    raw = ws.recv(timeout=max(0.01, end - time.monotonic()))
                except TimeoutError:
                    break
                if raw[:2] == b"WS":
                    out.append(dec.decode(raw))
            return out

        first = frames(1.0)  # 120 ticks happen; 10 are sent
        assert len(first) == 10
        ws.send(msgpack.packb({"t": "ack", "snap": first[-1].seq}))
        more = frames(1.0)
        assert len(more) == 10 and more[0].seq > first[-1].seq + 50  # the newest, not the next
        ws.close()
    finally:
        srv.stop()


def test_snapshot_precision_is_a_server_setting():
    """Compressed snapshots come at the server's precision (default Fiedler's 1/512 m
    and 9 bits): decoded positions are whole multiples of the step, within half a step
    of the truth; a bad precision is refused naming the field."""
    where = np.array([0.1234567, 5.0, -2.7654321])
    for kwargs, resolution in (({}, 1 / 512), ({"position_resolution": 1e-3, "orientation_bits": 12}, 1e-3)):
        srv = Server(port=0, scenes={"lab": "empty"}, **kwargs).start()
        try:
            with connect(srv.url, scene="lab") as c:
                c.add_body(wmo.Sphere(0.5), position=where, kind="static")
                snap = c.wait_snapshot()
                while len(snap.ids) < 2:
                    snap = c.wait_snapshot()
                steps = snap.positions[1] / resolution
                np.testing.assert_allclose(steps, np.rint(steps), rtol=0, atol=1e-9)
                np.testing.assert_allclose(snap.positions[1], where, rtol=0, atol=resolution / 2 + 1e-12)
                assert np.abs(snap.positions[1] - where).max() > 1e-4  # truly quantized at this step
        finally:
            srv.stop()
    with pytest.raises(ValueError, match="orientation_bits"):
        Server(port=0, orientation_bits=20)
    with pytest.raises(ValueError, match="position_resolution"):
        Server(port=0, position_resolution=0.0)
