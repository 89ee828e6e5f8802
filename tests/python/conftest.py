"""Shared fixtures, helpers and Hypothesis strategies for the Python tests."""
from __future__ import annotations

import math
import os

import numpy as np
import pytest
from hypothesis import HealthCheck, settings
from hypothesis import strategies as st

import wmo

# Hypothesis profiles. "default" is derandomized so CI runs the same examples every
# time (a failure reproduces); HYPOTHESIS_PROFILE=explore draws fresh random examples.
# 200 examples per property keeps the whole Python suite within a few seconds.
settings.register_profile(
    "default", max_examples=200, deadline=None, derandomize=True,
    suppress_health_check=[HealthCheck.too_slow])
settings.register_profile(
    "explore", max_examples=2000, deadline=None, suppress_health_check=[HealthCheck.too_slow])
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "default"))


def quat_axis_angle(axis, angle):
    """Unit quaternion (x, y, z, w) for a rotation of `angle` radians about `axis`."""
    axis = np.asarray(axis, dtype=float)
    axis = axis / np.linalg.norm(axis)
    s = math.sin(angle / 2)
    return (axis[0] * s, axis[1] * s, axis[2] * s, math.cos(angle / 2))


def rot_matrix(q):
    """3x3 rotation matrix of a unit quaternion (x, y, z, w), computed in NumPy
    independently of WMO (the textbook formula)."""
    x, y, z, w = q
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


def cube_corners(h=(1.0, 1.0, 1.0)):
    """The 8 corners of a box with half extents h, shape (8, 3)."""
    h = np.asarray(h, dtype=float)
    return np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]) * h


def random_poses(rng, n, spread=1.5):
    """(n, 7) array of random poses: positions in [-spread, spread]^3, uniformly random
    unit quaternions (normalised Gaussian 4-vectors, Shoemake)."""
    q = rng.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    p = rng.uniform(-spread, spread, size=(n, 3))
    return np.hstack([p, q])


@pytest.fixture
def rng():
    return np.random.default_rng(12345)


# ---- Hypothesis strategies ----

size = st.floats(min_value=0.1, max_value=1.5, allow_nan=False, allow_infinity=False)
coord = st.floats(min_value=-2.0, max_value=2.0, allow_nan=False, allow_infinity=False)


@st.composite
def unit_quaternions(draw):
    v = draw(st.tuples(*[st.floats(-1.0, 1.0, allow_nan=False)] * 4))
    n = math.sqrt(sum(c * c for c in v))
    if n < 0.1:  # too short to normalise without amplifying rounding: use identity
        return (0.0, 0.0, 0.0, 1.0)
    return tuple(c / n for c in v)


@st.composite
def poses(draw, spread=coord):
    return wmo.Pose(position=draw(st.tuples(spread, spread, spread)),
                    orientation=draw(unit_quaternions()))


@st.composite
def hull_points(draw):
    """8..16 points in [-1, 1]^3 that span a volume: a box's corners, jittered by up to
    30% of the extent, plus optional extra points. Never degenerate by construction."""
    h = np.array(draw(st.tuples(size, size, size)))
    corners = cube_corners(h)
    jitter = np.array(draw(st.lists(st.floats(-0.3, 0.3), min_size=24, max_size=24))).reshape(8, 3)
    pts = corners * (1.0 + jitter)
    extra = draw(st.lists(st.tuples(coord, coord, coord), max_size=8))
    if extra:
        pts = np.vstack([pts, np.array(extra) * 0.5])
    return pts


@st.composite
def convex_shapes(draw):
    kind = draw(st.sampled_from(["sphere", "box", "rounded_box", "capsule", "cylinder", "hull"]))
    if kind == "sphere":
        return wmo.Sphere(draw(size))
    if kind == "box":
        return wmo.Box(draw(st.tuples(size, size, size)))
    if kind == "rounded_box":
        h = draw(st.tuples(size, size, size))
        return wmo.Box(h, rounding=0.5 * min(h) * draw(st.floats(0.0, 0.9)))
    if kind == "capsule":
        return wmo.Capsule(draw(size), draw(size))
    if kind == "cylinder":
        return wmo.Cylinder(draw(size), draw(size))
    return wmo.ConvexHull(draw(hull_points()))
