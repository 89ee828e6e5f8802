"""A browser view of a live scene on a WMO server, built on viser.

Run it next to a server::

    wmo serve --port 8765 &                                  # or wmo.remote.Server(...)
    python -m wmo.remote.viewer ws://127.0.0.1:8765 --scene lab --port 8080 [--token T]

and open the address it prints (``http://127.0.0.1:8080``) in a browser. The page shows
the scene's bodies as they move (at most ``max_fps`` updates a second, 30 by default):
static bodies in grey, dynamic bodies in orange, kinematic bodies (and bodies someone is
dragging, which the server turns kinematic) in blue, over a ground grid in the y = 0
plane (+y is up, as in the canonical scenes). Bodies are drawn from their shape specs:
boxes, spheres, capsules and cylinders (axis along local y) as meshes, convex hulls as
their hull, triangle meshes as they are, planes as a large thin slab. Bodies that share
a geometry and a colour are drawn as one batched mesh with per-instance poses, so a
scene of thousands of bodies costs one scene node per kind of shape, not one per body.

Dragging: click a dynamic or kinematic body and a transform gizmo appears at its pose
(click it again to take the gizmo away; static bodies cannot be dragged). Pulling an
arrow, plane handle or ring of the gizmo grabs the body (it turns kinematic on the
server), every move of the gizmo sets the body's pose, and letting go releases it
(dynamic again), thrown with the gizmo's velocity over the last 0.1 s.

The viewer is a client of the server like any other (it connects in compressed mode and
follows PROTOCOL.md): while it drags a body, other clients get ``not_owner`` for it, and
a body another client is dragging cannot be dragged here; such refusals, and any other
server error, are shown as a notification in the page and logged, never fatal. If the
connection drops, the viewer keeps trying to reconnect every two seconds. The page
itself asks for no password: whoever opens it edits the scene as this viewer (with its
token), so serve it on loopback (the default) or behind an authenticating proxy.

The same drag operations are methods (:meth:`Viewer.begin_drag`, :meth:`Viewer.drag_to`,
:meth:`Viewer.end_drag`) that scripts and tests can call directly.
"""
from __future__ import annotations

import argparse
import collections
import json
import logging
import math
import queue
import signal
import sys
import threading
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .client import RemoteError, RemoteScene, connect

__all__ = ["Viewer", "main", "COLOURS"]

log = logging.getLogger("wmo.remote.viewer")

#: RGB (0-255) of each colour class: static bodies, dynamic bodies, kinematic or dragged.
COLOURS: dict[str, tuple[int, int, int]] = {
    "static": (150, 150, 150),
    "dynamic": (210, 60, 0),
    "kinematic": (20, 90, 220),
}

# Shapes drawn from one unit mesh scaled per instance (so that e.g. boxes of every size
# share one batch); every other shape gets a mesh of its own per distinct spec.
_SCALED = ("box", "sphere", "cylinder")
# A plane is infinite; it is drawn as a slab this wide (m) and this thick, below its surface.
_PLANE_SIZE, _PLANE_THICKNESS = 400.0, 0.05
# How far back the gizmo's throw velocity looks (s), and its cap (m/s): a drag that
# stopped before the release throws nothing, and a glitchy sample cannot fling a body.
_THROW_WINDOW, _THROW_MAX = 0.1, 30.0


def _geometry_key(spec: dict) -> str:
    """Bodies with equal keys share a mesh (up to the per-instance scale of _scale)."""
    t = spec.get("type")
    if t in _SCALED:
        return t
    return json.dumps(spec, sort_keys=True)


def _scale(spec: dict) -> tuple[float, float, float]:
    """The per-instance (x, y, z) scale of the unit mesh of a box, sphere or cylinder."""
    t = spec["type"]
    if t == "box":
        # A rounded box is drawn with sharp corners at its half extents.
        return tuple(float(h) for h in spec["half_extents"])
    if t == "sphere":
        r = float(spec["radius"])
        return (r, r, r)
    if t == "cylinder":
        r = float(spec["radius"])
        return (r, float(spec["half_height"]), r)
    return (1.0, 1.0, 1.0)


def _z_to_y(vertices: np.ndarray) -> np.ndarray:
    """Rotates trimesh's z-axis primitives so that their axis is WMO's local y
    (a rotation by -90 degrees about x: (x, y, z) -> (x, z, -y), winding unchanged)."""
    v = np.asarray(vertices, dtype=float)
    return np.stack([v[:, 0], v[:, 2], -v[:, 1]], axis=1)


def _side(spec: dict) -> str:
    """Which faces of a shape's mesh the browser draws: a two-sided triangle mesh (a
    sheet, solid from both sides) and a plane's slab both sides; a one-sided mesh only
    its front, the side that collides, so that a terrain seen from below, where bodies
    pass through it, is not drawn as if solid; closed convex meshes their front."""
    t = spec.get("type")
    if t == "triangle_mesh":
        return "front" if spec.get("one_sided", False) else "double"
    return "double" if t == "plane" else "front"


def _mesh(spec: dict) -> tuple[np.ndarray, np.ndarray, bool]:
    """(vertices (V, 3) in the body frame, faces (F, 3), flat shading) of a shape spec;
    box, sphere and cylinder are unit meshes that _scale stretches."""
    import trimesh

    t = spec["type"]
    if t == "box":
        m = trimesh.creation.box(extents=(2.0, 2.0, 2.0))  # half extents 1
        return m.vertices, m.faces, True
    if t == "sphere":
        m = trimesh.creation.icosphere(subdivisions=2, radius=1.0)
        return m.vertices, m.faces, False
    if t == "cylinder":
        m = trimesh.creation.cylinder(radius=1.0, height=2.0, sections=24)
        return _z_to_y(m.vertices), m.faces, True
    if t == "capsule":
        m = trimesh.creation.capsule(height=2.0 * float(spec["half_height"]), radius=float(spec["radius"]),
                                     count=[16, 16])
        return _z_to_y(m.vertices), m.faces, False
    if t == "convex_hull":
        # WMO's own hull (the one it collides with; trimesh's would need SciPy): faces are
        # polygons, counter-clockwise seen from outside, fanned into triangles.
        from .scene import shape_from_spec

        hull = shape_from_spec(spec)
        tris = [(f[0], f[i], f[i + 1]) for f in hull.faces for i in range(1, len(f) - 1)]
        return np.asarray(hull.vertices, dtype=float), np.asarray(tris, dtype=np.int64), True
    if t == "triangle_mesh":
        return np.asarray(spec["vertices"], dtype=float), np.asarray(spec["triangles"], dtype=np.int64), True
    if t == "plane":
        # The plane is {x : n . x = offset} in the body frame, solid below: a slab whose
        # top face is the plane, square in two directions perpendicular to n.
        n = np.asarray(spec["normal"], dtype=float)
        n = n / np.linalg.norm(n)
        m = trimesh.creation.box(extents=(_PLANE_SIZE, _PLANE_SIZE, _PLANE_THICKNESS))
        rot = trimesh.geometry.align_vectors([0.0, 0.0, 1.0], n)
        centre = n * (float(spec.get("offset", 0.0)) - 0.5 * _PLANE_THICKNESS)
        v = m.vertices @ rot[:3, :3].T + centre
        return v, m.faces, True
    if t == "compound":
        # The children's meshes in the compound's frame, as one mesh.
        from .. import Pose

        vs, fs, n = [], [], 0
        for c in spec["children"]:
            v, f, _ = _mesh(c["shape"])
            v = np.asarray(v, dtype=float) * np.asarray(_scale(c["shape"]))
            pose = Pose(c.get("position", (0.0, 0.0, 0.0)), c.get("orientation", (0.0, 0.0, 0.0, 1.0)))
            vs.append(v @ pose.matrix().T + np.asarray(pose.position))
            fs.append(np.asarray(f, dtype=np.int64) + n)
            n += len(v)
        return np.concatenate(vs), np.concatenate(fs), True
    raise ValueError(f"cannot draw a shape of type {t!r}")


def _bounding_radius(spec: dict) -> float:
    """A radius (m) about the body origin that holds the shape (planes: 0, unbounded)."""
    t = spec.get("type")
    if t == "box":
        return float(np.linalg.norm(spec["half_extents"]))
    if t == "sphere":
        return float(spec["radius"])
    if t in ("capsule", "cylinder"):
        return float(spec["radius"]) + float(spec["half_height"])
    if t in ("convex_hull", "triangle_mesh"):
        pts = np.asarray(spec.get("points", spec.get("vertices")), dtype=float)
        return float(np.linalg.norm(pts, axis=1).max()) if len(pts) else 0.0
    if t == "compound":
        return max(float(np.linalg.norm(c.get("position", (0.0, 0.0, 0.0)))) + _bounding_radius(c["shape"])
                   for c in spec["children"])
    return 0.0


def _colour_class(d: dict) -> str:
    kind = d.get("kind", "dynamic")
    if kind == "static":
        return "static"
    if kind == "kinematic" or d.get("owner") is not None:
        return "kinematic"
    return "dynamic"


def _xyzw_to_wxyz(q: np.ndarray) -> np.ndarray:
    return np.asarray(q)[..., [3, 0, 1, 2]]


def _wxyz_to_xyzw(q) -> np.ndarray:
    return np.asarray(q, dtype=float)[..., [1, 2, 3, 0]]


@dataclass
class _Batch:
    """One batched mesh: bodies of one geometry and colour class."""
    key: tuple[str, str]               # (geometry key, colour class)
    ids: np.ndarray                    # (n,) body ids, ascending; instance i is ids[i]
    scales: np.ndarray                 # (n, 3) per-instance scales
    handle: Any = None                 # viser's BatchedMeshHandle
    rows: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))  # rows in the snapshot


class Viewer:
    """Shows a scene of a WMO server in the browser (viser) and lets a user drag bodies.

    url: the server (``ws://host:port``); scene: the scene's name; token: the server's
    token, if it needs one. host, port: where the viser page is served (port 0 picks a
    free port; if the port is taken, viser tries the next ones: :attr:`address` tells
    the one in use). max_fps: the most pose updates per second sent to the browsers.

    Poses are the server's: positions in metres (world frame), orientations body to
    world. WMO's quaternions are (x, y, z, w); viser's are (w, x, y, z), and the viewer
    converts at its edges, so every method here takes and returns (x, y, z, w).
    """

    def __init__(self, url: str, scene: str = "default", *, token: str | None = None,
                 host: str = "127.0.0.1", port: int = 8080, max_fps: float = 30.0):
        if not (isinstance(max_fps, (int, float)) and math.isfinite(max_fps) and max_fps > 0):
            raise ValueError(f"max_fps must be a positive number, got {max_fps!r}")
        if not (isinstance(port, int) and 0 <= port <= 65535):
            raise ValueError(f"port must be in [0, 65535], got {port!r}")
        self.url, self.scene_name, self.token = url, scene, token
        self.host, self.requested_port, self.max_fps = host, port, float(max_fps)
        self._client: RemoteScene | None = None
        self._server = None                      # viser.ViserServer
        self._lock = threading.RLock()           # batches, gizmo and drag state
        self._stop = threading.Event()
        self._pusher: threading.Thread | None = None
        self._dragger: threading.Thread | None = None
        self._drags: queue.SimpleQueue = queue.SimpleQueue()
        self._batches: dict[tuple[str, str], _Batch] = {}
        self._batch_names = 0
        self._meshes: dict[str, tuple[np.ndarray, np.ndarray, bool]] = {}
        self._key_cache: dict[int, tuple[dict, tuple[str, str], tuple]] = {}
        self._built_ids: np.ndarray | None = None
        self._built_edit_seq = -1
        self._drawn_seq = -1
        self._drawn_cond = threading.Condition()
        self._gizmo = None
        self._gizmo_body: int | None = None
        self._gizmo_dragging = False
        # (time, position) of the gizmo during a drag (the drag thread's), for the throw.
        self._samples: collections.deque = collections.deque(maxlen=64)
        self._status = None
        self._stopped = False
        #: The newest errors reported (server refusals, lost connection), newest last.
        self.errors: collections.deque[str] = collections.deque(maxlen=50)

    # ---- life cycle ----

    def start(self) -> "Viewer":
        """Connects to the server (compressed mode), serves the page, and starts the
        thread that sends poses to the browsers; returns once the page is served."""
        try:
            import viser
        except ImportError as e:  # an optional dependency (pip install wmo[remote])
            raise ImportError("the viewer needs viser: pip install viser") from e
        if self._server is not None:
            return self
        self._client = connect(self.url, scene=self.scene_name, token=self.token, mode="compressed",
                               name="viewer")
        try:
            self._server = viser.ViserServer(host=self.host, port=self.requested_port, verbose=False)
            self._setup_scene()
            self._push(self._client.snapshot)   # the first frame before anyone connects
        except BaseException:
            self._client.close()
            if self._server is not None:
                self._server.stop()
                self._server = None
            raise
        self._pusher = threading.Thread(target=self._run_pusher, name="wmo-viewer-push", daemon=True)
        self._dragger = threading.Thread(target=self._run_dragger, name="wmo-viewer-drag", daemon=True)
        self._pusher.start()
        self._dragger.start()
        return self

    def stop(self) -> None:
        """Closes the connection and the page's server, and joins the threads. Idempotent."""
        if self._stopped:
            return
        self._stopped = True
        self._stop.set()
        self._drags.put(None)
        for t in (self._pusher, self._dragger):
            if t is not None:
                t.join(5)
        if self._client is not None:
            self._client.close()
        if self._server is not None:
            self._server.stop()

    def __enter__(self) -> "Viewer":
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()

    @property
    def address(self) -> str:
        """``http://host:port`` of the page (the port in use, also when 0 was asked for)."""
        if self._server is None:
            raise RuntimeError("the viewer is not started")
        host = self.host if ":" not in self.host else f"[{self.host}]"
        return f"http://{host}:{self._server.get_port()}"

    @property
    def server(self):
        """The viser server of the page (``viser.ViserServer``): add GUI or scene nodes
        to it; its ``initial_camera`` is the view that frames the bodies at start."""
        if self._server is None:
            raise RuntimeError("the viewer is not started")
        return self._server

    @property
    def client(self) -> RemoteScene:
        """The viewer's own connection to the scene."""
        if self._client is None:
            raise RuntimeError("the viewer is not started")
        return self._client

    # ---- what is drawn ----

    @property
    def drawn_seq(self) -> int:
        """The seq of the newest snapshot sent to the browsers (-1 before the first)."""
        return self._drawn_seq

    def wait_drawn(self, after: int, timeout: float = 10.0) -> int:
        """Blocks until a snapshot newer than seq `after` is drawn; returns its seq."""
        with self._drawn_cond:
            if not self._drawn_cond.wait_for(lambda: self._drawn_seq > after, timeout):
                raise TimeoutError(f"no snapshot after {after} drawn within {timeout} s")
            return self._drawn_seq

    def drawn_poses(self) -> dict[int, tuple[np.ndarray, np.ndarray, str]]:
        """What the browsers were last sent, by body id: (position (3,) m, orientation
        (4,) x y z w, colour class: static, dynamic or kinematic). float32, as sent."""
        out = {}
        with self._lock:
            for b in self._batches.values():
                pos = np.asarray(b.handle.batched_positions)
                q = _wxyz_to_xyzw(np.asarray(b.handle.batched_wxyzs))
                for i, rid in enumerate(b.ids):
                    out[int(rid)] = (pos[i], q[i], b.key[1])
        return out

    def _setup_scene(self) -> None:
        s = self._server
        s.scene.set_up_direction("+y")
        distance = self._frame_camera()
        s.scene.add_grid("/grid", width=200.0, height=200.0, plane="xz", cell_size=1.0, section_size=10.0,
                         fade_distance=max(100.0, 3.0 * distance),
                         # Just above y = 0, the canonical ground box's top, so that the
                         # two do not z-fight (with the camera's near plane, below). No
                         # shadows on the grid: the ground box right under it would shadow
                         # it ("acne") and blank out whole wedges of lines; the ground box
                         # shows the bodies' shadows anyway.
                         position=(0.0, 0.02, 0.0), shadow_opacity=0.0)
        self._status = s.gui.add_markdown(self._status_text())
        button = s.gui.add_button("Detach gizmo")

        @button.on_click
        def _(_event) -> None:
            with self._lock:
                if not self._gizmo_dragging:
                    self._detach_gizmo()

    def _status_text(self) -> str:
        n = len(self._client.bodies) if self._client is not None else 0
        return (f"**WMO** scene `{self.scene_name}` at `{self.url}`: {n} bodies.  \n"
                "Click a body to drag it with the gizmo; grey bodies are static.")

    def _frame_camera(self) -> float:
        """Points the initial camera (and "reset view") at the bodies' bounding box;
        returns the camera's distance (m) from the box's centre."""
        client = self._client
        snap = client.snapshot
        bodies = dict(client.bodies)
        lo, hi = [], []
        # Movable bodies define the view; the ground box (static, 500 m wide) would make
        # the tower a speck. With no movable bodies, frame the bounded static ones.
        for want_static in (False, True):
            for row, rid in enumerate(snap.ids):
                d = bodies.get(int(rid))
                if d is None or (d.get("kind") == "static") != want_static:
                    continue
                r = _bounding_radius(d["shape"])
                if want_static and (r == 0.0 or r > 100.0):
                    continue
                lo.append(snap.positions[row] - r)
                hi.append(snap.positions[row] + r)
            if lo:
                break
        if lo:
            lo_, hi_ = np.min(lo, axis=0), np.max(hi, axis=0)
        else:
            lo_, hi_ = np.array([-5.0, 0.0, -5.0]), np.array([5.0, 5.0, 5.0])
        centre = 0.5 * (lo_ + hi_)
        radius = max(0.5 * float(np.linalg.norm(hi_ - lo_)), 1.0)
        cam = self._server.initial_camera
        # Far enough that a sphere of `radius` fits the vertical field of view, from a
        # direction up and to the side (so a tower's height and stacking both show).
        distance = 1.1 * radius / math.sin(0.5 * cam.fov)
        direction = np.array([1.0, 0.35, 1.4])
        direction /= np.linalg.norm(direction)
        cam.up = (0.0, 1.0, 0.0)
        cam.look_at = tuple(centre)
        cam.position = tuple(centre + distance * direction)
        cam.far = max(1000.0, 4.0 * distance)
        # The depth buffer's resolution at distance z is about z**2 / (near * 2**24): with
        # viser's 1 cm near plane, 150 m away (boxes3000) it is 13 cm and the grid above
        # the ground box flickers in and out. A near plane 1/200 of the viewing distance
        # keeps it near 2 mm at the far side of the framed bodies.
        cam.near = min(max(distance / 200.0, 0.05), 1.0)
        return distance

    # ---- batches ----

    def _body_key(self, rid: int, d: dict) -> tuple[tuple[str, str], tuple]:
        # The client's mirror replaces a definition dict when the body changes, so the
        # dict's identity tells whether the cached key still holds (keys of thousands of
        # bodies are then not recomputed for every set_pose edit of a drag).
        cached = self._key_cache.get(rid)
        if cached is not None and cached[0] is d:
            return cached[1], cached[2]
        spec = d["shape"]
        key = (_geometry_key(spec), _colour_class(d))
        scale = _scale(spec) if spec["type"] in _SCALED else (1.0, 1.0, 1.0)
        self._key_cache[rid] = (d, key, scale)
        return key, scale

    def _sync_batches(self, snap) -> None:
        """Makes the batches hold the bodies of `snap` (and of the client's definitions):
        a batch whose members changed is re-created; others only get new rows."""
        client = self._client
        ids = snap.ids
        # Read before the definitions: an edit arriving meanwhile then triggers a rebuild.
        edit_seq = client.edit_seq
        if (edit_seq == self._built_edit_seq and self._built_ids is not None
                and np.array_equal(ids, self._built_ids)):
            return
        bodies = dict(client.bodies)
        members: dict[tuple[str, str], list[tuple[int, int, tuple]]] = {}
        specs: dict[str, dict] = {}
        for row, rid in enumerate(ids.tolist()):
            d = bodies.get(rid)
            if d is None:  # in the snapshot before its definition arrived: next frame
                continue
            key, scale = self._body_key(rid, d)
            members.setdefault(key, []).append((rid, row, scale))
            specs.setdefault(key[0], d["shape"])
        for rid in set(self._key_cache) - set(bodies):
            del self._key_cache[rid]
        for key in list(self._batches):
            if key not in members:
                self._remove_batch(key)
        for key, rows in members.items():
            new_ids = np.array([m[0] for m in rows], dtype=np.int64)
            new_scales = np.array([m[2] for m in rows], dtype=np.float32)
            b = self._batches.get(key)
            # Scales too: after reset or load_scene the same ids may be boxes of other sizes.
            if b is None or not np.array_equal(b.ids, new_ids) or not np.array_equal(b.scales, new_scales):
                if b is not None:
                    self._remove_batch(key)
                b = self._batches[key] = _Batch(key, new_ids, new_scales)
                b.rows = np.array([m[1] for m in rows], dtype=np.int64)
                self._add_batch(b, specs[key[0]], snap)
            else:
                b.rows = np.array([m[1] for m in rows], dtype=np.int64)
        self._built_ids = ids.copy()
        self._built_edit_seq = edit_seq
        if self._gizmo_body is not None and self._gizmo_body not in bodies:
            self._detach_gizmo()
        if self._status is not None:
            self._status.content = self._status_text()

    def _add_batch(self, b: _Batch, spec: dict, snap) -> None:
        geo = b.key[0]
        mesh = self._meshes.get(geo)
        if mesh is None:
            try:
                mesh = _mesh(spec)
            except Exception as e:  # drawn as a sphere of its size rather than not at all
                self._report("Cannot draw a shape", f"{spec.get('type')}: {type(e).__name__}: {e}", None)
                sphere = _mesh({"type": "sphere"})
                mesh = (sphere[0] * max(_bounding_radius(spec), 0.1), sphere[1], False)
            self._meshes[geo] = mesh
        vertices, faces, flat = mesh
        self._batch_names += 1
        b.handle = self._server.scene.add_batched_meshes_simple(
            f"/bodies/{b.key[1]}_{self._batch_names}", vertices, faces,
            batched_wxyzs=_xyzw_to_wxyz(snap.orientations[b.rows]).astype(np.float32),
            batched_positions=snap.positions[b.rows].astype(np.float32),
            batched_scales=b.scales, batched_colors=COLOURS[b.key[1]],
            # LOD off: these meshes are small, and instance indices of clicks must be ours.
            lod="off", flat_shading=flat,
            side=_side(spec))
        handle = b.handle

        @handle.on_click
        def _(event) -> None:
            self._clicked(handle, event)

    def _remove_batch(self, key: tuple[str, str]) -> None:
        b = self._batches.pop(key)
        try:
            b.handle.remove()
        except Exception:  # already gone with the server
            pass

    def _push(self, snap) -> None:
        """Sends the poses of `snap` to the browsers (one atomic update)."""
        if snap is None:
            return
        with self._lock:
            self._sync_batches(snap)
            with self._server.atomic():
                for b in self._batches.values():
                    b.handle.batched_positions = snap.positions[b.rows].astype(np.float32)
                    b.handle.batched_wxyzs = _xyzw_to_wxyz(snap.orientations[b.rows]).astype(np.float32)
                self._follow_gizmo(snap)
        with self._drawn_cond:
            self._drawn_seq = snap.seq
            self._drawn_cond.notify_all()

    def _run_pusher(self) -> None:
        period = 1.0 / self.max_fps
        seq = self._drawn_seq
        next_t = time.monotonic()
        retry_at = 0.0
        lost = False
        failures = 0     # failed reconnects since the loss: only the first is reported
        while not self._stop.is_set():
            client = self._client
            if lost or client.closed:
                # Lost connection: try again every 2 s (a restarted server restores the
                # scene; the viewer then starts from a fresh description and key frame).
                # `lost` stays set until a reconnect succeeds (a failed one leaves the
                # client looking open, without snapshots).
                lost = True
                if time.monotonic() >= retry_at:
                    retry_at = time.monotonic() + 2.0
                    try:
                        client.reconnect()
                        with self._lock:
                            self._built_edit_seq, self._built_ids = -1, None
                            self._key_cache.clear()
                        seq, lost, failures = -1, False, 0
                        self._report("Reconnected", f"to {self.url}", None, level=logging.INFO)
                    except Exception as e:
                        failures += 1
                        if failures == 1:
                            self._report("Connection lost", f"{self.url}: {e}; retrying every 2 s", None)
                        else:
                            log.debug("viewer: reconnecting to %s failed: %s", self.url, e)
                self._stop.wait(0.25)
                continue
            try:
                snap = client.wait_snapshot(after=seq, timeout=0.25)
            except TimeoutError:
                continue
            except ConnectionError:
                lost = True
                continue
            try:
                self._push(snap)
            except Exception as e:  # a browser-side problem must not end the view
                log.exception("viewer: pushing a frame failed")
                self.errors.append(f"push: {e}")
            seq = snap.seq
            # At most max_fps frames a second: snapshots arriving meanwhile are skipped
            # (the client keeps only the newest), so a slow page never lags behind.
            next_t = max(next_t + period, time.monotonic() - period)
            delay = next_t - time.monotonic()
            if delay > 0:
                self._stop.wait(delay)

    # ---- dragging: the gizmo ----

    def _clicked(self, handle, event) -> None:
        with self._lock:
            b = next((b for b in self._batches.values() if b.handle is handle), None)
            i = event.instance_index
            if b is None or i is None or not 0 <= i < len(b.ids):
                return  # a click on a batch replaced meanwhile
            rid = int(b.ids[i])
            if b.key[1] == "static":
                self._notify(event.client, "Static body", f"body {rid} is static: it cannot be dragged")
                return
            if self._gizmo_dragging:
                return
            if self._gizmo_body == rid:
                self._detach_gizmo()   # a second click on the body takes the gizmo away
                return
            self._attach_gizmo(rid)

    def _attach_gizmo(self, rid: int) -> None:
        self._detach_gizmo()
        snap = self._client.snapshot
        try:
            row = self._client.index(rid)
        except KeyError:
            return
        d = self._client.bodies.get(rid, {})
        size = max(1.0, 2.0 * _bounding_radius(d.get("shape", {})))
        gizmo = self._server.scene.add_transform_controls(
            "/drag_gizmo", scale=size, depth_test=False,
            position=tuple(snap.positions[row]), wxyz=tuple(_xyzw_to_wxyz(snap.orientations[row])))
        self._gizmo, self._gizmo_body = gizmo, rid

        # async: viser awaits these on its event loop, in order (start, updates, end);
        # the work (server round trips) is queued for the drag thread, never done here.
        @gizmo.on_update
        async def _(event) -> None:
            self._gizmo_event(gizmo, rid, event.phase, event.client)

    def _gizmo_event(self, gizmo, rid: int, phase: str, who) -> None:
        """A gizmo's drag phase (start, update, end) at its current pose: queued for the
        drag thread. Runs on viser's event loop, so it takes no lock (that would stall
        the loop while a frame is pushed) and does no I/O; its writes are atomic."""
        if self._gizmo is not gizmo:
            return
        if phase == "start":
            self._gizmo_dragging = True
        elif phase == "end":
            self._gizmo_dragging = False
        pos = np.asarray(gizmo.position, dtype=float)
        q = _wxyz_to_xyzw(gizmo.wxyz)
        # The time of the event, not of its handling: the throw velocity is the gizmo's.
        self._drags.put((phase, rid, pos, q, who, time.monotonic()))

    def _detach_gizmo(self) -> None:
        if self._gizmo is not None:
            try:
                self._gizmo.remove()
            except Exception:
                pass
        self._gizmo, self._gizmo_body, self._gizmo_dragging = None, None, False

    def _follow_gizmo(self, snap) -> None:
        """Keeps an idle gizmo on its body as the body moves (falls, is pushed)."""
        if self._gizmo is None or self._gizmo_dragging:
            return
        i = int(np.searchsorted(snap.ids, self._gizmo_body))
        if i >= len(snap.ids) or snap.ids[i] != self._gizmo_body:
            return
        p, q = snap.positions[i], _xyzw_to_wxyz(snap.orientations[i])
        if np.abs(np.asarray(self._gizmo.position) - p).max() > 1e-3:
            self._gizmo.position = tuple(p)
        if np.abs(np.asarray(self._gizmo.wxyz) - q).max() > 1e-3:
            self._gizmo.wxyz = tuple(q)

    def _run_dragger(self) -> None:
        """Carries the gizmo's events to the server, in order. Consecutive moves of one
        body are merged (only the newest is sent), so a slow server is not flooded."""
        refused: set[int] = set()   # bodies whose grab failed: their gesture is ignored
        while True:
            items = [self._drags.get()]
            while True:
                try:
                    items.append(self._drags.get_nowait())
                except queue.Empty:
                    break
            for k, item in enumerate(items):
                if item is None:
                    return
                phase, rid, pos, q, who, t = item
                nxt = items[k + 1] if k + 1 < len(items) else None
                if phase == "update" and nxt is not None and nxt[0] == "update" and nxt[1] == rid:
                    self._samples.append((t, pos))
                    continue
                try:
                    if phase == "start":
                        refused.discard(rid)
                        self._samples.clear()
                        try:
                            self.begin_drag(rid)
                        except Exception:
                            refused.add(rid)
                            raise
                        self._samples.append((t, pos))
                        self.drag_to(rid, pos, q, _who=who)
                    elif rid in refused:
                        continue
                    elif phase == "update":
                        self._samples.append((t, pos))
                        self.drag_to(rid, pos, q, _who=who)
                    elif phase == "end":
                        self.drag_to(rid, pos, q, _who=who)
                        self._samples.append((t, pos))
                        self.end_drag(rid, self._throw_velocity(t))
                except (RemoteError, ConnectionError, TimeoutError) as e:
                    self._report(f"Cannot drag body {rid}", str(e), who)
                except Exception as e:  # a bug: report, keep the viewer running
                    log.exception("viewer: drag %s of body %s failed", phase, rid)
                    self._report(f"Cannot drag body {rid}", f"{type(e).__name__}: {e}", who)

    def _throw_velocity(self, now: float) -> list[float] | None:
        """The gizmo's mean velocity (m/s) over the _THROW_WINDOW s before `now` (the
        release), or None if it stood still that long before the release."""
        recent = [(t, p) for t, p in self._samples if now - t <= _THROW_WINDOW]
        if len(recent) < 2 or recent[-1][0] - recent[0][0] < 1e-3:
            return None
        v = (recent[-1][1] - recent[0][1]) / (recent[-1][0] - recent[0][0])
        speed = float(np.linalg.norm(v))
        if speed > _THROW_MAX:
            v = v * (_THROW_MAX / speed)
        return v.tolist()

    # ---- dragging: the operations ----

    def begin_drag(self, body_id: int) -> None:
        """Grabs body `body_id` for this viewer (the server turns it kinematic, and only
        this viewer may move it until :meth:`end_drag`). Blocks until the server applied
        it; raises RemoteError if it refuses (``not_owner``: someone else drags it;
        ``bad_args``: a static body; ``unknown_body``). The body is also stopped: a
        kinematic body keeps moving at its velocity, and a grabbed body keeps the one
        it had (falling, say), so it would drift away from where the drag puts it."""
        client = self.client
        client.grab(int(body_id))
        client.set_velocity(int(body_id), linear=(0.0, 0.0, 0.0), angular=(0.0, 0.0, 0.0))

    def drag_to(self, body_id: int, position, orientation, *, _who=None) -> None:
        """Sets a grabbed body's pose: position (3,) m, world frame; orientation (4,)
        unit quaternion x, y, z, w (body to world), or None to keep it. Does not wait
        for the server: a refusal is reported (notification, log, :attr:`errors`)."""
        if orientation is not None:
            # Renormalised: a gizmo's quaternion comes from the browser in float32, and
            # the server wants unit quaternions within 1e-6.
            orientation = np.asarray(orientation, dtype=float)
            orientation = orientation / np.linalg.norm(orientation)
        fut = self.client.set_pose(int(body_id), position=position, orientation=orientation, wait=False)

        def done(f) -> None:
            e = f.exception()
            if e is not None:
                self._report(f"Cannot move body {body_id}", str(e), _who)

        fut.add_done_callback(done)

    def end_drag(self, body_id: int, velocity=None) -> None:
        """Releases a grabbed body: it gets back its kind (dynamic bodies fall again),
        with linear velocity `velocity` (3,) m/s if given (a throw). Blocks until the
        server applied it; raises RemoteError (``not_owner``) if this viewer does not
        hold it."""
        self.client.release(int(body_id), linear_velocity=velocity)

    # ---- reporting ----

    def _notify(self, who, title: str, body: str, color: str = "red") -> None:
        try:
            targets = [who] if who is not None else list(self._server.get_clients().values())
            for c in targets:
                c.add_notification(title, body, auto_close_seconds=4.0, color=color)
        except Exception:  # the page went away meanwhile
            pass

    def _report(self, title: str, body: str, who, level: int = logging.WARNING) -> None:
        """A problem the user should see: logged, kept in :attr:`errors`, and shown as a
        notification in the page (the browser that caused it, or all of them)."""
        log.log(level, "viewer: %s: %s", title, body)
        if level >= logging.WARNING:
            self.errors.append(f"{title}: {body}")
        if self._server is not None and not self._stopped:
            self._notify(who, title, body, "red" if level >= logging.WARNING else "green")


def main(argv: list[str] | None = None) -> int:
    """``python -m wmo.remote.viewer ws://127.0.0.1:8765 --scene lab --port 8080
    [--token T]``: serves the page until Ctrl-C; prints its address."""
    p = argparse.ArgumentParser(prog="python -m wmo.remote.viewer",
                                description="Shows a scene of a WMO server in the browser; drag bodies with the mouse.")
    p.add_argument("url", help="the server, ws://host:port")
    p.add_argument("--scene", default="default", help="the scene's name (default: default)")
    p.add_argument("--token", default=None, help="the server's token, if it needs one")
    p.add_argument("--host", default="127.0.0.1", help="address the page is served on (default 127.0.0.1)")
    p.add_argument("--port", type=int, default=8080, help="port of the page (default 8080; 0: any free one)")
    p.add_argument("--max-fps", type=float, default=30.0, help="pose updates per second, at most (default 30)")
    args = p.parse_args(argv)
    logging.basicConfig(level=logging.WARNING, format="%(message)s")
    log.setLevel(logging.INFO)  # the viewer's own news (reconnected), not the libraries' chatter
    try:
        viewer = Viewer(args.url, args.scene, token=args.token, host=args.host, port=args.port,
                        max_fps=args.max_fps).start()
    except (RemoteError, OSError, TimeoutError, ImportError) as e:
        print(f"wmo viewer: {e}", file=sys.stderr)
        return 1
    print(f"wmo viewer: scene {args.scene!r} of {args.url} at {viewer.address} (Ctrl-C stops)", flush=True)
    # SIGTERM (kill, service managers) stops it as cleanly as Ctrl-C does.
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(0))
    try:
        while True:
            time.sleep(3600)
    except KeyboardInterrupt:
        pass
    finally:
        viewer.stop()
    return 0


if __name__ == "__main__":
    sys.exit(main())
