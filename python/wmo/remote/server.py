"""The WMO server: hosts named scenes, simulates each at its own fixed rate on its own
thread, and serves clients over WebSocket (the protocol is PROTOCOL.md's).

Two kinds of thread, so that the network never slows the simulation:

- one *simulation thread* per scene (:class:`SceneHost`): at every tick it takes the
  edits that arrived, applies them in arrival order (each gets the scene's next edit
  sequence number), journals them and fsyncs (group commit), steps the world once (the
  GIL is released while it steps) and captures a snapshot of the state;
- one *network thread* running asyncio: it reads and checks client messages, queues
  edits for the scene's thread, and sends each client its acknowledgements, the edit
  broadcasts, and the newest snapshot, delta-coded against the last one that client
  acknowledged. A client's snapshots are a single slot that the newest overwrites: a slow
  client skips snapshots, and the server's memory per client stays bounded.

A scene's tick does not wait for any client: with clients 100 ms away the scene steps
at the same rate as with none.
"""
from __future__ import annotations

import asyncio
import hmac
import ipaddress
import logging
import math
import os
import queue
import re
import secrets
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import msgpack
import numpy as np
from websockets.asyncio.server import serve
from websockets.exceptions import ConnectionClosed

from .journal import SceneStore
from .scene import SCENE_BUILDERS, SCENE_FILE_SUFFIXES, EditError, SceneModel, register_file_scene
from .snapshot import Snapshot, SnapshotEncoder

__all__ = ["Server", "SceneHost", "PROTOCOL_VERSION", "ServerLimits"]

log = logging.getLogger("wmo.remote")

#: The protocol version; a client's hello must carry it (PROTOCOL.md).
PROTOCOL_VERSION = 1
_SCENE_NAME = re.compile(r"^[A-Za-z0-9_-]{1,64}$")
_MODES = ("compressed", "full")


@dataclass
class ServerLimits:
    """Per-client limits (PROTOCOL.md, "Limits"). A message over `max_message_bytes` gets
    a ``too_large`` error; one over 4x that closes the connection (1009) before it is
    read whole. Messages beyond `rate` per second (token bucket of `burst`) get
    ``rate_limited``. A client with more than `max_errors` errors in 10 s, or whose
    outgoing queue holds more than `max_queue` messages, is disconnected (1008, 1013)."""
    max_message_bytes: int = 1 << 20
    rate: float = 2000.0
    burst: float = 4000.0
    max_errors: int = 50
    max_queue: int = 20_000
    hello_timeout: float = 10.0
    max_scenes: int = 64
    #: Snapshots (and their bytes) sent to a client beyond its newest acknowledgement;
    #: past either, the server waits for an ack before sending it the next newest. Over
    #: TCP a link slower than the stream otherwise queues seconds of stale snapshots
    #: (measured through a 1 MB/s proxy: 3.5 s of delay, median); 30 snapshots is half
    #: a second at 60 Hz, more than a 200 ms round trip keeps in flight.
    max_unacked_snapshots: int = 30
    max_unacked_bytes: int = 1 << 19


def _is_loopback(host: str) -> bool:
    if host in ("localhost", ""):
        return host == "localhost"
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def _packb(msg: dict) -> bytes:
    return msgpack.packb(msg, use_bin_type=True)


class SceneHost:
    """One scene and its simulation thread. `rate` is the target steps per second."""

    def __init__(self, server: "Server", name: str, model: SceneModel, store: SceneStore | None,
                 rate: float, checkpoint_interval: float):
        self.server, self.name, self.model, self.store = server, name, model, store
        self.rate = rate
        self.checkpoint_interval = checkpoint_interval
        self.inbox: queue.SimpleQueue = queue.SimpleQueue()
        self.clients: dict[str, "ClientConn"] = {}    # the network thread's view
        self.snap_seq = 0
        self.latest: Snapshot | None = None
        # The range coder does the work in compressed mode; zlib level 1 then only packs
        # key frames' ids (boxes3000: level 6 saves 0.01 %). Full mode is zlib alone:
        # level 6 there. One encoding serves every client with the same baseline.
        self.encoders = {m: SnapshotEncoder(mode=m, level=1 if m == "compressed" else 6, position_resolution=server.position_resolution,
                                            orientation_bits=server.orientation_bits) for m in _MODES}
        self._frames: dict[tuple, bytes] = {}   # (mode, baseline) -> frame of `latest`
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name=f"wmo-scene-{name}", daemon=True)
        # Statistics, written by the simulation thread (floats: atomic enough to read).
        self.steps_per_second = 0.0
        self.step_ms = 0.0
        self.ticks = 0
        self._last_checkpoint = time.monotonic()

    # ---- simulation thread ----

    def start(self) -> None:
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        self.inbox.put(None)
        self._thread.join()
        if self.store is not None:
            self.store.checkpoint(self.model.to_document())
            self.store.close()

    def _capture(self) -> Snapshot:
        m = self.model
        w, order = m.world, m.order
        self.snap_seq += 1
        return Snapshot(seq=self.snap_seq, step=m.step_count, time=m.sim_time, wall_time=time.time(), ids=m.ids(),
                        positions=np.asarray(w.positions)[order], orientations=np.asarray(w.orientations)[order],
                        linear_velocities=np.asarray(w.linear_velocities)[order],
                        angular_velocities=np.asarray(w.angular_velocities)[order])

    def _changes(self, op: str, result: Any, args: dict) -> dict:
        """What a client mirror needs to follow an edit (PROTOCOL.md, "edit")."""
        m = self.model
        if op == "add_body":
            return {"bodies": {result["id"]: m.defs[result["id"]]}}
        if op == "remove_body":
            return {"removed": [args["id"]]}
        if op in ("grab", "release"):
            rid = args["id"]
            return {"bodies": {rid: {**m.defs[rid], "owner": m.owner.get(rid)}}}
        if op in ("pause", "resume", "step"):
            return {"paused": m.paused}
        if op in ("reset", "load_scene", "set_settings"):
            return {"describe": m.describe()}
        return {}

    def _apply(self, client: str, op: str, args: dict, records: list) -> tuple[int, Any, dict]:
        result = self.model.apply(op, args, client)
        self.model.edit_seq += 1
        seq = self.model.edit_seq
        records.append({"seq": seq, "op": op, "args": args, "client": client})
        return seq, result, self._changes(op, result, args)

    def _tick(self) -> None:
        events: list[tuple] = []
        records: list[dict] = []
        while True:
            try:
                item = self.inbox.get_nowait()
            except queue.Empty:
                break
            if item is None:
                continue
            kind = item[0]
            if kind == "cmd":
                _, client, req, op, args = item
                try:
                    seq, result, changes = self._apply(client, op, args, records)
                    events.append(("ok", client, req, seq, op, args, result, changes))
                except EditError as e:
                    events.append(("error", client, req, e.code, str(e)))
                except Exception as e:  # a bug, not the client's fault: report, keep serving
                    log.exception("scene %s: edit %s failed", self.name, op)
                    events.append(("error", client, req, "internal", f"{type(e).__name__}: {e}"))
            elif kind == "join":
                events.append(("join", item[1], self.model.describe()))
            elif kind == "leave":
                for rid in self.model.release_all(item[1]):
                    self.model.edit_seq += 1
                    seq = self.model.edit_seq
                    args = {"id": rid}
                    records.append({"seq": seq, "op": "release", "args": args, "client": item[1]})
                    events.append(("ok", item[1], None, seq, "release", args, None, self._changes("release", None, args)))
            elif kind == "describe":
                events.append(("describe", item[1], item[2], self.model.describe()))
        if records and self.store is not None:
            self.store.append(records)  # on disk before anything is acknowledged
        if not self.model.paused:
            t0 = time.perf_counter()
            self.model.step()
            self.step_ms = 1000 * (time.perf_counter() - t0)
        snap = self._capture()
        self.ticks += 1
        self.server._post(self, events, snap)
        if self.store is not None and time.monotonic() - self._last_checkpoint > self.checkpoint_interval:
            self.store.checkpoint(self.model.to_document())
            self._last_checkpoint = time.monotonic()

    def _run(self) -> None:
        period = 1.0 / self.rate
        next_t = time.monotonic()
        window_t, window_steps = next_t, 0
        while not self._stop.is_set():
            try:
                before = self.model.step_count
                self._tick()
                window_steps += self.model.step_count - before
            except Exception:  # never let one bad tick end the scene
                log.exception("scene %s: tick failed", self.name)
            now = time.monotonic()
            if now - window_t >= 1.0:
                self.steps_per_second = window_steps / (now - window_t)
                window_t, window_steps = now, 0
            next_t += period
            if next_t < now - period:  # fell behind (a slow step): do not try to catch up
                next_t = now
            delay = next_t - time.monotonic()
            if delay > 0:
                self._stop.wait(delay)

    # ---- network thread ----

    def frame_for(self, mode: str, baseline: int | None) -> bytes:
        """The newest snapshot for a client in `mode` that holds `baseline`; clients with
        the same mode and baseline share one encoding."""
        key = (mode, baseline)
        frame = self._frames.get(key)
        if frame is None:
            frame = self._frames[key] = self.encoders[mode].encode(self.latest, baseline)
        return frame

    def stats(self) -> dict:
        return {"scene": self.name, "steps_per_second": self.steps_per_second, "step_ms": self.step_ms,
                "rate": self.rate, "step": self.model.step_count, "bodies": len(self.model.bodies),
                "clients": len(self.clients), "snapshot": self.snap_seq, "paused": self.model.paused}


@dataclass
class ClientConn:
    """A connected client, as the network thread sees it."""
    id: str
    ws: Any
    host: SceneHost
    mode: str
    name: str
    out: asyncio.Queue = field(default_factory=asyncio.Queue)
    wake: asyncio.Event = field(default_factory=asyncio.Event)
    acked: int | None = None        # the newest snapshot seq it acknowledged
    sent_seq: int = 0               # the newest snapshot seq sent to it
    unacked: dict = field(default_factory=dict)  # seq -> frame bytes, sent and not yet acknowledged
    unacked_bytes: int = 0
    last_req: int = -1
    joined: bool = False
    tokens: float = 0.0
    token_t: float = 0.0
    errors: list = field(default_factory=list)
    closing: bool = False


class Server:
    """A WMO server. ``scenes`` maps names to the scene each starts as (a name of
    ``SCENE_BUILDERS``: empty, boxes3000, pyramid, tower; or the path of a USD or OBJ
    file, read once at start, see :func:`wmo.remote.scene.register_file_scene`), unless
    ``data_dir`` holds it already, in which case it is restored from there.

    host, port: where to listen (loopback by default; port 0 picks a free one).
    token: clients must present it; None means no token on loopback, and a fresh random
        one (printed, and readable as ``server.token``) on any other address.
    data_dir: where scenes are journaled (one folder per scene); None keeps them in
        memory only (nothing survives a restart).
    rate: simulation steps per second per scene (each scene's dt is its own).
    checkpoint_interval: seconds between checkpoints of each scene.
    create_scenes: a client may open a scene that does not exist (it starts empty).
    position_resolution, orientation_bits: the precision of compressed-mode snapshots
        (m; bits per smallest-three component, 6..16). The defaults, 1/512 m and 9 bits
        (Fiedler's), stream boxes3000 at 1.77 Mbit/s; 1 mm and 12 bits at 2.62.
        Full-mode clients get exact values whatever these are.
    """

    def __init__(self, host: str = "127.0.0.1", port: int = 8765, *, token: str | None = None,
                 data_dir: str | os.PathLike | None = None, scenes: dict[str, str] | None = None,
                 rate: float = 60.0, checkpoint_interval: float = 30.0, create_scenes: bool = True,
                 limits: ServerLimits | None = None, position_resolution: float = 1 / 512,
                 orientation_bits: int = 9):
        if not (isinstance(rate, (int, float)) and math.isfinite(rate) and rate > 0):
            raise ValueError(f"rate must be a positive number of steps per second, got {rate!r}")
        if not (isinstance(port, int) and 0 <= port <= 65535):
            raise ValueError(f"port must be in [0, 65535], got {port!r}")
        if token is None and not _is_loopback(host):
            token = secrets.token_urlsafe(24)
            print(f"wmo serve: listening beyond loopback ({host}); token: {token}", flush=True)
        self.host, self.requested_port, self.token = host, port, token
        self.data_dir = Path(data_dir) if data_dir is not None else None
        self.rate, self.checkpoint_interval = float(rate), float(checkpoint_interval)
        self.create_scenes = create_scenes
        self.limits = limits or ServerLimits()
        # Checked here (ValueError naming the field), used by every scene's encoder.
        SnapshotEncoder(position_resolution=position_resolution, orientation_bits=orientation_bits)
        self.position_resolution, self.orientation_bits = float(position_resolution), int(orientation_bits)
        self.scenes: dict[str, SceneHost] = {}
        self._initial = dict(scenes or {"default": "empty"})
        for name, base in list(self._initial.items()):
            self._check_name(name)
            if Path(base).suffix.lower() in SCENE_FILE_SUFFIXES:  # a scene file: read once, now
                self._initial[name], warnings = register_file_scene(base)
                for w in warnings:
                    log.warning("scene %s: %s", name, w)
            elif base not in SCENE_BUILDERS:
                raise ValueError(f"scene {name!r}: base must be one of {', '.join(SCENE_BUILDERS)}, got {base!r}")
        self._loop: asyncio.AbstractEventLoop | None = None
        self._thread: threading.Thread | None = None
        self._ready = threading.Event()
        self._stopped: asyncio.Event | None = None
        self._client_counter = 0
        self.port: int | None = None
        self._startup_error: BaseException | None = None

    @staticmethod
    def _check_name(name: str) -> None:
        if not isinstance(name, str) or not _SCENE_NAME.match(name):
            raise ValueError(f"scene name must be 1-64 of A-Z a-z 0-9 _ -, got {name!r}")

    @property
    def url(self) -> str:
        host = self.host if ":" not in self.host else f"[{self.host}]"
        return f"ws://{host}:{self.port}"

    # ---- scenes ----

    def _open_scene(self, name: str, base: str = "empty") -> SceneHost:
        store = SceneStore(self.data_dir / name) if self.data_dir is not None else None
        model = None
        if store is not None:
            doc, records = store.load()
            if doc is not None or records:
                model = SceneModel.from_document(doc) if doc is not None else SceneModel(base)
                for rec in records:  # replay, in server order
                    try:
                        model.apply(rec["op"], rec["args"], rec["client"])
                    except EditError as e:  # journaled edits were valid when applied
                        log.error("scene %s: replaying edit %s failed: %s", name, rec["seq"], e)
                    model.edit_seq = rec["seq"]
                # Clients of the previous run are gone: what they dragged is released.
                orphans = []
                for rid in sorted(model.owner):
                    client = model.owner[rid]
                    model.apply("release", {"id": rid}, client)
                    model.edit_seq += 1
                    orphans.append({"seq": model.edit_seq, "op": "release", "args": {"id": rid}, "client": client})
                store.append(orphans)
                log.info("scene %s restored: edit %d, %d bodies", name, model.edit_seq, len(model.bodies))
        if model is None:
            model = SceneModel(base)
        if store is not None:
            store.checkpoint(model.to_document())
        host = SceneHost(self, name, model, store, self.rate, self.checkpoint_interval)
        self.scenes[name] = host
        host.start()
        return host

    def _post(self, host: SceneHost, events: list, snap: Snapshot) -> None:
        loop = self._loop
        if loop is not None and not loop.is_closed():
            try:
                loop.call_soon_threadsafe(self._on_tick, host, events, snap)
            except RuntimeError:  # the loop closed while stopping
                pass

    def _on_tick(self, host: SceneHost, events: list, snap: Snapshot) -> None:
        for ev in events:
            kind = ev[0]
            if kind == "ok":
                _, client, req, seq, op, args, result, changes = ev
                # The broadcast first: when the sender's call returns, its mirror has the edit.
                msg = {"t": "edit", "seq": seq, "client": client, "op": op, "args": args, "result": result,
                       "changes": changes}
                for c in list(host.clients.values()):
                    if c.joined:
                        self._send(c, msg)
                if req is not None and client in host.clients:
                    self._send(host.clients[client], {"t": "ok", "id": req, "seq": seq, "result": result})
            elif kind == "error":
                _, client, req, code, message = ev
                c = host.clients.get(client)
                if c is not None:
                    self._error(c, code, message, req)
            elif kind == "join":
                c = host.clients.get(ev[1])
                if c is not None:
                    c.joined = True
                    self._send(c, {"t": "welcome", "v": PROTOCOL_VERSION, "client": c.id, "scene": host.name,
                                   "mode": c.mode, "describe": ev[2]})
            elif kind == "describe":
                c = host.clients.get(ev[1])
                if c is not None:
                    self._send(c, {"t": "scene", "id": ev[2], "describe": ev[3]})
        host.latest = snap
        host._frames = {}
        for c in host.clients.values():
            if c.joined:
                c.wake.set()

    # ---- clients ----

    def _send(self, c: ClientConn, msg: dict) -> None:
        if c.closing:
            return
        if c.out.qsize() >= self.limits.max_queue:
            c.closing = True
            asyncio.ensure_future(c.ws.close(1013, "client too slow: outgoing queue full"))
            return
        c.out.put_nowait(_packb(msg))
        c.wake.set()

    def _error(self, c: ClientConn, code: str, message: str, req: Any = None) -> None:
        self._send(c, {"t": "error", "id": req, "code": code, "message": message})
        now = time.monotonic()
        c.errors = [t for t in c.errors if now - t < 10.0] + [now]
        if len(c.errors) > self.limits.max_errors and not c.closing:
            c.closing = True
            asyncio.ensure_future(c.ws.close(1008, "too many bad messages"))

    async def _sender(self, c: ClientConn) -> None:
        try:
            while True:
                await c.wake.wait()
                c.wake.clear()
                while not c.out.empty():
                    await c.ws.send(c.out.get_nowait())
                host = c.host
                lim = self.limits
                if (c.joined and host.latest is not None and host.latest.seq > c.sent_seq
                        and len(c.unacked) < lim.max_unacked_snapshots and c.unacked_bytes < lim.max_unacked_bytes):
                    snap = host.latest
                    baseline = c.acked if c.acked is not None and c.acked < snap.seq else None
                    frame = host.frame_for(c.mode, baseline)
                    c.unacked[snap.seq] = len(frame)
                    c.unacked_bytes += len(frame)
                    c.sent_seq = snap.seq
                    await c.ws.send(frame)
        except (ConnectionClosed, asyncio.CancelledError):
            pass
        except Exception:  # a bug; this client is dropped, everyone else goes on
            log.exception("sending to client %s failed", c.id)
            await c.ws.close(1011, "server error")

    async def _hello(self, ws) -> ClientConn | None:
        lim = self.limits
        try:
            raw = await asyncio.wait_for(ws.recv(), lim.hello_timeout)
        except asyncio.TimeoutError:
            await ws.close(1008, "no hello")
            return None

        async def refuse(code: str, message: str) -> None:
            await ws.send(_packb({"t": "error", "id": None, "code": code, "message": message}))
            await ws.close(1008, message[:120])

        if not isinstance(raw, bytes) or len(raw) > lim.max_message_bytes:
            await refuse("bad_message", "the first message must be a binary msgpack hello")
            return None
        try:
            msg = msgpack.unpackb(raw, raw=False, strict_map_key=False)
        except Exception as e:
            await refuse("bad_message", f"hello is not msgpack: {type(e).__name__}")
            return None
        if not isinstance(msg, dict) or msg.get("t") != "hello":
            await refuse("out_of_order", "the first message must be hello")
            return None
        if msg.get("v") != PROTOCOL_VERSION:
            await refuse("version", f"protocol version must be {PROTOCOL_VERSION}, got {msg.get('v')!r}")
            return None
        if self.token is not None:
            given = msg.get("token")
            if not isinstance(given, str) or not hmac.compare_digest(given.encode(), self.token.encode()):
                await refuse("auth", "bad or missing token")
                return None
        scene = msg.get("scene", "default")
        mode = msg.get("mode", "compressed")
        if mode not in _MODES:
            await refuse("bad_args", f"mode must be compressed or full, got {mode!r}")
            return None
        try:
            self._check_name(scene)
        except ValueError as e:
            await refuse("bad_args", str(e))
            return None
        host = self.scenes.get(scene)
        if host is None:
            if not self.create_scenes or len(self.scenes) >= lim.max_scenes:
                await refuse("unknown_scene", f"no scene {scene!r} (and this server creates none)")
                return None
            host = self._open_scene(scene)  # an empty scene: quick
        name = msg.get("name") if isinstance(msg.get("name"), str) else ""
        self._client_counter += 1
        c = ClientConn(id=f"c{self._client_counter}", ws=ws, host=host, mode=mode, name=name[:64])
        c.tokens, c.token_t = lim.burst, time.monotonic()
        host.clients[c.id] = c
        host.inbox.put(("join", c.id))
        return c

    def _rate_ok(self, c: ClientConn) -> bool:
        now = time.monotonic()
        c.tokens = min(self.limits.burst, c.tokens + (now - c.token_t) * self.limits.rate)
        c.token_t = now
        if c.tokens < 1:
            return False
        c.tokens -= 1
        return True

    def _handle(self, c: ClientConn, raw: Any) -> None:
        if not isinstance(raw, bytes):
            self._error(c, "bad_message", "messages are binary msgpack frames, got a text frame")
            return
        # Decoded before the size and rate checks so that their errors can name the
        # request; the frame is at most 4x max_message_bytes (the socket's own cap).
        try:
            msg = msgpack.unpackb(raw, raw=False, strict_map_key=False)
        except Exception as e:
            self._error(c, "bad_message", f"not msgpack: {type(e).__name__}")
            return
        if not isinstance(msg, dict):
            self._error(c, "bad_message", f"a message is a map, got {type(msg).__name__}")
            return
        if len(raw) > self.limits.max_message_bytes:
            self._error(c, "too_large", f"message of {len(raw)} bytes, the cap is {self.limits.max_message_bytes}",
                        msg.get("id"))
            return
        if not self._rate_ok(c):
            self._error(c, "rate_limited", f"more than {self.limits.rate:g} messages per second", msg.get("id"))
            return
        t = msg.get("t")
        req = msg.get("id")
        if t == "cmd":
            if isinstance(req, bool) or not isinstance(req, int):
                self._error(c, "bad_message", f"cmd id must be an integer, got {req!r}")
                return
            if req <= c.last_req:
                self._error(c, "out_of_order", f"cmd id {req} is not above the previous {c.last_req}", req)
                return
            c.last_req = req
            op, args = msg.get("op"), msg.get("args", {})
            if not isinstance(op, str) or not isinstance(args, dict):
                self._error(c, "bad_message", "cmd needs op (a string) and args (a map)", req)
                return
            c.host.inbox.put(("cmd", c.id, req, op, args))
        elif t == "ack":
            snap = msg.get("snap")
            if isinstance(snap, bool) or not isinstance(snap, int) or snap > c.sent_seq or snap < 0:
                self._error(c, "bad_message", f"ack snap must be a snapshot seq this client was sent, got {snap!r}")
                return
            if c.acked is None or snap > c.acked:
                c.acked = snap
                for seq in [k for k in c.unacked if k <= snap]:  # in order: a dict keeps insertion order
                    c.unacked_bytes -= c.unacked.pop(seq)
                c.wake.set()  # the window may have opened
        elif t == "ping":
            self._send(c, {"t": "pong", "id": req, "time": time.time()})
        elif t == "stats":
            self._send(c, {"t": "stats", "id": req, "stats": c.host.stats()})
        elif t == "describe":
            c.host.inbox.put(("describe", c.id, req))
        elif t == "hello":
            self._error(c, "out_of_order", "hello was already received", req)
        else:
            self._error(c, "bad_message", f"unknown message type {t!r}", req)

    async def _connection(self, ws) -> None:
        c = await self._hello(ws)
        if c is None:
            return
        sender = asyncio.ensure_future(self._sender(c))
        try:
            async for raw in ws:
                self._handle(c, raw)
        except ConnectionClosed:
            pass
        finally:
            sender.cancel()
            c.host.clients.pop(c.id, None)
            c.host.inbox.put(("leave", c.id))

    # ---- running ----

    async def _main(self) -> None:
        self._loop = asyncio.get_running_loop()
        self._stopped = asyncio.Event()
        try:
            if self.data_dir is not None:
                self.data_dir.mkdir(parents=True, exist_ok=True)
                for d in sorted(self.data_dir.iterdir()):
                    if d.is_dir() and _SCENE_NAME.match(d.name) and d.name not in self.scenes:
                        self._open_scene(d.name, self._initial.get(d.name, "empty"))
            for name, base in self._initial.items():
                if name not in self.scenes:
                    self._open_scene(name, base)
            lim = self.limits
            async with serve(self._connection, self.host, self.requested_port, max_size=4 * lim.max_message_bytes,
                             max_queue=64, ping_interval=20, ping_timeout=60) as srv:
                self.port = srv.sockets[0].getsockname()[1]
                self._ready.set()
                await self._stopped.wait()
        except BaseException as e:
            self._startup_error = e
            self._ready.set()
            raise
        finally:
            for host in list(self.scenes.values()):
                host.stop()

    def start(self) -> "Server":
        """Runs the server on a background thread; returns once it listens."""
        self._thread = threading.Thread(target=lambda: asyncio.run(self._main()), name="wmo-server", daemon=True)
        self._thread.start()
        self._ready.wait()
        if self._startup_error is not None:
            raise self._startup_error
        return self

    def stop(self) -> None:
        """Stops serving, stops the scenes and checkpoints them. Idempotent."""
        if self._loop is not None and self._stopped is not None and not self._loop.is_closed():
            try:
                self._loop.call_soon_threadsafe(self._stopped.set)
            except RuntimeError:
                pass
        if self._thread is not None:
            self._thread.join()
            self._thread = None

    def serve_forever(self) -> None:
        """Runs in this thread until interrupted (Ctrl-C or SIGTERM)."""
        import signal

        async def main():
            loop = asyncio.get_running_loop()
            task = asyncio.ensure_future(self._main())
            for sig in (signal.SIGINT, signal.SIGTERM):
                try:
                    loop.add_signal_handler(sig, lambda: self._stopped and self._stopped.set())
                except (NotImplementedError, RuntimeError):
                    pass
            await task

        asyncio.run(main())

    def __enter__(self) -> "Server":
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()
