"""The accuracy cases of run.py in PyBullet and MuJoCo, so the peers' error-against-cost
points share the axes with WMO's. Same scenes, units and error measures as run.py.

Knobs: dt (both) and solver iterations (PyBullet's sequential-impulse iterations,
default 10; MuJoCo's Newton iterations, its default solver, default 100 with early
termination, so only small counts change anything). Not run: the bounce in MuJoCo,
which has no restitution coefficient (bounce comes from its contact spring, solref),
so e is not a setting there.

Each function returns (wall ms per simulated second, error), or None where the case
does not exist for that engine.
"""
from __future__ import annotations

import math
import time

import numpy as np

from wmo import scenes

G = 10.0
#: Sideways speed (m/s) given to a stack's top box at the start (run.py's stack cases):
#: the perturbation that tells a standing stack from an unstable equilibrium.
KICK = 0.01


#: The stacked-box cases of run.py: (boxes, simulated seconds).
STACKS = {"stack10": (10, 5.0), "tower30": (30, 20.0)}
#: The pyramid cases: layers; each runs 5 s.
PYRAMIDS = {"pyramid10": 10, "pyramid": 20}
#: The cases run through wmo.bench's engine drivers: (scene spec, simulated seconds).
BENCH_SCENES = {"boxes3000": (scenes.boxes3000_spec, 10.0)}


def bench_scene_case(engine: str, spec, seconds: float, dt: float, iterations: int):
    """(ms per simulated second, deepest penetration in m) of `spec` in `engine` through
    wmo.bench's drivers (the same build of the scene as `wmo bench`; steps timed alone)."""
    from wmo import bench

    run = bench.RUNNERS[engine](spec, max(1, round(seconds / dt)), dt, iterations, 1, False)
    return sum(run.step_times()) * 1e3 / seconds, max(r.max_penetration for r in run.records)


# ---- PyBullet --------------------------------------------------------------------------

class _Bullet:
    def __init__(self, dt: float, iterations: int):
        import pybullet as pb

        self.pb = pb
        self.cid = pb.connect(pb.DIRECT)
        pb.setGravity(0, -G, 0, physicsClientId=self.cid)
        pb.setPhysicsEngineParameter(fixedTimeStep=dt, numSolverIterations=iterations, numSubSteps=0,
                                     deterministicOverlappingPairs=1, physicsClientId=self.cid)
        self.dt = dt

    def box(self, half, pos, mass, friction, restitution=0.0, velocity=None):
        pb = self.pb
        shape = pb.createCollisionShape(pb.GEOM_BOX, halfExtents=list(half), physicsClientId=self.cid)
        b = pb.createMultiBody(mass, shape, -1, list(pos), useMaximalCoordinates=1, physicsClientId=self.cid)
        pb.changeDynamics(b, -1, lateralFriction=friction, restitution=restitution, linearDamping=0,
                          angularDamping=0, physicsClientId=self.cid)
        if mass > 0:
            pb.changeDynamics(b, -1, activationState=pb.ACTIVATION_STATE_DISABLE_SLEEPING, physicsClientId=self.cid)
        if velocity is not None:
            pb.resetBaseVelocity(b, list(velocity), [0, 0, 0], physicsClientId=self.cid)
        return b

    def sphere(self, r, pos, mass, restitution):
        pb = self.pb
        shape = pb.createCollisionShape(pb.GEOM_SPHERE, radius=r, physicsClientId=self.cid)
        b = pb.createMultiBody(mass, shape, -1, list(pos), useMaximalCoordinates=1, physicsClientId=self.cid)
        pb.changeDynamics(b, -1, restitution=restitution, linearDamping=0, angularDamping=0,
                          activationState=pb.ACTIVATION_STATE_DISABLE_SLEEPING, physicsClientId=self.cid)
        return b

    def ground(self, friction, restitution=0.0):
        return self.box((50, 1, 50), (0, -1, 0), 0.0, friction, restitution)

    def pos(self, b):
        return np.array(self.pb.getBasePositionAndOrientation(b, physicsClientId=self.cid)[0])

    def vel(self, b):
        return np.array(self.pb.getBaseVelocity(b, physicsClientId=self.cid)[0])

    def run(self, seconds, each=None):
        n = max(1, round(seconds / self.dt))
        t0 = time.perf_counter()
        for k in range(n):
            self.pb.stepSimulation(physicsClientId=self.cid)
            if each:
                each(k)
        return (time.perf_counter() - t0) * 1e3 / seconds

    def close(self):
        self.pb.disconnect(physicsClientId=self.cid)


def pybullet_case(case: str, dt: float, iterations: int):
    if case in BENCH_SCENES:
        spec, seconds = BENCH_SCENES[case]
        return bench_scene_case("pybullet", spec(), seconds, dt, iterations)
    w = _Bullet(dt, iterations)
    try:
        if case == "bounce":
            # Bullet multiplies the two restitutions: ground 1, ball e.
            e, h, r = 0.5, 1.0, 0.1
            w.ground(0.5, restitution=1.0)
            b = w.sphere(r, (0, r + h, 0), 1.0, e)
            state = {"fell": False, "peak": 0.0}

            def watch(_):
                y, vy = w.pos(b)[1] - r, w.vel(b)[1]
                if vy > 0:
                    state["fell"] = True
                if state["fell"]:
                    state["peak"] = max(state["peak"], y)

            ms = w.run(1.2, watch)
            return ms, abs(state["peak"] - e * e * h) / (e * e * h)
        if case == "slide":
            v0, mu = 5.0, 0.25
            w.ground(0.5)  # Bullet multiplies the frictions: 0.5 x 0.5
            b = w.box((0.5, 0.5, 0.5), (0, 0.5, 0), 1000.0, 0.5, velocity=(v0, 0, 0))
            ms = w.run(3.0)
            return ms, abs(w.pos(b)[0] - v0 * v0 / (2 * mu * G))
        if case in STACKS or case in PYRAMIDS:
            n, seconds = STACKS.get(case, (0, 5.0))
            if case in STACKS:
                pos = [(0.0, 0.5 + k, 0.0) for k in range(n)]
                masses = [1000.0] * n
                friction = math.sqrt(0.6)
            else:
                spec = scenes.pyramid_spec(PYRAMIDS[case])
                pos, masses, friction = [tuple(p) for p in spec.positions], list(spec.masses), spec.friction
            w.ground(friction)
            # A stack's top box kicked sideways (KICK), as in run.py.
            kicked = len(pos) - 1 if case in STACKS else -1
            ids = [w.box((0.5, 0.5, 0.5), p, m, friction, velocity=(KICK, 0, 0) if k == kicked else None)
                   for k, (p, m) in enumerate(zip(pos, masses))]
            p0 = np.array([w.pos(b) for b in ids])
            ms = w.run(seconds)
            p1 = np.array([w.pos(b) for b in ids])
            return ms, float(np.linalg.norm(p1 - p0, axis=1).max())
    finally:
        w.close()
    return None


# ---- MuJoCo ----------------------------------------------------------------------------

def _mujoco_run(xml: str, seconds: float, dt: float, init=None):
    """Steps the model for `seconds`; init(data), if given, sets the start state."""
    import mujoco

    model = mujoco.MjModel.from_xml_string(xml)
    data = mujoco.MjData(model)
    if init:
        init(data)
    n = max(1, round(seconds / dt))
    t0 = time.perf_counter()
    for _ in range(n):
        mujoco.mj_step(model, data)
    return (time.perf_counter() - t0) * 1e3 / seconds, model, data


def _mujoco_boxes(pos, masses, friction, dt, iterations):
    parts = [f'<mujoco><option timestep="{dt!r}" gravity="0 {-G} 0" iterations="{iterations}"/><worldbody>',
             f'<geom type="box" size="50 1 50" pos="0 -1 0" friction="{friction} 0 0"/>']
    for (x, y, z), m in zip(pos, masses):
        parts.append(f'<body pos="{x!r} {y!r} {z!r}"><freejoint/>'
                     f'<geom type="box" size="0.5 0.5 0.5" mass="{m!r}" friction="{friction} 0 0"/></body>')
    parts.append("</worldbody></mujoco>")
    return "".join(parts)


def mujoco_case(case: str, dt: float, iterations: int):
    if case == "bounce":
        return None
    if case == "slide":
        # MuJoCo takes the larger of the two geoms' frictions: both 0.25.
        v0, mu = 5.0, 0.25
        xml = _mujoco_boxes([(0.0, 0.5, 0.0)], [1000.0], mu, dt, iterations)
        ms, _, data = _mujoco_run(xml, 3.0, dt, init=lambda d: d.qvel.__setitem__(0, v0))
        return ms, abs(float(data.qpos[0]) - v0 * v0 / (2 * mu * G))
    if case in BENCH_SCENES:
        spec, seconds = BENCH_SCENES[case]
        return bench_scene_case("mujoco", spec(), seconds, dt, iterations)
    if case in STACKS or case in PYRAMIDS:
        n, seconds = STACKS.get(case, (0, 5.0))
        if case in STACKS:
            pos, masses = [(0.0, 0.5 + k, 0.0) for k in range(n)], [1000.0] * n
        else:
            spec = scenes.pyramid_spec(PYRAMIDS[case])
            pos, masses = [tuple(map(float, p)) for p in spec.positions], [float(m) for m in spec.masses]
        xml = _mujoco_boxes(pos, masses, 0.6, dt, iterations)
        # A free joint's qvel is (linear, angular) per body: the top box's x speed.
        kick = (lambda d: d.qvel.__setitem__(6 * (n - 1), KICK)) if case in STACKS else None
        ms, model, data = _mujoco_run(xml, seconds, dt, init=kick)
        p1 = data.qpos.reshape(-1, 7)[:, :3]
        return ms, float(np.linalg.norm(p1 - np.array(pos), axis=1).max())
    return None


ENGINES = {"pybullet": pybullet_case, "mujoco": mujoco_case}
#: Each peer's knobs and values (its defaults are dt 1/60 and its own iteration count).
PEER_SWEEPS = {
    "pybullet": {"dt": [1 / 30, 1 / 60, 1 / 120, 1 / 240, 1 / 480, 1 / 960], "iterations": [1, 2, 4, 10, 20, 50]},
    "mujoco": {"dt": [1 / 30, 1 / 60, 1 / 120, 1 / 240, 1 / 480, 1 / 960], "iterations": [1, 2, 4, 10, 20, 50]},
}
PEER_DEFAULT = {"pybullet": {"dt": 1 / 60, "iterations": 10}, "mujoco": {"dt": 1 / 60, "iterations": 100}}
