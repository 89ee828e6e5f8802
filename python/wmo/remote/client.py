"""Clients of a WMO server: :func:`connect` (blocking, usable from scripts and notebooks)
and :func:`connect_async` (asyncio). Both mirror the scene: the newest snapshot as NumPy
arrays, and the bodies' definitions and owners kept up to date from the server's edit
broadcasts. Their methods mirror :class:`wmo.World`'s where they can::

    scene = wmo.remote.connect("ws://127.0.0.1:8765", scene="lab")
    h = scene.add_body(wmo.Box((0.5, 0.5, 0.5)), position=(0, 5, 0), mass=1.0)
    scene.set_pose(h, position=(1, 5, 0))
    scene.positions        # (N, 3), the newest snapshot, rows in ascending id order
    scene.index(h)         # h's row

Bodies are named by integer ids (the server's, stable; `World` handles are not sent).
An edit method returns once the server has applied and journaled the edit (its result,
e.g. the new body's id), or raises :class:`RemoteError` with the server's error code;
``wait=False`` returns a future instead, so many edits can be in flight.
"""
from __future__ import annotations

import asyncio
import concurrent.futures
import itertools
import threading
import time
from typing import Any, Iterator

import msgpack
import numpy as np

from .. import _core
from .scene import MAX_BODIES, shape_to_spec
from .snapshot import Snapshot, SnapshotDecoder

__all__ = ["connect", "connect_async", "RemoteScene", "AsyncRemoteScene", "RemoteError"]

PROTOCOL_VERSION = 1
_SNAPSHOT_MAGIC = b"WS"


class RemoteError(Exception):
    """The server refused a request: ``code`` (PROTOCOL.md's error codes) and message."""

    def __init__(self, code: str, message: str):
        super().__init__(f"{code}: {message}")
        self.code, self.message = code, message


def _vec(v: Any, n: int, name: str) -> list[float] | None:
    if v is None:
        return None
    a = np.asarray(v, dtype=float).ravel()
    if a.shape != (n,):
        raise TypeError(f"{name} must have {n} components, got shape {np.shape(v)}")
    return a.tolist()


def _add_body_args(shape: Any, position, orientation, linear_velocity, angular_velocity, fields: dict) -> dict:
    spec = shape if isinstance(shape, dict) else shape_to_spec(shape) if isinstance(shape, _core.Shape) else None
    if spec is None:
        raise TypeError(f"shape must be a wmo shape or a shape spec dict, got {type(shape).__name__}")
    args = {"shape": spec}
    for k, v, n in (("position", position, 3), ("orientation", orientation, 4),
                    ("linear_velocity", linear_velocity, 3), ("angular_velocity", angular_velocity, 3)):
        if v is not None:
            args[k] = _vec(v, n, k)
    for k, v in fields.items():
        if v is not None:
            args[k] = v
    return args


def _settle(ev: tuple, pending: dict, replies: dict) -> None:
    """Resolves the future a received ok / error / reply answers (both clients: the
    futures are concurrent.futures or asyncio ones, which share these methods)."""
    kind = ev[0]
    if kind == "ok":
        fut, conv = pending.pop(ev[1], (None, None))
        if fut is not None and not fut.done():
            fut.set_result(conv(ev[2]) if conv else ev[2])
    elif kind == "error":
        fut = pending.pop(ev[1], (None, None))[0] if ev[1] is not None else None
        fut = fut or replies.pop(ev[1], None)
        if fut is not None and not fut.done():
            fut.set_exception(RemoteError(ev[2], ev[3]))
    elif kind == "reply":
        fut = replies.pop(ev[1], None)
        if fut is not None and not fut.done():
            fut.set_result(ev[2])


def _fail_all(pending: dict, replies: dict, err: BaseException) -> None:
    """Fails every request still waiting (the connection closed)."""
    for fut, _ in list(pending.values()):
        if not fut.done():
            fut.set_exception(err)
    for fut in list(replies.values()):
        if not fut.done():
            fut.set_exception(err)
    pending.clear()
    replies.clear()


class _Mirror:
    """The protocol state both clients share (no I/O): request ids, the snapshot
    decoder, and the scene mirror."""

    def __init__(self):
        # Bounded like the server's scenes, so a forged frame cannot claim more.
        self.decoder = SnapshotDecoder(max_bodies=MAX_BODIES)
        #: Called as on_snapshot(snapshot, frame_size, receipt_time) for every snapshot
        #: decoded, on the thread that receives it (experiments record with it).
        self.on_snapshot = None
        self.ids_ = itertools.count(1)
        self.latest: Snapshot | None = None
        self.bodies: dict[int, dict] = {}
        self.settings: dict = {}
        self.scene_name = ""
        self.base_scene = ""
        self.paused = False
        self.edit_seq = 0
        self.client_id = ""
        self.snapshots_received = 0
        self.bytes_received = 0

    def hello(self, scene: str, token: str | None, mode: str, name: str | None) -> bytes:
        return msgpack.packb({"t": "hello", "v": PROTOCOL_VERSION, "scene": scene, "token": token, "mode": mode,
                              "name": name or ""}, use_bin_type=True)

    def cmd(self, op: str, args: dict) -> tuple[int, bytes]:
        req = next(self.ids_)
        return req, msgpack.packb({"t": "cmd", "id": req, "op": op, "args": args}, use_bin_type=True)

    def request(self, t: str) -> tuple[int, bytes]:
        req = next(self.ids_)
        return req, msgpack.packb({"t": t, "id": req}, use_bin_type=True)

    def describe(self, d: dict) -> None:
        self.bodies = {int(k): v for k, v in d["bodies"].items()}
        self.settings = d["settings"]
        self.base_scene = d["scene"]
        self.paused = d["paused"]
        self.edit_seq = max(self.edit_seq, d["edit_seq"])

    def receive(self, raw: Any) -> tuple:
        """One message from the server, decoded and applied to the mirror: returns
        ("snapshot", snap, ack_bytes), ("ok", req, result), ("error", req, code, message),
        ("edit", msg), ("welcome", msg), ("reply", req, msg) or ("other", msg)."""
        self.bytes_received += len(raw)
        if isinstance(raw, bytes) and raw[:2] == _SNAPSHOT_MAGIC:
            snap = self.decoder.decode(raw)
            if self.on_snapshot is not None:
                self.on_snapshot(snap, len(raw), time.time())
            self.latest = snap
            self.snapshots_received += 1
            return "snapshot", snap, msgpack.packb({"t": "ack", "snap": snap.seq}, use_bin_type=True)
        msg = msgpack.unpackb(raw, raw=False, strict_map_key=False)
        t = msg.get("t")
        if t == "ok":
            return "ok", msg["id"], msg.get("result")
        if t == "error":
            return "error", msg.get("id"), msg.get("code"), msg.get("message")
        if t == "edit":
            ch = msg.get("changes") or {}
            if "describe" in ch:
                self.describe(ch["describe"])
            for k, v in (ch.get("bodies") or {}).items():
                self.bodies[int(k)] = v
            for k in ch.get("removed") or ():
                self.bodies.pop(int(k), None)
            if "paused" in ch:
                self.paused = ch["paused"]
            self.edit_seq = max(self.edit_seq, msg["seq"])
            return "edit", msg
        if t == "welcome":
            self.client_id = msg["client"]
            self.scene_name = msg["scene"]
            self.describe(msg["describe"])
            return "welcome", msg
        if t in ("pong", "stats", "scene"):
            if t == "scene":
                self.describe(msg["describe"])
            return "reply", msg.get("id"), msg
        return "other", msg

    # ---- state views ----

    def _snap(self) -> Snapshot:
        if self.latest is None:
            raise RuntimeError("no snapshot received yet")
        return self.latest

    def index(self, body: int) -> int:
        ids = self._snap().ids
        i = int(np.searchsorted(ids, body))
        if i >= len(ids) or ids[i] != body:
            raise KeyError(f"no body {body} in the newest snapshot")
        return i


class _SceneApi:
    """The edit methods, on top of `_call(op, args, wait)`."""

    def _call(self, op: str, args: dict, wait: bool = True):  # pragma: no cover - overridden
        raise NotImplementedError

    def add_body(self, shape, position=None, orientation=None, kind: str = "dynamic", mass: float | None = None,
                 density: float | None = None, friction: float | None = None, restitution: float | None = None,
                 linear_velocity=None, angular_velocity=None, linear_damping: float | None = None,
                 angular_damping: float | None = None, gravity_scale: float | None = None,
                 ccd: bool | None = None, collision_group: int | None = None, center_of_mass=None,
                 inertia=None, inertia_axes=None, wait: bool = True):
        """Adds a body (World.add_body's arguments); returns its id (int)."""
        args = _add_body_args(shape, position, orientation, linear_velocity, angular_velocity,
                              {"kind": kind, "mass": mass, "density": density, "friction": friction,
                               "restitution": restitution, "linear_damping": linear_damping,
                               "angular_damping": angular_damping, "gravity_scale": gravity_scale, "ccd": ccd,
                               "collision_group": collision_group,
                               "center_of_mass": _vec(center_of_mass, 3, "center_of_mass"),
                               "inertia": None if inertia is None else np.asarray(inertia, dtype=float).tolist(),
                               "inertia_axes": _vec(inertia_axes, 4, "inertia_axes")})
        return self._call("add_body", args, wait, lambda r: r["id"])

    def remove_body(self, body: int, wait: bool = True):
        return self._call("remove_body", {"id": int(body)}, wait)

    def set_pose(self, body: int, position=None, orientation=None, wait: bool = True):
        """Sets a body's position (m) and/or orientation (unit quaternion x, y, z, w)."""
        return self._call("set_pose", {"id": int(body), "position": _vec(position, 3, "position"),
                                       "orientation": _vec(orientation, 4, "orientation")}, wait)

    def set_velocity(self, body: int, linear=None, angular=None, wait: bool = True):
        """Sets linear (m/s) and/or angular (rad/s, world frame) velocity."""
        return self._call("set_velocity", {"id": int(body), "linear": _vec(linear, 3, "linear"),
                                           "angular": _vec(angular, 3, "angular")}, wait)

    def apply_impulse(self, body: int, impulse, point=None, wait: bool = True):
        """An impulse (N s) at a world point (m; the body's origin by default)."""
        return self._call("apply_impulse", {"id": int(body), "impulse": _vec(impulse, 3, "impulse"),
                                            "point": _vec(point, 3, "point")}, wait)

    def grab(self, body: int, wait: bool = True):
        """Takes a body for dragging: it turns kinematic and only this client may edit it
        until release (or until this client disconnects)."""
        return self._call("grab", {"id": int(body)}, wait)

    def release(self, body: int, linear_velocity=None, wait: bool = True):
        return self._call("release", {"id": int(body), "linear_velocity": _vec(linear_velocity, 3, "linear_velocity")},
                          wait)

    def pause(self, wait: bool = True):
        return self._call("pause", {}, wait)

    def resume(self, wait: bool = True):
        return self._call("resume", {}, wait)

    def step(self, n: int = 1, wait: bool = True):
        """Steps a paused scene n times (at most 1000 per call)."""
        return self._call("step", {"n": int(n)}, wait, lambda r: r["step"])

    def reset(self, wait: bool = True):
        """Back to the scene as it was loaded."""
        return self._call("reset", {}, wait)

    def load_scene(self, name: str, wait: bool = True, **settings):
        """Replaces the scene with a named one (empty, boxes3000, pyramid, tower) and
        World settings (dt, substeps, ...)."""
        return self._call("load_scene", {"name": name, "settings": settings}, wait)

    def set_settings(self, wait: bool = True, **settings):
        """Changes World settings: any keyword of ``wmo.World`` (dt, gravity, substeps,
        iterations, sleeping, speculative_motion, ...; the keys of ``World.settings``).
        The scene's bodies are kept; their contact warm starts begin afresh."""
        return self._call("set_settings", settings, wait)


class _StateViews:
    _m: _Mirror

    @property
    def snapshot(self) -> Snapshot | None:
        """The newest snapshot received (None before the first)."""
        return self._m.latest

    @property
    def ids(self) -> np.ndarray:
        """(N,) body ids of the newest snapshot, ascending (its row order)."""
        return self._m._snap().ids

    @property
    def positions(self) -> np.ndarray:
        """(N, 3) positions (m) of the newest snapshot."""
        return self._m._snap().positions

    @property
    def orientations(self) -> np.ndarray:
        """(N, 4) orientations (x, y, z, w) of the newest snapshot."""
        return self._m._snap().orientations

    @property
    def linear_velocities(self) -> np.ndarray | None:
        """(N, 3) m/s; full-precision mode only (None otherwise)."""
        return self._m._snap().linear_velocities

    @property
    def angular_velocities(self) -> np.ndarray | None:
        return self._m._snap().angular_velocities

    def index(self, body: int) -> int:
        """The row of body `body` in the newest snapshot's arrays."""
        return self._m.index(body)

    @property
    def bodies(self) -> dict[int, dict]:
        """Definitions by id (shape spec, kind, mass, friction, ..., owner)."""
        return self._m.bodies

    @property
    def paused(self) -> bool:
        return self._m.paused

    @property
    def edit_seq(self) -> int:
        """Sequence number of the newest edit this client has seen."""
        return self._m.edit_seq

    @property
    def client_id(self) -> str:
        return self._m.client_id

    @property
    def settings(self) -> dict:
        return self._m.settings

    @property
    def bytes_received(self) -> int:
        """Bytes received on this connection (snapshots and messages)."""
        return self._m.bytes_received

    def on_snapshot(self, callback) -> None:
        """Calls callback(snapshot, frame_size, receipt_time) (frame_size: the frame's length in
        bytes) for every snapshot from now on,
        on the receiving thread (None to stop): every one, also those that a newer one
        replaces before `wait_snapshot` sees them."""
        self._m.on_snapshot = callback


class RemoteScene(_SceneApi, _StateViews):
    """A scene on a server, from a blocking client (see :func:`connect`). A background
    thread receives snapshots and replies; methods may be called from any thread."""

    def __init__(self, url: str, scene: str, token: str | None, mode: str, name: str | None, timeout: float):
        from websockets.sync.client import connect as ws_connect

        self.url, self.scene_name, self.timeout = url, scene, timeout
        self._args = (scene, token, mode, name)
        self._m = _Mirror()
        self._cond = threading.Condition()
        self._send_lock = threading.Lock()  # request ids reach the server in order
        self._pending: dict[int, tuple[concurrent.futures.Future, Any]] = {}
        self._replies: dict[int, concurrent.futures.Future] = {}
        self._closed = False
        self._ws_connect = ws_connect
        self._open()

    def _open(self) -> None:
        # Entered as a context manager (websockets >= 17.1 warns about a bare connection).
        self._ws = self._ws_connect(self.url, max_size=None, open_timeout=self.timeout, compression=None).__enter__()
        self._ws.send(self._m.hello(*self._args))
        deadline = time.monotonic() + self.timeout
        while True:
            raw = self._ws.recv(timeout=max(0.0, deadline - time.monotonic()))
            ev = self._m.receive(raw)
            if ev[0] == "error":
                self._ws.close()
                raise RemoteError(ev[2], ev[3])
            if ev[0] == "welcome":
                break
        self._reader = threading.Thread(target=self._read, name="wmo-remote-reader", daemon=True)
        self._reader.start()
        self.wait_snapshot(timeout=self.timeout)

    def _read(self) -> None:
        from websockets.exceptions import ConnectionClosed

        err: BaseException = ConnectionError("connection closed")
        try:
            for raw in self._ws:
                ev = self._m.receive(raw)
                kind = ev[0]
                if kind == "snapshot":
                    try:
                        self._ws.send(ev[2])
                    except ConnectionClosed:
                        break
                else:
                    _settle(ev, self._pending, self._replies)
                with self._cond:
                    self._cond.notify_all()
        except ConnectionClosed as e:
            err = ConnectionError(f"connection closed: {e}")
        except Exception as e:  # a frame the client cannot read: report it to waiters
            err = e
        else:  # closed without an exception: say how, if the close frame told
            code = getattr(self._ws, "close_code", None)
            if code is not None:
                err = ConnectionError(f"connection closed: code {code} ({getattr(self._ws, 'close_reason', '')})")
        finally:
            with self._cond:
                self._closed = True
                _fail_all(self._pending, self._replies, err)
                self._cond.notify_all()

    def _call(self, op: str, args: dict, wait: bool = True, conv=None):
        fut: concurrent.futures.Future = concurrent.futures.Future()
        with self._send_lock:
            if self._closed:
                raise ConnectionError("the connection is closed")
            req, data = self._m.cmd(op, args)
            self._pending[req] = (fut, conv)
            self._ws.send(data)
        return fut.result(self.timeout) if wait else fut

    def _ask(self, t: str) -> dict:
        fut: concurrent.futures.Future = concurrent.futures.Future()
        with self._send_lock:
            if self._closed:
                raise ConnectionError("the connection is closed")
            req, data = self._m.request(t)
            self._replies[req] = fut
            self._ws.send(data)
        return fut.result(self.timeout)

    def ping(self) -> float:
        """Round-trip time to the server's network thread (s)."""
        t0 = time.perf_counter()
        self._ask("ping")
        return time.perf_counter() - t0

    def stats(self) -> dict:
        """The server's figures for this scene: steps_per_second, step_ms, clients, ..."""
        return self._ask("stats")["stats"]

    def describe(self) -> dict:
        """Refreshes the mirror from the server; returns the description."""
        return self._ask("describe")["describe"]

    def wait_snapshot(self, after: int | None = None, timeout: float | None = None) -> Snapshot:
        """Blocks until a snapshot newer than seq `after` (default: the newest one held)
        arrives; returns it."""
        with self._cond:
            after = after if after is not None else (self._m.latest.seq if self._m.latest else 0)
            ok = self._cond.wait_for(lambda: self._closed or (self._m.latest is not None and self._m.latest.seq > after),
                                     timeout if timeout is not None else self.timeout)
            if self._m.latest is None or self._m.latest.seq <= after:
                raise TimeoutError("no new snapshot") if not self._closed or ok else ConnectionError("closed")
            return self._m.latest

    def wait_edit(self, seq: int, timeout: float | None = None) -> None:
        """Blocks until this client has seen the edit broadcast with sequence `seq`."""
        with self._cond:
            if not self._cond.wait_for(lambda: self._closed or self._m.edit_seq >= seq,
                                       timeout if timeout is not None else self.timeout) or self._m.edit_seq < seq:
                raise TimeoutError(f"edit {seq} not seen (newest {self._m.edit_seq})")

    def snapshots(self, timeout: float | None = None) -> Iterator[Snapshot]:
        """Yields each new snapshot as it arrives (skipping any that a newer one replaced
        before it was read); ends when the connection closes."""
        seq = self._m.latest.seq if self._m.latest else 0
        while not self._closed:
            try:
                snap = self.wait_snapshot(seq, timeout)
            except ConnectionError:
                return
            seq = snap.seq
            yield snap

    def reconnect(self) -> None:
        """Connects again (same scene, token and mode) after the connection dropped, and
        starts from a full snapshot and a fresh description."""
        self.close()
        self._m = _Mirror()
        self._closed = False
        self._open()

    @property
    def closed(self) -> bool:
        return self._closed

    def close(self) -> None:
        try:
            self._ws.close()
        finally:
            if getattr(self, "_reader", None) is not None and self._reader is not threading.current_thread():
                self._reader.join(5)

    def __enter__(self) -> "RemoteScene":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __repr__(self) -> str:
        n = len(self._m.latest.ids) if self._m.latest is not None else 0
        return f"<RemoteScene {self.scene_name!r} at {self.url}: {n} bodies, edit {self._m.edit_seq}>"


def connect(url: str, scene: str = "default", token: str | None = None, mode: str = "compressed",
            name: str | None = None, timeout: float = 30.0) -> RemoteScene:
    """Connects to scene `scene` on the server at `url` (ws://host:port); returns once the
    first full snapshot has arrived. mode: "compressed" (quantized, delta-coded: 1 mm,
    smallest-three quaternions) or "full" (float64 poses and velocities). Raises
    RemoteError (auth, version, unknown_scene, ...) if the server refuses."""
    if mode not in ("compressed", "full"):
        raise ValueError(f"mode must be compressed or full, got {mode!r}")
    return RemoteScene(url, scene, token, mode, name, timeout)


class AsyncRemoteScene(_SceneApi, _StateViews):
    """The asyncio form of :class:`RemoteScene`: edit methods return awaitables."""

    def __init__(self, url: str, scene: str, token: str | None, mode: str, name: str | None, timeout: float):
        self.url, self.scene_name, self.timeout = url, scene, timeout
        self._args = (scene, token, mode, name)
        self._m = _Mirror()
        self._pending: dict[int, tuple[asyncio.Future, Any]] = {}
        self._replies: dict[int, asyncio.Future] = {}
        self._new = asyncio.Event()
        self._task: asyncio.Task | None = None
        self._closed = False

    async def _open(self) -> "AsyncRemoteScene":
        from websockets.asyncio.client import connect as ws_connect

        self._ws = await ws_connect(self.url, max_size=None, open_timeout=self.timeout, compression=None)
        await self._ws.send(self._m.hello(*self._args))
        while True:
            ev = self._m.receive(await asyncio.wait_for(self._ws.recv(), self.timeout))
            if ev[0] == "error":
                await self._ws.close()
                raise RemoteError(ev[2], ev[3])
            if ev[0] == "welcome":
                break
        self._task = asyncio.ensure_future(self._read())
        await self.wait_snapshot()
        return self

    async def _read(self) -> None:
        err: BaseException = ConnectionError("connection closed")
        try:
            async for raw in self._ws:
                ev = self._m.receive(raw)
                if ev[0] == "snapshot":
                    await self._ws.send(ev[2])
                else:
                    _settle(ev, self._pending, self._replies)
                self._new.set()
        except Exception as e:
            err = e if not type(e).__name__.startswith("ConnectionClosed") else err
        finally:
            self._closed = True
            _fail_all(self._pending, self._replies, err)
            self._new.set()

    def _call(self, op: str, args: dict, wait: bool = True, conv=None):
        if self._closed:
            raise ConnectionError("the connection is closed")
        fut = asyncio.get_running_loop().create_future()
        req, data = self._m.cmd(op, args)
        self._pending[req] = (fut, conv)

        async def go():
            await self._ws.send(data)
            return await asyncio.wait_for(fut, self.timeout)

        return go()

    async def _ask(self, t: str) -> dict:
        fut = asyncio.get_running_loop().create_future()
        req, data = self._m.request(t)
        self._replies[req] = fut
        await self._ws.send(data)
        return await asyncio.wait_for(fut, self.timeout)

    async def ping(self) -> float:
        t0 = time.perf_counter()
        await self._ask("ping")
        return time.perf_counter() - t0

    async def stats(self) -> dict:
        return (await self._ask("stats"))["stats"]

    async def describe(self) -> dict:
        return (await self._ask("describe"))["describe"]

    async def wait_snapshot(self, after: int | None = None) -> Snapshot:
        after = after if after is not None else (self._m.latest.seq if self._m.latest else 0)
        deadline = time.monotonic() + self.timeout
        while self._m.latest is None or self._m.latest.seq <= after:
            if self._closed:
                raise ConnectionError("the connection is closed")
            self._new.clear()
            await asyncio.wait_for(self._new.wait(), max(0.0, deadline - time.monotonic()))
        return self._m.latest

    async def snapshots(self):
        """Async iterator over new snapshots (``async for snap in scene.snapshots()``)."""
        seq = self._m.latest.seq if self._m.latest else 0
        while not self._closed:
            try:
                snap = await self.wait_snapshot(seq)
            except ConnectionError:
                return
            seq = snap.seq
            yield snap

    async def close(self) -> None:
        await self._ws.close()
        if self._task is not None:
            await self._task

    async def __aenter__(self) -> "AsyncRemoteScene":
        return self

    async def __aexit__(self, *exc) -> None:
        await self.close()


async def connect_async(url: str, scene: str = "default", token: str | None = None, mode: str = "compressed",
                        name: str | None = None, timeout: float = 30.0) -> AsyncRemoteScene:
    """The asyncio form of :func:`connect`: ``scene = await wmo.remote.connect_async(url)``."""
    if mode not in ("compressed", "full"):
        raise ValueError(f"mode must be compressed or full, got {mode!r}")
    return await AsyncRemoteScene(url, scene, token, mode, name, timeout)._open()
