"""Wavefront OBJ meshes in: one OBJ file becomes one WMO body.

What is read: ``v x y z [w]`` vertices, ``f`` faces (``i``, ``i/t``, ``i//n``, ``i/t/n``;
negative indices count back from the last vertex; polygons are fan-triangulated), and
``o`` / ``g`` group names (they split the mesh into parts). Texture coordinates,
normals, materials (``mtllib``, ``usemtl``; the .mtl file is never opened, so a missing
one is fine), smoothing groups, lines and points are skipped. Any other keyword, a
malformed number, a NaN or infinite coordinate (or one beyond 1e15), a face index out of range raises
:class:`wmo.io.SceneFormatError` (a ``ValueError``) naming the file and the line.

The file is parsed here rather than through trimesh because trimesh skips malformed
lines silently, and a loader must name the line it cannot read; trimesh and coacd are
only used as references in the tests and (coacd) for convex decomposition.

How the mesh becomes a shape (``as_``):

- ``"static_mesh"``: a ``wmo.TriangleMesh`` of all faces (static bodies only, as WMO
  requires). Triangles of zero area are dropped (counted in a warning).
- ``"convex_hull"``: one ``wmo.ConvexHull`` of all vertices used by faces.
- ``"convex_decomposition"``: a ``wmo.Compound`` of convex hulls. When the file has
  several ``o``/``g`` groups and every group is already convex (each of its vertices
  lies on the boundary of the group's own hull, within 1e-6 of the mesh size: the
  output of V-HACD or CoACD), the groups are the parts as they are. Otherwise the
  whole mesh is decomposed with the ``coacd`` package, with a bounded budget
  (``max_convex_hull``, ``threshold``; see ``coacd_options``); without coacd the loader
  falls back to one convex hull and says so in the warnings.

Units and axes: OBJ has no units; ``scale`` (metres per file unit, default 1) multiplies
every coordinate. ``up`` names the file's up axis (OBJ tools mostly write ``"y"``);
``world_up`` the up axis wanted in WMO (default ``"y"``, matching ``wmo.World``'s
default gravity along -Y). When they differ the mesh is rotated by 90 degrees about X
(z-up to y-up maps (x, y, z) to (x, z, -y)). The body is then placed at ``position`` /
``orientation`` (metres, (x, y, z, w), world frame); the mesh keeps its own origin as
the body's shape-frame origin.
"""
from __future__ import annotations

import math
import os
from pathlib import Path
from typing import Any, Dict, List, Optional, Sequence, Tuple, Union

import numpy as np

from .. import _core as wmo
from . import LoadResult, SceneFileNotFoundError, SceneFormatError

__all__ = ["load_obj", "ObjMesh", "parse_obj"]

# Refuse files that would need absurd allocations before building arrays (a 1 GB OBJ
# holds ~25 M vertices; WMO is not the tool for more).
MAX_VERTICES = 20_000_000
MAX_TRIANGLES = 40_000_000
MAX_FILE_BYTES = 2_000_000_000
# Coordinates beyond this (file units) are refused: products of two of them (areas,
# normals, volumes) must stay far from float64 overflow, and no scene in metres,
# millimetres or microns comes near it.
MAX_COORDINATE = 1e15

_SKIPPED_KEYWORDS = {"vt", "vn", "vp", "mtllib", "usemtl", "s", "l", "p", "cstype", "deg",
                     "bmat", "step", "curv", "curv2", "surf", "parm", "trim", "hole",
                     "scrv", "sp", "end", "con", "mg", "bevel", "c_interp", "d_interp",
                     "lod", "shadow_obj", "trace_obj", "ctech", "stech", "maplib", "usemap"}


class ObjMesh:
    """A parsed OBJ file: ``vertices`` (V, 3) float64 in file units, ``triangles``
    (T, 3) int64 indices into vertices, ``groups`` a list of (name, triangle index
    array) in file order (a file without ``o``/``g`` lines has one group named after
    the file), ``face_lines`` (T,) the 1-based line of each triangle's face."""

    def __init__(self, vertices: np.ndarray, triangles: np.ndarray,
                 groups: List[Tuple[str, np.ndarray]], face_lines: np.ndarray) -> None:
        self.vertices = vertices
        self.triangles = triangles
        self.groups = groups
        self.face_lines = face_lines


def parse_obj(path: Union[str, "os.PathLike[str]"]) -> ObjMesh:
    """Parses the OBJ file at ``path`` (see the module docstring for what is read).
    Raises SceneFileNotFoundError if missing, SceneFormatError naming the line if bad."""
    p = Path(path)
    name = os.fspath(path)
    try:
        size = p.stat().st_size
    except FileNotFoundError:
        raise SceneFileNotFoundError(f"{name}: no such file") from None
    if size > MAX_FILE_BYTES:
        raise SceneFormatError(f"{name}: file of {size} bytes is larger than the {MAX_FILE_BYTES} accepted")
    try:
        text = p.read_bytes().decode("utf-8", errors="strict")
    except UnicodeDecodeError as e:
        # Count the line of the bad byte so the message can name it.
        line = p.read_bytes()[: e.start].count(b"\n") + 1
        raise SceneFormatError(f"{name}:{line}: not UTF-8 text (byte {e.start})") from None

    verts: List[Tuple[float, float, float]] = []
    tris: List[Tuple[int, int, int]] = []
    tri_lines: List[int] = []
    group_starts: List[Tuple[str, int]] = []
    for lineno, raw in enumerate(text.splitlines(), start=1):
        line = raw.split("#", 1)[0].strip()
        if not line:
            continue
        # A trailing backslash continues the line in the spec; rare, refuse clearly.
        if line.endswith("\\"):
            raise SceneFormatError(f"{name}:{lineno}: line continuation is not supported")
        parts = line.split()
        key = parts[0]
        if key == "v":
            if len(parts) not in (4, 5, 7):  # x y z [w] or x y z r g b (vertex colours)
                raise SceneFormatError(f"{name}:{lineno}: 'v' needs 3 coordinates, got {line!r}")
            try:
                x, y, z = (float(t) for t in parts[1:4])
                for t in parts[4:]:
                    float(t)
            except ValueError:
                raise SceneFormatError(f"{name}:{lineno}: bad number in {line!r}") from None
            if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(z)):
                raise SceneFormatError(f"{name}:{lineno}: vertex is not finite: {line!r}")
            if max(abs(x), abs(y), abs(z)) > MAX_COORDINATE:
                raise SceneFormatError(f"{name}:{lineno}: vertex coordinate beyond +-{MAX_COORDINATE:g} "
                                       f"(file units): {line!r}")
            if len(verts) >= MAX_VERTICES:
                raise SceneFormatError(f"{name}:{lineno}: more than {MAX_VERTICES} vertices")
            verts.append((x, y, z))
        elif key == "f":
            if len(parts) < 4:
                raise SceneFormatError(f"{name}:{lineno}: a face needs at least 3 vertices, got {line!r}")
            idx = []
            n = len(verts)
            for tok in parts[1:]:
                head = tok.split("/", 1)[0]
                try:
                    i = int(head)
                except ValueError:
                    raise SceneFormatError(f"{name}:{lineno}: bad vertex index {tok!r}") from None
                # OBJ indices are 1-based; negative ones are relative to the end so far.
                j = i - 1 if i > 0 else n + i
                if i == 0 or not 0 <= j < n:
                    raise SceneFormatError(
                        f"{name}:{lineno}: vertex index {i} out of range (1..{n} defined so far)")
                idx.append(j)
            if len(tris) + len(idx) - 2 > MAX_TRIANGLES:
                raise SceneFormatError(f"{name}:{lineno}: more than {MAX_TRIANGLES} triangles")
            for k in range(1, len(idx) - 1):
                tris.append((idx[0], idx[k], idx[k + 1]))
                tri_lines.append(lineno)
        elif key in ("o", "g"):
            gname = " ".join(parts[1:]) or f"{key}@{lineno}"
            # A new group starts at the next face; consecutive o/g lines (o then g) merge.
            if group_starts and group_starts[-1][1] == len(tris):
                group_starts[-1] = (gname if key == "o" or not group_starts[-1][0] else group_starts[-1][0],
                                    len(tris))
            else:
                group_starts.append((gname, len(tris)))
        elif key in _SKIPPED_KEYWORDS:
            continue
        else:
            raise SceneFormatError(f"{name}:{lineno}: unknown OBJ statement {key!r}")

    vertices = np.array(verts, dtype=np.float64).reshape(-1, 3)
    triangles = np.array(tris, dtype=np.int64).reshape(-1, 3)
    if not group_starts or group_starts[0][1] > 0:
        group_starts.insert(0, (p.stem, 0))
    groups = []
    for k, (gname, start) in enumerate(group_starts):
        end = group_starts[k + 1][1] if k + 1 < len(group_starts) else len(triangles)
        if end > start:
            groups.append((gname, np.arange(start, end)))
    return ObjMesh(vertices, triangles, groups, np.array(tri_lines, dtype=np.int64))


# ---------------------------------------------------------------------------------------
# Helpers shared with the USD reader.


def quat_from_matrix(r: np.ndarray) -> Tuple[float, float, float, float]:
    """Unit quaternion (x, y, z, w) of a proper rotation matrix (column convention)."""
    m = np.asarray(r, dtype=np.float64)
    tr = m[0, 0] + m[1, 1] + m[2, 2]
    # Shepperd's method: divide by the largest of the four candidates for stability.
    if tr > 0:
        s = math.sqrt(tr + 1.0) * 2
        q = ((m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s, 0.25 * s)
    elif m[0, 0] > m[1, 1] and m[0, 0] > m[2, 2]:
        s = math.sqrt(1.0 + m[0, 0] - m[1, 1] - m[2, 2]) * 2
        q = (0.25 * s, (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s, (m[2, 1] - m[1, 2]) / s)
    elif m[1, 1] > m[2, 2]:
        s = math.sqrt(1.0 + m[1, 1] - m[0, 0] - m[2, 2]) * 2
        q = ((m[0, 1] + m[1, 0]) / s, 0.25 * s, (m[1, 2] + m[2, 1]) / s, (m[0, 2] - m[2, 0]) / s)
    else:
        s = math.sqrt(1.0 + m[2, 2] - m[0, 0] - m[1, 1]) * 2
        q = ((m[0, 2] + m[2, 0]) / s, (m[1, 2] + m[2, 1]) / s, 0.25 * s, (m[1, 0] - m[0, 1]) / s)
    qa = np.array(q)
    qa /= np.linalg.norm(qa)
    if qa[3] < 0:  # canonical sign: w >= 0
        qa = -qa
    return tuple(float(v) for v in qa)  # type: ignore[return-value]


def drop_degenerate(vertices: np.ndarray, triangles: np.ndarray, where: str,
                    warnings: List[str]) -> np.ndarray:
    """Returns ``triangles`` without those of zero area (relative to the mesh size);
    SceneFormatError naming ``where`` if none is left."""
    if len(triangles) == 0:
        raise SceneFormatError(f"{where}: mesh has no faces")
    a, b, c = (vertices[triangles[:, k]] for k in range(3))
    area2 = np.linalg.norm(np.cross(b - a, c - a), axis=1)
    extent = float(np.ptp(vertices, axis=0).max()) if len(vertices) else 0.0
    keep = area2 > (1e-12 * extent * extent)
    if not keep.any():
        raise SceneFormatError(f"{where}: every face has zero area ({len(triangles)} triangles)")
    if not keep.all():
        warnings.append(f"{where}: dropped {int((~keep).sum())} zero-area triangle(s)")
    return triangles[keep]


def make_hull(points: np.ndarray, where: str, warnings: List[str], *, flat: str = "error",
              normal_hint: Optional[np.ndarray] = None) -> "wmo.ConvexHull":
    """A ConvexHull of ``points`` (metres, shape frame). Collinear or coincident points
    raise SceneFormatError naming ``where``; coplanar ones too unless ``flat="thicken"``,
    which extrudes the flat polygon behind its face (against ``normal_hint``, the way the
    surface faces) by 1% of its size (at least 1 mm), with a warning."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if len(pts) < 4:
        raise SceneFormatError(f"{where}: a convex hull needs at least 4 points, got {len(pts)}")
    if not np.isfinite(pts).all():
        raise SceneFormatError(f"{where}: convex hull point is not finite")
    centred = pts - pts.mean(axis=0)
    sv, vt = np.linalg.svd(centred, full_matrices=False)[1:]
    size = float(sv[0]) if len(sv) else 0.0
    if size == 0.0 or sv[1] <= 1e-9 * size:
        raise SceneFormatError(f"{where}: convex hull points are coincident or collinear")
    if sv[2] <= 1e-9 * size:
        if flat != "thicken":
            raise SceneFormatError(f"{where}: convex hull points are coplanar (no volume)")
        n = vt[2]
        if normal_hint is not None and float(np.dot(n, normal_hint)) < 0:
            n = -n
        extent = float(np.ptp(pts, axis=0).max())
        thickness = max(1e-3, 0.01 * extent)
        pts = np.vstack([pts, pts - thickness * n])
        warnings.append(f"{where}: coplanar convex hull thickened by {thickness:.4g} m behind its face")
    try:
        return wmo.ConvexHull(pts)
    except ValueError as e:
        raise SceneFormatError(f"{where}: cannot build a convex hull: {e}") from None


def convex_position(points: np.ndarray, tol: float) -> bool:
    """True when every point lies on the boundary of the hull of all (within ``tol``):
    the points already are a convex piece."""
    try:
        hull = wmo.ConvexHull(points)
    except ValueError:
        return False
    d = np.asarray(points) @ hull.face_normals.T - hull.face_offsets
    return bool((d.max(axis=1) > -tol).all())


DEFAULT_COACD_OPTIONS: Dict[str, Any] = {
    # A budget that decomposes a ~1000-triangle mesh in a few seconds on one core; raise
    # max_convex_hull / lower threshold for finer pieces.
    "threshold": 0.08, "max_convex_hull": 16, "preprocess_resolution": 30, "resolution": 1000,
    "mcts_iterations": 60, "mcts_max_depth": 2, "seed": 1,
}


def convex_decomposition(vertices: np.ndarray, triangles: np.ndarray, where: str,
                         warnings: List[str], coacd_options: Optional[Dict[str, Any]] = None
                         ) -> List["wmo.ConvexHull"]:
    """Convex pieces (hulls in the mesh's frame) of a triangle mesh through coacd; one
    hull with a warning when coacd is not installed or fails."""
    try:
        import coacd  # type: ignore[import-not-found]
    except ImportError:
        warnings.append(f"{where}: convex decomposition needs the 'coacd' package; used one convex hull")
        return [make_hull(vertices[np.unique(triangles)], where, warnings)]
    opts = dict(DEFAULT_COACD_OPTIONS)
    opts.update(coacd_options or {})
    try:
        coacd.set_log_level("error")
        pieces = coacd.run_coacd(coacd.Mesh(np.asarray(vertices, np.float64), np.asarray(triangles, np.int32)),
                                 **opts)
    except Exception as e:  # coacd raises RuntimeError on meshes it cannot process
        warnings.append(f"{where}: coacd failed ({e}); used one convex hull")
        return [make_hull(vertices[np.unique(triangles)], where, warnings)]
    hulls = []
    for k, piece in enumerate(pieces):
        pv = np.asarray(piece[0], dtype=np.float64)
        try:
            hulls.append(make_hull(pv, f"{where} (piece {k})", warnings))
        except SceneFormatError:
            # A sliver piece without volume carries no mass or contact; skip it.
            warnings.append(f"{where}: coacd piece {k} has no volume; skipped")
    if not hulls:
        warnings.append(f"{where}: coacd produced no usable piece; used one convex hull")
        return [make_hull(vertices[np.unique(triangles)], where, warnings)]
    return hulls


# ---------------------------------------------------------------------------------------

_AXES = {"x": 0, "y": 1, "z": 2}


def _axis_rotation(up: str, world_up: str) -> np.ndarray:
    """Rotation (column convention) taking the file's up axis onto world_up."""
    u, w = up.lower(), world_up.lower()
    if u not in ("y", "z") or w not in ("y", "z"):
        raise ValueError(f"up and world_up must be 'y' or 'z', got {up!r} and {world_up!r}")
    if u == w:
        return np.eye(3)
    if u == "z":  # -90 degrees about X takes +Z to +Y: (x, y, z) -> (x, z, -y)
        return np.array([[1.0, 0, 0], [0, 0, 1.0], [0, -1.0, 0]])
    return np.array([[1.0, 0, 0], [0, 0, -1.0], [0, 1.0, 0]])  # +90 degrees: (x, y, z) -> (x, -z, y)


def load_obj(path: Union[str, "os.PathLike[str]"], as_: str = "static_mesh", *, scale: float = 1.0,
             up: str = "y", world_up: str = "y", position: Sequence[float] = (0.0, 0.0, 0.0),
             orientation: Sequence[float] = (0.0, 0.0, 0.0, 1.0), kind: Optional[str] = None,
             mass: Optional[float] = None, density: float = 1000.0, friction: float = 0.5,
             restitution: float = 0.0, world: Optional["wmo.World"] = None,
             coacd_options: Optional[Dict[str, Any]] = None, one_sided: bool = False,
             **world_options: Any) -> LoadResult:
    """Reads the OBJ file at ``path`` into one body of a World (see the module docstring).

    ``as_``: ``"static_mesh"``, ``"convex_hull"`` or ``"convex_decomposition"``.
    ``scale``: metres per file unit. ``up`` / ``world_up``: the file's and the wanted up
    axis (``"y"`` or ``"z"``). ``position`` (m) and ``orientation`` ((x, y, z, w)) place
    the body in the world. ``kind``: ``"static"`` (the default, and the only one allowed,
    for ``static_mesh``), ``"dynamic"`` (default otherwise) or ``"kinematic"``. ``mass``
    (kg) overrides ``density`` (kg/m^3). ``friction`` and ``restitution`` go to
    ``World.add_body``. ``world``: add to this World instead of a new one (a new World
    gets ``world_options``, e.g. ``dt``). ``coacd_options``: overrides of
    :data:`DEFAULT_COACD_OPTIONS`. ``one_sided``: for ``static_mesh``, make the
    ``wmo.TriangleMesh`` one-sided (the surface of a solid behind its faces: terrain,
    or a closed mesh wound outwards; see ``wmo.TriangleMesh``).

    Returns a LoadResult whose ``bodies`` has one entry keyed by the file's stem;
    ``info`` holds the vertex and triangle counts read and, for a decomposition, how the
    parts were found (``"groups"``, ``"coacd"`` or ``"hull"``).
    """
    if as_ not in ("static_mesh", "convex_hull", "convex_decomposition"):
        raise ValueError(f"as_ must be 'static_mesh', 'convex_hull' or 'convex_decomposition', got {as_!r}")
    if not (isinstance(scale, (int, float)) and math.isfinite(scale) and scale > 0):
        raise ValueError(f"scale must be a positive finite number, got {scale!r}")
    rot = _axis_rotation(up, world_up)
    if kind is None:
        kind = "static" if as_ == "static_mesh" else "dynamic"
    if not isinstance(one_sided, bool):
        raise TypeError(f"one_sided must be True or False, got {one_sided!r}")
    if one_sided and as_ != "static_mesh":
        raise ValueError(f"one_sided applies to as_='static_mesh' only, got as_={as_!r}")
    if as_ == "static_mesh" and kind != "static":
        raise ValueError(f"a static_mesh body must be static (WMO triangle meshes are static), got kind={kind!r}")

    name = os.fspath(path)
    mesh = parse_obj(path)
    warnings: List[str] = []
    if len(mesh.triangles) == 0:
        raise SceneFormatError(f"{name}: no faces")
    verts = (mesh.vertices @ rot.T) * float(scale)
    info: Dict[str, Any] = {"vertices": len(mesh.vertices), "triangles": len(mesh.triangles),
                            "groups": [g for g, _ in mesh.groups]}

    shape: wmo.Shape
    if as_ == "static_mesh":
        tris = drop_degenerate(verts, mesh.triangles, name, warnings)
        shape = wmo.TriangleMesh(verts, tris, one_sided=one_sided)
    elif as_ == "convex_hull":
        used = np.unique(mesh.triangles)
        shape = make_hull(verts[used], name, warnings)
    else:
        extent = float(np.ptp(verts, axis=0).max())
        group_points = [verts[np.unique(mesh.triangles[idx])] for _, idx in mesh.groups]
        if len(mesh.groups) > 1 and all(
                len(gp) >= 4 and convex_position(gp, 1e-6 * extent) for gp in group_points):
            hulls = [make_hull(gp, f"{name} (group {g!r})", warnings)
                     for gp, (g, _) in zip(group_points, mesh.groups)]
            info["parts_from"] = "groups"
        else:
            tris = drop_degenerate(verts, mesh.triangles, name, warnings)
            hulls = convex_decomposition(verts, tris, name, warnings, coacd_options)
            info["parts_from"] = "coacd" if not any("coacd" in w for w in warnings) else "hull"
        shape = hulls[0] if len(hulls) == 1 else wmo.Compound([(h, wmo.Pose()) for h in hulls])
        info["parts"] = len(hulls)

    w = world if world is not None else wmo.World(**world_options)
    spec = dict(shape=shape, position=position, orientation=orientation, kind=kind, mass=mass,
                density=density, friction=friction, restitution=restitution)
    body = w.add_body(**spec)
    key = Path(path).stem
    return LoadResult(world=w, bodies={key: body}, warnings=warnings, specs={key: spec}, info=info)
