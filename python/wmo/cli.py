"""The ``wmo`` command line.

    wmo bench SCENE [--steps 600] [--engines wmo,pybullet,mujoco] [--out DIR]
                    [--iterations 10] [--substeps 4] [--dt 1/60] [--repeats 1] [--sleeping]

    wmo serve [--host 127.0.0.1] [--port 8765] [--token T | --token-file F] [--data DIR]
              [--rate 60] [--scene NAME=BASE ...] [--no-persist]

    wmo experiment latency [--delays 0,20,40,100] [--seconds 10] [--presets lossy,mobile]
                           [--weak] [--mode compressed|full] [--clients 1] [--out DIR]

    wmo run SCENE_FILE [--steps 600 | --seconds S] [--out OUT] [--dt 1/60] [--substeps N]
                       [--iterations N] [--threads N]

``run`` simulates a scene file (USD with UsdPhysics, or OBJ: see ``wmo.io.load``) and
writes the result: to a .usda/.usdc/.usd ``--out`` (default ``SCENE_run.usda`` in the
current folder) the scene as it started plus every step's body poses as time samples
(it plays back in usdview or Omniverse), or to a .obj ``--out`` the final geometry. It
prints what it read (bodies, warnings), what it ran and how fast, and where it wrote.

``serve`` runs a WMO server (PROTOCOL.md) until Ctrl-C: each scene simulates at
``--rate`` steps per second on its own thread and clients connect with
``wmo.remote.connect("ws://HOST:PORT", scene=NAME)``. Scenes and their edits are journaled
in ``--data`` (default ``wmo-server-data``) and restored from there on the next start.

``bench`` steps a canonical scene (boxes3000 or pyramid, shared/SCENES.md) in WMO and in
its peers in the same run (in turns of 10 steps each, so that the machine's drift hits
all alike; ``--sequential`` runs them one after the other), prints a summary with the
ratios, and writes
``DIR/SCENE_steps.csv`` (one row per engine and step: time, contact points, awake
bodies, deepest penetration) and PNG plots of steps per second and contact points over
simulated time.
"""
from __future__ import annotations

import argparse
import sys
from fractions import Fraction
from pathlib import Path


def _dt(text: str) -> float:
    try:
        v = float(Fraction(text))
    except (ValueError, ZeroDivisionError):
        raise argparse.ArgumentTypeError(f"dt must be a number such as 0.0166 or 1/60, got {text!r}")
    if not v > 0:
        raise argparse.ArgumentTypeError(f"dt must be > 0, got {text!r}")
    return v


def main(argv: list[str] | None = None) -> int:
    from . import bench

    ap = argparse.ArgumentParser(prog="wmo", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="command", required=True)
    b = sub.add_parser("bench", help="step a canonical scene in WMO and its peers")
    b.add_argument("scene", choices=sorted(bench._scenes.SPECS))
    b.add_argument("--steps", type=int, default=600)
    b.add_argument("--engines", default=",".join(bench.ENGINES),
                   help="comma-separated, from " + ", ".join(bench.ENGINES))
    b.add_argument("--out", type=Path, default=Path("results/bench"))
    b.add_argument("--iterations", type=int, default=10, help="peer solver iterations (default 10)")
    b.add_argument("--substeps", type=int, default=4, help="WMO soft-step substeps (default 4)")
    b.add_argument("--dt", type=_dt, default=1 / 60)
    b.add_argument("--repeats", type=int, default=1, help="runs per engine; the median run is kept")
    b.add_argument("--sequential", action="store_true",
                   help="run each engine's steps in one go instead of in interleaved turns of 10 steps")
    b.add_argument("--sleeping", action="store_true",
                   help="sleeping on (default off: the throughput figure of SCENES.md)")
    b.add_argument("--threads", type=int, default=1,
                   help="threads for WMO (default 1; the peers run single-threaded)")
    b.add_argument("--contact-hertz", type=float, default=None,
                   help="WMO's contact spring in Hz (default: the World's, 36, at which the pyramid "
                        "stands to the centimetre)")
    b.add_argument("--block-solver", action="store_true",
                   help="WMO solves each contact pair's normal rows together (World(block_solver=True))")
    b.add_argument("--centroid-rows", action="store_true",
                   help="WMO gives each contact pair a centroid row before its point rows "
                        "(World(centroid_rows=True))")
    b.add_argument("--memory", action="store_true",
                   help="also measure each engine's peak memory, in a fresh process each (Linux)")
    sv = sub.add_parser("serve", help="run a server that simulates scenes for remote clients")
    sv.add_argument("--host", default="127.0.0.1", help="address to listen on (default loopback)")
    sv.add_argument("--port", type=int, default=8765)
    sv.add_argument("--token", default=None, help="clients must present this token (default: none on "
                    "loopback, a random one printed at start on any other address)")
    sv.add_argument("--token-file", type=Path, default=None, help="read the token from this file")
    sv.add_argument("--data", type=Path, default=Path("wmo-server-data"),
                    help="folder where scenes are journaled and restored from (default wmo-server-data)")
    sv.add_argument("--no-persist", action="store_true", help="keep scenes in memory only")
    sv.add_argument("--rate", type=float, default=60.0, help="simulation steps per second per scene")
    sv.add_argument("--scene", action="append", default=[], metavar="NAME=BASE",
                    help="host scene NAME, started as BASE (empty, boxes3000, pyramid, tower, or a "
                         ".usda/.usdc/.usd/.obj scene file); repeatable; default: default=empty")
    sv.add_argument("--checkpoint-interval", type=float, default=30.0, help="seconds between checkpoints")
    sv.add_argument("--position-resolution", type=float, default=1 / 512, metavar="M",
                    help="compressed snapshots: position step in m (default 1/512)")
    sv.add_argument("--orientation-bits", type=int, default=9, metavar="B",
                    help="compressed snapshots: bits per smallest-three quaternion component, 6..16 (default 9)")
    r = sub.add_parser("run", help="simulate a USD or OBJ scene file and write the result")
    r.add_argument("scene_file", type=Path)
    when = r.add_mutually_exclusive_group()
    when.add_argument("--steps", type=int, default=None, help="steps to simulate (default 600)")
    when.add_argument("--seconds", type=float, default=None, help="simulated seconds (rounded up to whole steps)")
    r.add_argument("--out", type=Path, default=None,
                   help="result file: .usda/.usdc/.usd (a run as time samples) or .obj (final geometry); "
                        "default SCENE_run.usda")
    r.add_argument("--dt", type=_dt, default=None, help="time step (default: the file's, else 1/60)")
    r.add_argument("--substeps", type=int, default=None)
    r.add_argument("--iterations", type=int, default=None)
    r.add_argument("--threads", type=int, default=None)
    ex = sub.add_parser("experiment", help="the thesis's experiments on a local server (see wmo.remote.experiment)",
                        add_help=False)
    ex.add_argument("which", choices=["latency"])
    ex.add_argument("rest", nargs=argparse.REMAINDER)
    args = ap.parse_args(argv)

    if args.command == "experiment":
        from .remote import experiment

        return experiment.main(args.rest)
    if args.command == "serve":
        return _serve(args)
    if args.command == "run":
        return _run(args)

    if args.command == "bench":
        engines = [e for e in args.engines.split(",") if e]
        if args.threads < 1:
            print(f"wmo bench: threads must be >= 1, got {args.threads}", file=sys.stderr)
            return 2
        if args.contact_hertz is not None and not args.contact_hertz >= 0:
            print(f"wmo bench: contact-hertz must be >= 0, got {args.contact_hertz}", file=sys.stderr)
            return 2
        bench.WMO_THREADS = args.threads
        bench.WMO_CONTACT_HERTZ = args.contact_hertz
        bench.WMO_BLOCK_SOLVER = args.block_solver
        bench.WMO_CENTROID_ROWS = args.centroid_rows
        try:
            result = bench.run_bench(args.scene, steps=args.steps, engines=engines, dt=args.dt,
                                     iterations=args.iterations, substeps=args.substeps,
                                     repeats=args.repeats, sleeping=args.sleeping,
                                     interleave=not args.sequential)
        except ValueError as e:
            print(f"wmo bench: {e}", file=sys.stderr)
            return 2
        print(result.summary())
        csv_path = args.out / f"{args.scene}_steps.csv"
        bench.write_csv(result, csv_path, args.dt)
        written = [csv_path, *bench.plot(result, args.dt, args.out)]
        if args.memory:
            mem, mem_skipped = bench.measure_memory(args.scene, steps=args.steps, engines=engines, dt=args.dt,
                                                    iterations=args.iterations, substeps=args.substeps,
                                                    sleeping=args.sleeping)
            print(bench.memory_summary(args.scene, mem, mem_skipped))
            mem_path = args.out / f"{args.scene}_memory.csv"
            bench.write_memory_csv(args.scene, mem, mem_path)
            written.append(mem_path)
        for p in written:
            print(f"wrote {p}")
        return 0
    return 2


def _serve(args) -> int:
    import logging

    from .remote.server import Server

    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s %(levelname)s %(message)s")
    scenes = {}
    for item in args.scene:
        name, sep, base = item.partition("=")
        if not sep:
            print(f"wmo serve: --scene wants NAME=BASE, got {item!r}", file=sys.stderr)
            return 2
        scenes[name] = base
    token = args.token
    if args.token_file is not None:
        try:
            token = args.token_file.read_text().strip()
        except OSError as e:
            print(f"wmo serve: cannot read --token-file {args.token_file}: {e}", file=sys.stderr)
            return 2
    try:
        server = Server(args.host, args.port, token=token, data_dir=None if args.no_persist else args.data,
                        scenes=scenes or None, rate=args.rate, checkpoint_interval=args.checkpoint_interval,
                        position_resolution=args.position_resolution, orientation_bits=args.orientation_bits)
    except ValueError as e:
        print(f"wmo serve: {e}", file=sys.stderr)
        return 2
    print(f"wmo serve: scenes {', '.join(scenes or ['default'])} at ws://{args.host}:{args.port} "
          f"({'journaled in ' + str(args.data) if not args.no_persist else 'in memory'}); Ctrl-C stops",
          flush=True)
    server.serve_forever()
    return 0


def _run(args) -> int:
    import math
    import time

    from . import io

    def fail(msg: str) -> int:
        print(f"wmo run: {msg}", file=sys.stderr)
        return 2

    options = {k: getattr(args, k) for k in ("dt", "substeps", "iterations", "threads") if getattr(args, k) is not None}
    out = args.out if args.out is not None else Path(f"{args.scene_file.stem}_run.usda")
    if out.suffix.lower() not in (".usda", ".usdc", ".usd", ".obj"):
        return fail(f"--out must end in .usda, .usdc, .usd or .obj, got {str(out)!r}")
    if args.steps is not None and args.steps < 0:
        return fail(f"--steps must be >= 0, got {args.steps}")
    if args.seconds is not None and not (math.isfinite(args.seconds) and args.seconds >= 0):
        return fail(f"--seconds must be a finite number >= 0, got {args.seconds}")
    try:
        result = io.load(args.scene_file, **options)
    except (ValueError, ImportError) as e:  # SceneFormatError, a missing file, a bad setting
        return fail(str(e))
    world = result.world
    for w in result.warnings:
        print(f"warning: {w}")
    steps = args.steps if args.steps is not None else (
        math.ceil(args.seconds / world.dt - 1e-9) if args.seconds is not None else 600)
    print(f"{args.scene_file}: {world.body_count} bodies ({sum(world.body(k).kind == 'dynamic' for k in range(world.body_count))} "
          f"dynamic), dt {world.dt:.6g} s, {steps} steps ({steps * world.dt:.6g} s)")
    t0 = time.perf_counter()
    if out.suffix.lower() == ".obj":
        world.step(steps)
        elapsed = time.perf_counter() - t0
        io.save(world, out)
    else:
        io.save(world, out, steps=steps)  # simulates while it records the time samples
        elapsed = time.perf_counter() - t0
    print(f"ran {steps} steps in {elapsed:.3f} s (recording included); kinetic energy {world.kinetic_energy():.6g} J, "
          f"deepest penetration {world.max_penetration:.3g} m")
    print(f"wrote {out}")
    return 0
