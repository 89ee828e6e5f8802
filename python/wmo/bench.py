"""Scene benchmarks: a canonical scene stepped in WMO and in its peers (PyBullet, MuJoCo)
in the same run, with the same dt, solver iterations and sleeping, per SCENES.md.

Each engine is timed per step (wall clock around the engine's own step call only);
contact points, awake bodies and the deepest penetration are read after the step,
outside the timing. The engines' scenes are built first and then stepped in turns of
``BLOCK`` steps each (WMO's 10 steps, PyBullet's 10, MuJoCo's 10, WMO's next 10...),
so that a change of the machine's speed during the run (a shared VM drifts by 1.5x
within minutes) hits every engine alike instead of whichever ran in the slow minutes;
with ``interleave=False`` each engine runs all its steps in turn. Results: one CSV row
per engine and step, PNG plots of steps per second and contact points over simulated
time (the thesis's FPS figures), and a summary with median step times and the ratios
to WMO.

Settings that cannot be made identical are stated in the summary: WMO's soft-step
solver runs ``substeps`` substeps of one velocity iteration each plus the World's relax
passes (2 by default; Box2D v3's scheme has 1), where Bullet's sequential impulse solver runs ``iterations``
passes once per step; MuJoCo solves its soft-constraint problem with PGS capped at
``iterations`` iterations. Bullet's friction rule is the product of the two bodies'
coefficients, MuJoCo's the maximum, so MuJoCo's geoms get the pair friction itself.

Peers are optional imports: one that is not installed is reported and skipped.
"""
from __future__ import annotations

import csv
import json
import math
import statistics
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from functools import partial
from itertools import count
from typing import Callable, Iterable, Iterator

import numpy as np

from . import scenes as _scenes

ENGINES = ("wmo", "pybullet", "mujoco")


@dataclass
class StepRecord:
    step: int  #: 1-based
    seconds: float  #: wall time of this step
    contacts: int  #: contact points after the step
    awake: int  #: awake dynamic bodies after the step (-1: the engine does not say)
    max_penetration: float  #: deepest penetration after the step (m, >= 0)


@dataclass
class EngineRun:
    engine: str
    build: str  #: which build of the engine (version string)
    settings: str  #: the settings it ran with, in words
    records: list[StepRecord] = field(default_factory=list)

    def step_times(self) -> list[float]:
        return [r.seconds for r in self.records]

    @property
    def median_ms(self) -> float:
        return 1e3 * statistics.median(self.step_times())


# ---- WMO ------------------------------------------------------------------------------

#: Threads WMO steps with (its narrowphase is parallel; peers run single-threaded).
WMO_THREADS = 1
#: WMO's contact spring (Hz); None keeps the World's default (36), at which the 20-layer
#: pyramid stands to the centimetre (tests/python/test_stability.py).
WMO_CONTACT_HERTZ: float | None = None
#: World(block_solver=...): each contact pair's normal rows solved together (scalar solver).
WMO_BLOCK_SOLVER = False
#: World(centroid_rows=...): each contact pair's centroid row before its point rows.
WMO_CENTROID_ROWS = False


def step_wmo(spec: _scenes.BoxScene, dt: float, iterations: int, substeps: int,
             sleeping: bool) -> Iterator[EngineRun]:
    """Builds the scene in WMO and yields its EngineRun; each further ``next`` steps it
    once and appends the step's record (see STEPPERS)."""
    extra = {} if WMO_CONTACT_HERTZ is None else {"contact_hertz": WMO_CONTACT_HERTZ}
    world = _scenes.build(spec, dt=dt, substeps=substeps, iterations=1, sleeping=sleeping,
                          threads=WMO_THREADS, block_solver=WMO_BLOCK_SOLVER,
                          centroid_rows=WMO_CENTROID_ROWS, **extra)
    hertz = "default contact Hz" if WMO_CONTACT_HERTZ is None else f"{WMO_CONTACT_HERTZ:g} Hz contacts"
    relax = world.settings["relax_iterations"]
    rows = ", block-solved manifolds" if WMO_BLOCK_SOLVER else ""
    rows += ", centroid rows" if WMO_CENTROID_ROWS else ""
    run = EngineRun("wmo", f"wmo {_version()}",
                    f"dt {dt:g}, {substeps} substeps x 1 iteration + {relax} relax{rows}, {hertz}, "
                    f"sleeping {'on' if sleeping else 'off'}, {WMO_THREADS} thread(s)")
    yield run
    for k in count():
        t0 = time.perf_counter()
        world.step()
        t1 = time.perf_counter()
        run.records.append(StepRecord(k + 1, t1 - t0, world.contact_count, world.awake_count,
                                      float(world.max_penetration)))
        yield run


def _version() -> str:
    from . import __version__
    return __version__


# ---- PyBullet --------------------------------------------------------------------------

def pybullet_contact_rows(rows: list[tuple], pair_rows: Callable[[int, int], list[tuple]]) -> list[tuple]:
    """The genuine rows of an unfiltered ``pybullet.getContactPoints()``; `pair_rows(a, b)`
    returns that call filtered to bodies a and b (whose answers are always exact: one
    pair's few points fit one chunk).

    PyBullet's server sends contact points in chunks of at most 47,661 rows (an 8 MiB
    buffer), and every chunk, the last included, is a full chunk: past its N real points
    it copies whatever lies beyond the end of its cache, zeros, garbage, or real-looking
    rows left there by an earlier query or an earlier client in the same process (a CI
    run counted 219 such rows on the pyramid's first step, of 62,400). The real rows are
    the first N, one contiguous group of at most 4 per manifold (one manifold per pair of
    convex bodies), in the server's manifold order. So:

    1. The rows are kept up to the first one that is malformed (a link other than the
       base, a body against itself, a non-finite value), returns to a pair seen in an
       earlier group, repeats a row of its group, or makes a group longer than 4 points.
       N lies within this prefix.
    2. A row of the prefix is real exactly if `pair_rows` returns it, bit for bit (the
       same manifold point computed the same way; compared on the fields the server
       sets, the first ten, up to the normal force): a stale row is of another pair, or of
       the same pair in another state, and one equal to a real row repeats that row's
       pair or row, which ends the prefix. So "returned by pair_rows" holds for the first
       N rows of the prefix and for none after: a binary search finds N with about 16
       filtered calls (each scans the server's manifolds once: ~0.2 ms on the pyramid)."""
    prefix = 0
    seen: set[tuple[int, int]] = set()
    last, group = None, []
    for c in rows:
        if not (c[3] == -1 and c[4] == -1 and c[1] != c[2] and math.isfinite(c[8])
                and all(map(math.isfinite, c[5])) and all(map(math.isfinite, c[6]))):
            break
        key = (c[1], c[2])
        if key == last:
            if len(group) == 4 or c[:10] in group:
                break
            group.append(c[:10])
        else:
            if key in seen:
                break
            seen.add(key)
            last, group = key, [c[:10]]
        prefix += 1

    def real(i: int) -> bool:
        return rows[i][:10] in [r[:10] for r in pair_rows(rows[i][1], rows[i][2])]

    lo, hi = 0, prefix  # rows[:lo] are real; rows[hi:] (within the prefix) are not
    while lo < hi:
        mid = (lo + hi) // 2
        if real(mid):
            lo = mid + 1
        else:
            hi = mid
    return list(rows[:lo])


def step_pybullet(spec: _scenes.BoxScene, dt: float, iterations: int, substeps: int,
                  sleeping: bool) -> Iterator[EngineRun]:
    import pybullet as pb  # optional peer

    cid = pb.connect(pb.DIRECT)
    try:
        pb.setGravity(*spec.gravity, physicsClientId=cid)
        pb.setPhysicsEngineParameter(fixedTimeStep=dt, numSolverIterations=iterations, numSubSteps=0,
                                     deterministicOverlappingPairs=1, physicsClientId=cid)
        ground = pb.createCollisionShape(pb.GEOM_BOX, halfExtents=list(_scenes.GROUND_HALF_EXTENTS),
                                         physicsClientId=cid)
        # Maximal coordinates: btRigidBody, as Bullet's BenchmarkDemo uses (PyBullet's
        # default, btMultiBody, runs the Featherstone solver: 10-20x slower here).
        g = pb.createMultiBody(0, ground, -1, list(_scenes.GROUND_CENTRE), useMaximalCoordinates=1,
                               physicsClientId=cid)
        pb.changeDynamics(g, -1, lateralFriction=spec.friction, restitution=0, physicsClientId=cid)
        shapes: dict[tuple, int] = {}
        ids = []
        for h, p, m in zip(spec.half_extents, spec.positions, spec.masses):
            key = tuple(h)
            if key not in shapes:
                shapes[key] = pb.createCollisionShape(pb.GEOM_BOX, halfExtents=list(key), physicsClientId=cid)
            b = pb.createMultiBody(float(m), shapes[key], -1, list(p), useMaximalCoordinates=1,
                                   physicsClientId=cid)
            pb.changeDynamics(b, -1, lateralFriction=spec.friction, restitution=0, linearDamping=0,
                              angularDamping=0, physicsClientId=cid)
            if not sleeping:
                pb.changeDynamics(b, -1, activationState=pb.ACTIVATION_STATE_DISABLE_SLEEPING,
                                  physicsClientId=cid)
            ids.append(b)
        run = EngineRun("pybullet", f"pybullet {pb.getAPIVersion()} (PyPI wheel, Bullet 3)",
                        f"dt {dt:g}, {iterations} iterations, sleeping {'on' if sleeping else 'off'}")
        yield run
        for k in count():
            t0 = time.perf_counter()
            pb.stepSimulation(physicsClientId=cid)
            t1 = time.perf_counter()
            cps = pybullet_contact_rows(
                pb.getContactPoints(physicsClientId=cid),
                lambda a, b: pb.getContactPoints(bodyA=a, bodyB=b, physicsClientId=cid))
            pen = max([-c[8] for c in cps] + [0.0])
            # PyBullet does not report activation states: with sleeping on the awake
            # count is unknown (-1 in the CSV).
            awake = -1 if sleeping else len(ids)
            run.records.append(StepRecord(k + 1, t1 - t0, len(cps), awake, pen))
            yield run
    finally:
        pb.disconnect(physicsClientId=cid)


# ---- MuJoCo ----------------------------------------------------------------------------

def mujoco_xml(spec: _scenes.BoxScene, dt: float, iterations: int) -> str:
    """MJCF of the scene: gravity along -y, free boxes, the ground box, pair friction on
    every geom (MuJoCo takes the maximum of the two), PGS solver."""
    mu = spec.pair_friction
    gx, gy, gz = spec.gravity
    parts = [f'<mujoco><option timestep="{dt!r}" gravity="{gx} {gy} {gz}" iterations="{iterations}" '
             f'solver="PGS"/><worldbody>',
             f'<geom type="box" size="{" ".join(map(str, _scenes.GROUND_HALF_EXTENTS))}" '
             f'pos="{" ".join(map(str, _scenes.GROUND_CENTRE))}" friction="{mu} 0 0"/>']
    for n, (h, p, m) in enumerate(zip(spec.half_extents, spec.positions, spec.masses)):
        px, py, pz = map(float, p)
        hx, hy, hz = map(float, h)
        parts.append(f'<body pos="{px!r} {py!r} {pz!r}"><freejoint/>'
                     f'<geom type="box" size="{hx!r} {hy!r} {hz!r}" mass="{float(m)!r}" friction="{mu} 0 0"/></body>')
    parts.append("</worldbody></mujoco>")
    return "".join(parts)


def step_mujoco(spec: _scenes.BoxScene, dt: float, iterations: int, substeps: int,
                sleeping: bool) -> Iterator[EngineRun]:
    import mujoco  # optional peer

    model = mujoco.MjModel.from_xml_string(mujoco_xml(spec, dt, iterations))
    data = mujoco.MjData(model)
    run = EngineRun("mujoco", f"mujoco {mujoco.__version__} (PyPI)",
                    f"dt {dt:g}, PGS {iterations} iterations, no sleeping (MuJoCo has none)")
    yield run
    for k in count():
        t0 = time.perf_counter()
        mujoco.mj_step(model, data)
        t1 = time.perf_counter()
        n = data.ncon
        pen = float(max(0.0, -data.contact.dist[:n].min())) if n else 0.0
        run.records.append(StepRecord(k + 1, t1 - t0, int(n), len(spec), pen))
        yield run


#: Steppers by engine: generators that build the scene and yield the engine's EngineRun,
#: then step once per ``next`` (closing one releases its engine).
STEPPERS: dict[str, Callable[..., Iterator[EngineRun]]] = {
    "wmo": step_wmo, "pybullet": step_pybullet, "mujoco": step_mujoco}


def _run_alone(stepper: Callable[..., Iterator[EngineRun]], spec: _scenes.BoxScene, steps: int, dt: float,
               iterations: int, substeps: int, sleeping: bool) -> EngineRun:
    """`steps` steps of the scene in one engine alone."""
    gen = stepper(spec, dt, iterations, substeps, sleeping)
    try:
        run = next(gen)
        for _ in range(steps):
            next(gen)
        return run
    finally:
        gen.close()


#: Each engine alone: ``RUNNERS[name](spec, steps, dt, iterations, substeps, sleeping)``.
RUNNERS: dict[str, Callable[..., EngineRun]] = {
    name: partial(_run_alone, stepper) for name, stepper in STEPPERS.items()}
run_wmo = RUNNERS["wmo"]

#: Steps each engine takes in its turn when the engines are interleaved.
BLOCK = 10


# ---- Driver ----------------------------------------------------------------------------

@dataclass
class BenchResult:
    scene: str
    runs: list[EngineRun]
    skipped: dict[str, str]
    interleaved: bool = True  #: engines stepped in turns of BLOCK steps

    def summary(self) -> str:
        steps = len(self.runs[0].records) if self.runs else 0
        order = f"engines interleaved in turns of {BLOCK} steps" if self.interleaved else "engines one after the other"
        lines = [f"scene {self.scene}: {steps} steps, WMO on {WMO_THREADS} thread(s), peers on one, {order}"]
        base = next((r for r in self.runs if r.engine == "wmo"), None)
        lines.append(f"{'engine':10s} {'median ms':>10s} {'steps/s':>9s} {'max contacts':>13s} "
                     f"{'deepest pen. m':>15s}  ratio to wmo   build / settings")
        for r in self.runs:
            ratio = (r.median_ms / base.median_ms) if base else math.nan
            lines.append(f"{r.engine:10s} {r.median_ms:10.2f} {1e3 / r.median_ms:9.1f} "
                         f"{max(x.contacts for x in r.records):13d} "
                         f"{max(x.max_penetration for x in r.records):15.3f}  {ratio:11.2f}   "
                         f"{r.build}; {r.settings}")
        for name, why in self.skipped.items():
            lines.append(f"{name:10s} skipped: {why}")
        return "\n".join(lines)


def _interleaved(spec: _scenes.BoxScene, engines: list[str], steps: int, dt: float, iterations: int,
                 substeps: int, sleeping: bool, skipped: dict[str, str]) -> list[EngineRun]:
    """Every engine's scene built, then stepped in turns of BLOCK steps (see the module
    docstring); an engine that is not installed or refuses the scene goes to `skipped`."""
    gens, runs = [], []
    try:
        for name in engines:
            gen = STEPPERS[name](spec, dt, iterations, substeps, sleeping)
            try:
                runs.append(next(gen))
            except ImportError as e:
                skipped[name] = f"not installed ({e})"
                continue
            except ValueError as e:
                skipped[name] = str(e)
                continue
            gens.append(gen)
        for start in range(0, steps, BLOCK):
            for gen in gens:
                for _ in range(min(BLOCK, steps - start)):
                    next(gen)
        return runs
    finally:
        for gen in gens:
            gen.close()


def run_bench(scene: str = "boxes3000", steps: int = 600, engines: Iterable[str] = ENGINES,
              dt: float = 1 / 60, iterations: int = 10, substeps: int = 4, sleeping: bool = False,
              repeats: int = 1, interleave: bool = True) -> BenchResult:
    """Runs `scene` for `steps` steps in each engine, interleaved in turns of BLOCK steps
    (``interleave=False``: each engine's steps in one go, WMO first); with ``repeats`` > 1
    the whole run is repeated and for each engine the run with the median of its
    medians is kept."""
    if scene not in _scenes.SPECS:
        raise ValueError(f"scene must be one of {sorted(_scenes.SPECS)}, got {scene!r}")
    if steps < 1:
        raise ValueError(f"steps must be >= 1, got {steps}")
    engines = list(engines)
    for name in engines:
        if name not in STEPPERS:
            raise ValueError(f"engine must be one of {list(STEPPERS)}, got {name!r}")
    spec = _scenes.SPECS[scene]()
    skipped: dict[str, str] = {}
    tries: dict[str, list[EngineRun]] = {}
    for _ in range(repeats):
        if interleave:
            done = _interleaved(spec, engines, steps, dt, iterations, substeps, sleeping, skipped)
        else:
            done = []
            for name in engines:
                done += _interleaved(spec, [name], steps, dt, iterations, substeps, sleeping, skipped)
        for r in done:
            tries.setdefault(r.engine, []).append(r)
    runs = []
    for name in engines:
        if name in tries:
            t = sorted(tries[name], key=lambda r: r.median_ms)
            runs.append(t[len(t) // 2])
    return BenchResult(scene, runs, skipped, interleave)


# ---- memory -------------------------------------------------------------------------

def _status_kib(field_name: str) -> int:
    """A ``/proc/self/status`` field in KiB (Linux): VmRSS now, VmHWM the peak so far."""
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith(field_name + ":"):
                return int(line.split()[1])
    raise OSError(f"/proc/self/status has no {field_name}")


_PEER_MODULES = {"wmo": "wmo._core", "pybullet": "pybullet", "mujoco": "mujoco"}


def _memory_child(scene: str, engine: str, steps: int, dt: float, iterations: int, substeps: int,
                  sleeping: bool) -> None:
    """Runs one engine in this (fresh) process and prints its memory as JSON: the
    resident set after importing the engine and building nothing (baseline), and the
    peak resident set after building and stepping the scene."""
    import importlib

    importlib.import_module(_PEER_MODULES[engine])
    spec = _scenes.SPECS[scene]()
    base = _status_kib("VmRSS")
    run = RUNNERS[engine](spec, steps, dt, iterations, substeps, sleeping)
    peak = _status_kib("VmHWM")
    print(json.dumps({"baseline_kib": base, "peak_kib": peak, "bodies": len(spec) + 1,
                      "max_contacts": max(r.contacts for r in run.records)}))


@dataclass
class MemoryRun:
    engine: str
    baseline_bytes: int  #: resident set with the engine imported, before the scene
    peak_bytes: int  #: peak resident set of the process after building and stepping
    bodies: int  #: bodies in the scene, ground included
    max_contacts: int  #: most contact points after any step

    @property
    def scene_bytes(self) -> int:
        """Peak growth over the baseline: what the scene and its stepping cost."""
        return self.peak_bytes - self.baseline_bytes

    @property
    def bytes_per_body(self) -> float:
        """Scene bytes over bodies: everything (shapes, state, broadphase, contacts)
        charged to the bodies, so comparable across engines whatever their layout."""
        return self.scene_bytes / self.bodies


def measure_memory(scene: str = "boxes3000", steps: int = 600, engines: Iterable[str] = ENGINES,
                   dt: float = 1 / 60, iterations: int = 10, substeps: int = 4,
                   sleeping: bool = False) -> tuple[list[MemoryRun], dict[str, str]]:
    """Peak memory of each engine on `scene`, each in a fresh Python process (in one
    process, memory freed by one engine is reused by the next and hides its cost).
    Linux only (reads /proc/self/status). Returns the runs and the engines skipped."""
    if scene not in _scenes.SPECS:
        raise ValueError(f"scene must be one of {sorted(_scenes.SPECS)}, got {scene!r}")
    runs, skipped = [], {}
    for name in engines:
        if name not in RUNNERS:
            raise ValueError(f"engine must be one of {list(RUNNERS)}, got {name!r}")
        code = (f"from wmo import bench; bench.WMO_THREADS = {WMO_THREADS!r}; "
                f"bench.WMO_CONTACT_HERTZ = {WMO_CONTACT_HERTZ!r}; bench.WMO_BLOCK_SOLVER = {WMO_BLOCK_SOLVER!r}; "
                f"bench.WMO_CENTROID_ROWS = {WMO_CENTROID_ROWS!r}; "
                f"bench._memory_child({scene!r}, {name!r}, {steps}, {dt!r}, {iterations}, {substeps}, {sleeping})")
        proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
        if proc.returncode != 0:
            last = (proc.stderr.strip().splitlines() or ["failed"])[-1]
            skipped[name] = last
            continue
        d = json.loads(proc.stdout.strip().splitlines()[-1])
        runs.append(MemoryRun(name, 1024 * d["baseline_kib"], 1024 * d["peak_kib"], d["bodies"],
                              d["max_contacts"]))
    return runs, skipped


def memory_summary(scene: str, runs: list[MemoryRun], skipped: dict[str, str]) -> str:
    lines = [f"memory, scene {scene} (each engine in a fresh process; scene = peak resident "
             f"set minus the resident set before the scene)",
             f"{'engine':10s} {'peak MB':>9s} {'scene MB':>9s} {'bytes/body':>11s} {'max contacts':>13s}"]
    for r in runs:
        lines.append(f"{r.engine:10s} {r.peak_bytes / 1e6:9.1f} {r.scene_bytes / 1e6:9.1f} "
                     f"{r.bytes_per_body:11.0f} {r.max_contacts:13d}")
    for name, why in skipped.items():
        lines.append(f"{name:10s} skipped: {why}")
    return "\n".join(lines)


def write_memory_csv(scene: str, runs: list[MemoryRun], path: Path) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["scene", "engine", "baseline_bytes", "peak_bytes", "scene_bytes", "bodies",
                    "bytes_per_body", "max_contact_points"])
        for r in runs:
            w.writerow([scene, r.engine, r.baseline_bytes, r.peak_bytes, r.scene_bytes, r.bodies,
                        "%.1f" % r.bytes_per_body, r.max_contacts])


def write_csv(result: BenchResult, path: Path, dt: float) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["scene", "engine", "step", "sim_time_s", "step_seconds", "contact_points", "awake_bodies",
                    "max_penetration_m"])
        for r in result.runs:
            for x in r.records:
                w.writerow([result.scene, r.engine, x.step, "%.9g" % (x.step * dt),
                            "%.9f" % x.seconds, x.contacts, x.awake, "%.6g" % x.max_penetration])


def plot(result: BenchResult, dt: float, out_dir: Path) -> list[Path]:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out_dir.mkdir(parents=True, exist_ok=True)
    paths = []
    fig, ax = plt.subplots(figsize=(8, 4.5))
    for r in result.runs:
        t = np.array([x.step for x in r.records]) * dt
        sps = 1.0 / np.maximum(np.array(r.step_times()), 1e-9)
        k = min(15, len(sps))  # a moving median over 15 steps shows the trend through the noise
        smooth = np.array([np.median(sps[max(0, i - k + 1):i + 1]) for i in range(len(sps))])
        ax.plot(t, smooth, label=f"{r.engine} (median {r.median_ms:.1f} ms/step)")
    ax.set_xlabel("simulated time (s)")
    ax.set_ylabel("steps per second (moving median of 15)")
    ax.set_yscale("log")
    ax.set_title(f"{result.scene}: simulation rate")
    ax.legend()
    ax.grid(True, which="both", alpha=0.3)
    p = out_dir / f"{result.scene}_steps_per_second.png"
    fig.tight_layout()
    fig.savefig(p, dpi=120)
    plt.close(fig)
    paths.append(p)
    fig, ax = plt.subplots(figsize=(8, 4.5))
    for r in result.runs:
        t = np.array([x.step for x in r.records]) * dt
        ax.plot(t, [x.contacts for x in r.records], label=r.engine)
    ax.set_xlabel("simulated time (s)")
    ax.set_ylabel("contact points")
    ax.set_title(f"{result.scene}: contact points")
    ax.legend()
    ax.grid(True, alpha=0.3)
    p = out_dir / f"{result.scene}_contacts.png"
    fig.tight_layout()
    fig.savefig(p, dpi=120)
    plt.close(fig)
    paths.append(p)
    return paths
