"""Hard cases of the world (issue 3, section 5), each with its threshold and why.

Known failures are pinned as strict xfails with what was measured, so they turn into
passes (and fail the xfail) the day the solver is fixed, and cannot be forgotten."""
from __future__ import annotations

import numpy as np
import pytest

import wmo
from wmo import scenes


state_hash = wmo.state_hash


@pytest.mark.parametrize("block_solver", [False, True])
def test_determinism_same_scene_twice_gives_the_same_bits(block_solver):
    # Box2D's determinism test: the same inputs and settings give the same bits.
    hashes = []
    for _ in range(2):
        w = scenes.mixed_pile(count=60, seed=11, block_solver=block_solver)
        w.step(300)
        hashes.append(state_hash(w))
    assert hashes[0] == hashes[1]
    w = scenes.mixed_pile(count=60, seed=12, block_solver=block_solver)
    w.step(300)
    assert state_hash(w) != hashes[0]  # the hash does see the state


@pytest.mark.parametrize("block_solver", [False, True])
def test_determinism_one_and_two_threads_give_the_same_bits(block_solver):
    # The hash test: the narrowphase splits the pairs into fixed parts and
    # joins them in order, so the thread count cannot change a bit of the result.
    # Enough pairs (a 200-body pile and 400 boxes) that the parallel path is taken.
    hashes = {}
    for threads in (1, 2):
        w = scenes.mixed_pile(count=200, seed=3, threads=threads, block_solver=block_solver)
        w.step(200)
        b = scenes.boxes3000(layers=6, threads=threads, sleeping=False, block_solver=block_solver)
        b.step(200)
        assert b.profile["narrowphase"]["count"] > 64
        hashes[threads] = (state_hash(w), state_hash(b))
    assert hashes[1] == hashes[2]


def test_determinism_the_solvers_regions_give_the_same_bits_on_any_thread_count():
    # The pyramid (~18,000 contact constraints, well above the 8,192 at which the solver
    # cuts a pile into four slabs whose passes run at once on a team of threads,
    # World::solve_order): 1, 2 and 3 threads (3: two slabs on one thread, one on each
    # of the others) give the same bits, and the run does move the boxes (the hash
    # sees the state).
    hashes = []
    for threads in (1, 2, 3):
        w = scenes.pyramid(threads=threads, sleeping=False)
        start = state_hash(w)
        w.step(30)
        assert w.profile["solve"]["count"] > 4 * 8192  # contact points: more than 8,192 manifolds
        hashes.append(state_hash(w))
    assert hashes[0] != start
    assert hashes[0] == hashes[1] == hashes[2]


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_random_scenes_never_produce_nan_or_escape(seed):
    # 10,000 steps of a random pile (spheres, capsules, hulls) dropped into a closed
    # box of static walls, sleeping off so every body is simulated every step. Nothing
    # may become NaN or infinite, and no body may leave the container (walls 0.5 m
    # thick: a body outside them tunnelled or exploded).
    w = scenes.mixed_pile(count=30, seed=seed, sleeping=False)
    for x, z, hx, hz in ((6.5, 0, 0.5, 7), (-6.5, 0, 0.5, 7), (0, 6.5, 7, 0.5), (0, -6.5, 7, 0.5)):
        w.add_body(wmo.Box((hx, 10, hz)), position=(x, 10, z), kind="static")
    w.add_body(wmo.Box((7, 0.5, 7)), position=(0, 20.5, 0), kind="static")  # lid
    rng = np.random.default_rng(seed)
    dyn = [i for i in range(len(w)) if w.body(i).kind == "dynamic"]
    for block in range(20):
        # Kick a few bodies now and then (about 5 m/s: fast bodies tunnel through 1 m walls
    # without CCD, which is issue 4) so the pile never just settles.
        for i in rng.choice(dyn, size=3, replace=False):
            b = w.body(int(i))
            w.apply_impulse(b, rng.normal(size=3) * 5 * b.mass, b.position)
        w.step(500)
        for a in (w.positions, w.orientations, w.linear_velocities, w.angular_velocities):
            assert np.isfinite(a).all(), f"non-finite state after {500 * (block + 1)} steps"
        # Centres of mass, not body origins: a hull's origin (the centre of the sphere
        # its points were drawn on) can lie outside the hull (seen: 3.8 mm past a face
        # of a 157 kg hull resting flat against a wall). A centre of mass lies at least
        # a quarter of the body's width behind any face it touches (Gruenbaum), so one
        # past a wall's inner face means the body is deep in the wall or through it.
        p = _world_centres_of_mass(w, dyn)
        assert (np.abs(p[:, [0, 2]]) < 6.0).all() and (p[:, 1] > -0.1).all() and (p[:, 1] < 20.0).all(), \
            f"a body left the container after {500 * (block + 1)} steps"


def _world_centres_of_mass(w, bodies):
    """World positions of the bodies' centres of mass: origin + R(q) c."""
    return np.array([w.positions[i] + _rotation(w.orientations[i]) @ np.asarray(w.body(i).center_of_mass)
                     for i in bodies])


def _rolling_ground(one_sided):
    """A triangle-mesh ground: 8 x 8 cells of 2 m, heights 0.2 sin(x + z) m (convex and
    concave edges, flat ones along the cells' diagonals)."""
    xs = np.linspace(-8, 8, 9)
    v = np.array([(x, 0.2 * np.sin(x + z), z) for x in xs for z in xs])
    t = [tri for i in range(8) for j in range(8)
         for tri in ((9 * i + j, 9 * i + j + 1, 9 * i + j + 9), (9 * i + j + 1, 9 * i + j + 10, 9 * i + j + 9))]
    return wmo.TriangleMesh(v, t, one_sided=one_sided)


def _random_shape(rng):
    # Sizes 8 to 80 cm, log-uniform; hulls squashed or stretched along y (flat discs
    # down to a few cm thick), and a box-and-ball compound.
    def s():
        return float(np.exp(rng.uniform(np.log(0.08), np.log(0.8))))
    k = rng.integers(0, 6)
    if k == 0:
        return wmo.Sphere(s())
    if k == 1:
        return wmo.Box((s(), s(), s()))
    if k == 2:
        return wmo.Capsule(s(), s())
    if k == 3:
        return wmo.Cylinder(s(), s())
    if k == 4:
        p = rng.normal(size=(int(rng.integers(4, 24)), 3))
        p /= np.linalg.norm(p, axis=1)[:, None]
        return wmo.ConvexHull(p * s() * np.array([1, s() / 0.4, 1]))
    return wmo.Compound([(wmo.Box((s(), s() / 3, s() / 3)), wmo.Pose()),
                         (wmo.Sphere(s() / 2), wmo.Pose(position=(0.5, 0, 0)))])


def test_a_one_sided_mesh_ground_pushes_a_sunken_box_back_up():
    # A box three quarters through a flat triangle-mesh ground, at rest. Two-sided, its
    # shortest way out is down: it is pushed through and falls. One-sided (the surface
    # of a solid below it), it is pushed up and rests on top: centre at its half height
    # within 1 cm (the contacts' speculative slop and sag are millimetres) and level.
    v = [[-5, 0, -5], [5, 0, -5], [5, 0, 5], [-5, 0, 5]]
    for one_sided in (False, True):
        w = wmo.World(sleeping=False)
        w.add_body(wmo.TriangleMesh(v, [[0, 2, 1], [0, 3, 2]], one_sided=one_sided), kind="static")
        box = w.add_body(wmo.Box((0.5, 0.5, 0.5)), position=(0.3, -0.25, 0.2))
        w.step(180)
        if one_sided:
            assert abs(box.position[1] - 0.5) < 0.01
            assert _tilt_degrees(box.orientation) < 0.1
        else:
            assert box.position[1] < -5


@pytest.mark.parametrize("heavy, drop", [(10.0, 0.05), (10.0, 0.3), (10.0, 1.0), (100.0, 0.3)])
def test_a_thin_plate_pressed_through_a_one_sided_mesh_ground_is_pushed_back(heavy, drop):
    # A 10 g plate 1 mm thick on a one-sided triangle-mesh ground, a 10 or 100 kg box
    # dropped on it, CCD on both, 10 s. The box lands and presses the plate into the
    # ground: its top never more than 1 mm below the surface (measured: 0.1-0.2 mm) and
    # it ends there, under the box. A body wholly behind a one-sided triangle is behind
    # the solid and gets no contact; the plate, pushed that far within one step, was
    # dropped and fell away (measured: 60-100 m below after 5 s). The world now tells
    # the narrowphase which triangles the pair touched at the last step
    # (CollideSettings::touched_before), and those push it back out.
    v = [[-5, 0, -5], [5, 0, -5], [5, 0, 5], [-5, 0, 5]]
    w = wmo.World(sleeping=False)
    w.add_body(wmo.TriangleMesh(v, [[0, 2, 1], [0, 3, 2]], one_sided=True), kind="static")
    plate = w.add_body(wmo.Box((0.3, 0.0005, 0.3)), position=(0, 0.0005, 0), mass=0.01, ccd=True)
    w.add_body(wmo.Box((0.25, 0.25, 0.25)), position=(0.05, 0.251 + drop, 0.02), mass=heavy, ccd=True)
    lowest = 0.0
    for _ in range(600):
        w.step()
        lowest = min(lowest, plate.position[1] + 0.0005)
    assert lowest > -0.001
    assert abs(plate.position[1]) < 0.002


@pytest.mark.parametrize("ccd", [False, True])
@pytest.mark.parametrize("heavy, drop", [(0.1, 0.1), (1.0, 1.0), (10.0, 0.1), (100.0, 1.0)])
def test_a_thin_plate_under_a_box_landing_on_it_stays_on_a_two_sided_mesh_ground(heavy, drop, ccd):
    # A 10 g plate 4 mm thick on a two-sided triangle-mesh ground, a 0.1-100 kg box
    # dropped on it, 10 s. The plate may be pressed into the sheet but never more than
    # 5 mm below it, and ends within 5 mm of it (measured: its centre at most 2.5 mm
    # below, ending 1.2 mm above without CCD, 2.1 mm below with it, under the box). A
    # two-sided sheet pushes a body out on whichever side less of it has passed: the
    # plate, pressed past its middle within one step, was pushed out below and fell
    # (100 m in 5 s; with CCD at every mass and drop, since the overlap projection
    # shared each push by mass; without, from 1 m). A touched triangle now keeps the
    # side it was touched from (CollideSettings::touched_before).
    v = [[-5, 0, -5], [5, 0, -5], [5, 0, 5], [-5, 0, 5]]
    w = wmo.World(sleeping=False)
    w.add_body(wmo.TriangleMesh(v, [[0, 2, 1], [0, 3, 2]]), kind="static")
    plate = w.add_body(wmo.Box((0.3, 0.002, 0.3)), position=(0, 0.002, 0), mass=0.01, ccd=ccd)
    w.add_body(wmo.Box((0.25, 0.25, 0.25)), position=(0.05, 0.254 + drop, 0.02), mass=heavy, ccd=ccd)
    lowest = 0.0
    for _ in range(600):
        w.step()
        lowest = min(lowest, plate.position[1])
    assert lowest > -0.005
    assert abs(plate.position[1]) < 0.005


@pytest.mark.parametrize("form", ["box", "hull", "compound"])
@pytest.mark.parametrize("load", [0.0, 0.01])
def test_a_thin_plate_resting_on_a_two_sided_mesh_at_a_long_substep_stays_in_front(load, form):
    # A 1 g plate 4 mm thick resting on a two-sided triangle-mesh ground at dt 1/30 with
    # one substep, alone or under a 10 g box, 10 s. The soft contacts' spring is capped
    # at a quarter of the substep rate (7.5 Hz against the ground) and its sag does not
    # depend on the body's size: the plate sank wholly behind the sheet (its top 0.44 mm
    # below, alone or loaded), where a sheet of no thickness no longer knows its side
    # (fuzz seed 1312 lost such a hull). Contacts now push an overlap past a quarter of
    # the thinner moving body's thickness out within the substep
    # (ContactConstraint::allow). Its top must stay in front of the sheet at every step
    # (measured: at least 2.5 mm alone, 0.8 mm loaded), and alone it must end less than
    # half its thickness deep (measured 1.3 mm, the allowance 1 mm). The same plate as a
    # hull whose points are turned 45 degrees about z in its own frame (the body turned
    # back, so it lies flat) is thin along no local axis: its thickness is taken from its
    # inner radius, not its local bounding box (7 cm high: an allowance of 18 mm). And
    # as the flat child of a compound with a 4 mm pin standing on one corner (a bounding
    # box 6.4 cm high): the allowance is the touching child's (1 mm; measured, alone, it
    # ends 1.1 mm deep); from the compound's bounding box (16 mm) it ended 2.5 mm deep,
    # and under the load its top came within 3 um of the sheet.
    v = [[-5, 0, -5], [5, 0, -5], [5, 0, 5], [-5, 0, 5]]
    w = wmo.World(dt=1 / 30, substeps=1, iterations=1)
    w.add_body(wmo.TriangleMesh(v, [[0, 2, 1], [0, 3, 2]], one_sided=False), kind="static")
    if form == "compound":
        pin = wmo.Box((0.002, 0.03, 0.002))
        plate = w.add_body(wmo.Compound([(wmo.Box((0.05, 0.002, 0.05)), wmo.Pose()),
                                         (pin, wmo.Pose(position=(0.048, 0.032, 0.048)))]),
                           position=(0, 0.002, 0), mass=0.001)
    elif form == "hull":
        c, s = np.cos(np.pi / 4), np.sin(np.pi / 4)
        turn = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
        corners = np.array([[x, y, z] for x in (-0.05, 0.05) for y in (-0.002, 0.002) for z in (-0.05, 0.05)])
        plate = w.add_body(wmo.ConvexHull(corners @ turn.T), position=(0, 0.002, 0), mass=0.001,
                           orientation=(0, 0, -np.sin(np.pi / 8), np.cos(np.pi / 8)))
    else:
        plate = w.add_body(wmo.Box((0.05, 0.002, 0.05)), position=(0, 0.002, 0), mass=0.001)
    if load:
        w.add_body(wmo.Box((0.04, 0.04, 0.04)), position=(0, 0.044, 0), mass=load)
    lowest_top = np.inf
    for _ in range(300):
        w.step()
        lowest_top = min(lowest_top, plate.position[1] + 0.002)
    assert lowest_top > 0
    if not load:
        assert plate.position[1] - 0.002 > -0.002


@pytest.mark.parametrize("one_sided", [True, False])
@pytest.mark.parametrize("seed", range(1, 11))
def test_random_piles_on_a_mesh_ground_with_ccd_never_escape(seed, one_sided):
    # 30 random bodies (spheres, boxes, capsules, cylinders, flat or long hulls, compounds;
    # density 100-5000 kg/m^3) dropped from up to 15 m onto a rolling triangle-mesh ground
    # in a box of static walls, three kicked at ~4 m/s every 300 steps, 3000 steps at the
    # defaults. Measured over seeds 1-40 (this file's scene), before the mesh contacts got
    # speculative rim points (collide_mesh.cpp): with a two-sided ground 18 scenes lost a
    # body through it, nearly all flat hulls whose first corner impact spins them at ~100
    # rad/s (1.7 rad a step), so their far side passes the zero-thickness ground before any
    # contact holds it and the two-sided rule then pushes them out below; one-sided, 4.
    # With the rim points: two-sided 10, one-sided 2 (seeds 18 and 22: a 2 cm disc
    # sliding at 6.5 m/s sinks 1 cm into the ground and is then wholly behind a face,
    # which ignores it); one-sided with ccd=True on every body, none of the 40 (two-sided
    # with CCD, 17; 13 once the CCD projection pushed along each contact's own side).
    # Since a touched triangle keeps the side it was touched from (a body pressed past
    # a two-sided sheet's middle within one step is pushed back), two-sided with CCD
    # also loses none of the 40.
    rng = np.random.default_rng(seed)
    w = wmo.World(sleeping=False)
    w.add_body(_rolling_ground(one_sided), kind="static")
    for x, z, hx, hz in ((8.5, 0, 0.5, 9), (-8.5, 0, 0.5, 9), (0, 8.5, 9, 0.5), (0, -8.5, 9, 0.5)):
        w.add_body(wmo.Box((hx, 10, hz)), position=(x, 9, z), kind="static")
    w.add_body(wmo.Box((9, 0.5, 9)), position=(0, 19.5, 0), kind="static")
    dyn = [w.add_body(_random_shape(rng), position=(rng.uniform(-6, 6), rng.uniform(3, 15), rng.uniform(-6, 6)),
                      density=float(np.exp(rng.uniform(np.log(100), np.log(5000)))),
                      friction=float(rng.uniform(0, 1)), ccd=True).index for _ in range(30)]
    for block in range(10):
        for i in rng.choice(dyn, size=3, replace=False):
            b = w.body(int(i))
            w.apply_impulse(b, rng.normal(size=3) * 4 * b.mass, b.position)
        w.step(300)
        p = w.positions[dyn]
        assert np.isfinite(p).all()
        # Inside the walls and above the ground's lowest point (-0.2 m) less 0.4 m.
        assert (np.abs(p[:, [0, 2]]) < 8.2).all() and (p[:, 1] > -0.6).all() and (p[:, 1] < 19.2).all(), \
            f"a body left the container after {300 * (block + 1)} steps"


def closed_frictionless_box(**world_kwargs):
    """No gravity, no friction, no restitution, no damping: 40 spheres and boxes fired
    around a closed container of static walls (wmo.scenes.closed_box)."""
    return scenes.closed_box(**world_kwargs)


def test_energy_never_exceeds_what_the_system_started_with():
    # Contacts can only remove kinetic energy (inelastic impacts): at no step may the
    # energy exceed the initial energy (1e-12 relative: round-off of the sum). Over 600
    # steps the impacts remove almost all of it.
    w = closed_frictionless_box()
    e0 = w.kinetic_energy()
    assert e0 > 100
    for k in range(600):
        w.step()
        assert w.kinetic_energy() <= e0 * (1 + 1e-12), f"energy above the start at step {k + 1}"
    assert w.kinetic_energy() < 0.05 * e0


@pytest.mark.xfail(strict=True, reason="issue 3, open: at the defaults 19 of 600 steps gain kinetic "
                   "energy, the largest by 3.0e-8 relative (step 255: a sphere on another, the soft contacts' "
                   "push-out kept as velocity where the two relax passes do not converge, the chain tests "
                   "below). With contact_push_max=0 (no push-out) 3 steps gain, up to 1.1e-9 (boxes turning "
                   "with a corner on a wall: the rows' anchors turn between the biased and the relax passes); "
                   "energy_guard_passes=8 (off by default, next test) leaves the same. Tried 2026-12-07: the "
                   "relax passes restarted from the velocities and impulses before the biased pass (split "
                   "impulses, emulated): 94 steps gained, up to 2.6e-3 (impacts in columns, left to the relax "
                   "passes alone, bounced). The warm-started impact that gained 8.0e-4 here (a column "
                   "of three spheres in a corner: the contact that stopped an impact carried its impulse "
                   "into the next step, and the relax passes did not take it all back) no longer occurs in "
                   "this scene since the broadphase boxes are swept by the static motion margin (the walls' "
                   "contacts come a step earlier); seed 3 has one (7.5e-4, next test)")
def test_energy_never_increases_from_one_step_to_the_next():
    # The demand, step by step: 1e-12 relative allows round-off of the sum.
    w = closed_frictionless_box()
    e = w.kinetic_energy()
    for k in range(600):
        w.step()
        e_next = w.kinetic_energy()
        assert e_next <= e * (1 + 1e-12), f"energy rose from {e} to {e_next} at step {k + 1}"
        e = e_next


def _pushed_out_chain(**world_kwargs):
    """Kinetic energy at the start and after each of 30 steps: two spheres (radius 0.3 m,
    113 kg) stacked on a static floor with no gravity or friction, each 0.5 mm into what
    is under it, the upper one approaching at 1.4 mm/s (0.11 mJ)."""
    w = wmo.World(gravity=(0, 0, 0), sleeping=False, **world_kwargs)
    w.add_body(wmo.Box((3, 0.5, 3)), position=(0, -0.5, 0), kind="static", friction=0.0)
    w.add_body(wmo.Sphere(0.3), position=(0, 0.2995, 0), friction=0.0, density=1000)
    w.add_body(wmo.Sphere(0.3), position=(0, 0.899, 0), linear_velocity=(0, -0.0014, 0), friction=0.0,
               density=1000)
    energies = [w.kinetic_energy()]
    for _ in range(30):
        w.step()
        energies.append(w.kinetic_energy())
    return np.array(energies)


def test_a_pushed_out_chain_gains_no_energy_when_its_relax_passes_converge():
    # The soft step pushes both overlaps out with a biased pass and then takes the push's
    # velocity back with unbiased (relax) passes. Run to convergence (50 passes) the
    # relax passes leave the chain no more energy than it had, and less, the approach
    # being stopped: the mechanism is sound when solved exactly.
    e = _pushed_out_chain(relax_iterations=50)
    assert (np.diff(e) <= 1e-12 * e[0]).all()
    assert e[-1] < 1e-6 * e[0]


@pytest.mark.xfail(strict=True, reason="issue 3, open: at the defaults (two relax passes, Gauss-Seidel) the "
                   "chain does not converge: the upper sphere keeps the push-out it got through the lower "
                   "one and leaves at 5 mm/s, its energy 12 times what it had (1.4 mJ against 0.11), the "
                   "closed box's largest gain (xfail above). 10 relax passes leave 0.2 mm/s, 50 none (test "
                   "above). Tried 2026-12-07, split push (Bullet's split impulse in the soft step: the biased "
                   "pass's bias on overlapping points drove push velocities of their own, which moved the "
                   "bodies over the substep and were then forgotten, the push's turn carrying w with it): "
                   "the chain gains nothing and the closed box's largest gain falls to 5.7e-10 (6.1e-11 "
                   "with rigid rows), but stacks lose the spring that carries them in the biased pass: with "
                   "the rows soft the pyramid moved 0.42 m in 600 steps and a box below its friction angle "
                   "crept 3.8 mm; with them rigid the 30-box towers fell (78 m). Not kept")
def test_a_pushed_out_chain_gains_no_energy_at_the_defaults():
    e = _pushed_out_chain()
    assert (np.diff(e) <= 1e-12 * e[0]).all()


@pytest.mark.parametrize("gyroscopic", [False, True])
def test_the_energy_guard_takes_back_a_warm_started_impact(gyroscopic):
    # The closed box (seed 3, which has a warm-started impact: two spheres pressed into
    # a corner of the ceiling) with the energy guard (energy_guard_passes=8): relax
    # passes are added to a substep until the bodies in contact have no more energy than
    # before its contact solve (to energy_guard_tolerance, 1e-6 relative a substep), so
    # no step may gain 4e-6 (four substeps of it). Measured: at most 3.0e-8 (9.1e-8 with
    # the gyroscopic term). Without the guard the same scene gains 7.5e-4 in one step
    # (step 566, gyroscopic term off): the test sees the guard. (Seed 7 had the impact
    # until the rows followed the inertia of fast-turning boxes, integrate_positions,
    # which changed the scenes' courses.)
    def largest_gain(**kw):
        w = closed_frictionless_box(seed=3, **kw)
        e, worst, added = w.kinetic_energy(), 0.0, 0
        for _ in range(600):
            w.step()
            e_next = w.kinetic_energy()
            worst = max(worst, (e_next - e) / e)
            added += w.energy_guard_added_passes
            e = e_next
        return worst, added
    worst, added = largest_gain(energy_guard_passes=8, gyroscopic=gyroscopic)
    assert worst < 4e-6
    assert added > 0
    if not gyroscopic:
        assert largest_gain(energy_guard_passes=0)[0] > 1e-4


@pytest.mark.parametrize("friction", [0.5, 0.0])
def test_a_body_swinging_on_one_contact_point_gains_no_energy(friction):
    # A cube (10 kg, 25 cm) with its centre of mass 0.48 m beyond one corner, hanging
    # from that corner on the ground: a pendulum on a one-point contact, given 0.5
    # rad/s (0.5 J of swing). Nothing may add energy: bound 5 mJ, 1% of the swing.
    # Measured: at most +4.2 mJ (friction 0.5) and +0.3 mJ (frictionless), rising and
    # falling with the swing (the integrator's energy error), no trend; it used to gain
    # 0.43 J and 1.1 J when the rows kept the step's anchors while the corner turned
    # away (ContactConstraintPoint::ca in contact_solver.h).
    w = wmo.World(gravity=(0, 0, -9.81), sleeping=False)
    w.add_body(wmo.Box((7.5, 7.5, 0.075)), position=(0, 0, -0.075), kind="static", friction=friction)
    d = np.array([1.0, 1.0, 1.0]) / np.sqrt(3)  # the corner's diagonal, turned to point down
    axis = np.cross(d, [0, 0, -1.0])
    q = np.array([*axis, 1 + d @ [0, 0, -1.0]])
    q /= np.linalg.norm(q)
    corner = _rotation(q) @ np.full(3, 0.125)
    b = w.add_body(wmo.Box((0.125,) * 3), position=-corner, orientation=q, mass=10.0,
                   center_of_mass=(0.4, 0.4, 0.4), friction=friction, angular_velocity=(0.5, 0, 0))

    def energy():
        com = b.position + _rotation(b.orientation) @ b.center_of_mass
        return w.kinetic_energy() + 10 * 9.81 * com[2]

    w.step(60)
    e0 = energy()
    for _ in range(17):
        w.step(60)
        assert w.contact_count == 1  # one corner all along
        assert energy() - e0 < 0.005


@pytest.mark.parametrize("spin", [10.0, 50.0, 200.0])
def test_a_ball_spinning_in_place_neither_sinks_nor_moves(spin):
    # A frictionless ball (r 0.5 m) spinning about a horizontal axis on the ground: its
    # contact stays at its bottom whatever it turns, so it must sit still at its spring
    # sag. With the rows' anchors turned as material points (Box2D v3 turns them in the
    # separation) the anchor swings off the contact: measured 2.6 mm / 1.2 cm / 14 cm
    # deep and 0.08 / 0.12 / 1.3 m/s of drift from nothing at 10 / 50 / 200 rad/s. Now:
    # 0.07 mm of sag (load / spring), no motion.
    w = wmo.World(gravity=(0, -9.81, 0), sleeping=False)
    w.add_body(wmo.Box((5, 0.5, 5)), position=(0, -0.5, 0), kind="static", friction=0.0)
    b = w.add_body(wmo.Sphere(0.5), position=(0, 0.5, 0), mass=1.0, friction=0.0,
                   angular_velocity=(spin, 0, 0))
    w.step(30)
    for _ in range(300):
        w.step()
        assert abs(b.position[1] - 0.5) < 2e-4
        assert np.linalg.norm(b.linear_velocity) < 1e-6
    assert b.angular_velocity[0] == pytest.approx(spin, rel=1e-9)


def _rod():
    # A rod with a ball at one end (1 m x 8 cm x 8 cm and r 8 cm): 4.3 kg at density
    # 500, principal inertias 0.0062 / 0.47 / 0.47 kg m^2 about its centre of mass (77:1).
    return wmo.Compound([(wmo.Box((0.5, 0.04, 0.04)), wmo.Pose()),
                         (wmo.Sphere(0.08), wmo.Pose(position=(0.5, 0, 0)))])


def _mechanical_energy(b, g=9.81):
    # Kinetic (translation and rotation about the centre of mass) plus potential (y up).
    r = _rotation(b.orientation)
    om, v = np.asarray(b.angular_velocity), np.asarray(b.linear_velocity)
    com = np.asarray(b.position) + r @ np.asarray(b.center_of_mass)
    return 0.5 * b.mass * v @ v + 0.5 * om @ (r @ np.asarray(b.inertia) @ r.T) @ om + b.mass * g * com[1]


@pytest.mark.parametrize("substeps, iterations, block_solver",
                         [(4, 4, False), (1, 10, False), (4, 4, True), (1, 10, True)])
def test_a_fast_spinning_rod_dropped_on_the_ground_gains_no_energy(substeps, iterations, block_solver):
    # The rod dropped from 1 m spinning at 170 rad/s about a random axis (2.8 rad a step
    # at 60 Hz), gyroscopic term on so that its flight keeps its energy, 12 seeds, 4 s
    # each: contacts may take energy out, never put it in. Bound: the energy at the start
    # plus the lift of pushing out the deepest penetration so far (m g depth: the soft
    # contacts' position correction raises the body by at most that) plus 1e-5 of it
    # (the gyroscopic integrator's error in flight, measured up to 3.5e-7 at one
    # substep). The contact rows used to apply impulses through the world inverse
    # inertia of the step's start while the rod turned radians within the step, which
    # is energy-consistent in that stale metric, not in the rod's: measured, 5 of 12
    # drops gained energy at these settings (up to 5.5 times), all 12 at one substep
    # of 10 iterations (one to 67,779 times, 376,000 rad/s). The rows now use the
    # inertia the body has after each substep (World::integrate_positions).
    for seed in range(12):
        rng = np.random.default_rng(seed)
        w = wmo.World(gravity=(0, -9.81, 0), substeps=substeps, iterations=iterations,
                      block_solver=block_solver, gyroscopic=True, sleeping=False)
        w.add_body(wmo.Box((10, 0.5, 10)), position=(0, -0.5, 0), kind="static")
        q = rng.normal(size=4)
        om = rng.normal(size=3)
        b = w.add_body(_rod(), position=(0, 1, 0), orientation=q / np.linalg.norm(q), density=500,
                       angular_velocity=om * 170 / np.linalg.norm(om))
        e0 = _mechanical_energy(b)
        depth = 0.0
        touched = False
        for k in range(240):
            w.step()
            touched = touched or w.contact_count > 0
            depth = max(depth, w.max_penetration)
            e = _mechanical_energy(b)
            assert e <= e0 * (1 + 1e-5) + b.mass * 9.81 * depth, \
                f"seed {seed}: energy {e:.1f} J at step {k + 1}, started with {e0:.1f} J"
        assert touched


@pytest.mark.parametrize("block_solver", [False, True])
def test_a_rod_spinning_flat_on_the_ground_gains_no_energy(block_solver):
    # The rod lying on the ground spinning at 50-200 rad/s about the vertical (and a few
    # rad/s about the horizontal axes), friction 0.3-1.5, 10 seeds, 5 s each: friction
    # and contacts only take energy out. Bound from one step to the next: the lift of
    # pushing out the last step's penetration (m g depth) plus 1e-6 of the start's
    # energy (round-off; measured 1.4e-15). Besides the refreshed inertia (test above)
    # this needs the friction rows' effective masses at the turned anchors (row_mass):
    # with the step's masses 1 of 10 seeds rose by 4.3% of its energy in one step; with
    # neither, 7 of 10 (one doubled its energy).
    for seed in range(10):
        rng = np.random.default_rng(seed)
        w = wmo.World(gravity=(0, -9.81, 0), block_solver=block_solver, sleeping=False)
        w.add_body(wmo.Box((10, 0.5, 10)), position=(0, -0.5, 0), kind="static")
        b = w.add_body(_rod(), position=(0, 0.09, 0), density=500, friction=float(rng.uniform(0.3, 1.5)),
                       angular_velocity=(rng.normal() * 5, rng.uniform(50, 200), rng.normal() * 5),
                       linear_velocity=(rng.normal(), 0, rng.normal()))
        e0 = e = _mechanical_energy(b)
        depth = 0.0
        for k in range(300):
            w.step()
            e_next = _mechanical_energy(b)
            assert e_next <= e + 1e-6 * e0 + b.mass * 9.81 * depth, \
                f"seed {seed}: energy rose from {e:.2f} J to {e_next:.2f} J at step {k + 1}"
            e, depth = e_next, w.max_penetration


def _tilt_degrees(q):
    # Angle between a box's up axis and the world's (q is x, y, z, w).
    return np.degrees(np.arccos(np.clip(_rotation(q)[1, 1], -1, 1)))


def _greenhill_hertz(n, half_extent, g=9.81):
    # The contact frequency below which a tower of n cubes of half-extent a buckles under
    # its own weight. Between two cubes each of the four corner rows is a spring of
    # stiffness m_eff (2 pi f)^2 with m_eff = m / 8 (1/m + (r x n).I^-1 (r x n) = 4/m per
    # body, r a corner, I = 2 m a^2 / 3), so a joint resists tilting with 4 m_eff
    # (2 pi f)^2 a^2 = m (2 pi f)^2 a^2 / 2 per radian: a column of bending stiffness EI
    # = that times the joint spacing 2a, loaded by its own weight q = m g / 2a over its
    # height L = 2 a n. Greenhill's column (clamped base, free top) buckles when q L^3 >
    # 7.837 EI, that is when (2 pi f)^2 < 4 g n^3 / (7.837 a).
    return np.sqrt(4 * g * n ** 3 / (7.837 * half_extent)) / (2 * np.pi)


def _kicked_tower(n, kick=0.01, **kw):
    # A tower whose top box is pushed sideways at `kick` m/s for a box of unit size (scaled
    # with the box; scenes.tower's kick): the perturbation that tells a stable tower from
    # an unstable equilibrium. A perfectly stacked tower stepped by a solver that treats a
    # contact's points symmetrically (block_solver, centroid_rows) never leaves its axis,
    # stable or not: unkicked, 28 unit boxes at the defaults stood 6000 steps with
    # centroid rows, where a 1 cm/s kick topples anything above 17. The rows alone kick a
    # tower themselves (each contact's first point takes the correction, the opposite one
    # the reaction).
    return scenes.tower(n, sleeping=False, kick=kick * 2 * kw.get("half_extent", 0.5), **kw)


SCHEMES = {"rows": {}, "centroid_rows": {"centroid_rows": True}, "block_solver": {"block_solver": True}}


@pytest.mark.parametrize("scheme", list(SCHEMES))
@pytest.mark.parametrize("n, half_extent, substeps", [(20, 0.5, 4), (30, 0.5, 8), (20, 0.25, 8), (12, 0.1, 8)])
def test_a_tower_stands_exactly_when_its_contacts_are_stiffer_than_greenhills_column(n, half_extent, substeps,
                                                                                      scheme):
    # The soft contacts make a tower of boxes an elastic column, and it stands or falls by
    # Greenhill's criterion (_greenhill_hertz) whatever the rows' scheme: kicked
    # (_kicked_tower), with contact_hertz 10% below the critical frequency every tower
    # here falls (some box more than 10% of the tower's height from its start within 3000
    # steps; measured 1.4-2.7 times the height), 10% above it stands (every box within 2%
    # of the height; measured 0.2-0.9%). At the defaults (36 Hz) the critical height of
    # unit boxes is 17 (measured: 17 stand 6000 steps, 18 fall by step 400), hence the
    # 30-box tower's xfail below: it needs 83 Hz, which takes 6 substeps (the cap is a
    # quarter of the substep rate). Substeps here so that 1.1x is under the cap.
    f = _greenhill_hertz(n, half_extent)
    height = 2 * half_extent * n
    for scale, falls in ((0.9, True), (1.1, False)):
        w = _kicked_tower(n, half_extent=half_extent, substeps=substeps, contact_hertz=scale * f, **SCHEMES[scheme])
        p0 = np.array(w.positions)
        worst = 0.0
        for _ in range(30):
            w.step(100)
            worst = max(worst, np.linalg.norm(w.positions - p0, axis=1).max())
        if falls:
            assert worst > 0.1 * height, f"stood at {scale} x {f:.1f} Hz"
        else:
            assert worst < 0.02 * height, f"moved {worst:.3f} m at {scale} x {f:.1f} Hz"


@pytest.mark.parametrize("scheme", ["centroid_rows", "block_solver"])
def test_symmetric_rows_keep_an_unkicked_tower_on_its_axis_but_do_not_raise_its_critical_height(scheme):
    # 20 unit boxes at the defaults, 3 above the critical height (17 at 36 Hz), 1000
    # steps. Unkicked, a scheme that treats each contact's points alike keeps the tower on
    # its axis: with centroid rows no box moves sideways at all (measured 0), with
    # block-solved manifolds round-off grows as an unstable equilibrium's does (measured
    # 1e-15 m at step 200, 5e-12 m at step 1000, five times more each 200 steps: 4e-5 m
    # by step 3000); under 1 um either way. The rows alone rock the same tower over
    # (measured 38 m). Kicked at 1 cm/s, it falls whatever the scheme (measured 2.0 and
    # 37 m): the symmetric rows do not make the springs stiffer.
    rows = scenes.tower(20, sleeping=False)
    p0 = np.array(rows.positions)
    rows.step(1000)
    assert np.linalg.norm(rows.positions - p0, axis=1).max() > 0.5
    w = scenes.tower(20, sleeping=False, **SCHEMES[scheme])
    w.step(1000)
    d = w.positions - p0
    assert np.hypot(d[:, 0], d[:, 2]).max() < 1e-6
    kicked = _kicked_tower(20, **SCHEMES[scheme])
    kicked.step(1000)
    assert np.linalg.norm(kicked.positions - p0, axis=1).max() > 0.5


def _stiff_tower_after(steps, **kw):
    # The 30-box tower at 8 substeps and 120 Hz, kicked (_kicked_tower): its start, and its
    # positions at steps[0] and at steps[1] with the largest motion from steps[0] seen at
    # the 100-step marks in between.
    w = _kicked_tower(30, substeps=8, contact_hertz=120, **kw)
    p0 = np.array(w.positions)
    w.step(steps[0])
    p_first = np.array(w.positions)
    moved = 0.0
    for _ in range((steps[1] - steps[0]) // 100):
        w.step(100)
        moved = max(moved, np.linalg.norm(w.positions - p_first, axis=1).max())
    return w, p0, moved


def test_tower_of_30_stands_for_6000_steps_with_stiff_contacts():
    # A soft contact of f Hz is a spring of stiffness m_eff (2 pi f)^2 per point, so a
    # tower of N unit boxes is an elastic column: it buckles below Greenhill's critical
    # frequency (83 Hz at N = 30, _greenhill_hertz; the defaults, 36 Hz, buckle it, see
    # the xfail below). 8 substeps allow 120 Hz (a quarter of the substep rate). "Stands":
    # kicked at 1 cm/s, after 6000 steps every box is within 5 cm (5% of its size) of
    # where it started and upright within 0.5 degrees. Measured: 2.6 cm at most, most of
    # it sideways: the tower sways (next test), so the 1 cm a rigid tower would allow is
    # not met. The sag follows the springs: 900 g / (2 pi f)^2 = 15.5 mm for this tower
    # (per-point loads over per-point effective masses), within 20%.
    w, p0, _ = _stiff_tower_after((600, 6000))
    d = w.positions - p0
    assert np.linalg.norm(d, axis=1).max() < 0.05
    assert max(_tilt_degrees(q) for q in w.orientations[1:]) < 0.5
    sag = -d[-1, 1]
    assert abs(sag - 900 * 9.81 / (2 * np.pi * 120) ** 2) < 0.2 * 0.0155


@pytest.mark.xfail(strict=True, reason="issue 3, open: at the default two relax passes the stiff 30-box "
                   "tower never comes to rest: kicked at 1 cm/s it still moves 17 mm (rows alone) and 16 mm "
                   "(block-solved manifolds) over steps 5000-6000 (the block solver's sway decays with a time "
                   "constant of about 100 s: a 10 cm/s kick's swing went from 32 to 17 mm peak to peak "
                   "over 6000 steps). What damps the sway is the relax passes, an inelastic projection of the "
                   "velocities, and two Gauss-Seidel passes over a 30-box chain are far from converged: "
                   "with 10 the tower comes to rest (next test); 10 boxes come to rest within 500 steps "
                   "at two. Unkicked, block-solved manifolds keep it on its axis, still to 1e-13 m: the "
                   "symmetric equilibrium (test_symmetric_rows_...), which the rows alone break")
@pytest.mark.parametrize("scheme", ["rows", "block_solver"])
def test_tower_of_30_comes_to_rest_with_stiff_contacts(scheme):
    # Still: under 2 mm of motion over the last 1000 of 6000 steps (100 s) after the kick.
    _, _, moved = _stiff_tower_after((5000, 6000), **SCHEMES[scheme])
    assert moved < 0.002


@pytest.mark.parametrize("scheme", ["rows", "block_solver"])
def test_tower_of_30_comes_to_rest_with_stiff_contacts_and_converged_relax_passes(scheme):
    # The same kicked tower with relax_iterations=10: the relax passes, which take the
    # approach out of the velocities inelastically, are what damp its sway, and 10 of
    # them converge far enough over the 30-box chain (2 do not: xfail above). Still: under
    # 2 mm over steps 5000-6000 (measured 0.51 mm with the rows alone, 0.053 mm
    # block-solved; with block-solved manifolds the swing of a 10 cm/s kick falls e-fold
    # in ~500 steps, 32.8 -> 1.4 mm peak to peak in 3000), and within the 5 cm of the
    # standing test.
    w, p0, moved = _stiff_tower_after((5000, 6000), relax_iterations=10, **SCHEMES[scheme])
    assert moved < 0.002
    assert np.linalg.norm(w.positions - p0, axis=1).max() < 0.05


def test_load_stiffened_contacts_hold_a_30_box_tower_at_8_substeps():
    # At 8 substeps and the default 36 Hz, 30 unit boxes buckle as an elastic column
    # under its own weight does (their springs hold the tilt, and are as soft at the
    # base, under 29 boxes, as at the top): kicked at 1 cm/s (_kicked_tower), 0.5 m off
    # by step ~300, down by ~800. With contact_max_sag=1e-3 each contact is stiffened in
    # proportion to the weight on it (estimated from the support graph), so no contact
    # sags more than 1 mm: the kicked tower stands through step 3000 within 10 cm of its
    # start (a tenth of a box; measured 7.3 cm, the sag and a slow sway; unkicked, 3.3 cm;
    # the unstiffened springs would sag 17 cm; 8 substeps let a contact be stiffened up
    # to 11x, 4 only 2.8x).
    plain = _kicked_tower(30, substeps=8, centroid_rows=True)
    p0 = np.array(plain.positions)
    plain.step(1000)
    assert np.linalg.norm(plain.positions - p0, axis=1).max() > 0.5
    w = _kicked_tower(30, substeps=8, centroid_rows=True, contact_max_sag=1e-3)
    for _ in range(30):
        w.step(100)
        assert np.linalg.norm(w.positions - p0, axis=1).max() < 0.1
    assert max(_tilt_degrees(q) for q in w.orientations[1:]) < 0.5


@pytest.mark.parametrize("ratio, crush", [(100.0, 0.03), (1000.0, 0.25)])
def test_load_stiffening_keeps_a_light_box_under_a_heavy_one(ratio, crush):
    # contact_max_sag stiffens the light box's contacts, which carry the heavy box's
    # weight, but never past what the substep resolves (a quarter of its rate, the
    # contact_hertz cap). Uncapped, the rows got too stiff for the substep and pumped:
    # the 1 kg box was squeezed 0.7 m out from under 100 kg and shot ~300 m away from
    # under 1000 kg. Capped it stays under, crushed less than without stiffening
    # (measured 1.8 / 18 cm; without: 2.8 / 34 cm; `crush` bounds the displacement).
    w = wmo.World(contact_max_sag=1e-3, sleeping=False)
    w.add_body(wmo.Box((5, 0.5, 5)), position=(0, -0.5, 0), kind="static")
    light = w.add_body(wmo.Box((0.5, 0.5, 0.5)), position=(0, 0.5, 0), mass=1.0)
    w.add_body(wmo.Box((0.5, 0.5, 0.5)), position=(0, 1.5, 0), mass=ratio)
    p0 = np.array(w.positions)
    for _ in range(10):
        w.step(60)
        assert np.linalg.norm(w.positions - p0, axis=1).max() < crush
    assert abs(light.position[0]) < 0.1 and abs(light.position[2]) < 0.1


def test_load_stiffening_is_checked_and_off_by_default():
    assert wmo.World().settings["contact_max_sag"] == 0.0
    assert wmo.World().settings["centroid_rows"] is False
    with pytest.raises(ValueError, match="contact_max_sag"):
        wmo.World(contact_max_sag=-1e-3)
    with pytest.raises(ValueError, match="contact_max_sag"):
        wmo.World(contact_max_sag=float("nan"))


@pytest.mark.xfail(strict=True, reason="issue 3, open: at the default soft step (4 substeps, 36 Hz) a "
                   "30-box tower buckles by step ~600, as an elastic column under its own weight does "
                   "when its springs are too soft for its height: by Greenhill's criterion (test above, "
                   "which it follows to a few percent) unit boxes stand to 17 at 36 Hz, 30 need 83 Hz, "
                   "which the soft step resolves from 6 substeps: at 4 no stiffness under its cap (60 Hz, a "
                   "quarter of the substep rate) holds more than 24 unit cubes, even graded by load (a "
                   "discrete column model, which puts the 30-box threshold at 81 Hz, measured 80-85), and "
                   "a cap of 0.4 of the rate (tried 2026-12-07) let 90 Hz fall by step 500 at 4 substeps "
                   "and pumped a 1 kg box out from under 1000 kg (270 m); centroid_rows=True and block_solver=True "
                   "hold no more than the rows alone once kicked (17; unkicked, centroid rows keep even 28 on "
                   "its axis, an unstable equilibrium: test_symmetric_rows_...). 6 "
                   "substeps at 90 Hz hold it 6000 steps, swaying up to 29 cm (near the criterion); within 5 cm: "
                   "120 Hz at 8 substeps; within 10 cm: 8 substeps with load-stiffened contacts (contact_max_sag, tests above), both twice the "
                   "solve cost; load stiffening at 4 substeps delays the fall but does not stop it, even with "
                   "its cap (a quarter of the substep rate) lifted 100-fold (down by step ~900). Measured "
                   "2026-12-07, falling (0.5 m off) by step: iterations 2-10 or relax_iterations 4-10, "
                   "300-500; contact_hertz 60 (the cap), 500; block_solver=True, ~3200 unkicked; rigid rows (no "
                   "softness, the soft bias kept: an experiment, not a setting) ~300, standing only at 30 "
                   "iterations, 6.5x the step. The peers, kicked the same way (benchmarks/accuracy/run.py "
                   "--cases tower30, 20 s): PyBullet and MuJoCo topple it at their defaults too (30 and 31 m "
                   "at dt 1/60); MuJoCo holds it from dt 1/120 (7.1 cm, 14.7 ms a simulated second), PyBullet "
                   "from dt 1/960 (7.9 cm, 92 ms), WMO from 6 substeps at the cap, 90 Hz (5.6 cm, 11.1 ms; 8 "
                   "substeps and 120 Hz: 4.1 cm, 14-15 ms)")
def test_tower_of_30_stands_for_6000_steps_at_the_defaults():
    w = _kicked_tower(30)
    p0 = np.array(w.positions)
    w.step(6000)
    assert np.linalg.norm(w.positions - p0, axis=1).max() < 0.03


def test_heavy_box_on_a_light_one_stands():
    # 100:1 (100 kg on 1 kg, unit boxes) at 60 Hz, the stiffest contact 4 substeps
    # allow. Gauss-Seidel solved from the top down carries the heavy box's weight to the
    # ground within one pass; in broadphase order the light box rocks loose and the
    # stack falls (measured before the ordering: 1.7 m). "Stands": both boxes within
    # 3 cm of where they started, upright within 0.5 degrees, still from step 600 to
    # 6000 (1 mm). The sag is the springs': about 2 x 100 g / (2 pi 60)^2 = 14 mm.
    w = wmo.World(sleeping=False, contact_hertz=60)
    scenes.ground_box(w, friction=0.5)
    w.add_body(wmo.Box((0.5, 0.5, 0.5)), position=(0, 0.5, 0), mass=1.0)
    w.add_body(wmo.Box((0.5, 0.5, 0.5)), position=(0, 1.5, 0), mass=100.0)
    p0 = np.array(w.positions)
    w.step(600)
    p600 = np.array(w.positions)
    w.step(5400)
    assert np.linalg.norm(w.positions - p0, axis=1).max() < 0.03
    assert max(_tilt_degrees(q) for q in w.orientations[1:]) < 0.5
    assert np.linalg.norm(w.positions - p600, axis=1).max() < 0.001


def _box_on_slope(theta_deg, mu):
    th = np.radians(theta_deg)
    q = (0.0, 0.0, np.sin(th / 2), np.cos(th / 2))  # the slope rises towards +x
    w = wmo.World(gravity=(0, -9.81, 0), sleeping=False)
    w.add_body(wmo.Box((20, 0.5, 5)), orientation=q, kind="static", friction=np.sqrt(mu))
    up = np.array([-np.sin(th), np.cos(th), 0.0])
    b = w.add_body(wmo.Box((0.5, 0.5, 0.5)), position=up, orientation=q, friction=np.sqrt(mu))
    downhill = np.array([-np.cos(th), -np.sin(th), 0.0])
    return w, b, downhill


@pytest.mark.parametrize("theta", [20.0, 25.0, 29.0])
def test_box_below_the_friction_angle_does_not_creep(theta):
    # Friction 0.6: friction angle 31 degrees. Resting on the slope, the box may settle
    # into its contact (the springs' sag, 0.1-0.2 mm measured) but must not creep:
    # under 1 mm down the slope in 10 s, and under 0.01 mm in the last 5 s.
    w, b, downhill = _box_on_slope(theta, 0.6)
    x0 = np.array(b.position)
    w.step(300)
    x5 = np.array(b.position)
    w.step(300)
    assert np.dot(np.asarray(b.position) - x0, downhill) < 1e-3
    assert abs(np.dot(np.asarray(b.position) - x5, downhill)) < 1e-5


@pytest.mark.parametrize("theta", [35.0, 45.0])
def test_box_above_the_friction_angle_slides_with_the_analytic_acceleration(theta):
    # a = g (sin theta - mu cos theta); the velocity grows by a dt per step once
    # sliding: within 2% (the issue's bound; measured 1e-4). The friction rows' first
    # tangent follows the slip: with a fixed basis the two rows' different effective
    # masses turned the friction off the slip, 5% too weak at 35 degrees.
    w, b, downhill = _box_on_slope(theta, 0.6)
    th = np.radians(theta)
    a = 9.81 * (np.sin(th) - 0.6 * np.cos(th))
    w.step(30)
    v0 = np.dot(b.linear_velocity, downhill)
    w.step(60)
    v1 = np.dot(b.linear_velocity, downhill)
    assert abs((v1 - v0) / 1.0 - a) < 0.02 * a


def test_pyramid_stands_for_600_and_6000_steps():
    # The bar, at the defaults: every box within 1 cm of its start after 600 and
    # after 6000 steps, sleeping off, and the pile at rest (under 1 mm of motion from
    # step 600 to 6000). Measured: 8.3 mm at both (2.1 mm of it sideways, the rest the
    # springs' sag), no motion after step 600. The defaults that hold it: 36 Hz
    # contacts, static contacts at twice that, two relax passes forward then backward
    # (SolverSettings::contact_hertz has the measurements behind them); Box2D v3's 30
    # Hz with one relax pass moved a box 1.9 cm, 1.1 cm of it creeping sideways.
    w = scenes.pyramid(sleeping=False)
    p0 = np.array(w.positions)
    w.step(600)
    assert np.linalg.norm(w.positions - p0, axis=1).max() < 0.01
    p600 = np.array(w.positions)
    w.step(5400)
    assert np.linalg.norm(w.positions - p0, axis=1).max() < 0.01
    assert np.linalg.norm(w.positions - p600, axis=1).max() < 0.001


def test_projectile_follows_the_integrators_closed_form():
    # h = dt / substeps; a free body takes each substep's gravity first, v_k = v0 + k h g,
    # and moves with the substep's mean velocity, so it follows the exact parabola
    # x_k = x0 + k h v0 + g (k h)^2 / 2 (plain semi-implicit Euler adds h^2 g k / 2, 5 cm
    # low here), exactly up to rounding (1e-9 m over 2400 substeps of metre-scale sums).
    w = wmo.World(gravity=(0, -9.81, 0), dt=1 / 60, substeps=4, sleeping=False)
    b = w.add_body(wmo.Sphere(0.1), position=(1, 2, 3), linear_velocity=(3, 4, -1))
    w.step(600)
    k, h = 2400, 1 / 240
    g = np.array([0, -9.81, 0])
    x = np.array([1, 2, 3]) + k * h * np.array([3, 4, -1]) + h * h * g * k * k / 2
    np.testing.assert_allclose(b.position, x, atol=1e-9)
    np.testing.assert_allclose(b.linear_velocity, np.array([3, 4, -1]) + k * h * g, atol=1e-9)


def test_a_body_that_does_not_turn_keeps_its_orientation_bit_for_bit():
    # integrate_rotation leaves q alone when w is exactly 0, the exact answer. (Before, each
    # substep renormalised q; on the quaternions add_body stores that was idempotent in
    # practice, 300 random ones tried, so this pins the property, not the speed-up.) A
    # turning body is still integrated and kept unit to rounding.
    w = wmo.World(gravity=(0, -9.81, 0), dt=1 / 60, substeps=4, sleeping=False)
    q = np.array([0.1, -0.7, 0.3, 0.6])
    still = w.add_body(wmo.Box((0.3, 0.2, 0.1)), position=(0, 5, 0), orientation=q / np.linalg.norm(q))
    turning = w.add_body(wmo.Box((0.3, 0.2, 0.1)), position=(5, 5, 0), angular_velocity=(0.3, 2.0, -1.0))
    q_still, q_turning = still.orientation.copy(), turning.orientation.copy()
    w.step(600)
    assert np.array_equal(still.orientation, q_still)
    assert not np.allclose(turning.orientation, q_turning)
    assert abs(np.linalg.norm(turning.orientation) - 1) < 1e-14


def _rotation(q):
    x, y, z, w = q
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def _momentum_and_energy(body, half_extents):
    a, b, c = 2 * np.asarray(half_extents)
    inertia = body.mass / 12 * np.diag([b * b + c * c, a * a + c * c, a * a + b * b])
    r = _rotation(body.orientation)
    w = np.asarray(body.angular_velocity)
    ang = r @ inertia @ r.T @ w
    return ang, 0.5 * w @ ang


@pytest.mark.parametrize("half_extents, w0", [
    ((0.1, 0.3, 0.6), (0.01, 5.0, 0.0)),   # near the intermediate axis: flips
    ((0.02, 0.02, 1.0), (0.5, 0.3, 20.0)),  # 50:1 rod spinning about its long axis
    ((0.02, 0.02, 1.0), (3.0, 0.1, 0.0)),   # the same rod tumbling end over end
    ((0.1, 0.3, 0.6), (7.0, -3.0, 11.0)),   # a general spin
])
def test_gyroscopic_spin_conserves_angular_momentum(half_extents, w0):
    # Torque-free: the world angular momentum and the energy are conserved. The
    # integrator keeps the momentum exactly while rotating, so 1e-10 relative over
    # 6000 steps is round-off. The rotation's midpoint rule alone lets the energy drift
    # (measured over 6000 steps at dt 1/60, 4 substeps: -3.5% for the spinning rod,
    # +2.6e-5 near the intermediate axis); the energy-momentum projection after it
    # keeps it to 1e-8 relative (measured: at most 2.5e-10, the sum of the errors of
    # 1e-13 E it leaves per substep as round-off).
    w = wmo.World(gravity=(0, 0, 0), gyroscopic=True, sleeping=False)
    b = w.add_body(wmo.Box(half_extents), angular_velocity=w0)
    l0, e0 = _momentum_and_energy(b, half_extents)
    for _ in range(60):
        w.step(100)
        ang, e = _momentum_and_energy(b, half_extents)
        assert np.linalg.norm(ang - l0) <= 1e-10 * np.linalg.norm(l0)
        assert abs(e - e0) <= 1e-8 * e0


@pytest.mark.parametrize("w0", [(400.0, 300.0, 200.0), (2000.0, 100.0, 50.0)])
def test_gyroscopic_fast_spin_keeps_its_energy(w0):
    # A small box (0.1 x 0.2 x 0.4 m, 0.5 kg) spinning at 540 and 2000 rad/s: 2.3 and
    # 8.3 rad a substep. The implicit midpoint's fixed point does not converge at such
    # turns; taken whole, the energy rose by 2.8% and by 300% (|L| kept, the spin
    # pushed towards the minor axis), and in a random pile a light hull kicked off its
    # centre to 600 rad/s spun itself up to 15,000 rad/s and flew 130 km. The turn is
    # now taken in parts of at most 0.25 rad: |L| to 1e-10 and the energy never more
    # than 1e-6 above the start over 6000 steps (measured: 0 and 5.5e-7).
    half = (0.05, 0.1, 0.2)
    w = wmo.World(gravity=(0, 0, 0), gyroscopic=True, sleeping=False)
    b = w.add_body(wmo.Box(half), mass=0.5, angular_velocity=w0)
    l0, e0 = _momentum_and_energy(b, half)
    for _ in range(60):
        w.step(100)
        ang, e = _momentum_and_energy(b, half)
        assert np.linalg.norm(ang - l0) <= 1e-10 * np.linalg.norm(l0)
        assert e <= e0 * (1 + 1e-6)


# A thin rod, 1.04 m x 3.9 cm x 3.9 cm, 0.62 kg (principal inertias 1:383), tumbling at
# 60 rad/s: the body of a random-scene fuzz (scripts/fuzz_worlds.py, seed 316) that blew
# up to NaN.
_THIN_ROD = dict(half=(0.5219735905402046, 0.01938522990405698, 0.0196757398289545), mass=0.618757172101693,
                 orientation=(-0.83183849, -0.11295245, -0.27283419, 0.46994466),
                 angular_velocity=(0.63231761, 31.62333319, -51.04977782))


@pytest.mark.parametrize("substeps, dt", [(1, 1 / 30), (1, 1 / 60), (2, 1 / 30), (4, 1 / 60), (8, 1 / 30), (16, 1 / 30)])
def test_gyroscopic_thin_rod_keeps_its_energy_at_any_step(substeps, dt):
    # Torque-free, 100 steps: the energy to 1e-9 relative and the angular momentum to
    # 1e-12 (measured: at most 5.2e-11 and 6e-13). The rotation's parts were sized once,
    # from the speed at the substep's start, at most 0.25 rad each: the implicit
    # midpoint's fixed point contracts by about h |w| times the inertia ratio, so at
    # 0.25 rad it did not converge for this rod; the energy rose 1.8% in one substep
    # (beyond the projection's small corrections), and at one substep of 1/60 s the rod
    # went from 60 to 2,647 rad/s (energy 8.2 times its start). Parts are now halved until the
    # fixed point converges.
    w = wmo.World(gravity=(0, 0, 0), dt=dt, substeps=substeps, gyroscopic=True, sleeping=False)
    b = w.add_body(wmo.Box(_THIN_ROD["half"]), mass=_THIN_ROD["mass"], orientation=_THIN_ROD["orientation"],
                   angular_velocity=_THIN_ROD["angular_velocity"])
    l0, e0 = _momentum_and_energy(b, _THIN_ROD["half"])
    for _ in range(100):
        w.step()
        ang, e = _momentum_and_energy(b, _THIN_ROD["half"])
        assert np.linalg.norm(ang - l0) <= 1e-12 * np.linalg.norm(l0)
        assert abs(e - e0) <= 1e-9 * e0


@pytest.mark.parametrize("substeps, iterations, dt", [(8, 2, 1 / 30), (4, 10, 1 / 30), (4, 4, 1 / 60), (1, 10, 1 / 60)])
def test_a_spinning_thin_rod_thrown_at_a_wall_with_ccd_gains_no_energy(substeps, iterations, dt):
    # The thin rod at 8 m/s into a static wall, gyroscopic term and CCD on, 1 s: contacts
    # and the CCD stage may take energy out, never put it in (1e-9 of it: round-off;
    # measured, none gained). The CCD stage put the body back at its time of impact with
    # the angular velocity of the step's end, which with the gyroscopic term belongs to
    # the end's orientation: turned back, the rod had a spin about its long axis now
    # across it (energy 11,000 and 2.1e6 times at the first two settings, 180 times at
    # one substep, where the free flight's error above added to it; none at the third).
    # The angular velocity now turns back with the body.
    w = wmo.World(dt=dt, substeps=substeps, iterations=iterations, gyroscopic=True, sleeping=False)
    w.add_body(wmo.Box((0.5, 12, 11)), position=(10.5, 11, 0), kind="static")
    b = w.add_body(wmo.Box(_THIN_ROD["half"]), mass=_THIN_ROD["mass"], orientation=_THIN_ROD["orientation"],
                   angular_velocity=_THIN_ROD["angular_velocity"], position=(9.08667797, 3.46573204, -2.46356529),
                   linear_velocity=(6.80562985, 4.59103416, -1.12725519), friction=1.13, ccd=True)
    e0 = _mechanical_energy(b)
    hits = 0
    for _ in range(round(1 / dt)):
        w.step()
        hits += w.ccd_hits
        assert _mechanical_energy(b) <= e0 * (1 + 1e-9)
    assert hits > 0  # the CCD stage put the rod back at least once: the test sees it


def test_gyroscopic_intermediate_axis_flips_and_is_absent_without_the_term():
    # Dzhanibekov effect: a spin about the intermediate principal axis (body y here,
    # half-extents 0.1, 0.3, 0.6) with a 0.2% perturbation reverses its body-frame
    # component within 10 s. Without the gyroscopic term the world angular velocity is
    # constant, so nothing flips: the test sees the term.
    for gyro in (True, False):
        w = wmo.World(gravity=(0, 0, 0), gyroscopic=gyro, sleeping=False)
        b = w.add_body(wmo.Box((0.1, 0.3, 0.6)), angular_velocity=(0.01, 5.0, 0.0))
        body_wy = []
        for _ in range(600):
            w.step()
            body_wy.append((_rotation(b.orientation).T @ np.asarray(b.angular_velocity))[1])
        if gyro:
            assert min(body_wy) < -4.5 and max(body_wy) > 4.9  # flipped to about -5 rad/s
        else:
            np.testing.assert_allclose(b.angular_velocity, (0.01, 5.0, 0.0), atol=1e-12)


def _bounce_apex(e, dt, threshold=1.0):
    # A ball of radius 0.1 dropped from 1 m (bottom at 1 m) onto a static box, g = 10;
    # returns the height of the first rebound's apex (sampled at step ends).
    w = wmo.World(gravity=(0, -10, 0), dt=dt, restitution_threshold=threshold)
    w.add_body(wmo.Box((50, 1, 50)), position=(0, -1, 0), kind="static", restitution=e)
    b = w.add_body(wmo.Sphere(0.1), position=(0, 1.1, 0), restitution=e)
    apex, bounced = 0.0, False
    for _ in range(int(3 / dt)):
        w.step()
        vy, y = b.linear_velocity[1], b.position[1] - 0.1
        bounced = bounced or vy > 0
        if bounced:
            apex = max(apex, y)
            if vy < 0:
                break
    return apex


def test_ball_bounces_to_e_squared_height_at_the_default_step():
    # e = 0.8 at dt 1/60: within the 2% of e^2 h (measured -0.2%). Restitution
    # reverses the approach speed of the substep where the contact first pushes, not
    # the step's start (which was a step of gravity slower: 8.7% low with e = 0.5).
    assert _bounce_apex(0.8, 1 / 60) == pytest.approx(0.64, rel=0.02)


def test_ball_bounces_to_e_squared_height_with_a_low_restitution():
    # e = 0.5 at dt 1/60: 4.5 m/s at impact, 7.5 cm a step. Two things bring it within
    # 2% of e^2 h (measured -0.5%): the pair with the static ground gets a margin that
    # covers the step's approach (speculative_motion_static), so the contact exists
    # before the ball arrives (without it the ball sinks 1.25 cm first: -1.1%; it was
    # 2.2 cm and -5.6% with plain semi-implicit Euler in flight); and a free body moves
    # with each substep's mean velocity, exact under gravity (plain semi-implicit Euler
    # loses v h / 2 of height on the way up: -2.8% with the margin).
    assert _bounce_apex(0.5, 1 / 60, threshold=0.1) == pytest.approx(0.25, rel=0.02)
    assert _bounce_apex(0.3, 1 / 60, threshold=0.1) == pytest.approx(0.09, rel=0.02)  # measured -1.6%


def _stack_and_slider(offset, rotated_ground=False):
    # A 10-box stack (boxes of 0.4 m) and a box sliding at 2 m/s on a 100 m ground
    # centred at `offset`. The ground is large on purpose: its contact anchors are tens
    # of metres from its centre, the case where a solver carrying separations as big
    # offsets cancelled by big anchors loses precision. The boxes start 1.3 mm apart:
    # from exactly touching, a separation of 0 or of +1e-14 (the rounding of a far
    # position) picks the penetrating or the speculative branch of the contact row, two
    # valid but different answers, and the runs part by 1e-5 m at once (measured).
    o = np.asarray(offset, dtype=float)
    w = wmo.World(gravity=(0, -9.81, 0), sleeping=False)
    w.add_body(wmo.Box((50, 0.5, 50)), position=o + (0, -0.5, 0), kind="static", friction=0.7)
    for k in range(10):
        w.add_body(wmo.Box((0.2, 0.2, 0.2)), position=o + (30, 0.2013 + 0.4013 * k, -20), mass=1.0,
                   friction=0.7)
    w.add_body(wmo.Box((0.2, 0.2, 0.2)), position=o + (-40, 0.2013, 35), linear_velocity=(2, 0, 0), mass=1.0,
               friction=0.7)
    return w, o


@pytest.mark.parametrize("offset", [(1e4, 0, 0), (-7e3, 3e3, 5e3), (1e5, 0, 1e5)])
def test_far_from_the_origin_a_scene_does_what_it_does_at_the_origin(offset):
    # The same scene at the origin and 10-140 km away: positions are doubles (ulp 1.5e-11
    # m at 1e5 m) and the solver works only on quantities relative to the bodies, so the
    # two runs may differ by rounding, not by behaviour. Bar: every body within 0.1 mm
    # of its twin after 300 steps (the 0.1 mm at 10 km), the stack standing and
    # the slider stopped by friction at the same place (measured: 3e-8 m apart at most).
    near, o0 = _stack_and_slider((0, 0, 0))
    far, o1 = _stack_and_slider(offset)
    p0 = np.array(near.positions)
    near.step(300)
    far.step(300)
    np.testing.assert_allclose(far.positions - o1, near.positions - o0, atol=1e-4)
    # The stack stands: its boxes stay within 1 cm of their start sideways (the springs
    # sag it by 2.8 cm: small boxes have small effective masses at their corners).
    assert np.linalg.norm((near.positions[1:11] - p0[1:11])[:, [0, 2]], axis=1).max() < 0.01
    assert np.linalg.norm(near.linear_velocities[11]) < 1e-3  # the slider has stopped
