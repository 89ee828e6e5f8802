"""The canonical benchmark scenes, built exactly as ``shared/SCENES.md`` specifies, plus
a few harder ones. Each function returns a new :class:`wmo.World`; keyword arguments
not named below go to the World (``dt``, ``substeps``, ``iterations``, ...).

Scenes are defined once, here, and shared by the tests, the benchmarks and the
notebooks. Units: metres, kilograms, seconds; +y is up; every body starts at rest with
identity orientation unless stated.

- :func:`boxes3000`: Bullet's BenchmarkDemo "3000 boxes" (createTest1): 47 layers of
  8 x 8 boxes of half-extent 1, mass 2, in free fall onto a ground box; pair friction
  0.25 (0.5 per body, multiplied), restitution 0, gravity (0, -10, 0).
- :func:`pyramid`: a 20-layer square pyramid of 2870 unit boxes (half-extent 0.5,
  mass 1) resting face to face on the ground; pair friction 0.6.
- :func:`tower`: a column of boxes stacked face to face (30 by default), the top one
  optionally kicked sideways.
- :func:`mixed_pile`: spheres, capsules and convex hulls dropped onto the ground.

The boxes are sharp (no rounding): Bullet's 0.04 collision margin lies inside its
boxes and leaves their size unchanged; WMO's speculative contacts play its part.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from . import _core

__all__ = ["BoxScene", "boxes3000", "boxes3000_spec", "build", "closed_box", "ground_box", "mixed_pile",
           "pyramid", "pyramid_spec", "tower", "SCENES", "SPECS"]

#: The ground of both canonical scenes: a static box of half-extents 250 x 50 x 250
#: centred at (0, -50, 0), so its top face is the plane y = 0.
GROUND_HALF_EXTENTS = (250.0, 50.0, 250.0)
GROUND_CENTRE = (0.0, -50.0, 0.0)
GRAVITY = (0.0, -10.0, 0.0)


def _world(kwargs: dict[str, Any]) -> _core.World:
    kwargs.setdefault("gravity", GRAVITY)
    kwargs.setdefault("dt", 1.0 / 60.0)
    return _core.World(**kwargs)


def ground_box(world: _core.World, friction: float) -> _core.Body:
    """Adds the canonical static ground box (top face at y = 0)."""
    return world.add_body(_core.Box(GROUND_HALF_EXTENTS), position=GROUND_CENTRE,
                          kind="static", friction=friction)


@dataclass(frozen=True)
class BoxScene:
    """A scene of dynamic boxes on the canonical ground, as plain arrays, so that the
    same scene can be built in WMO and in each peer engine (wmo.bench). Rows: one per
    dynamic box, at rest with identity orientation."""
    name: str
    half_extents: np.ndarray  #: (N, 3) m
    positions: np.ndarray  #: (N, 3) m, box centres
    masses: np.ndarray  #: (N,) kg
    friction: float  #: per body (ground included); pair friction = friction ** 2
    gravity: tuple = GRAVITY

    @property
    def pair_friction(self) -> float:
        """The coefficient a contact uses (Bullet's product rule)."""
        return self.friction ** 2

    def __len__(self) -> int:
        return len(self.positions)


def boxes3000_spec(layers: int = 47, grid: int = 8) -> BoxScene:
    """Bullet's "3000 boxes" as arrays: layer k, cell (i, j) at (-12 - 0.35 k + 3 i,
    2 + 3 k, -12 - 0.35 k + 3 j); half-extent 1, mass 2, friction 0.5 per body."""
    if layers < 1 or grid < 1:
        raise ValueError(f"layers and grid must be >= 1, got layers={layers}, grid={grid}")
    k, i, j = np.meshgrid(np.arange(layers), np.arange(grid), np.arange(grid), indexing="ij")
    k, i, j = k.ravel(), i.ravel(), j.ravel()
    offset = -12.0 - 0.35 * k
    pos = np.stack([offset + 3.0 * i, 2.0 + 3.0 * k, offset + 3.0 * j], axis=1)
    n = len(pos)
    return BoxScene("boxes3000", np.ones((n, 3)), pos, np.full(n, 2.0), 0.5)


def pyramid_spec(layers: int = 20) -> BoxScene:
    """The pyramid as arrays: layer k is an n x n grid (n = layers - k) at
    (i - (n - 1)/2, 0.5 + k, j - (n - 1)/2); half-extent 0.5, mass 1, friction
    sqrt(0.6) per body."""
    if layers < 1:
        raise ValueError(f"layers must be >= 1, got {layers}")
    rows = []
    for k in range(layers):
        n = layers - k
        for i in range(n):
            for j in range(n):
                rows.append((i - (n - 1) / 2, 0.5 + k, j - (n - 1) / 2))
    pos = np.array(rows, dtype=float)
    n = len(pos)
    return BoxScene("pyramid", np.full((n, 3), 0.5), pos, np.ones(n), math.sqrt(0.6))


def build(spec: BoxScene, **world_kwargs: Any) -> _core.World:
    """A World holding `spec`: the ground box (row 0) and the dynamic boxes (rows 1..N,
    in the spec's order). One shape is shared by all boxes of the same size."""
    world_kwargs.setdefault("gravity", spec.gravity)
    world = _world(world_kwargs)
    world.reserve(1 + len(spec))
    ground_box(world, friction=spec.friction)
    shapes: dict[tuple, _core.Box] = {}
    for h, p, m in zip(spec.half_extents, spec.positions, spec.masses):
        key = tuple(h)
        if key not in shapes:
            shapes[key] = _core.Box(key)
        world.add_body(shapes[key], position=p, mass=float(m), friction=spec.friction, restitution=0.0)
    return world


def boxes3000(layers: int = 47, grid: int = 8, **world_kwargs: Any) -> _core.World:
    """Bullet's "3000 boxes": ``layers`` x ``grid`` x ``grid`` dynamic boxes (3008 by
    default). Layer k, cell (i, j): centre (-12 - 0.35 k + 3 i, 2 + 3 k,
    -12 - 0.35 k + 3 j); half-extent 1, mass 2 (solid-box inertia 4/3), friction 0.5
    per body (pair friction 0.25 with the default multiply rule), restitution 0."""
    return build(boxes3000_spec(layers, grid), **world_kwargs)


def pyramid(layers: int = 20, **world_kwargs: Any) -> _core.World:
    """A square pyramid of unit boxes: layer k (0-based) is an n x n grid, n = layers - k,
    centres (i - (n - 1)/2, 0.5 + k, j - (n - 1)/2); half-extent 0.5, mass 1, per-body
    friction sqrt(0.6) so that the multiplied pair friction is 0.6 (ground included).
    2870 boxes for 20 layers; the base rests exactly on the ground."""
    return build(pyramid_spec(layers), **world_kwargs)


def tower(height: int = 30, half_extent: float = 0.5, friction: float = 0.6, kick: float = 0.0,
          **world_kwargs: Any) -> _core.World:
    """``height`` boxes of half-extent ``half_extent`` (density 1000) stacked face to
    face on the ground, the lowest resting on y = 0; pair friction ``friction``.

    ``kick`` (m/s, default 0): the top box starts moving along +x at this speed. A
    perfectly stacked tower is symmetric, and a solver that treats a contact's points
    alike (``centroid_rows``, ``block_solver``) keeps it on its axis even where it is
    an unstable equilibrium; a small kick (the tests use 1 cm/s for a unit box) tells a
    tower that stands from one that only balances."""
    if height < 1:
        raise ValueError(f"height must be >= 1, got {height}")
    if not math.isfinite(kick):
        raise ValueError(f"kick must be finite, got {kick}")
    world = _world(world_kwargs)
    mu = math.sqrt(friction)
    ground_box(world, friction=mu)
    box = _core.Box((half_extent,) * 3)
    for k in range(height):
        top = k == height - 1
        world.add_body(box, position=(0.0, half_extent * (2 * k + 1), 0.0), friction=mu,
                       linear_velocity=(kick if top else 0.0, 0.0, 0.0))
    return world


def closed_box(count: int = 40, seed: int = 5, **world_kwargs: Any) -> _core.World:
    """A closed system for energy tests: ``count`` bodies (alternately boxes of
    half-extents 0.3 x 0.25 x 0.35 and spheres of radius 0.3, density 1000) on a 2 m
    grid, fired with random velocities (3 m/s and 1 rad/s per component, standard
    normal, from ``seed``) around a closed container of static walls (inside 10 x 10 x
    10 m), with no gravity, friction or restitution; ``sleeping`` is off. With no
    damping nothing may add kinetic energy: the contacts are inelastic."""
    if not 1 <= count <= 50:
        raise ValueError(f"count must be in [1, 50], got {count}")
    world_kwargs.setdefault("gravity", (0.0, 0.0, 0.0))
    world_kwargs.setdefault("sleeping", False)
    world = _world(world_kwargs)
    for x, z, hx, hz in ((5.5, 0, 0.5, 6), (-5.5, 0, 0.5, 6), (0, 5.5, 6, 0.5), (0, -5.5, 6, 0.5)):
        world.add_body(_core.Box((hx, 6, hz)), position=(x, 0, z), kind="static", friction=0.0)
    for y in (-5.5, 5.5):
        world.add_body(_core.Box((6, 0.5, 6)), position=(0, y, 0), kind="static", friction=0.0)
    rng = np.random.default_rng(seed)
    for i in range(count):
        shape = _core.Sphere(0.3) if i % 2 else _core.Box((0.3, 0.25, 0.35))
        world.add_body(shape, position=(-4 + 2 * (i % 5), -4 + 2 * ((i // 5) % 5), -3 + 2 * (i // 25)),
                       linear_velocity=rng.normal(size=3) * 3, angular_velocity=rng.normal(size=3),
                       friction=0.0)
    return world


def mixed_pile(count: int = 200, seed: int = 0, **world_kwargs: Any) -> _core.World:
    """``count`` bodies, a third each spheres (radius 0.2..0.5), capsules (radius
    0.15..0.3, half-height 0.2..0.5) and convex hulls (12 random points on a sphere of
    radius 0.3..0.6), on a jittered grid of pitch 1.5 m from y = 2 up, with random
    orientations, falling onto the ground; density 1000, friction 0.5 per body. The
    layout depends only on ``seed``."""
    if count < 1:
        raise ValueError(f"count must be >= 1, got {count}")
    rng = np.random.default_rng(seed)
    world = _world(world_kwargs)
    world.reserve(1 + count)
    ground_box(world, friction=0.5)
    side = max(1, int(math.ceil(count ** (1 / 3))))
    for n in range(count):
        i, j, k = n % side, (n // side) % side, n // (side * side)
        pos = (1.5 * (i - (side - 1) / 2) + rng.uniform(-0.2, 0.2),
               2.0 + 1.5 * k + rng.uniform(0, 0.2),
               1.5 * (j - (side - 1) / 2) + rng.uniform(-0.2, 0.2))
        q = rng.normal(size=4)
        q /= np.linalg.norm(q)
        kind = n % 3
        if kind == 0:
            shape = _core.Sphere(rng.uniform(0.2, 0.5))
        elif kind == 1:
            shape = _core.Capsule(rng.uniform(0.15, 0.3), rng.uniform(0.2, 0.5))
        else:
            p = rng.normal(size=(12, 3))
            p *= rng.uniform(0.3, 0.6) / np.linalg.norm(p, axis=1)[:, None]
            shape = _core.ConvexHull(p)
        world.add_body(shape, position=pos, orientation=q, friction=0.5)
    return world


#: Scene builders by name, for the command line and the benchmarks.
SCENES = {"boxes3000": boxes3000, "pyramid": pyramid, "tower": tower, "mixed_pile": mixed_pile}
#: Box scenes as arrays, for building them in the peer engines too.
SPECS = {"boxes3000": boxes3000_spec, "pyramid": pyramid_spec}
