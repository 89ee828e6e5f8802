"""Random-world fuzzer: many random scenes and settings, each stepped for a while, checked
for non-finite state, bodies that leave their container, and exceptions.

Not a test (it runs for as long as it is told to); tests/python/test_fuzz_worlds.py pins
seeds it found failing, and named tests in tests/python/test_stability.py the defects
behind them. Each seed builds one scene:

  * a container of static walls and a lid, with a ground that is a box, a plane, or a
    rolling triangle mesh (one- or two-sided), reaching under the walls;
  * 10 to 40 dynamic bodies of random shape (sphere, box, capsule, cylinder, flat or
    long hulls, a box-and-ball compound), sizes 5 cm to 1 m log-uniform, densities
    10 to 10,000 kg/m^3 (mass ratios up to ~1e7), random friction and restitution,
    random initial linear and angular velocities (typically up to ~20 m/s and ~60 rad/s), some
    with CCD, some with damping or a gravity scale, a few kinematic movers;
  * random world settings: dt 1/30 to 1/240, 1 to 8 substeps, 1 to 10 iterations,
    block solver, centroid rows, gyroscopic term, sleeping, threads 1 or 2, friction
    and restitution combine rules, energy guard;
  * every `kick_every` steps three bodies get a random impulse (~8 m/s), and now and
    then a body is removed or added between steps.

Usage: python scripts/fuzz_worlds.py [--first N] [--count N] [--steps N] [--ccd-share F]
                                     [--grounds box,plane,one-sided,two-sided]
--ccd-share is the fraction of dynamic bodies with CCD (default 0.4). At 1, on the box,
plane and one-sided mesh grounds, any escape is a defect; a body without CCD fired at a
thin wall may tunnel (what CCD is for), and a two-sided mesh ground lets a body whose
centre was driven through it be pushed out below (TriangleMesh::one_sided).
Prints one line per seed that fails (and why), and a summary. Exit status 1 if any did.
"""
from __future__ import annotations

import sys
import traceback

import numpy as np

import wmo


def _size(rng, lo=0.05, hi=1.0):
    return float(np.exp(rng.uniform(np.log(lo), np.log(hi))))


def random_shape(rng):
    k = int(rng.integers(0, 7))
    if k == 0:
        return wmo.Sphere(_size(rng))
    if k == 1:
        return wmo.Box((_size(rng), _size(rng), _size(rng)))
    if k == 2:
        return wmo.Capsule(_size(rng), _size(rng))
    if k == 3:
        return wmo.Cylinder(_size(rng), _size(rng))
    if k in (4, 5):
        p = rng.normal(size=(int(rng.integers(4, 30)), 3))
        p /= np.linalg.norm(p, axis=1)[:, None]
        squash = np.array([1, _size(rng, 0.02, 2.0), 1]) if k == 4 else np.array([_size(rng, 0.5, 4), 1, 1])
        return wmo.ConvexHull(p * _size(rng) * squash)
    return wmo.Compound([(wmo.Box((_size(rng), _size(rng) / 3, _size(rng) / 3)), wmo.Pose()),
                         (wmo.Sphere(_size(rng) / 2), wmo.Pose(position=(0.5, 0, 0)))])


def rolling_ground(rng, one_sided):
    xs = np.linspace(-12, 12, 13)  # under the walls too: no seam at their feet
    amp = rng.uniform(0, 0.5)
    v = np.array([(x, amp * np.sin(x + z), z) for x in xs for z in xs])
    t = [tri for i in range(12) for j in range(12)
         for tri in ((13 * i + j, 13 * i + j + 1, 13 * i + j + 13), (13 * i + j + 1, 13 * i + j + 14, 13 * i + j + 13))]
    return wmo.TriangleMesh(v, t, one_sided=one_sided)


GROUNDS = ("box", "plane", "two-sided", "one-sided")


def build(seed, ccd_share, grounds=GROUNDS):
    rng = np.random.default_rng(seed)
    settings = dict(
        dt=float(rng.choice([1 / 30, 1 / 60, 1 / 60, 1 / 120, 1 / 240])),
        substeps=int(rng.choice([1, 2, 4, 4, 8])),
        iterations=int(rng.choice([1, 1, 2, 4, 10])),
        block_solver=bool(rng.random() < 0.3),
        centroid_rows=bool(rng.random() < 0.2),
        gyroscopic=bool(rng.random() < 0.3),
        sleeping=bool(rng.random() < 0.5),
        threads=int(rng.choice([1, 2])),
        friction_combine=str(rng.choice(["multiply", "min", "max", "average"])),
        restitution_combine=str(rng.choice(["max", "min", "multiply", "average"])),
        energy_guard_passes=int(rng.choice([0, 0, 0, 8])),
    )
    w = wmo.World(**settings)
    ground = GROUNDS.index(grounds[int(rng.integers(0, len(grounds)))])
    if ground == 0:
        w.add_body(wmo.Box((12, 0.5, 12)), position=(0, -0.5, 0), kind="static")
    elif ground == 1:
        w.add_body(wmo.Plane((0, 1, 0), 0), kind="static")
    else:
        w.add_body(rolling_ground(rng, ground == 3), kind="static")
    for x, z, hx, hz in ((10.5, 0, 0.5, 11), (-10.5, 0, 0.5, 11), (0, 10.5, 11, 0.5), (0, -10.5, 11, 0.5)):
        w.add_body(wmo.Box((hx, 12, hz)), position=(x, 11, z), kind="static")
    w.add_body(wmo.Box((11, 0.5, 11)), position=(0, 23.5, 0), kind="static")
    count = int(rng.integers(10, 41))
    for _ in range(count):
        w.add_body(random_shape(rng),
                   position=(rng.uniform(-8, 8), rng.uniform(1, 20), rng.uniform(-8, 8)),
                   orientation=tuple(_unit_quat(rng)),
                   density=float(np.exp(rng.uniform(np.log(10), np.log(10000)))),
                   friction=float(rng.uniform(0, 1.2)),
                   restitution=float(rng.uniform(0, 1)) if rng.random() < 0.3 else 0.0,
                   linear_velocity=tuple(rng.normal(size=3) * rng.uniform(0, 12)),
                   angular_velocity=tuple(rng.normal(size=3) * rng.uniform(0, 35)),
                   linear_damping=float(rng.uniform(0, 0.5)) if rng.random() < 0.2 else 0.0,
                   angular_damping=float(rng.uniform(0, 0.5)) if rng.random() < 0.2 else 0.0,
                   gravity_scale=float(rng.uniform(0, 2)) if rng.random() < 0.1 else 1.0,
                   ccd=bool(rng.random() < ccd_share))
    for _ in range(int(rng.integers(0, 3))):
        w.add_body(wmo.Box((_size(rng, 0.2, 1.5),) * 3), position=(rng.uniform(-6, 6), rng.uniform(2, 10), 0),
                   kind="kinematic", linear_velocity=tuple(rng.normal(size=3) * 2),
                   angular_velocity=tuple(rng.normal(size=3)))
    return w, rng, settings, ground


def _unit_quat(rng):
    q = rng.normal(size=4)
    return q / np.linalg.norm(q)


def centres_of_mass(w, rows):
    """World centres of mass of the bodies in `rows` (N, 3): the check of a body's place.
    Not `positions`, the body frames' origins, which a hull's points need not surround:
    a 4-point hull of seed 1902 touched the wall from inside, its centre of mass 0.1 m
    within, its origin 0.6 m beyond it (reported as an escape until this check)."""
    p = w.positions[rows]
    q = w.orientations[rows]
    c = np.array([w.body(int(i)).center_of_mass for i in rows]).reshape(-1, 3)
    u, s = q[:, :3], q[:, 3:4]
    t = 2 * np.cross(u, c)  # c rotated by q: c + s t + u x t
    return p + c + s * t + np.cross(u, t)


def run(seed, steps, ccd_share, grounds=GROUNDS, kick_every=200):
    w, rng, settings, ground = build(seed, ccd_share, grounds)
    done = 0
    while done < steps:
        n = min(kick_every, steps - done)
        dyn = [i for i in range(len(w)) if w.body(i).kind == "dynamic"]
        for i in rng.choice(dyn, size=min(3, len(dyn)), replace=False):
            b = w.body(int(i))
            w.apply_impulse(b, rng.normal(size=3) * 8 * b.mass, b.position)
        if rng.random() < 0.2 and len(dyn) > 5:
            w.remove_body(w.body(int(rng.choice(dyn))))
        if rng.random() < 0.2:
            w.add_body(random_shape(rng), position=(rng.uniform(-8, 8), rng.uniform(10, 20), rng.uniform(-8, 8)),
                       ccd=bool(rng.random() < ccd_share))
        w.step(n)
        done += n
        for name in ("positions", "orientations", "linear_velocities", "angular_velocities"):
            a = getattr(w, name)
            if not np.isfinite(a).all():
                return f"non-finite {name} by step {done}", settings
        dyn = [i for i in range(len(w)) if w.body(i).kind == "dynamic"]
        p = centres_of_mass(w, dyn)
        if not ((np.abs(p[:, [0, 2]]) < 10.5).all() and (p[:, 1] > -1.0).all() and (p[:, 1] < 24).all()):
            k = int(np.argmax(np.maximum(np.abs(p[:, [0, 2]]).max(axis=1) - 10.5,
                                         np.maximum(-1.0 - p[:, 1], p[:, 1] - 24))))
            b = w.body(dyn[k])
            return (f"body {dyn[k]} ({type(b.shape).__name__}, {b.mass:.3g} kg, ccd={b.ccd}) left the container "
                    f"by step {done}: centre of mass at {np.round(p[k], 2)}, ground {GROUNDS[ground]}"), settings
    return None, settings


def main():
    import argparse
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--first", type=int, default=1)
    ap.add_argument("--count", type=int, default=50)
    ap.add_argument("--steps", type=int, default=2000)
    ap.add_argument("--ccd-share", type=float, default=0.4)
    ap.add_argument("--grounds", default=",".join(GROUNDS))
    a = ap.parse_args()
    grounds = tuple(a.grounds.split(","))
    for g in grounds:
        if g not in GROUNDS:
            ap.error(f"unknown ground {g!r}; choose from {GROUNDS}")
    failed = 0
    for seed in range(a.first, a.first + a.count):
        try:
            why, settings = run(seed, a.steps, a.ccd_share, grounds)
        except Exception:  # noqa: BLE001 - a fuzzer reports every failure
            why, settings = "exception:\n" + traceback.format_exc(), None
        if why:
            failed += 1
            print(f"seed {seed}: {why}  settings={settings}", flush=True)
    print(f"{failed} of {a.count} seeds failed ({a.steps} steps each)")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
