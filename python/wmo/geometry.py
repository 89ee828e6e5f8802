"""Pair queries, ray casts and their batched forms.

Conventions (``cpp/include/wmo/types.h``): poses are world poses and every result is in
world space; normals are unit vectors pointing from A to B; ``depth > 0`` means the
shapes overlap; ``points_b = points_a - depth * normal``.

Poses: every ``pose`` argument takes a :class:`wmo.Pose` or a ``(position,
orientation)`` pair such as ``((0, 0, 1), (0, 0, 0, 1))``; both are validated (ValueError
naming the argument for NaN or a non-unit quaternion).

Status: single-query results carry ``status``, a ``str`` — ``"ok"``, ``"unsupported"``
(no routine exists for this pair of shape types: nothing was computed),
``"max_iterations"`` (GJK/EPA hit its cap; best answer so far) or ``"degenerate"``.
:class:`QueryStatus` names them; because it is a ``str`` enum, ``result.status ==
QueryStatus.UNSUPPORTED`` and ``result.status == "unsupported"`` both work. Batched
queries return the status as ``uint8`` codes; ``QueryStatus.from_code`` decodes them.

Batched queries (``*_batch``) loop in C++ with the GIL released, so other Python threads
keep running. Poses come as ``(N, 7)`` float arrays with rows ``[x, y, z, qx, qy, qz,
qw]`` (``Pose.as_array()`` gives one row); a ``(7,)`` row or a :class:`wmo.Pose` stands for
the same pose in every query. Every input is validated before the loop starts: a wrong
shape raises TypeError naming the expected shape, a NaN or non-unit quaternion row raises
ValueError naming the row (``poses_a[17].orientation ...``). They return a ``dict`` of
NumPy arrays (keys listed per function).

GJK / EPA settings are keyword-only (``gjk_tolerance``, ``gjk_max_iterations``,
``epa_tolerance``, ``epa_max_iterations``); defaults are the C++ defaults.
"""
from __future__ import annotations

import enum
from typing import Dict, List, Tuple, Union

import numpy as np
import numpy.typing as npt

from . import _core
from ._core import DistanceResult, Manifold, Pose, RayHit, Shape, ToiResult

__all__ = [
    "DistanceResult",
    "Manifold",
    "QueryStatus",
    "RayHit",
    "closest_points",
    "closest_points_batch",
    "collide",
    "collide_all",
    "collide_batch",
    "collide_supported",
    "distance",
    "distance_batch",
    "intersect",
    "penetration",
    "penetration_batch",
    "raycast",
    "raycast_batch",
    "time_of_impact",
    "time_of_impact_batch",
    "ToiResult",
]

_g = _core.geometry

PoseLike = Union[Pose, Tuple[npt.ArrayLike, npt.ArrayLike]]
"""A :class:`wmo.Pose` or a ``(position (3,), orientation (4,) as (x, y, z, w))`` pair."""
PoseArrayLike = Union[Pose, npt.ArrayLike]
"""An ``(N, 7)`` array of ``[x, y, z, qx, qy, qz, qw]`` rows, one ``(7,)`` row or a Pose."""

# Defaults of GjkSettings / EpaSettings (cpp/include/wmo/types.h), read from the module.
_GJK_TOL: float = _g.GJK_TOLERANCE
_GJK_ITER: int = _g.GJK_MAX_ITERATIONS
_EPA_TOL: float = _g.EPA_TOLERANCE
_EPA_ITER: int = _g.EPA_MAX_ITERATIONS
_TOI_TOL: float = _g.TOI_TOLERANCE
_TOI_ITER: int = _g.TOI_MAX_ITERATIONS
_ZERO3 = (0.0, 0.0, 0.0)


class QueryStatus(str, enum.Enum):
    """Outcome of a query. A ``str`` enum: members compare equal to their names."""

    OK = "ok"
    UNSUPPORTED = "unsupported"
    MAX_ITERATIONS = "max_iterations"
    DEGENERATE = "degenerate"

    @property
    def code(self) -> int:
        """The ``uint8`` code used by the batched queries."""
        return _STATUS_CODES[self]

    @classmethod
    def from_code(cls, code: int) -> "QueryStatus":
        """Decode a ``uint8`` status code from a batched query."""
        return cls(_STATUS_NAMES[int(code)])

    def __str__(self) -> str:
        return self.value


# The order is the C++ enum's (QueryStatus in types.h), read from the module so the
# codes cannot drift from the C++ side.
_STATUS_NAMES: Tuple[str, ...] = tuple(_g.status_names())
_STATUS_CODES = {QueryStatus(name): code for code, name in enumerate(_STATUS_NAMES)}


def distance(a: Shape, pose_a: PoseLike, b: Shape, pose_b: PoseLike, *,
             gjk_tolerance: float = _GJK_TOL, gjk_max_iterations: int = _GJK_ITER
             ) -> DistanceResult:
    """Separation distance of A at ``pose_a`` and B at ``pose_b`` (metres, >= 0).

    When the shapes overlap, ``intersecting`` is True and ``distance`` is 0 (use
    :func:`closest_points` or :func:`penetration` for the depth). ``point_a`` /
    ``point_b`` are the closest points, ``normal`` the unit direction from A to B.
    """
    return _g.distance(a, pose_a, b, pose_b, gjk_tolerance=gjk_tolerance,
                       gjk_max_iterations=gjk_max_iterations)


def closest_points(a: Shape, pose_a: PoseLike, b: Shape, pose_b: PoseLike, *,
                   gjk_tolerance: float = _GJK_TOL, gjk_max_iterations: int = _GJK_ITER,
                   epa_tolerance: float = _EPA_TOL, epa_max_iterations: int = _EPA_ITER
                   ) -> DistanceResult:
    """Signed distance with witness points: as :func:`distance` when apart; when
    overlapping, the deepest points (EPA) and ``distance = -depth``."""
    return _g.closest_points(a, pose_a, b, pose_b, gjk_tolerance=gjk_tolerance,
                             gjk_max_iterations=gjk_max_iterations,
                             epa_tolerance=epa_tolerance, epa_max_iterations=epa_max_iterations)


def penetration(a: Shape, pose_a: PoseLike, b: Shape, pose_b: PoseLike, *,
                gjk_tolerance: float = _GJK_TOL, gjk_max_iterations: int = _GJK_ITER,
                epa_tolerance: float = _EPA_TOL, epa_max_iterations: int = _EPA_ITER
                ) -> DistanceResult:
    """Penetration depth (``-distance``), normal (A to B) and witness points of an
    overlapping pair; for a separated pair ``intersecting`` is False and the result is
    the plain distance."""
    return _g.penetration(a, pose_a, b, pose_b, gjk_tolerance=gjk_tolerance,
                          gjk_max_iterations=gjk_max_iterations,
                          epa_tolerance=epa_tolerance, epa_max_iterations=epa_max_iterations)


def intersect(a: Shape, pose_a: PoseLike, b: Shape, pose_b: PoseLike, *,
              gjk_tolerance: float = _GJK_TOL, gjk_max_iterations: int = _GJK_ITER) -> bool:
    """True if the shapes overlap or touch."""
    return _g.intersect(a, pose_a, b, pose_b, gjk_tolerance=gjk_tolerance,
                        gjk_max_iterations=gjk_max_iterations)


def raycast(shape: Shape, pose: PoseLike, origin: npt.ArrayLike, direction: npt.ArrayLike,
            max_distance: float = float("inf")) -> RayHit:
    """Casts the ray ``origin + t * direction``, ``0 <= t <= max_distance`` (world frame).

    ``direction`` need not be unit but must be finite and non-zero; ``t`` and
    ``max_distance`` are in units of ``|direction|``. A ray starting inside a solid shape
    hits at distance 0 with a zero normal. ``child`` is the triangle / compound child hit.
    """
    return _g.raycast(shape, pose, origin, direction, max_distance)


def collide(a: Shape, pose_a: PoseLike, b: Shape, pose_b: PoseLike, *, margin: float = 0.0,
            special: bool = True, gjk_tolerance: float = _GJK_TOL,
            gjk_max_iterations: int = _GJK_ITER, epa_tolerance: float = _EPA_TOL,
            epa_max_iterations: int = _EPA_ITER) -> Manifold:
    """One contact manifold (up to 4 points, one normal from A to B).

    For a convex pair this is the pair's manifold. For composite shapes (triangle mesh,
    compound), which produce one manifold per touching child, it is the manifold with
    the deepest point; use :func:`collide_all` for all of them. When the shapes are
    farther apart than ``margin`` the manifold is empty (``count == 0``, falsy, zero
    normal) with status ``"ok"``; for a pair no routine handles it is empty with status
    ``"unsupported"``.

    Args:
        margin: speculative margin in metres (>= 0): points with depth >= -margin are
            reported, so nearby pairs give contacts with negative depth.
        special: use the fast special routines where they exist; False forces the
            generic GJK/EPA + clipping path.
    """
    return _g.collide(a, pose_a, b, pose_b, margin=margin, special=special,
                      gjk_tolerance=gjk_tolerance, gjk_max_iterations=gjk_max_iterations,
                      epa_tolerance=epa_tolerance, epa_max_iterations=epa_max_iterations)


def collide_all(a: Shape, pose_a: PoseLike, b: Shape, pose_b: PoseLike, *, margin: float = 0.0,
                special: bool = True, gjk_tolerance: float = _GJK_TOL,
                gjk_max_iterations: int = _GJK_ITER, epa_tolerance: float = _EPA_TOL,
                epa_max_iterations: int = _EPA_ITER) -> List[Manifold]:
    """All manifolds: none when apart, one for a convex pair, one per touching triangle
    or compound child (see ``child_a`` / ``child_b``) for composite shapes.

    An unsupported pair returns a list holding one empty manifold whose status is
    ``"unsupported"``, never a silent empty list. Arguments as :func:`collide`.
    """
    return _g.collide_all(a, pose_a, b, pose_b, margin=margin, special=special,
                          gjk_tolerance=gjk_tolerance, gjk_max_iterations=gjk_max_iterations,
                          epa_tolerance=epa_tolerance, epa_max_iterations=epa_max_iterations)


def collide_supported(a: Shape, b: Shape) -> bool:
    """True if :func:`collide` has a routine for this pair of shape types."""
    return _g.collide_supported(a, b)


def distance_batch(a: Shape, b: Shape, poses_a: PoseArrayLike, poses_b: PoseArrayLike, *,
                   gjk_tolerance: float = _GJK_TOL, gjk_max_iterations: int = _GJK_ITER
                   ) -> Dict[str, np.ndarray]:
    """:func:`distance` for N pose pairs, looped in C++ with the GIL released.

    Returns a dict with ``distance`` (N,), ``point_a`` (N, 3), ``point_b`` (N, 3),
    ``normal`` (N, 3), ``intersecting`` (N,) bool, ``status`` (N,) uint8 (see
    :class:`QueryStatus`) and ``iterations`` (N,) int32.
    """
    return _g.distance_batch(a, b, poses_a, poses_b, gjk_tolerance=gjk_tolerance,
                             gjk_max_iterations=gjk_max_iterations)


def closest_points_batch(a: Shape, b: Shape, poses_a: PoseArrayLike, poses_b: PoseArrayLike, *,
                         gjk_tolerance: float = _GJK_TOL, gjk_max_iterations: int = _GJK_ITER,
                         epa_tolerance: float = _EPA_TOL, epa_max_iterations: int = _EPA_ITER
                         ) -> Dict[str, np.ndarray]:
    """:func:`closest_points` for N pose pairs; keys as :func:`distance_batch`."""
    return _g.closest_points_batch(a, b, poses_a, poses_b, gjk_tolerance=gjk_tolerance,
                                   gjk_max_iterations=gjk_max_iterations,
                                   epa_tolerance=epa_tolerance,
                                   epa_max_iterations=epa_max_iterations)


def penetration_batch(a: Shape, b: Shape, poses_a: PoseArrayLike, poses_b: PoseArrayLike, *,
                      gjk_tolerance: float = _GJK_TOL, gjk_max_iterations: int = _GJK_ITER,
                      epa_tolerance: float = _EPA_TOL, epa_max_iterations: int = _EPA_ITER
                      ) -> Dict[str, np.ndarray]:
    """:func:`penetration` for N pose pairs; keys as :func:`distance_batch`."""
    return _g.penetration_batch(a, b, poses_a, poses_b, gjk_tolerance=gjk_tolerance,
                                gjk_max_iterations=gjk_max_iterations,
                                epa_tolerance=epa_tolerance,
                                epa_max_iterations=epa_max_iterations)


def collide_batch(a: Shape, b: Shape, poses_a: PoseArrayLike, poses_b: PoseArrayLike, *,
                  margin: float = 0.0, special: bool = True, gjk_tolerance: float = _GJK_TOL,
                  gjk_max_iterations: int = _GJK_ITER, epa_tolerance: float = _EPA_TOL,
                  epa_max_iterations: int = _EPA_ITER) -> Dict[str, np.ndarray]:
    """:func:`collide` for N pose pairs (one manifold per query, the deepest one for
    composite shapes), looped in C++ with the GIL released.

    Returns a dict with ``count`` (N,) int32, ``normal`` (N, 3), ``max_depth`` (N,)
    (``-inf`` where ``count == 0``), ``points_a`` / ``points_b`` (N, 4, 3), ``depths``
    (N, 4), ``feature_ids`` (N, 4) uint32, ``child_a`` / ``child_b`` (N,) int32 and
    ``status`` (N,) uint8. Slots ``k >= count[i]`` are zero-filled; normals of empty
    manifolds are zero.
    """
    return _g.collide_batch(a, b, poses_a, poses_b, margin=margin, special=special,
                            gjk_tolerance=gjk_tolerance, gjk_max_iterations=gjk_max_iterations,
                            epa_tolerance=epa_tolerance, epa_max_iterations=epa_max_iterations)


def raycast_batch(shape: Shape, pose: PoseLike, origins: npt.ArrayLike,
                  directions: npt.ArrayLike, max_distance: float = float("inf")
                  ) -> Dict[str, np.ndarray]:
    """:func:`raycast` for N rays against one placed shape, GIL released.

    ``origins`` and ``directions`` are (N, 3) arrays, or (3,) for one value shared by
    every ray. Every direction must be finite and non-zero (ValueError naming the row).
    Returns a dict with ``hit`` (N,) bool, ``distance`` (N,), ``point`` (N, 3),
    ``normal`` (N, 3), ``child`` (N,) int32 and ``status`` (N,) uint8.
    """
    return _g.raycast_batch(shape, pose, origins, directions, max_distance)


def time_of_impact(a: Shape, pose_a: PoseLike, b: Shape, pose_b: PoseLike, *,
                   velocity_a: npt.ArrayLike = _ZERO3, angular_velocity_a: npt.ArrayLike = _ZERO3,
                   velocity_b: npt.ArrayLike = _ZERO3, angular_velocity_b: npt.ArrayLike = _ZERO3,
                   center_a: npt.ArrayLike = _ZERO3, center_b: npt.ArrayLike = _ZERO3,
                   duration: float = 1.0, tolerance: float = _TOI_TOL,
                   target_distance: float = 0.0, max_iterations: int = _TOI_ITER,
                   gjk_tolerance: float = _GJK_TOL, gjk_max_iterations: int = _GJK_ITER
                   ) -> ToiResult:
    """First time (seconds, within ``[0, duration]``) at which A and B touch while moving.

    Each shape starts at its pose and moves with constant velocities (world frame):
    its local point ``center_*`` (metres; the rotation centre, e.g. the centre of mass)
    moves at ``velocity_*`` (m/s) and the shape turns about it at ``angular_velocity_*``
    (rad/s). Conservative advancement on the distance query: the returned ``time`` is
    never later than the true first contact, and the shapes are then at most
    ``tolerance`` metres apart (default 1e-4 m); for a pair closing at speed v it is
    early by at most ``tolerance / v``. Works for every pair :func:`distance` supports
    (convex pairs, planes, triangle meshes, compounds); a plane may translate but not
    turn (status ``"unsupported"``). ``result.hit`` is False when they do not touch in
    the interval; ``result.initially_overlapping`` when they overlap at the start.
    Status ``"max_iterations"`` means the cap stopped the search; ``hit`` is then True
    at the last time known to be safe.

    ``target_distance`` (m, signed, default 0) moves what counts as contact: the search
    stops within ``tolerance`` above it, so -0.01 finds when the shapes first overlap by
    1 cm (measured with EPA), 0.01 when they first come within 1 cm. Compounds are
    searched child by child and triangle meshes triangle by triangle, so a far part that
    closes fast is not hidden behind a near one that closes slowly.

    Example::

        ball, plate = wmo.Sphere(0.05), wmo.Box((1, 0.005, 1))
        r = wmo.geometry.time_of_impact(ball, ((0, 1, 0), (0, 0, 0, 1)), plate, wmo.Pose(),
                                        velocity_a=(0, -500, 0), duration=1 / 60)
        r.time   # ~ (1 - 0.05 - 0.005) / 500 s
    """
    return _g.time_of_impact(a, pose_a, b, pose_b, velocity_a=velocity_a,
                             angular_velocity_a=angular_velocity_a, velocity_b=velocity_b,
                             angular_velocity_b=angular_velocity_b, center_a=center_a,
                             center_b=center_b, duration=duration, tolerance=tolerance,
                             target_distance=target_distance,
                             max_iterations=max_iterations, gjk_tolerance=gjk_tolerance,
                             gjk_max_iterations=gjk_max_iterations)


def time_of_impact_batch(a: Shape, b: Shape, poses_a: PoseArrayLike, poses_b: PoseArrayLike, *,
                         velocities_a: npt.ArrayLike = _ZERO3,
                         angular_velocities_a: npt.ArrayLike = _ZERO3,
                         velocities_b: npt.ArrayLike = _ZERO3,
                         angular_velocities_b: npt.ArrayLike = _ZERO3, duration: float = 1.0,
                         tolerance: float = _TOI_TOL, max_iterations: int = _TOI_ITER,
                         gjk_tolerance: float = _GJK_TOL, gjk_max_iterations: int = _GJK_ITER
                         ) -> Dict[str, np.ndarray]:
    """:func:`time_of_impact` for N motions, looped in C++ with the GIL released.

    Poses as in the other batches ((N, 7) or one pose); velocities (N, 3) or (3,) for one
    value shared by every query. Each shape turns about its own origin. Returns a dict
    with ``hit`` (N,) bool, ``time`` (N,), ``initially_overlapping`` (N,) bool,
    ``distance`` (N,), ``point_a`` / ``point_b`` / ``normal`` (N, 3), ``status`` (N,)
    uint8 (see :class:`QueryStatus`) and ``iterations`` (N,) int32.
    """
    return _g.time_of_impact_batch(a, b, poses_a, poses_b, velocities_a=velocities_a,
                                   angular_velocities_a=angular_velocities_a,
                                   velocities_b=velocities_b,
                                   angular_velocities_b=angular_velocities_b, duration=duration,
                                   tolerance=tolerance, max_iterations=max_iterations,
                                   gjk_tolerance=gjk_tolerance,
                                   gjk_max_iterations=gjk_max_iterations)
