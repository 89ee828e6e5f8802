"""Wavefront OBJ out: a world's current geometry, or one triangle mesh.

:func:`save_obj` writes one object ``o body_<k>`` per body, k its row in the world's
state arrays (``World.positions[k]``), in row order: the body's shape tessellated by
:func:`wmo.io.tessellate.shape_mesh` (curved surfaces inscribed, a plane drawn as a
100 m square slab) and placed at the body's current pose. :func:`save_mesh_obj` writes
one given mesh as one object.

What is written: a ``#`` comment header (the WMO version, the body count, units and up
axis, and each body's shape type and kind above its object), ``o`` lines, ``v x y z``
lines and ``f a b c`` triangles, 1-based and numbered across the whole file,
counter-clockwise seen from outside. No normals, texture coordinates or materials.
Numbers use ``%.<precision>g``: 9 significant digits keep about a nanometre at a metre.

Units and frames: metres, world frame (for ``save_mesh_obj``, whatever frame the
vertices are given in). OBJ has no units or up axis of its own; ``up="y"`` writes WMO's
frame as it is (the Y-up convention most OBJ tools assume, and the default gravity
along -Y), ``up="z"`` rotates it by +90 degrees about X, (x, y, z) -> (x, -z, y), for
tools that want Z up (:func:`wmo.io.obj.load_obj` with ``up="z"`` undoes it).

Both write a temporary file in the target folder and rename it over ``path``
(``os.replace``), so a failed write leaves no partial file. Bad arguments raise
ValueError naming the argument and its value.
"""
from __future__ import annotations

import os
import secrets
from pathlib import Path
from typing import Iterable, List, Sequence, Tuple, Union

import numpy as np

from .. import _core
from .tessellate import shape_mesh

__all__ = ["save_obj", "save_mesh_obj"]

PathLike = Union[str, "os.PathLike[str]"]

# (x, y, z) -> (x, -z, y): +90 degrees about X takes WMO's +Y up onto +Z.
_Y_UP_TO_Z_UP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])


def _obj_path(path: PathLike) -> Path:
    p = Path(path)
    if p.suffix.lower() != ".obj":
        raise ValueError(f"path must end in .obj, got {os.fspath(path)!r}")
    return p


def _check_precision(precision: object) -> int:
    if isinstance(precision, bool) or not isinstance(precision, (int, np.integer)) or not 1 <= precision <= 17:
        raise ValueError(f"precision must be an integer in 1..17 (significant digits), got {precision!r}")
    return int(precision)


def _write(path: Path, header: Sequence[str], objects: Iterable[Tuple[str, str, np.ndarray, np.ndarray]],
           precision: int) -> None:
    """Writes the header comments then each (name, comment, vertices, triangles) object,
    through a temporary file renamed over ``path``."""
    v_fmt = f"v %.{precision}g %.{precision}g %.{precision}g\n"
    # Not tempfile.mkstemp: its 0600 mode would stay on the renamed file; 0666 here goes
    # through the umask like any newly created file.
    tmp = path.parent / f".{path.name}.{os.getpid()}.{secrets.token_hex(4)}.tmp"
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
    try:
        with os.fdopen(fd, "w", encoding="utf-8", newline="\n") as f:
            f.writelines(f"# {line}\n" for line in header)
            offset = 1  # OBJ indices are 1-based and count every vertex written so far
            for name, comment, vertices, triangles in objects:
                f.write(f"# {comment}\no {name}\n")
                f.writelines(v_fmt % tuple(row) for row in vertices.tolist())
                f.writelines("f %d %d %d\n" % tuple(row) for row in (triangles + offset).tolist())
                offset += len(vertices)
        os.replace(tmp, path)
    except BaseException:
        os.unlink(tmp)
        raise


def save_obj(world: "_core.World", path: PathLike, *, up: str = "y", precision: int = 9) -> None:
    """Writes ``world``'s current geometry to ``path`` (a .obj file), one object
    ``body_<k>`` per body row k (see the module docstring).

    ``up``: ``"y"`` writes WMO's frame as is, ``"z"`` rotates it to Z up. ``precision``:
    significant digits of the coordinates (1..17). Raises ValueError naming a bad
    argument; nothing is written then.
    """
    from .. import __version__

    p = _obj_path(path)
    if up not in ("y", "z"):
        raise ValueError(f"up must be 'y' or 'z', got {up!r}")
    precision = _check_precision(precision)
    if not isinstance(world, _core.World):
        raise TypeError(f"world must be a wmo.World, got {type(world).__name__}")

    positions, orientations = np.asarray(world.positions), np.asarray(world.orientations)
    objects: List[Tuple[str, str, np.ndarray, np.ndarray]] = []
    for k in range(world.body_count):
        body = world.body(k)
        v, t = shape_mesh(body.shape)
        rotation = np.asarray(_core.Pose(positions[k], orientations[k]).matrix())
        v = v @ rotation.T + positions[k]
        if up == "z":
            v = v @ _Y_UP_TO_Z_UP.T
        objects.append((f"body_{k}", f"body {k}: {body.shape.type}, {body.kind}", v, t))
    header = [f"wmo {__version__}", f"bodies: {world.body_count}",
              "units: metres; up: +Y (WMO's world frame)" if up == "y"
              else "units: metres; up: +Z (WMO's world frame turned by (x, y, z) -> (x, -z, y))"]
    _write(p, header, objects, precision)


def save_mesh_obj(vertices: np.ndarray, triangles: np.ndarray, path: PathLike, *, name: str = "mesh",
                  precision: int = 9) -> None:
    """Writes one triangle mesh to ``path`` (a .obj file) as the object ``name``.

    ``vertices``: (V, 3) finite coordinates (metres, any frame). ``triangles``: (T, 3)
    integer 0-based indices into vertices (written 1-based), in their given winding.
    ``name``: the object name, non-empty, without whitespace. Raises ValueError naming
    the bad field; nothing is written then.
    """
    from .. import __version__

    p = _obj_path(path)
    precision = _check_precision(precision)
    if not isinstance(name, str) or not name or any(c.isspace() for c in name):
        raise ValueError(f"name must be a non-empty string without whitespace, got {name!r}")
    try:
        v = np.asarray(vertices, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"vertices must be a (V, 3) array of numbers, got {type(vertices).__name__}") from None
    if v.ndim != 2 or v.shape[1] != 3:
        raise ValueError(f"vertices must have shape (V, 3), got {v.shape}")
    if not np.isfinite(v).all():
        raise ValueError(f"vertices must be finite; row {int(np.argwhere(~np.isfinite(v))[0, 0])} is not")
    t = np.asarray(triangles)
    if t.ndim != 2 or t.shape[1] != 3 or (t.size and not np.issubdtype(t.dtype, np.integer)):
        raise ValueError(f"triangles must be a (T, 3) integer array, got shape {t.shape} of {t.dtype}")
    t = t.astype(np.int64)
    if t.size and (t.min() < 0 or t.max() >= len(v)):
        raise ValueError(f"triangles index out of range 0..{len(v) - 1}: {int(t.min())}..{int(t.max())}")
    _write(p, [f"wmo {__version__}", "units: metres"],
           [(name, f"{len(v)} vertices, {len(t)} triangles", v, t)], precision)
