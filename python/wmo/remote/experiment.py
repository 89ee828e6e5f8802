"""The thesis's latency experiment, done properly: `wmo experiment latency`.

A server (its own process, optionally limited to one core: the "weak server") simulates
``boxes3000`` at 60 Hz; a client (this process) watches it through the latency proxy
(another process, :mod:`wmo.remote.proxy`) at each added latency in turn. For every
snapshot received it records the server's capture time and the receipt time (one
machine, one clock: the end-to-end delay), the frame's size; twice a second it asks the
server for its simulation rate. Output: ``latency.csv`` (one row per snapshot),
``latency_summary.csv`` (one row per run) and plots of the simulation rate, the
client's snapshot rate, the delay and the bandwidth over time, one line per latency,
like the thesis's figures 28-34.

The thesis's prototype lost about 25% of its frame rate at 20-40 ms because its
simulation waited on the network; here the simulation runs on its own thread and the
scene's rate must not depend on the latency.
"""
from __future__ import annotations

import csv
import os
import shutil
import socket
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

__all__ = ["Run", "run_latency_experiment", "main"]


@dataclass
class Run:
    """One run: a latency setting and what the client measured."""
    label: str
    delay_ms: float
    jitter_ms: float = 0.0
    loss: float = 0.0
    mode: str = "compressed"
    clients: int = 1
    receipt: list = field(default_factory=list)     # client receipt time, s since the run began
    capture: list = field(default_factory=list)     # server capture time, same clock
    nbytes: list = field(default_factory=list)      # frame bytes
    step: list = field(default_factory=list)
    rate_t: list = field(default_factory=list)      # times of the server's rate readings
    rate: list = field(default_factory=list)        # server steps per second

    def summary(self) -> dict:
        r = np.asarray(self.receipt)
        dur = r[-1] - r[0] if len(r) > 1 else float("nan")
        delay = (np.asarray(self.receipt) - np.asarray(self.capture)) * 1000
        bits = 8 * float(np.sum(self.nbytes[1:])) if len(self.nbytes) > 1 else float("nan")
        rates = np.asarray(self.rate[1:] or [float("nan")])
        return {"label": self.label, "delay_ms": self.delay_ms, "jitter_ms": self.jitter_ms, "loss": self.loss,
                "mode": self.mode, "clients": self.clients,
                "server_steps_per_s": float(np.median(rates)),
                "client_snapshots_per_s": (len(r) - 1) / dur if len(r) > 1 else float("nan"),
                "delay_median_ms": float(np.median(delay)) if len(delay) else float("nan"),
                "delay_p95_ms": float(np.percentile(delay, 95)) if len(delay) else float("nan"),
                "mbit_per_s": bits / dur / 1e6 if len(r) > 1 else float("nan"),
                "bytes_per_snapshot": float(np.mean(self.nbytes)) if self.nbytes else float("nan"),
                "snapshots": len(r)}


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _wait_port(port: int, proc: subprocess.Popen, timeout: float = 60.0) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        try:
            with socket.create_connection(("127.0.0.1", port), timeout=0.5):
                return
        except OSError:
            if proc.poll() is not None:
                raise RuntimeError(f"process exited: {proc.args}")
            time.sleep(0.05)
    raise RuntimeError(f"nothing listens on port {port} after {timeout} s")


def _spawn(args: list[str], weak: bool = False) -> subprocess.Popen:
    cmd = [sys.executable, *args]
    if weak:
        if shutil.which("taskset"):
            cmd = ["taskset", "-c", "0", *cmd]
        else:
            print("note: taskset not found; the weak-server run is not limited to one core", file=sys.stderr)
    return subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)


def _light_watchers(url: str, scene: str, n: int) -> None:
    """n clients in one asyncio loop that receive every snapshot and acknowledge it from
    its header alone (no decoding): the load of n viewers on the server, without this
    machine's cores spent decoding for them. Runs until killed."""
    import asyncio

    import msgpack
    from websockets.asyncio.client import connect as ws_connect

    from .snapshot import frame_info

    async def one() -> None:
        async with ws_connect(url, max_size=None, compression=None) as ws:
            await ws.send(msgpack.packb({"t": "hello", "v": 1, "scene": scene, "mode": "compressed"}))
            async for raw in ws:
                if raw[:2] == b"WS":
                    await ws.send(msgpack.packb({"t": "ack", "snap": frame_info(raw)["seq"]}))

    async def main() -> None:
        await asyncio.gather(*(one() for _ in range(n)))

    asyncio.run(main())


def _measure(url: str, run: Run, seconds: float, scene: str, scene_base: str | None = None) -> None:
    """Records `run` for `seconds` from a client at `url`. With `scene_base`, the scene is
    loaded afresh from it once every client is connected, so the run covers the scene's
    first `seconds` of motion, whatever the run before it left."""
    from .client import connect

    # The other clients watch from another process (see _light_watchers).
    others = _spawn(["-c", f"from wmo.remote.experiment import _light_watchers; "
                           f"_light_watchers({url!r}, {scene!r}, {run.clients - 1})"]) if run.clients > 1 else None
    c = connect(url, scene=scene, mode=run.mode)
    t0 = time.time()

    def record(snap, nbytes: int, receipt: float) -> None:  # on the client's reader thread
        run.receipt.append(receipt - t0)
        run.capture.append(snap.wall_time - t0)
        run.nbytes.append(nbytes)
        run.step.append(snap.step)

    try:
        if others is not None:
            deadline = time.monotonic() + 30
            while c.stats()["clients"] < run.clients and time.monotonic() < deadline:
                time.sleep(0.1)
        if scene_base is not None:
            c.load_scene(scene_base, sleeping=False)  # returns once the server applied it
        t0 = time.time()
        c.on_snapshot(record)
        while time.time() - t0 < seconds:
            st = c.stats()
            run.rate_t.append(time.time() - t0)
            run.rate.append(st["steps_per_second"])
            time.sleep(0.5)
        c.on_snapshot(None)
    finally:
        c.close()
        if others is not None:
            others.terminate()
            others.wait(10)


def run_latency_experiment(out: Path, delays_ms=(0, 20, 40, 100), seconds: float = 10.0, scene_base: str = "boxes3000",
                           presets: tuple[str, ...] = (), weak: bool = False, mode: str = "compressed",
                           clients: int = 1, rate: float = 60.0, warmup: float = 2.0,
                           view_port: int | None = None, precision: tuple[float, int] | None = None) -> list[Run]:
    """Runs the experiment; writes CSVs and plots to `out`; returns the runs. With
    `view_port`, a browser view of the scene (wmo.remote.viewer, its own process) serves
    http://127.0.0.1:view_port while it runs. `precision`: (position resolution m,
    orientation bits) of compressed snapshots; None for the server's defaults."""
    from .proxy import PRESETS

    out.mkdir(parents=True, exist_ok=True)
    runs: list[Run] = []
    settings = [(f"{d:g} ms", {"delay": d / 1000.0}) for d in delays_ms]
    settings += [(p, PRESETS[p]) for p in presets]
    with tempfile.TemporaryDirectory() as tmp:
        sport = _free_port()
        extra = [] if precision is None else ["--position-resolution", repr(float(precision[0])),
                                              "--orientation-bits", str(int(precision[1]))]
        server = _spawn(["-m", "wmo", "serve", "--port", str(sport), "--no-persist", "--rate", str(rate),
                         "--scene", f"exp={scene_base}", *extra], weak=weak)
        viewer = None
        try:
            _wait_port(sport, server)
            from .client import connect

            if view_port is not None:
                viewer = _spawn(["-m", "wmo.remote.viewer", f"ws://127.0.0.1:{sport}", "--scene", "exp",
                                 "--port", str(view_port)])
                _wait_port(view_port, viewer)
                print(f"browser view: http://127.0.0.1:{view_port} (live while the experiment runs)", flush=True)

            for label, preset in settings:
                pport = _free_port()
                pargs = ["-m", "wmo.remote.proxy", "--target", f"127.0.0.1:{sport}", "--listen", f"127.0.0.1:{pport}"]
                for k in ("delay", "jitter"):
                    if preset.get(k):
                        pargs += [f"--{k}", f"{preset[k]}"]
                if preset.get("loss"):
                    pargs += ["--loss", f"{preset['loss']}"]
                if preset.get("bandwidth"):
                    pargs += ["--bandwidth", f"{preset['bandwidth']}"]
                proxy = _spawn(pargs)
                try:
                    _wait_port(pport, proxy)
                    run = Run(label, 1000 * preset.get("delay", 0.0), 1000 * preset.get("jitter", 0.0),
                              preset.get("loss", 0.0), mode, clients)
                    time.sleep(warmup if runs else 0.0)  # the previous run's clients leave
                    # Each run starts from the scene as loaded, so runs see the same motion.
                    _measure(f"ws://127.0.0.1:{pport}", run, seconds, "exp", scene_base)
                    runs.append(run)
                    s = run.summary()
                    print(f"{label:>10}: server {s['server_steps_per_s']:.1f} steps/s, client "
                          f"{s['client_snapshots_per_s']:.1f} snapshots/s, delay median {s['delay_median_ms']:.1f} ms "
                          f"(p95 {s['delay_p95_ms']:.1f}), {s['mbit_per_s']:.3f} Mbit/s, "
                          f"{s['bytes_per_snapshot']:.0f} B/snapshot", flush=True)
                finally:
                    proxy.terminate()
                    proxy.wait(10)
        finally:
            if viewer is not None:
                viewer.terminate()
                viewer.wait(10)
            server.terminate()
            try:
                server.wait(20)
            except subprocess.TimeoutExpired:
                server.kill()
    write_csv(runs, out)
    plot(runs, out)
    return runs


def write_csv(runs: list[Run], out: Path) -> None:
    with open(out / "latency.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["run", "delay_ms", "receipt_s", "capture_s", "end_to_end_ms", "bytes", "step"])
        for r in runs:
            for t, c, b, s in zip(r.receipt, r.capture, r.nbytes, r.step):
                w.writerow([r.label, r.delay_ms, f"{t:.6f}", f"{c:.6f}", f"{1000 * (t - c):.3f}", b, s])
    with open(out / "latency_summary.csv", "w", newline="") as f:
        rows = [r.summary() for r in runs]
        if rows:
            w = csv.DictWriter(f, fieldnames=list(rows[0]))
            w.writeheader()
            w.writerows(rows)


def plot(runs: list[Run], out: Path) -> list[Path]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(2, 2, figsize=(12, 8))
    for r in runs:
        t = np.asarray(r.receipt)
        if len(t) < 3:
            continue
        ax[0, 0].plot(r.rate_t[1:], r.rate[1:], label=r.label)
        # Client snapshot rate over 1 s windows.
        edges = np.arange(0, t[-1] + 1, 1.0)
        counts, _ = np.histogram(t, edges)
        ax[0, 1].step(edges[1:], counts, where="post", label=r.label)
        ax[1, 0].plot(t, 1000 * (t - np.asarray(r.capture)), lw=0.7, label=r.label)
        bits, _ = np.histogram(t, edges, weights=8 * np.asarray(r.nbytes, dtype=float))
        ax[1, 1].step(edges[1:], bits / 1e6, where="post", label=r.label)
    titles = [("server simulation rate", "steps / s"), ("client snapshot rate", "snapshots / s"),
              ("end-to-end delay (capture to receipt)", "ms"), ("bandwidth to the client", "Mbit / s")]
    for a, (title, unit) in zip(ax.ravel(), titles):
        a.set_title(title)
        a.set_xlabel("time (s)")
        a.set_ylabel(unit)
        a.grid(alpha=0.3)
        a.legend(fontsize=8)
    fig.suptitle("boxes3000 on a WMO server, one client behind the latency proxy")
    fig.tight_layout()
    path = out / "latency.png"
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return [path]


def main(argv: list[str] | None = None) -> int:
    import argparse

    ap = argparse.ArgumentParser(prog="wmo experiment latency", description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", type=Path, default=Path("results/latency"))
    ap.add_argument("--delays", default="0,20,40,100", help="added one-way latencies, ms (comma-separated)")
    ap.add_argument("--presets", default="", help="proxy presets too (e.g. lossy,mobile)")
    ap.add_argument("--seconds", type=float, default=10.0, help="seconds per run")
    ap.add_argument("--weak", action="store_true", help="limit the server to one core (taskset)")
    ap.add_argument("--mode", choices=("compressed", "full"), default="compressed")
    ap.add_argument("--clients", type=int, default=1, help="clients watching (all behind the proxy)")
    ap.add_argument("--scene", default="boxes3000", help="empty, boxes3000, pyramid or tower")
    ap.add_argument("--view", type=int, default=None, metavar="PORT",
                    help="also serve a browser view of the scene on this port (viser)")
    ap.add_argument("--position-resolution", type=float, default=None, metavar="M",
                    help="compressed snapshots: position step in m (default: the server's, 1/512)")
    ap.add_argument("--orientation-bits", type=int, default=None, metavar="B",
                    help="compressed snapshots: bits per quaternion component (default: the server's, 9)")
    args = ap.parse_args(argv)
    try:
        delays = [float(x) for x in args.delays.split(",") if x]
    except ValueError:
        print(f"wmo experiment latency: --delays must be numbers in ms, got {args.delays!r}", file=sys.stderr)
        return 2
    if any(d < 0 for d in delays) or args.seconds <= 0 or args.clients < 1:
        print("wmo experiment latency: delays >= 0, seconds > 0 and clients >= 1 please", file=sys.stderr)
        return 2
    presets = tuple(p for p in args.presets.split(",") if p)
    from .proxy import PRESETS

    bad = [p for p in presets if p not in PRESETS]
    if bad:
        print(f"wmo experiment latency: unknown preset {bad[0]!r} (known: {', '.join(PRESETS)})", file=sys.stderr)
        return 2
    precision = None
    if args.position_resolution is not None or args.orientation_bits is not None:
        precision = (1 / 512 if args.position_resolution is None else args.position_resolution,
                     9 if args.orientation_bits is None else args.orientation_bits)
        from .snapshot import SnapshotEncoder
        try:
            SnapshotEncoder(position_resolution=precision[0], orientation_bits=precision[1])
        except ValueError as e:
            print(f"wmo experiment latency: {e}", file=sys.stderr)
            return 2
    run_latency_experiment(args.out, delays, args.seconds, args.scene, presets, args.weak, args.mode, args.clients,
                           view_port=args.view, precision=precision)
    print(f"wrote {args.out / 'latency.csv'}, {args.out / 'latency_summary.csv'}, {args.out / 'latency.png'}")
    return 0
