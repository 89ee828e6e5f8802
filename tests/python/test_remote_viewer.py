"""The browser viewer (wmo.remote.viewer): what it sends to viser matches the server's
snapshots, its drag operations follow the protocol's ownership rules, and a real
(headless, software-rendered) Chromium shows the bodies. Everything listens on loopback;
every wait is bounded."""
from __future__ import annotations

import base64
import io
import json
import math
import os
import shutil
import signal
import subprocess
import tempfile
import time
import types
import urllib.request

import numpy as np
import pytest

pytest.importorskip("msgpack")
pytest.importorskip("websockets")
pytest.importorskip("viser", reason="the viewer is built on viser (pip install viser)")

from wmo.remote.client import RemoteError, connect  # noqa: E402
from wmo.remote.server import Server  # noqa: E402
from wmo.remote.viewer import COLOURS, Viewer  # noqa: E402

BOX = {"type": "box", "half_extents": [0.5, 0.5, 0.5]}


def _wait(cond, timeout: float = 5.0, what: str = "condition"):
    deadline = time.monotonic() + timeout
    while True:
        value = cond()
        if value:
            return value
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {timeout} s waiting for {what}")
        time.sleep(0.01)


@pytest.fixture
def lab():
    """A server with the tower (ground + 30 unit boxes, ids 1..31) and a viewer of it."""
    srv = Server(port=0, scenes={"lab": "tower"}).start()
    viewer = None
    try:
        viewer = Viewer(srv.url, "lab", port=0).start()
        yield srv, viewer
    finally:
        if viewer is not None:
            viewer.stop()
        srv.stop()


def _assert_drawn_matches(viewer: Viewer, snap) -> None:
    drawn = viewer.drawn_poses()
    assert sorted(drawn) == snap.ids.tolist()
    for row, rid in enumerate(snap.ids.tolist()):
        pos, q, _ = drawn[rid]
        # float32 on the wire to the browser: 30 m carries about 2e-6 m of rounding.
        np.testing.assert_allclose(pos, snap.positions[row], atol=1e-5, err_msg=f"body {rid}")
        np.testing.assert_allclose(q, snap.orientations[row], atol=1e-6, err_msg=f"body {rid}")


def test_the_batches_hold_every_body_at_its_snapshot_pose(lab):
    srv, viewer = lab
    other = connect(srv.url, scene="lab")
    try:
        other.pause()  # from here on every snapshot holds the same poses
        snap = viewer.client.wait_snapshot()
        viewer.wait_drawn(snap.seq - 1)
        drawn = viewer.drawn_poses()
        assert len(drawn) == 31
        assert drawn[1][2] == "static" and {drawn[i][2] for i in range(2, 32)} == {"dynamic"}
        _assert_drawn_matches(viewer, snap)
        # One batch per geometry and colour, not one node per body: all boxes are one
        # unit mesh scaled per instance, so the ground and the tower are two batches.
        assert sorted(b.key for b in viewer._batches.values()) == [("box", "dynamic"), ("box", "static")]

        # A body with a real rotation, added while the viewer runs: the batches are
        # rebuilt, and viser gets (w, x, y, z) where WMO says (x, y, z, w).
        q = np.array([math.sin(0.4) / math.sqrt(2), 0.0, math.sin(0.4) / math.sqrt(2), math.cos(0.4)])
        rid = other.add_body(BOX, position=(4, 0.5, 1), orientation=q, kind="kinematic")
        snap = _wait(lambda: (s := viewer.client.wait_snapshot()) is not None and rid in s.ids and s,
                     what="the new body in a snapshot")
        viewer.wait_drawn(snap.seq - 1)
        _assert_drawn_matches(viewer, snap)
        assert viewer.drawn_poses()[rid][2] == "kinematic"
        batch = next(b for b in viewer._batches.values() if b.key == ("box", "kinematic"))
        drawn_q = snap.orientations[int(np.searchsorted(snap.ids, rid))]  # q as decoded (9 bits)
        np.testing.assert_allclose(drawn_q, q, atol=5e-3)
        np.testing.assert_allclose(batch.handle.batched_wxyzs[0], [drawn_q[3], *drawn_q[:3]], atol=1e-6)
    finally:
        other.close()


def test_dragging_grabs_moves_and_releases_on_the_server(lab):
    srv, viewer = lab
    model = srv.scenes["lab"].model
    viewer.begin_drag(10)
    assert model.owner.get(10) == viewer.client.client_id
    assert model.bodies[10].kind == "kinematic"

    viewer.drag_to(10, (3, 20, 0), (0, 0, 0, 1))
    _wait(lambda: np.allclose(model.bodies[10].position, (3, 20, 0), atol=1e-9), what="body 10 at (3, 20, 0)")
    # The viewer draws it where it was put, in the dragged (kinematic) colour.
    _wait(lambda: viewer.drawn_poses()[10][2] == "kinematic"
          and np.allclose(viewer.drawn_poses()[10][0], (3, 20, 0), atol=2e-3), what="body 10 drawn dragged")

    # The viewer is a client like any other: while it drags body 10, others cannot.
    other = connect(srv.url, scene="lab")
    try:
        with pytest.raises(RemoteError) as e:
            other.set_pose(10, position=(0, 5, 0))
        assert e.value.code == "not_owner"
        viewer.end_drag(10)
        assert model.owner.get(10) is None and model.bodies[10].kind == "dynamic"

        # ... and it cannot take a body someone else drags, nor a static one; the
        # refusals are errors, not crashes.
        other.grab(11)
        with pytest.raises(RemoteError) as e:
            viewer.begin_drag(11)
        assert e.value.code == "not_owner"
        with pytest.raises(RemoteError) as e:
            viewer.begin_drag(1)
        assert e.value.code == "bad_args"
    finally:
        other.close()


def test_a_click_attaches_the_gizmo_and_its_drag_moves_the_body(lab):
    # The browser's side, without a browser: what viser's click and gizmo callbacks
    # call, with the events they would pass.
    srv, viewer = lab
    model = srv.scenes["lab"].model
    batch = next(b for b in viewer._batches.values() if b.key == ("box", "dynamic"))
    instance = int(np.searchsorted(batch.ids, 12))
    viewer._clicked(batch.handle, types.SimpleNamespace(instance_index=instance, client=None))
    assert viewer._gizmo_body == 12
    gizmo = viewer._gizmo

    viewer._gizmo_event(gizmo, 12, "start", None)
    gizmo.position = (-2.0, 15.0, 1.0)   # the user pulls the gizmo
    viewer._gizmo_event(gizmo, 12, "update", None)
    _wait(lambda: model.owner.get(12) == viewer.client.client_id
          and np.allclose(model.bodies[12].position, (-2.0, 15.0, 1.0), atol=1e-9), what="body 12 dragged")
    time.sleep(0.15)  # held still longer than the throw window: released without a throw
    viewer._gizmo_event(gizmo, 12, "end", None)
    _wait(lambda: model.owner.get(12) is None and model.bodies[12].kind == "dynamic", what="body 12 released")
    v = model.bodies[12].linear_velocity
    assert abs(v[0]) < 0.1 and abs(v[2]) < 0.1, v
    assert not viewer.errors

    # Static bodies are not draggable: a click on the ground attaches nothing.
    ground = next(b for b in viewer._batches.values() if b.key == ("box", "static"))
    viewer._clicked(ground.handle, types.SimpleNamespace(instance_index=0, client=None))
    assert viewer._gizmo_body == 12


# ---- a real browser ----

def _chromium() -> str | None:
    return shutil.which("chromium") or shutil.which("chromium-browser") or shutil.which("google-chrome")


def _group_gone(pgid: int) -> bool:
    try:
        os.killpg(pgid, 0)  # signal 0: only asks whether any process of the group is left
    except ProcessLookupError:
        return True
    return False


def _project(points: np.ndarray, cam, width: int, height: int) -> np.ndarray:
    """Pixel (x, y) of world points for viser's perspective camera (vertical fov)."""
    eye, target = np.asarray(cam.position, float), np.asarray(cam.look_at, float)
    f = (target - eye) / np.linalg.norm(target - eye)
    r = np.cross(f, (0.0, 1.0, 0.0))
    r /= np.linalg.norm(r)
    u = np.cross(r, f)
    d = points - eye
    t = math.tan(0.5 * cam.fov)
    x_ndc = (d @ r) / ((d @ f) * t * width / height)
    y_ndc = (d @ u) / ((d @ f) * t)
    return np.stack([(x_ndc + 1) * 0.5 * width, (1 - y_ndc) * 0.5 * height], axis=1)


class _Cdp:
    """A minimal Chrome DevTools Protocol session over one page's WebSocket."""

    def __init__(self, ws_url: str):
        from websockets.sync.client import connect as ws_connect

        self.ws = ws_connect(ws_url, max_size=None, open_timeout=10)
        self.next_id = 0
        self.events: list[str] = []   # names of the events received so far

    def call(self, method: str, timeout: float = 30.0, **params) -> dict:
        self.next_id += 1
        self.ws.send(json.dumps({"id": self.next_id, "method": method, "params": params}))
        deadline = time.monotonic() + timeout
        while True:  # events (no "id") are noted, other replies skipped
            msg = json.loads(self.ws.recv(timeout=max(0.1, deadline - time.monotonic())))
            if "method" in msg:
                self.events.append(msg["method"])
            elif msg.get("id") == self.next_id:
                if "error" in msg:
                    raise RuntimeError(f"{method}: {msg['error']}")
                return msg["result"]

    def wait_event(self, name: str, timeout: float) -> None:
        deadline = time.monotonic() + timeout
        while name not in self.events:
            msg = json.loads(self.ws.recv(timeout=max(0.1, deadline - time.monotonic())))
            if "method" in msg:
                self.events.append(msg["method"])

    def close(self) -> None:
        self.ws.close()


@pytest.mark.skipif(_chromium() is None, reason="no chromium, chromium-browser or google-chrome binary on PATH")
def test_headless_chromium_shows_the_tower(lab, tmp_path):
    Image = pytest.importorskip("PIL.Image", reason="decoding the screenshot needs Pillow")

    srv, viewer = lab
    other = connect(srv.url, scene="lab")
    other.pause()  # the tower stays exactly where the camera was aimed
    other.close()
    width, height = 800, 600
    profile = tempfile.mkdtemp(prefix="wmo-viewer-chromium-")
    log_path = tmp_path / "chromium.log"
    with open(log_path, "wb") as log_file:
        # Software WebGL (SwiftShader through ANGLE): no GPU needed. Port 0: Chromium
        # picks a free port and writes it to DevToolsActivePort in the profile (no race).
        proc = subprocess.Popen(
            [_chromium(), "--headless=new", "--no-sandbox", "--disable-gpu", "--use-gl=angle",
             "--use-angle=swiftshader", "--enable-unsafe-swiftshader", f"--window-size={width},{height}",
             "--remote-debugging-port=0", f"--user-data-dir={profile}", "--no-first-run",
             "--no-default-browser-check", "--disable-extensions", "about:blank"],
            # Its own process group: Chromium's renderer, GPU and zygote processes are
            # killed with it (killing the browser process alone leaves them to exit
            # later, writing into the profile after it is removed).
            stdout=subprocess.DEVNULL, stderr=log_file, start_new_session=True)
    cdp = None
    try:
        port_file = os.path.join(profile, "DevToolsActivePort")
        _wait(lambda: os.path.exists(port_file) and open(port_file).read().strip(), timeout=15,
              what=f"Chromium's DevTools port (log: {log_path})")
        port = int(open(port_file).read().split()[0])
        with urllib.request.urlopen(f"http://127.0.0.1:{port}/json", timeout=10) as r:
            page = next(t for t in json.load(r) if t["type"] == "page")
        cdp = _Cdp(page["webSocketDebuggerUrl"])
        # The viewport itself at 800 x 600 (--window-size includes the window's frame).
        cdp.call("Emulation.setDeviceMetricsOverride", width=width, height=height, deviceScaleFactor=1,
                 mobile=False)
        cdp.call("Page.enable")
        cdp.call("Page.navigate", url=viewer.address)
        cdp.wait_event("Page.loadEventFired", timeout=15)

        # Where the 30 boxes must appear: their corners through the viewer's camera.
        snap = viewer.client.snapshot
        corners = np.array([[sx, sy, sz] for sx in (-0.5, 0.5) for sy in (-0.5, 0.5) for sz in (-0.5, 0.5)])
        pts = (snap.positions[1:, None, :] + corners[None]).reshape(-1, 3)
        xy = _project(pts, viewer.server.initial_camera, width, height)
        x0, y0 = np.floor(xy.min(axis=0)).astype(int)
        x1, y1 = np.ceil(xy.max(axis=0)).astype(int)
        assert 0 <= x0 < x1 <= width and 0 <= y0 < y1 <= height, "the camera does not frame the tower"

        assert COLOURS["dynamic"] == (210, 60, 0), "the colour test below is tuned to this colour"

        def orange(img: np.ndarray) -> np.ndarray:
            # The dynamic colour, (210, 60, 0), renders fully lit as about (211-218,
            # 130-140, 39-42) (the lights and tone mapping brighten it): red well above
            # green well above blue. The first frames, before the page's environment
            # light arrives, show it pale, about (218, 176, 128), which fails this on
            # purpose (the wait goes on). Grey ground, white sky, grid lines and the
            # blue GUI fail it too; the one other orange thing is the warning about
            # software WebGL in the top-left corner, outside the tower's rectangle.
            r, g, b = (img[..., k].astype(int) for k in range(3))
            return (r - g > 60) & (g - b > 40)

        # Until the tower shows in two screenshots in a row that are the same (the page
        # has settled), or 30 s (software rendering compiles shaders for seconds).
        deadline = time.monotonic() + 30.0
        previous = None
        while True:
            png = base64.b64decode(cdp.call("Page.captureScreenshot", format="png")["data"])
            img = np.asarray(Image.open(io.BytesIO(png)).convert("RGB"))
            mask = orange(img)
            inside = mask[y0:y1, x0:x1].mean()
            settled = previous is not None and np.array_equal(img, previous)
            if (inside > 0.5 and settled) or time.monotonic() > deadline:
                break
            previous = img
            time.sleep(0.25)
        (tmp_path / "viewer.png").write_bytes(png)

        assert img.shape == (height, width, 3)
        assert img.std() > 10, "a uniform image: nothing rendered"
        # Measured: the tower covers 81.5% of its projected bounding rectangle, 23 x 427
        # pixels (a box seen at an angle fills most of its rectangle; the rest is the
        # corners' slant) and 1.67% of the image (8,000 of 480,000 pixels). A page that
        # draws no boxes, or draws them elsewhere, has 0% there; the halves leave room
        # for other drivers' anti-aliasing and lighting.
        assert inside > 0.5, f"orange covers {inside:.1%} of the tower's rectangle; screenshot: {tmp_path}"
        assert mask[y0:y1, x0:x1].sum() / mask.size > 0.008, f"too few orange pixels; screenshot: {tmp_path}"
    finally:
        if cdp is not None:
            cdp.close()
        try:
            os.killpg(proc.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
        proc.wait(10)
        _wait(lambda: _group_gone(proc.pid), timeout=10, what="Chromium's processes to exit")
        shutil.rmtree(profile, ignore_errors=True)


def test_a_compound_is_drawn_as_its_children_in_place():
    # One mesh in the body's frame: each child's mesh (unit meshes stretched by their
    # scale) moved by its pose; the bounding radius holds every child.
    import wmo
    from wmo.remote.scene import shape_to_spec
    from wmo.remote.viewer import _bounding_radius, _mesh

    q = (0.0, 0.0, math.sin(math.pi / 8), math.cos(math.pi / 8))  # 45 degrees about z
    spec = shape_to_spec(wmo.Compound([(wmo.Sphere(0.25), wmo.Pose((1.0, 0, 0))),
                                       (wmo.Box((0.5, 0.1, 0.1)), wmo.Pose((0, 0, 0), q))]))
    v, f, _ = _mesh(spec)
    sphere_v = len(_mesh({"type": "sphere"})[0])
    assert f.max() == len(v) - 1 and f.min() == 0
    np.testing.assert_allclose(np.linalg.norm(v[:sphere_v] - [1.0, 0, 0], axis=1), 0.25, rtol=1e-12)
    # The box's long axis turned 45 degrees: its corners reach sqrt(0.5^2 + 0.1^2) from the centre in xy.
    box = v[sphere_v:]
    assert np.allclose(np.abs(box[:, 2]), 0.1)
    np.testing.assert_allclose(np.hypot(box[:, 0], box[:, 1]).max(), math.hypot(0.5, 0.1), rtol=1e-12)
    assert _bounding_radius(spec) == pytest.approx(1.25)


def test_a_one_sided_mesh_is_drawn_from_its_front_only():
    # A one-sided mesh collides only from the side its triangles face: drawn double-
    # sided, a terrain seen from below looked solid where bodies pass through it.
    import wmo
    from wmo.remote.scene import shape_to_spec
    from wmo.remote.viewer import _side

    v = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]
    assert _side(shape_to_spec(wmo.TriangleMesh(v, [[0, 2, 1]], one_sided=True))) == "front"
    assert _side(shape_to_spec(wmo.TriangleMesh(v, [[0, 2, 1]]))) == "double"
    assert _side(shape_to_spec(wmo.Plane((0, 1, 0), 0))) == "double"
    assert _side(BOX) == "front"
