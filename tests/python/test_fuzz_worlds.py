"""Random worlds of scripts/fuzz_worlds.py (every setting, shape and mass ratio, kicks,
bodies added and removed; 2000 steps each), pinned: the seeds that found a defect, now
fixed, must hold, and the ones that still fail are strict xfails saying why.

With CCD on every dynamic body, losing a body through the ground or the walls, or any
non-finite state, is a defect. (A body without CCD may tunnel through a thin wall:
fuzz_worlds.py reports those too, as a known limit.)"""
from __future__ import annotations

import importlib.util
import pathlib

import pytest

_SCRIPT = pathlib.Path(__file__).resolve().parents[2] / "scripts" / "fuzz_worlds.py"
_spec = importlib.util.spec_from_file_location("fuzz_worlds", _SCRIPT)
fuzz = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(fuzz)

GROUNDS = ("box", "plane", "one-sided")


def _holds(seed, grounds=GROUNDS):
    """The scene of `seed` over 2000 steps, CCD on every body: no body lost, nothing
    non-finite."""
    why, _settings = fuzz.run(seed, 2000, 1.0, grounds)
    assert why is None, f"seed {seed}: {why}"


@pytest.mark.parametrize("seed", [35, 202, 266, 267, 295, 316, 549])
def test_a_random_world_that_found_a_defect_now_holds(seed):
    # The engine of commit 11da153 (before the fixes of 2026-12-06), on these same
    # scenes: seed 316 went non-finite (a thin rod spinning with the gyroscopic term,
    # put back by CCD with the wrong angular velocity); the others lost a light body
    # (a 0.7-195 g hull, a 72 g capsule) through the one-sided mesh ground, pressed
    # wholly behind it within one step. Of seeds 1-800, 10 failed then and 3 now (the
    # xfails below). Now none of these loses a body or goes non-finite.
    _holds(seed)


@pytest.mark.xfail(strict=True, reason="issue 3, open: a light body sandwiched between the ground and a "
                   "body pressing on it is pushed back and forth by the CCD stage's overlap projection "
                   "(project_ccd_overlaps: pushes shared by inverse mass, 64 rounds), and can end a step "
                   "far from where it started (seed 74: a 0.32 kg cylinder under another body, 17 cm down "
                   "in one step, then behind a one-sided ground); seeds 415 and 765 lose a 14 g hull and a "
                   "756 kg sphere near the walls' feet. Pushing the body that touches the ground no "
                   "further (shock propagation, the approach stopped on the other body only) kept it and "
                   "held seed 74, but then the projection lifted a heavy body resting on a light one every "
                   "step (its soft contacts sag 2 cm at 100:1, beyond the allowance) and the heavy box of "
                   "test_ccd.py slid 5 cm off the light one")
@pytest.mark.parametrize("seed", [74, 415, 765])
def test_a_random_world_with_a_sandwiched_light_body_holds(seed):
    _holds(seed)


@pytest.mark.parametrize("seed", [6, 10, 11, 49, 52, 62])
def test_a_random_world_on_a_two_sided_mesh_ground_holds(seed):
    # Two-sided mesh grounds: the engine of commit 11da153 lost a body in 95 of seeds
    # 1-200 (6, 10 and 11 among them), pressed past the sheet's middle within one step
    # and pushed out below; 5 of 200 once a touched triangle kept the side it was
    # touched from (commit c4cbbe2: 52 and 62 among them, 52 lost only since then),
    # none now. Seed 62: a 1.8 m box landing beside a wall, 6 cm above a ridge's flank,
    # got a speculative contact from the flank's back (its plane, extended past the
    # crest, cut through the box) and sank through the ground; a speculative contact
    # whose nearest point and larger part disagree on the side now gives none
    # (collide_mesh.cpp). Seed 49 failed with the nearest point's side alone (a
    # compound's child reaching under the next triangle's plane), and once more while
    # a sleeping body's contact history was dropped: a hull resting half through the
    # sheet woke with none and one triangle took the far side (the cache now keeps a
    # sleeping body's pairs, test_manifold_reuse.py).
    _holds(seed, ("two-sided",))


@pytest.mark.xfail(strict=True, reason="issue 3, open: two-sided mesh grounds still lose a body in 2 of "
                   "seeds 201-400 (0 of 1-200), both within 200 steps and both lost by the engine of "
                   "commit c4cbbe2 too (9 of 201-400 then): seed 318 a 35 kg hull through the ground, 320 a "
                   "154 g hull (under the ground, then out below a wall). In 318 the CCD overlap projection "
                   "runs to its 64-round cap and lifts the hull 0.3 m in one step, after which one triangle "
                   "takes it from behind (the sandwich of the xfail above); in 320 the hull, touched by a "
                   "heavier body, sinks 6 cm a step at zero vertical velocity while its ground contacts, "
                   "normal up, report 0.06-0.25 m depth and ~1e-3 N s impulses. Use one_sided=True for grounds")
@pytest.mark.parametrize("seed", [318, 320])
def test_a_random_world_on_a_two_sided_mesh_ground_with_the_ccd_projection_at_its_cap_holds(seed):
    _holds(seed, ("two-sided",))
