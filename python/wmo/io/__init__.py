"""Scenes in: read USD (UsdPhysics) stages and Wavefront OBJ meshes into a ``wmo.World``.

>>> import wmo.io
>>> result = wmo.io.load("scene.usda")            # doctest: +SKIP
>>> result.world.step(60)                          # doctest: +SKIP
>>> result.bodies["/World/BoxActor"].position      # doctest: +SKIP
>>> result.warnings                                # doctest: +SKIP

``load`` picks the reader from the file suffix: ``.usd``, ``.usda``, ``.usdc`` (and
``.usdz``) go to :func:`wmo.io.usd.load_usd`, which needs Pixar's ``usd-core`` package;
``.obj`` goes to :func:`wmo.io.obj.load_obj` (convex decomposition of a concave mesh uses
the optional ``coacd`` package). Both return a :class:`LoadResult`. Everything in a file
that WMO cannot represent yet (joints, an offset centre of mass, ...) is listed in
``LoadResult.warnings``: nothing is dropped silently.

Errors: a missing file raises :class:`SceneFileNotFoundError` (both a ``ValueError`` and a
``FileNotFoundError``); a malformed file, a NaN coordinate, a mesh without any triangle of
non-zero area, a hull from coplanar points, ... raise :class:`SceneFormatError` (a
``ValueError``) naming the USD prim path or the OBJ line. The readers never leave a
half-built world behind in the result: on error nothing is returned.

Units: WMO works in metres, kilograms, seconds and radians; the readers convert.
"""
from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Dict, List, Union

from .._core import Body, World

__all__ = ["LoadResult", "SceneFormatError", "SceneFileNotFoundError", "load", "load_usd", "load_obj", "save"]


class SceneFormatError(ValueError):
    """The file cannot be read as a scene; the message names the file and the USD prim
    path or the OBJ line number."""


class SceneFileNotFoundError(SceneFormatError, FileNotFoundError):
    """The scene file does not exist (a ValueError and a FileNotFoundError)."""


@dataclass
class LoadResult:
    """What a reader built.

    ``world``: the ``wmo.World`` holding the bodies (a new one unless the caller passed
    ``world=``). ``bodies``: each body created, keyed by USD prim path (the rigid body's
    path, or the collider's path for a static collider) or by OBJ object name.
    ``warnings``: one human-readable line per thing in the file that was ignored or
    approximated. ``specs``: for each key of ``bodies``, the arguments given to
    ``World.add_body`` (``shape``, ``kind``, ``position``, ``orientation``, ``mass`` or
    ``density``, ``friction``, ``restitution``, velocities), since a Body does not expose
    its shape or material. ``info``: reader facts such as ``meters_per_unit``,
    ``up_axis`` and the gravity used (m/s^2).
    """

    world: World
    bodies: Dict[str, Body] = field(default_factory=dict)
    warnings: List[str] = field(default_factory=list)
    specs: Dict[str, Dict[str, Any]] = field(default_factory=dict)
    info: Dict[str, Any] = field(default_factory=dict)


_USD_SUFFIXES = (".usd", ".usda", ".usdc", ".usdz")
_OBJ_SUFFIXES = (".obj",)


def load(path: Union[str, "os.PathLike[str]"], **options: Any) -> LoadResult:
    """Reads the scene at ``path``, choosing the reader from its suffix (case-insensitive).

    ``options`` go to the reader: :func:`wmo.io.usd.load_usd` for .usd/.usda/.usdc/.usdz,
    :func:`wmo.io.obj.load_obj` for .obj. An unknown suffix raises ``ValueError`` naming it.
    """
    suffix = Path(path).suffix.lower()
    if suffix in _USD_SUFFIXES:
        return load_usd(path, **options)
    if suffix in _OBJ_SUFFIXES:
        return load_obj(path, **options)
    raise ValueError(
        f"unknown scene file suffix {suffix!r} for {os.fspath(path)!r}; "
        f"expected one of {', '.join(_USD_SUFFIXES + _OBJ_SUFFIXES)}")


def load_usd(path: Union[str, "os.PathLike[str]"], **options: Any) -> LoadResult:
    """See :func:`wmo.io.usd.load_usd` (imported lazily: pxr is optional)."""
    from .usd import load_usd as _load_usd
    return _load_usd(path, **options)


def load_obj(path: Union[str, "os.PathLike[str]"], **options: Any) -> LoadResult:
    """See :func:`wmo.io.obj.load_obj`."""
    from .obj import load_obj as _load_obj
    return _load_obj(path, **options)


def save(world: World, path: Union[str, "os.PathLike[str]"], **options: Any) -> None:
    """Writes ``world`` to ``path``, the format from its suffix: .usda/.usdc/.usd through
    :func:`wmo.io.usd_writer.save_usd` (a UsdPhysics stage that loads back bit for bit;
    ``steps=N`` also records a run as time samples), .obj through
    :func:`wmo.io.obj_writer.save_obj` (the world's current geometry, one object per
    body; ``up="z"`` for Z-up tools). Another suffix raises ValueError naming it."""
    suffix = Path(path).suffix.lower()
    if suffix in (".usd", ".usda", ".usdc"):
        from .usd_writer import save_usd
        save_usd(world, path, **options)
        return
    if suffix in _OBJ_SUFFIXES:
        from .obj_writer import save_obj
        save_obj(world, path, **options)
        return
    raise ValueError(f"cannot save to {os.fspath(path)!r}: unknown suffix {suffix!r}; "
                     f"expected .usda, .usdc, .usd or .obj")
