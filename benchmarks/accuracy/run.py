"""What accuracy costs in time (issue 3, section 6): each accuracy knob of the world (time
step, substeps, velocity iterations, contact margins growing with the approach
(speculative_motion for every pair, speculative_motion_static for pairs with fixed
geometry), manifold reuse tolerance, contact spring stiffness, block-solved manifolds,
the energy guard's added relax passes, and the substeps with the contact spring at its
cap, COMBINED) swept one at a time from the defaults (dt 1/60 s, 4 substeps, 1 iteration, motion margins
0 and 1, reuse 1 mm, 36 Hz contacts, rows one by one) on cases with a
known answer, measuring the error against the
cost in milliseconds of wall time per simulated second; the same cases in PyBullet and
MuJoCo (their dt and solver iterations swept, peers.py) on the same axes.

Cases (the error is in metres or a relative number, as stated):
  bounce   a ball (restitution 0.5) dropped from 1 m onto the ground: relative error of
           the first rebound height against e^2 h (not in MuJoCo: no restitution setting).
  slide    a box launched at 5 m/s on ground with pair friction 0.25: error of the
           stopping distance against v^2 / (2 mu g) (m).
  stack10  10 unit boxes stacked face to face, the top one kicked sideways at 1 cm/s
           (peers.KICK, in every engine: an unkicked stack can stand as an unstable
           equilibrium), 5 s: the largest displacement of a box centre (m; a standing
           stack stays at the millimetre level).
  tower30  30 unit boxes stacked face to face (scenes.tower), kicked, 20 s: the same measure. At
           the defaults it buckles (an elastic column under its own weight, see
           SolverSettings::contact_hertz), so this is where the knobs' cost to hold a
           tall stack shows, next to the peers' (a fallen tower: tens of metres).
  pyramid10  the SCENES.md pyramid with 10 layers (385 boxes), 5 s: the same measure.
  pyramid  the SCENES.md pyramid itself (20 layers, 2870 boxes), 5 s: the same measure.
  boxes3000  the SCENES.md scene (3008 boxes falling onto the ground), 10 s (600 steps at the
           default dt): the deepest penetration seen after any step (m), the scene's measure
           of accuracy in `wmo bench`; the peers run through wmo.bench's drivers (MuJoCo
           with PGS, as `wmo bench`).
  energy   20 spheres and 20 boxes fired around a closed box of static walls, no gravity,
           friction, restitution or damping, 10 s: the largest one-step rise of the
           kinetic energy, relative (inelastic contacts should only remove energy; WMO
           only: the peers' defaults are not such a closed system).

Writes results/accuracy/accuracy.csv (one row per engine, case and setting) and one PNG
per case (error against cost, one series per engine and knob, and each engine's Pareto
front over all its settings as a broad pale line; a peer that is not
installed is skipped and said so). Usage:
.venv/bin/python benchmarks/accuracy/run.py [--out DIR] [--quick] [--no-peers] [--cases tower30,...]
"""
from __future__ import annotations

import argparse
import csv
import sys
import time
from pathlib import Path

import numpy as np

import wmo
from wmo import scenes

# The peers' cases (peers.py, beside this file), and the kick WMO's stack cases share with
# them: one value, so that every engine's stack gets the same perturbation.
sys.path.insert(0, str(Path(__file__).resolve().parent))
import peers  # noqa: E402

G = 10.0
KICK = peers.KICK
#: Wall seconds after which a sweep's remaining (dearer) settings are skipped.
BUDGET_S = 60.0
DEFAULT = {"dt": 1 / 60, "substeps": 4, "iterations": 1, "speculative_motion": 0.0,
           "speculative_motion_static": 1.0, "manifold_reuse_distance": 1e-3, "contact_hertz": 36.0,
           "block_solver": False, "energy_guard_passes": 0}
SWEEPS = {
    "dt": [1 / 30, 1 / 60, 1 / 120, 1 / 240, 1 / 480, 1 / 960],
    "substeps": [1, 2, 4, 8, 16],
    "iterations": [1, 2, 4, 10, 20, 50],
    # Contact margins that grow with the approach (off by default for pairs of moving
    # bodies, on against static geometry) and manifold reuse (1 mm by default; 0
    # recomputes every pair every step).
    "speculative_motion": [0.0, 1.0],
    "speculative_motion_static": [0.0, 1.0],
    "manifold_reuse_distance": [0.0, 1e-3, 1e-2],
    # The contact spring (capped at a quarter of the substep rate): stiffer sags less
    # under a stack's load but creeps at 4 substeps (the 20-layer pyramid after 10 s,
    # one relax pass: 1.9 cm at 30 Hz, 4.3 cm at 40 Hz, 51 cm at 60 Hz; with the default
    # two, 8.1 mm at 36 Hz).
    "contact_hertz": [15.0, 30.0, 36.0, 45.0, 60.0],
    # Each manifold's normal rows solved together (a small LCP per pair, scalar solver).
    "block_solver": [False, True],
    # Relax passes added where a substep's contact solve left more energy than it found.
    "energy_guard_passes": [0, 8],
}
KNOBS = list(SWEEPS)
#: Knobs that set several World settings at once: name -> (value -> those settings, the
#: values swept). substeps_at_cap: the substeps with contact_hertz at the soft step's cap, a
#: quarter of the substep rate (SolverSettings::contact_hertz). A tall stack needs the
#: stiffness that more substeps allow, not the substeps alone: the 30-box tower needs 83 Hz
#: (Greenhill's criterion), which 8 substeps at 36 Hz do not give it.
COMBINED = {"substeps_at_cap": (lambda v: {"substeps": v, "contact_hertz": 0.25 * v / DEFAULT["dt"]},
                                [4, 6, 8, 16])}


def setting(knob, value):
    """DEFAULT with one knob, or one combined knob (COMBINED), set to `value`."""
    return dict(DEFAULT, **(COMBINED[knob][0](value) if knob in COMBINED else {knob: value}))


def pareto_front(points):
    """The (cost, error) points that no other point beats in both, by increasing cost: each
    kept point has a lower error than every cheaper one."""
    front = []
    for cost, err in sorted(points):
        if not front or err < front[-1][1]:
            front.append((cost, err))
    return front


def world_settings(s):
    """The World keyword arguments of a setting (everything swept above)."""
    return {k: s[k] for k in KNOBS}


def world(settings, **kw):
    return wmo.World(gravity=(0, -G, 0), sleeping=False, **world_settings(settings), **kw)


def ground(w, friction=0.5):
    w.add_body(wmo.Box((50, 1, 50)), position=(0, -1, 0), kind="static", friction=friction)


def run_for(w, seconds, dt, each=None):
    n = max(1, round(seconds / dt))
    t0 = time.perf_counter()
    for k in range(n):
        w.step()
        if each:
            each(k)
    return (time.perf_counter() - t0) * 1e3 / seconds, n


def case_bounce(s):
    e, h, r = 0.5, 1.0, 0.1
    w = world(s, restitution_threshold=0.1)
    ground(w)
    b = w.add_body(wmo.Sphere(r), position=(0, r + h, 0), restitution=e)
    state = {"fell": False, "peak": 0.0}

    def watch(_):
        y, vy = b.position[1] - r, b.linear_velocity[1]
        if vy > 0:
            state["fell"] = True
        if state["fell"]:
            state["peak"] = max(state["peak"], y)

    ms, _ = run_for(w, 1.2, s["dt"], watch)  # fall (0.45 s) and first rebound (0.22 s up)
    return ms, abs(state["peak"] - e * e * h) / (e * e * h)


def case_slide(s):
    v0, mu = 5.0, 0.25
    w = world(s)
    ground(w, friction=0.5)
    b = w.add_body(wmo.Box((0.5, 0.5, 0.5)), position=(0, 0.5, 0), linear_velocity=(v0, 0, 0), friction=0.5)
    ms, _ = run_for(w, 3.0, s["dt"])  # stops after v0 / (mu g) = 2 s
    return ms, abs(b.position[0] - v0 * v0 / (2 * mu * G))


def case_stack(s, n=10, seconds=5.0):
    w = scenes.tower(n, sleeping=False, kick=KICK, **world_settings(s))
    p0 = np.array(w.positions)
    ms, _ = run_for(w, seconds, s["dt"])
    return ms, float(np.linalg.norm(w.positions - p0, axis=1).max())


def case_tower(s):
    return case_stack(s, n=30, seconds=20.0)


def case_pyramid(s, layers=10):
    w = scenes.pyramid(layers, sleeping=False, **world_settings(s))
    p0 = np.array(w.positions)
    ms, _ = run_for(w, 5.0, s["dt"])
    return ms, float(np.linalg.norm(w.positions - p0, axis=1).max())


def case_boxes3000(s, layers=47, seconds=10.0):
    # Timed by the steps alone, as wmo.bench times every engine (the peers' penetration
    # queries are not cheap).
    w = scenes.boxes3000(layers, sleeping=False, **world_settings(s))
    n = max(1, round(seconds / s["dt"]))
    spent, deepest = 0.0, 0.0
    for _ in range(n):
        t0 = time.perf_counter()
        w.step()
        spent += time.perf_counter() - t0
        deepest = max(deepest, w.max_penetration)
    return spent * 1e3 / seconds, deepest


def case_energy(s):
    w = scenes.closed_box(**world_settings(s))
    state = {"e": w.kinetic_energy(), "rise": 0.0}

    def watch(_):
        e = w.kinetic_energy()
        state["rise"] = max(state["rise"], (e - state["e"]) / state["e"])
        state["e"] = e

    ms, _ = run_for(w, 10.0, s["dt"], watch)
    return ms, state["rise"]


CASES = {"bounce": (case_bounce, "relative error of e^2 h"), "slide": (case_slide, "stopping distance error (m)"),
         "stack10": (case_stack, "largest displacement (m)"),
         "tower30": (case_tower, "largest displacement (m)"), "pyramid10": (case_pyramid, "largest displacement (m)"),
         "pyramid": (lambda s: case_pyramid(s, layers=20), "largest displacement (m)"),
         "boxes3000": (case_boxes3000, "deepest penetration (m)"),
         "energy": (case_energy, "largest one-step energy rise (relative)")}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", type=Path, default=Path("results/accuracy"))
    ap.add_argument("--quick", action="store_true", help="the two cheapest cases and fewer settings")
    ap.add_argument("--no-peers", action="store_true", help="WMO only")
    ap.add_argument("--cases", help=f"comma-separated subset of {','.join(CASES)} (default: all)")
    args = ap.parse_args()
    cases = ["bounce", "slide"] if args.quick else list(CASES)
    if args.cases:
        cases = [c for c in args.cases.split(",") if c]
        unknown = [c for c in cases if c not in CASES]
        if unknown:
            ap.error(f"unknown case(s) {unknown}; known: {list(CASES)}")
    sweeps = {k: v[:3] for k, v in SWEEPS.items()} if args.quick else dict(SWEEPS)
    sweeps.update({k: v[:3] if args.quick else v for k, (_, v) in COMBINED.items()})
    args.out.mkdir(parents=True, exist_ok=True)
    rows = []
    path = args.out / "accuracy.csv"
    fields = ["engine", "case", "knob", "value", "dt", "substeps", "iterations", "ms_per_sim_second", "error",
              "error_is"]
    csv_file = open(path, "w", newline="")
    writer = csv.DictWriter(csv_file, fieldnames=fields)
    writer.writeheader()

    def record(engine, case, knob, value, s, ms, err):
        # Written as it comes, so an interrupted run keeps what it measured.
        rows.append({"engine": engine, "case": case, "knob": knob, "value": value, "dt": s["dt"],
                     "substeps": s.get("substeps", ""), "iterations": s["iterations"], "ms_per_sim_second": ms,
                     "error": err, "error_is": CASES[case][1]})
        writer.writerow(rows[-1])
        csv_file.flush()
        print(f"{engine:9s} {case:10s} {knob:10s} {value:10.5g}  {ms:9.2f} ms/sim s  error {err:.3e}", flush=True)

    def sweep(engine, case, knob, values, run):
        # The settings of a sweep get dearer along it; once one has taken more than
        # BUDGET_S of wall time the rest are skipped (and said so), which keeps the
        # whole run bounded (MuJoCo's pyramid costs 9 s per simulated second at dt 1/60).
        for value in values:
            t0 = time.perf_counter()
            out = run(value)
            if out is not None:
                record(engine, case, knob, value, *out)
            if time.perf_counter() - t0 > BUDGET_S:
                rest = values[values.index(value) + 1:]
                if rest:
                    print(f"{engine:9s} {case:10s} {knob:10s} skipped {rest}: the last setting took over "
                          f"{BUDGET_S:.0f} s", flush=True)
                return

    for case in cases:
        fn, _ = CASES[case]
        for knob, values in sweeps.items():
            sweep("wmo", case, knob, values, lambda value: (setting(knob, value), *fn(setting(knob, value))))
    engines = ["wmo"]
    if not args.no_peers:
        for engine, run_case in peers.ENGINES.items():
            try:
                __import__(engine)
            except ImportError as e:
                print(f"{engine}: skipped, not installed ({e})")
                continue
            engines.append(engine)
            for case in cases:
                for knob, values in peers.PEER_SWEEPS[engine].items():
                    def run(value, engine=engine, knob=knob, case=case, run_case=run_case):
                        s = dict(peers.PEER_DEFAULT[engine], **{knob: value})
                        out = run_case(case, s["dt"], s["iterations"])
                        return None if out is None else (s, *out)
                    sweep(engine, case, knob, values[:3] if args.quick else values, run)
    csv_file.close()
    print(f"wrote {path}")
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    for case in cases:
        fig, ax = plt.subplots(figsize=(7.5, 5))
        style = {"wmo": ("o", "-"), "pybullet": ("s", "--"), "mujoco": ("^", ":")}
        for engine in engines:
            for knob in KNOBS + list(COMBINED):
                pts = [(r["ms_per_sim_second"], r["error"], r["value"]) for r in rows
                       if r["engine"] == engine and r["case"] == case and r["knob"] == knob]
                if not pts:
                    continue
                marker, line = style[engine]
                ax.plot([p[0] for p in pts], [max(p[1], 1e-16) for p in pts], marker=marker, linestyle=line,
                        label=f"{engine} {knob}")
                for x, y, v in pts:
                    label = f"1/{round(1 / v)}" if knob == "dt" else f"{v:g}"
                    ax.annotate(label, (x, max(y, 1e-16)), fontsize=6, xytext=(3, 3), textcoords="offset points")
        # Each engine's Pareto front over all its settings: the points that no cheaper one
        # matches in error (the best error each cost buys).
        colours = {"wmo": "tab:blue", "pybullet": "tab:orange", "mujoco": "tab:green"}
        for engine in engines:
            front = pareto_front([(r["ms_per_sim_second"], r["error"]) for r in rows
                                  if r["engine"] == engine and r["case"] == case])
            if len(front) > 1:
                ax.plot([p[0] for p in front], [max(p[1], 1e-16) for p in front], color=colours[engine],
                        linewidth=6, alpha=0.2, solid_capstyle="round", label=f"{engine} Pareto front")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("cost: wall ms per simulated second")
        ax.set_ylabel(CASES[case][1])
        ax.set_title(f"{case}: error against cost (one knob at a time from each engine's defaults)", fontsize=9)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7)
        fig.tight_layout()
        p = args.out / f"{case}_accuracy.png"
        fig.savefig(p, dpi=120)
        plt.close(fig)
        print(f"wrote {p}")


if __name__ == "__main__":
    main()
