"""Triangle meshes of WMO shapes, for export and display.

:func:`shape_mesh` turns any ``wmo`` shape into ``(vertices, triangles)``: vertices
``(V, 3)`` float64 in metres in the shape's own frame (the frame a body's pose places in
the world), triangles ``(T, 3)`` int64 indices, counter-clockwise seen from outside (so
the right-hand normal points out). Every mesh but a ``TriangleMesh``'s is closed: each
edge is shared by exactly two triangles (a compound's mesh is its children's closed
meshes side by side, not their merged union).

Curved surfaces are inscribed: every vertex lies on the shape's surface, so the mesh
encloses slightly less than the shape. A sphere is an icosphere (20 * 4**n triangles
for ``sphere_subdivisions`` n); capsules and cylinders are surfaces of revolution about
the shape's Y axis with ``segments`` vertices per ring (a capsule's hemispheres have
``segments // 4`` latitude steps each); a rounded box is the Minkowski sum of its core box
and an icosphere of the rounding radius (the convex hull of an icosphere at each core
corner). A plane, which has no bounds, is drawn as a square slab of side ``plane_size``
(m) and thickness ``plane_size / 100``, centred on the plane's point nearest the shape
origin, its top face on the plane and the rest below (the plane's solid side).
"""
from __future__ import annotations

import math
from typing import Tuple

import numpy as np

from .. import _core

__all__ = ["shape_mesh"]

Mesh = Tuple[np.ndarray, np.ndarray]

# A box's 8 corners: bit 0, 1, 2 of the index give the sign of x, y, z. Each face is a
# quad counter-clockwise from outside (-x, +x, -y, +y, -z, +z).
_BOX_SIGNS = np.array([[1 if i & 1 else -1, 1 if i & 2 else -1, 1 if i & 4 else -1] for i in range(8)],
                      dtype=np.float64)
_BOX_QUADS = np.array([[0, 4, 6, 2], [1, 3, 7, 5], [0, 1, 5, 4], [2, 6, 7, 3], [0, 2, 3, 1], [4, 5, 7, 6]])
_BOX_TRIANGLES = np.concatenate([_BOX_QUADS[:, [0, 1, 2]], _BOX_QUADS[:, [0, 2, 3]]]).astype(np.int64)

# Icosahedron with vertices (0, +-1, +-t) and its cyclic permutations: the set is closed
# under every sign flip of a coordinate, and so are its subdivisions (a rounded box
# relies on it: see _rounded_box).
_T = (1.0 + math.sqrt(5.0)) / 2.0
_ICOSA_VERTICES = np.array([[-1, _T, 0], [1, _T, 0], [-1, -_T, 0], [1, -_T, 0], [0, -1, _T], [0, 1, _T],
                            [0, -1, -_T], [0, 1, -_T], [_T, 0, -1], [_T, 0, 1], [-_T, 0, -1], [-_T, 0, 1]])
_ICOSA_TRIANGLES = np.array([[0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11], [1, 5, 9], [5, 11, 4],
                             [11, 10, 2], [10, 7, 6], [7, 1, 8], [3, 9, 4], [3, 4, 2], [3, 2, 6], [3, 6, 8],
                             [3, 8, 9], [4, 9, 5], [2, 4, 11], [6, 2, 10], [8, 6, 7], [9, 8, 1]])


def _unit_icosphere(subdivisions: int) -> Mesh:
    """Unit icosphere: each step splits every triangle into 4 at its edge midpoints,
    pushed out onto the sphere."""
    v = _ICOSA_VERTICES / np.linalg.norm(_ICOSA_VERTICES, axis=1, keepdims=True)
    t = _ICOSA_TRIANGLES.astype(np.int64)
    for _ in range(subdivisions):
        edges = np.sort(t[:, [[0, 1], [1, 2], [2, 0]]].reshape(-1, 2), axis=1)
        unique, inverse = np.unique(edges, axis=0, return_inverse=True)
        mid = v[unique[:, 0]] + v[unique[:, 1]]
        v = np.vstack([v, mid / np.linalg.norm(mid, axis=1, keepdims=True)])
        m = inverse.reshape(-1, 3) + (len(v) - len(unique))  # midpoints of edges 01, 12, 20
        a, b, c = t.T
        t = np.concatenate([np.stack([a, m[:, 0], m[:, 2]], 1), np.stack([b, m[:, 1], m[:, 0]], 1),
                            np.stack([c, m[:, 2], m[:, 1]], 1), m])
    return v, t


def _revolution(profile: np.ndarray, segments: int) -> Mesh:
    """Surface of revolution about +Y of ``profile``, rows (rho, y) from bottom to top:
    the first and last rows are poles on the axis (rho = 0), the others rings."""
    phi = 2.0 * math.pi * np.arange(segments) / segments
    rho, y = profile[1:-1, 0:1], profile[1:-1, 1:2]
    rings = np.stack([rho * np.cos(phi), np.broadcast_to(y, rho.shape[:1] + phi.shape),
                      -rho * np.sin(phi)], axis=-1).reshape(-1, 3)
    bottom, top = len(rings), len(rings) + 1
    v = np.vstack([rings, [[0.0, profile[0, 1], 0.0]], [[0.0, profile[-1, 1], 0.0]]])
    s = np.arange(segments)
    s1 = (s + 1) % segments
    tris = [np.stack([np.full(segments, bottom), s1, s], 1)]
    for j in range(len(rho) - 1):
        a, b = j * segments, (j + 1) * segments
        tris += [np.stack([a + s, a + s1, b + s1], 1), np.stack([a + s, b + s1, b + s], 1)]
    last = (len(rho) - 1) * segments
    tris.append(np.stack([np.full(segments, top), last + s, last + s1], 1))
    return v, np.concatenate(tris).astype(np.int64)


def _hull_mesh(hull: "_core.ConvexHull") -> Mesh:
    """Fan triangulation of a hull's convex faces (already counter-clockwise from outside)."""
    faces = [np.asarray(f, dtype=np.int64) for f in hull.faces]
    tris = [np.stack([np.full(len(f) - 2, f[0]), f[1:-1], f[2:]], 1) for f in faces]
    return np.array(hull.vertices, dtype=np.float64), np.concatenate(tris).astype(np.int64)


def _rounded_box(core: np.ndarray, rounding: float, subdivisions: int) -> Mesh:
    """The core box inflated by ``rounding``: the hull of an icosphere at each core
    corner. Because the icosphere is symmetric under sign flips, a point whose offset
    points back into the core (toward the box's middle) never wins a support direction
    over its mirror image, so every hull vertex lies at distance ``rounding`` from the
    core: on the rounded surface."""
    ball = _unit_icosphere(subdivisions)[0] * rounding
    points = (_BOX_SIGNS * core)[:, None, :] + ball[None, :, :]
    return _hull_mesh(_core.ConvexHull(points.reshape(-1, 3)))


def _check_count(name: str, value: object, smallest: int) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < smallest:
        raise ValueError(f"{name} must be an integer >= {smallest}, got {value!r}")
    return int(value)


def shape_mesh(shape: "_core.Shape", *, sphere_subdivisions: int = 2, segments: int = 24,
               plane_size: float = 100.0) -> Mesh:
    """Triangle mesh of ``shape`` in its own frame (see the module docstring).

    ``sphere_subdivisions`` (>= 0): icosphere refinement of spheres and of rounded box
    corners. ``segments`` (>= 3): vertices per ring of capsules and cylinders.
    ``plane_size`` (m, > 0): side of the square drawn for a plane.

    Returns ``(vertices (V, 3) float64 metres, triangles (T, 3) int64)``, counter-clockwise
    seen from outside. Raises ValueError naming a bad option, TypeError for an object
    that is not a WMO shape.
    """
    subdivisions = _check_count("sphere_subdivisions", sphere_subdivisions, 0)
    segments = _check_count("segments", segments, 3)
    if isinstance(plane_size, bool) or not isinstance(plane_size, (int, float, np.floating)) \
            or not (math.isfinite(plane_size) and plane_size > 0):
        raise ValueError(f"plane_size must be a finite number > 0 (metres), got {plane_size!r}")
    options = dict(sphere_subdivisions=subdivisions, segments=segments, plane_size=plane_size)

    if isinstance(shape, _core.Box):
        half, r = np.asarray(shape.half_extents, dtype=np.float64), float(shape.rounding)
        if r > 0:
            return _rounded_box(half - r, r, subdivisions)
        return _BOX_SIGNS * half, _BOX_TRIANGLES.copy()
    if isinstance(shape, _core.Sphere):
        v, t = _unit_icosphere(subdivisions)
        return v * float(shape.radius), t
    if isinstance(shape, _core.Capsule):
        r, h = float(shape.radius), float(shape.half_height)
        k = max(1, segments // 4)
        alpha = (math.pi / 2) * np.arange(1, k + 1) / k  # latitude of the rings, from the pole
        lower = np.stack([r * np.sin(alpha), -h - r * np.cos(alpha)], 1)
        upper = np.stack([r * np.sin(alpha[::-1]), h + r * np.cos(alpha[::-1])], 1)
        return _revolution(np.vstack([[0.0, -h - r], lower, upper, [0.0, h + r]]), segments)
    if isinstance(shape, _core.Cylinder):
        r, h = float(shape.radius), float(shape.half_height)
        return _revolution(np.array([[0.0, -h], [r, -h], [r, h], [0.0, h]]), segments)
    if isinstance(shape, _core.ConvexHull):
        return _hull_mesh(shape)
    if isinstance(shape, _core.TriangleMesh):
        return np.array(shape.vertices, dtype=np.float64), np.array(shape.triangles, dtype=np.int64)
    if isinstance(shape, _core.Plane):
        n = np.asarray(shape.normal, dtype=np.float64)
        # (t1, t2, n) is a right-handed basis, so the rotation keeps the winding.
        t1 = np.cross(n, np.eye(3)[int(np.argmin(np.abs(n)))])
        t1 /= np.linalg.norm(t1)
        rotation = np.column_stack([t1, np.cross(n, t1), n])
        half = 0.5 * float(plane_size)
        slab = _BOX_SIGNS * [half, half, 0.01 * half] - [0.0, 0.0, 0.01 * half]
        return slab @ rotation.T + float(shape.offset) * n, _BOX_TRIANGLES.copy()
    if isinstance(shape, _core.Compound):
        vertices, triangles, count = [], [], 0
        for child, pose in shape.children:
            v, t = shape_mesh(child, **options)
            vertices.append(v @ np.asarray(pose.matrix()).T + pose.position)
            triangles.append(t + count)
            count += len(v)
        return np.vstack(vertices), np.concatenate(triangles)
    raise TypeError(f"shape must be a wmo shape (Box, Sphere, Capsule, Cylinder, ConvexHull, TriangleMesh, "
                    f"Plane or Compound), got {type(shape).__name__}")
