"""The server's authoritative scene: a :class:`wmo.World` plus what the world does not
keep (each body's definition, its remote id, who is dragging it), and the edits that
change it.

Every change to a hosted scene is an *edit*: an operation name and a dict of plain
arguments (msgpack-able: numbers, strings, lists, dicts). :meth:`SceneModel.apply`
checks an edit completely before it changes anything, so a rejected edit
(:class:`EditError`, with a code and a message naming the field and the bad value)
leaves the scene exactly as it was. The same edits, replayed in the same order on the
same document, give the same scene: this is what the journal relies on.

Bodies are named by *remote ids*: positive integers given out in order, never reused,
stable for the life of a scene (the world's own handles are not: a body dragged by a
client is re-created as kinematic). Snapshots list bodies in ascending id order.
"""
from __future__ import annotations

import math
import os
from pathlib import Path
from typing import Any, Callable

import numpy as np

from .. import _core, scenes

__all__ = ["EditError", "SceneModel", "OPS", "SETTINGS", "SCENE_BUILDERS", "register_file_scene", "shape_from_spec",
           "shape_to_spec"]

#: World settings a client may set (load_scene, set_settings), with their types: every
#: keyword of ``wmo.World`` (the keys of ``World.settings``). A value of the right type
#: then meets the World's own checks (ranges, named in the error), and integers are also
#: capped at 1000 (a scene is shared: one edit must not stall its thread).
SETTINGS: dict[str, type] = {
    "gravity": list, "dt": float, "substeps": int, "iterations": int, "relax_iterations": int,
    "energy_guard_passes": int, "energy_guard_tolerance": float, "block_solver": bool, "centroid_rows": bool,
    "contact_hertz": float, "contact_damping_ratio": float, "contact_push_max": float,
    "contact_static_hertz_scale": float, "contact_max_sag": float,
    "restitution_threshold": float, "speculative_distance": float, "speculative_motion": float,
    "speculative_motion_static": float, "manifold_reuse_distance": float, "manifold_reuse_angle": float,
    "friction_combine": str, "restitution_combine": str, "sleeping": bool,
    "sleep_linear_threshold": float, "sleep_angular_threshold": float, "time_to_sleep": float,
    "gyroscopic": bool, "ccd": bool, "ccd_motion_threshold": float, "ccd_penetration": float,
    "threads": int, "broadphase": str,
    # The scene's, not a World keyword: pairs of collision groups [a, b] (0..63) whose
    # bodies do not collide (World.set_group_collision(a, b, False)); every other pair of
    # groups collides.
    "collision_groups_off": list,
    # Also the scene's: pairs of body ids [a, b] that do not collide
    # (World.set_pair_collision(a, b, False)); a removed body's pairs go with it.
    "collision_pairs_off": list,
}

#: Settings that are not World keywords (applied by SceneModel after the World is made).
SCENE_SETTINGS = ("collision_groups_off", "collision_pairs_off")
MAX_PAIR_FILTERS = 100_000

#: Caps on edit arguments: a scene is a shared resource, and one edit must not stall the
#: simulation thread or exhaust memory.
MAX_BODIES = 100_000
MAX_HULL_POINTS = 4096
MAX_MESH_TRIANGLES = 200_000
MAX_STEPS_PER_EDIT = 1000
MAX_COMPOUND_CHILDREN = 256
#: Hull points of all the children of one compound together.
MAX_COMPOUND_POINTS = 4 * MAX_HULL_POINTS

#: Body definition fields an add_body edit may carry, with defaults (those of World.add_body).
BODY_FIELDS: dict[str, Any] = {
    "kind": "dynamic", "mass": None, "density": 1000.0, "friction": 0.5, "restitution": 0.0,
    "linear_damping": 0.0, "angular_damping": 0.0, "gravity_scale": 1.0, "ccd": False,
    "collision_group": 0, "center_of_mass": None, "inertia": None, "inertia_axes": None,
}


class EditError(ValueError):
    """A rejected edit. ``code`` is one of the protocol's error codes (PROTOCOL.md):
    ``bad_args``, ``unknown_op``, ``unknown_body``, ``not_owner``, ``not_paused``,
    ``limit``."""

    def __init__(self, code: str, message: str):
        super().__init__(message)
        self.code = code


# ---- argument checks: each names the field and the bad value ----

def _finite(name: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise EditError("bad_args", f"{name} must be a number, got {value!r}")
    v = float(value)
    if not math.isfinite(v):
        raise EditError("bad_args", f"{name} must be finite, got {value!r}")
    return v


def _positive(name: str, value: Any) -> float:
    v = _finite(name, value)
    if v <= 0:
        raise EditError("bad_args", f"{name} must be > 0, got {value!r}")
    return v


def _int(name: str, value: Any, lo: int, hi: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int):
        raise EditError("bad_args", f"{name} must be an integer, got {value!r}")
    if not lo <= value <= hi:
        raise EditError("bad_args", f"{name} must be in [{lo}, {hi}], got {value!r}")
    return value


def _vec(name: str, value: Any, n: int = 3) -> list[float]:
    if not isinstance(value, (list, tuple)) or len(value) != n:
        raise EditError("bad_args", f"{name} must be a list of {n} numbers, got {value!r}")
    return [_finite(f"{name}[{i}]", x) for i, x in enumerate(value)]


def _quat(name: str, value: Any) -> list[float]:
    q = _vec(name, value, 4)
    norm = math.sqrt(sum(x * x for x in q))
    # The world accepts unit quaternions to 1e-6 and renormalises them; a client's
    # float32 or rounded quaternion is within that.
    if abs(norm - 1) > 1e-6:
        raise EditError("bad_args", f"{name} must be a unit quaternion (x, y, z, w), got {value!r} (norm {norm})")
    return q


def _group_pairs(value: Any) -> list[list[int]]:
    """collision_groups_off: a list of [a, b] pairs of collision groups (0..63), at most
    one per unordered pair of groups (64 * 65 / 2)."""
    if not isinstance(value, (list, tuple)):
        raise EditError("bad_args", f"collision_groups_off must be a list of [a, b] pairs, got {value!r}")
    if len(value) > 64 * 65 // 2:
        raise EditError("limit", f"collision_groups_off has {len(value)} pairs, more than the {64 * 65 // 2} there are")
    out = []
    for i, pair in enumerate(value):
        if not isinstance(pair, (list, tuple)) or len(pair) != 2:
            raise EditError("bad_args", f"collision_groups_off[{i}] must be a pair [a, b], got {pair!r}")
        out.append([_int(f"collision_groups_off[{i}][{j}]", g, 0, 63) for j, g in enumerate(pair)])
    return out


def _id_pairs(value: Any) -> list[list[int]]:
    """collision_pairs_off: a list of [a, b] pairs of body ids."""
    if not isinstance(value, (list, tuple)):
        raise EditError("bad_args", f"collision_pairs_off must be a list of [a, b] pairs, got {value!r}"[:200])
    if len(value) > MAX_PAIR_FILTERS:
        raise EditError("limit", f"collision_pairs_off has {len(value)} pairs, more than the cap {MAX_PAIR_FILTERS}")
    out = []
    for i, pair in enumerate(value):
        if not isinstance(pair, (list, tuple)) or len(pair) != 2:
            raise EditError("bad_args", f"collision_pairs_off[{i}] must be a pair [a, b], got {pair!r}"[:200])
        out.append([_int(f"collision_pairs_off[{i}][{j}]", r, 1, 2**31 - 1) for j, r in enumerate(pair)])
    return out


def _points(name: str, value: Any, cap: int | None, width: int = 3) -> np.ndarray:
    if not isinstance(value, (list, tuple)) or not value:
        raise EditError("bad_args", f"{name} must be a non-empty list of rows")
    if cap is not None and len(value) > cap:
        raise EditError("limit", f"{name} has {len(value)} rows, more than the cap {cap}")
    try:
        arr = np.array(value, dtype=float)
    except (TypeError, ValueError):
        raise EditError("bad_args", f"{name} must be a list of rows of {width} numbers")
    if arr.ndim != 2 or arr.shape[1] != width:
        raise EditError("bad_args", f"{name} must have shape (n, {width}), got {arr.shape}")
    if not np.isfinite(arr).all():
        raise EditError("bad_args", f"{name} must be finite (row {int(np.argwhere(~np.isfinite(arr))[0][0])})")
    return arr


def _check_keys(what: str, args: dict, allowed) -> None:
    extra = sorted(set(args) - set(allowed))
    if extra:
        raise EditError("bad_args", f"{what}: unknown field {extra[0]!r} (allowed: {', '.join(sorted(allowed))})")


# ---- shapes as plain specs ----

def shape_from_spec(spec: Any, *, limits: bool = True) -> _core.Shape:
    """A shape from its spec, e.g. ``{"type": "box", "half_extents": [1, 1, 1]}``
    (PROTOCOL.md lists the types). Raises EditError naming the bad field. ``limits``:
    apply a scene's caps on hull points and mesh triangles (an edit's; a scene file
    read by its operator, wmo.io.usd_exact, passes False)."""
    if not isinstance(spec, dict) or not isinstance(spec.get("type"), str):
        raise EditError("bad_args", f"shape must be a dict with a 'type', got {spec!r}"[:200])
    t = spec["type"]
    fields = {"sphere": ("radius",), "box": ("half_extents", "rounding"), "capsule": ("radius", "half_height"),
              "cylinder": ("radius", "half_height"), "convex_hull": ("points",), "plane": ("normal", "offset"),
              "triangle_mesh": ("vertices", "triangles", "one_sided"), "compound": ("children",)}
    if t not in fields:
        raise EditError("bad_args", f"shape.type must be one of {', '.join(fields)}, got {t!r}")
    _check_keys(f"shape {t}", spec, ("type",) + fields[t])
    try:
        if t == "sphere":
            return _core.Sphere(_positive("shape.radius", spec.get("radius")))
        if t == "box":
            return _core.Box(_vec("shape.half_extents", spec.get("half_extents")),
                             _finite("shape.rounding", spec.get("rounding", 0.0)))
        if t == "capsule":
            return _core.Capsule(_positive("shape.radius", spec.get("radius")),
                                 _positive("shape.half_height", spec.get("half_height")))
        if t == "cylinder":
            return _core.Cylinder(_positive("shape.radius", spec.get("radius")),
                                  _positive("shape.half_height", spec.get("half_height")))
        if t == "convex_hull":
            return _core.ConvexHull(_points("shape.points", spec.get("points"), MAX_HULL_POINTS if limits else None))
        if t == "plane":
            return _core.Plane(_vec("shape.normal", spec.get("normal")), _finite("shape.offset", spec.get("offset", 0.0)))
        if t == "compound":
            return _compound_from_spec(spec.get("children"), limits)
        vertices = _points("shape.vertices", spec.get("vertices"), 3 * MAX_MESH_TRIANGLES if limits else None)
        tris = _points("shape.triangles", spec.get("triangles"), MAX_MESH_TRIANGLES if limits else None)
        if (tris != np.round(tris)).any() or tris.min() < 0 or tris.max() >= len(vertices):
            raise EditError("bad_args", f"shape.triangles must index the {len(vertices)} vertices")
        one_sided = spec.get("one_sided", False)
        if not isinstance(one_sided, bool):
            raise EditError("bad_args", f"shape.one_sided must be true or false, got {one_sided!r}"[:200])
        return _core.TriangleMesh(vertices, tris.astype(np.int32), one_sided=one_sided)
    except EditError:
        raise
    except (ValueError, TypeError) as e:  # the core's own checks (degenerate hull, ...)
        raise EditError("bad_args", f"shape {t}: {e}")


def _compound_from_spec(children: Any, limits: bool) -> _core.Compound:
    """A compound from its children's specs: [{"shape", "position", "orientation"}, ...],
    convex shapes placed in the compound's frame (no nested compounds)."""
    if not isinstance(children, (list, tuple)) or not children:
        raise EditError("bad_args", "shape.children must be a non-empty list of {shape, position, orientation}")
    if limits and len(children) > MAX_COMPOUND_CHILDREN:
        raise EditError("limit", f"shape.children has {len(children)} children, more than the cap {MAX_COMPOUND_CHILDREN}")
    parts, points = [], 0
    for i, c in enumerate(children):
        name = f"shape.children[{i}]"
        if not isinstance(c, dict):
            raise EditError("bad_args", f"{name} must be a map with shape, position, orientation, got {c!r}"[:200])
        _check_keys(name, c, ("shape", "position", "orientation"))
        sub = c.get("shape")
        if isinstance(sub, dict) and sub.get("type") == "compound":
            raise EditError("bad_args", f"{name}.shape: compounds do not nest")
        if isinstance(sub, dict) and isinstance(sub.get("points"), (list, tuple)):
            points += len(sub["points"])
            if limits and points > MAX_COMPOUND_POINTS:
                raise EditError("limit", f"shape.children hold more than {MAX_COMPOUND_POINTS} hull points")
        try:
            child = shape_from_spec(sub, limits=limits)
        except EditError as e:
            raise EditError(e.code, f"{name}: {e}") from None
        pos = _vec(f"{name}.position", c["position"]) if c.get("position") is not None else [0.0, 0.0, 0.0]
        q = _quat(f"{name}.orientation", c["orientation"]) if c.get("orientation") is not None else [0.0, 0.0, 0.0, 1.0]
        parts.append((child, _core.Pose(pos, q)))
    return _core.Compound(parts)


def shape_to_spec(shape: _core.Shape) -> dict:
    """The spec of a shape object (the inverse of shape_from_spec)."""
    t = shape.type
    if isinstance(shape, _core.Sphere):
        return {"type": "sphere", "radius": shape.radius}
    if isinstance(shape, _core.Box):
        spec = {"type": "box", "half_extents": [float(x) for x in shape.half_extents]}
        if shape.rounding:
            spec["rounding"] = shape.rounding
        return spec
    if isinstance(shape, (_core.Capsule, _core.Cylinder)):
        return {"type": "capsule" if isinstance(shape, _core.Capsule) else "cylinder",
                "radius": shape.radius, "half_height": shape.half_height}
    if isinstance(shape, _core.ConvexHull):
        return {"type": "convex_hull", "points": np.asarray(shape.vertices).tolist()}
    if isinstance(shape, _core.Plane):
        return {"type": "plane", "normal": np.asarray(shape.normal).tolist(), "offset": shape.offset}
    if isinstance(shape, _core.TriangleMesh):
        spec = {"type": "triangle_mesh", "vertices": np.asarray(shape.vertices).tolist(),
                "triangles": np.asarray(shape.triangles).tolist()}
        if shape.one_sided:
            spec["one_sided"] = True
        return spec
    if isinstance(shape, _core.Compound):
        return {"type": "compound", "children": [
            {"shape": shape_to_spec(child), "position": np.asarray(pose.position).tolist(),
             "orientation": np.asarray(pose.orientation).tolist()} for child, pose in shape.children]}
    raise TypeError(f"a {t} shape cannot be sent to a remote scene (supported: sphere, box, capsule, "
                    f"cylinder, convex_hull, plane, triangle_mesh, compound)")


def _shape_key(spec: dict) -> str:
    return repr(sorted(spec.items()))


# ---- scenes a client can load by name ----

def _ground() -> dict:
    return {"shape": {"type": "box", "half_extents": list(scenes.GROUND_HALF_EXTENTS)}, "kind": "static",
            "position": list(scenes.GROUND_CENTRE)}


def _box_scene(spec: "scenes.BoxScene") -> tuple[dict, list[dict]]:
    ground = _ground()
    ground["friction"] = spec.friction
    bodies = [ground]
    for h, p, m in zip(spec.half_extents, spec.positions, spec.masses):
        bodies.append({"shape": {"type": "box", "half_extents": [float(x) for x in h]},
                       "position": [float(x) for x in p], "mass": float(m), "friction": spec.friction})
    return {"gravity": list(spec.gravity)}, bodies


def _tower(height: int = 30) -> tuple[dict, list[dict]]:
    mu = math.sqrt(0.6)
    ground = _ground()
    ground["friction"] = mu
    return {"gravity": list(scenes.GRAVITY)}, [ground] + [
        {"shape": {"type": "box", "half_extents": [0.5, 0.5, 0.5]}, "position": [0.0, 0.5 * (2 * k + 1), 0.0],
         "friction": mu} for k in range(height)]


#: Scene name -> () -> (world settings, body definitions). "empty" is the ground alone.
SCENE_BUILDERS: dict[str, Callable[[], tuple[dict, list[dict]]]] = {
    "empty": lambda: ({"gravity": list(scenes.GRAVITY)}, [_ground()]),
    "boxes3000": lambda: _box_scene(scenes.boxes3000_spec()),
    "pyramid": lambda: _box_scene(scenes.pyramid_spec()),
    "tower": _tower,
}


SCENE_FILE_SUFFIXES = (".usd", ".usda", ".usdc", ".usdz", ".obj")


def register_file_scene(path: "str | os.PathLike[str]") -> tuple[str, list[str]]:
    """Reads a scene file (USD or OBJ, through :func:`wmo.io.load`) and makes it a scene
    a server can host, reset to and ``load_scene`` by name: ``"file:<absolute path>"``.
    Only files the server's operator registers can be loaded (a client cannot make the
    server read a path of its choosing). Bodies keep their given mass data and collision
    groups, the scene its group collision matrix and its filtered pairs of bodies (the
    ``collision_groups_off`` and ``collision_pairs_off`` settings). Returns (name,
    warnings): the reader's warnings. Raises ValueError for an unreadable file or a
    shape a remote scene cannot hold."""
    from .. import io

    p = Path(path).resolve()
    result = io.load(p)
    warnings = list(result.warnings)
    bodies = []
    for key, spec in result.specs.items():
        try:
            shape = shape_to_spec(spec["shape"])
        except TypeError as e:
            raise ValueError(f"{p}: body {key}: {e}") from None
        d: dict[str, Any] = {"shape": shape}
        for k in (*BODY_FIELDS, "position", "orientation", "linear_velocity", "angular_velocity"):
            if spec.get(k) is not None:
                v = spec[k]
                d[k] = np.asarray(v, dtype=float).tolist() if isinstance(v, (list, tuple, np.ndarray)) else v
        bodies.append(d)
    ws = result.world.settings
    settings = {k: (np.asarray(ws[k]).tolist() if k == "gravity" else ws[k]) for k in SETTINGS if k in ws}
    off = [[a, b] for a in range(64) for b in range(a, 64) if not result.world.group_collision(a, b)]
    if off:
        settings["collision_groups_off"] = off
    # A loaded scene gives its bodies ids 1, 2, ... in this order.
    rid_of = {body.index: i + 1 for i, body in enumerate(result.bodies[k] for k in result.specs)}
    pairs = [[rid_of[a.index], rid_of[b.index]] for a, b in result.world.filtered_pairs()]
    if pairs:
        settings["collision_pairs_off"] = pairs
    name = f"file:{p}"
    SCENE_BUILDERS[name] = lambda: (dict(settings), [dict(b) for b in bodies])
    return name, warnings


class SceneModel:
    """One hosted scene. Not thread-safe: the scene's simulation thread owns it.

    State that survives a restart is :meth:`to_document` (definitions, current poses and
    velocities, settings, the next id, the scene it was loaded from, the last edit's
    sequence number); :meth:`from_document` rebuilds it."""

    def __init__(self, scene: str = "empty", settings: dict | None = None):
        self.paused = False
        self.edit_seq = 0          # sequence number of the last edit applied
        self.next_id = 1
        self.step_count = 0        # steps simulated since the scene was created (monotonic)
        self.sim_time = 0.0        # simulated seconds since then (dt may change on the way)
        self.base_scene = "empty"
        self.base_settings: dict = {}
        self._load(scene, settings or {})

    # ---- the world and the id map ----

    def _new_world(self, settings: dict) -> None:
        kwargs = {k: v for k, v in settings.items() if k not in SCENE_SETTINGS}
        if "gravity" in kwargs:
            kwargs["gravity"] = tuple(kwargs["gravity"])
        self.world = _core.World(**kwargs)
        for a, b in settings.get("collision_groups_off", ()):
            self.world.set_group_collision(a, b, False)
        self.settings = dict(settings)
        self.bodies: dict[int, _core.Body] = {}      # remote id -> world handle
        self.defs: dict[int, dict] = {}              # remote id -> definition (spec + fields)
        self.owner: dict[int, str] = {}              # remote id -> client dragging it
        self._shapes: dict[str, _core.Shape] = {}
        self._ids_by_index = np.zeros(0, dtype=np.uint32)
        self._order: np.ndarray | None = None

    def _load(self, scene: str, settings: dict) -> None:
        if scene not in SCENE_BUILDERS:
            raise EditError("bad_args", f"scene must be one of {', '.join(SCENE_BUILDERS)}, got {scene!r}")
        base, bodies = SCENE_BUILDERS[scene]()
        merged = {**base, **settings}
        self._check_settings(merged)
        self._new_world(merged)
        self.world.reserve(len(bodies))
        self.next_id = 1
        for d in bodies:
            self._add(self._normalise_def(d), d)
        self._apply_pair_filters()
        self.base_scene, self.base_settings = scene, dict(settings)

    def _shape(self, spec: dict) -> _core.Shape:
        key = _shape_key(spec)
        shape = self._shapes.get(key)
        if shape is None:
            shape = self._shapes[key] = shape_from_spec(spec)
        return shape

    def _normalise_def(self, args: dict) -> dict:
        """The definition part of an add_body edit, checked and with defaults filled in."""
        d = {"shape": args.get("shape")}
        self._shape(d["shape"])  # checks the spec
        for k, default in BODY_FIELDS.items():
            d[k] = args.get(k, default)
        if d["kind"] not in ("dynamic", "static", "kinematic"):
            raise EditError("bad_args", f"kind must be dynamic, static or kinematic, got {d['kind']!r}")
        if d["mass"] is not None:
            d["mass"] = _positive("mass", d["mass"])
        d["density"] = _positive("density", d["density"])
        d["friction"] = _finite("friction", d["friction"])
        if d["friction"] < 0:
            raise EditError("bad_args", f"friction must be >= 0, got {d['friction']!r}")
        d["restitution"] = _finite("restitution", d["restitution"])
        if not 0 <= d["restitution"] <= 1:
            raise EditError("bad_args", f"restitution must be in [0, 1], got {d['restitution']!r}")
        for k in ("linear_damping", "angular_damping"):
            d[k] = _finite(k, d[k])
            if d[k] < 0:
                raise EditError("bad_args", f"{k} must be >= 0, got {d[k]!r}")
        d["gravity_scale"] = _finite("gravity_scale", d["gravity_scale"])
        if not isinstance(d["ccd"], bool):
            raise EditError("bad_args", f"ccd must be true or false, got {d['ccd']!r}")
        d["collision_group"] = _int("collision_group", d["collision_group"], 0, 63)
        # Given mass data (World.add_body's center_of_mass, inertia, inertia_axes): the
        # structure here, the values (positive definite, ...) by the World when added.
        if d["center_of_mass"] is not None:
            d["center_of_mass"] = _vec("center_of_mass", d["center_of_mass"])
        if d["inertia"] is not None:
            v = d["inertia"]
            if isinstance(v, (list, tuple)) and len(v) == 3 and all(isinstance(r, (list, tuple)) for r in v):
                d["inertia"] = [_vec(f"inertia[{i}]", r) for i, r in enumerate(v)]
            else:
                d["inertia"] = _vec("inertia", v)  # principal moments
        if d["inertia_axes"] is not None:
            d["inertia_axes"] = _quat("inertia_axes", d["inertia_axes"])
        return d

    def _add(self, d: dict, state: dict, rid: int | None = None) -> int:
        """Adds a body with definition d and state (position, orientation, velocities)."""
        kw = {k: d[k] for k in BODY_FIELDS if k != "mass"}
        if d["mass"] is not None and d["kind"] == "dynamic":
            kw["mass"] = d["mass"]
        for k in ("position", "orientation", "linear_velocity", "angular_velocity"):
            if state.get(k) is not None:
                kw[k] = state[k]
        try:
            body = self.world.add_body(self._shape(d["shape"]), **kw)
        except (ValueError, TypeError) as e:  # the world's checks; it is unchanged
            raise EditError("bad_args", str(e))
        if rid is None:
            rid = self.next_id
            self.next_id += 1
        self.bodies[rid] = body
        self.defs[rid] = d
        self._ids_by_index = np.append(self._ids_by_index, np.uint32(rid))
        self._order = None
        return rid

    def _apply_pair_filters(self, only: int | None = None) -> None:
        """World.set_pair_collision(False) for the collision_pairs_off setting (after the
        bodies are in the world); `only`: just the pairs of that body."""
        for a, b in self.settings.get("collision_pairs_off", ()):
            if (only is None or only in (a, b)) and a != b and a in self.bodies and b in self.bodies:
                self.world.set_pair_collision(self.bodies[a], self.bodies[b], False)

    def _remove(self, rid: int) -> None:
        body = self.bodies.pop(rid)
        self.defs.pop(rid)
        self.owner.pop(rid, None)
        i = body.index
        self.world.remove_body(body)
        # The world removes by swapping the last body into the hole (dense arrays).
        last = len(self._ids_by_index) - 1
        self._ids_by_index[i] = self._ids_by_index[last]
        self._ids_by_index = self._ids_by_index[:last].copy()
        self._order = None

    def _state(self, rid: int) -> dict:
        i = self.bodies[rid].index
        w = self.world
        return {"position": w.positions[i].tolist(), "orientation": w.orientations[i].tolist(),
                "linear_velocity": w.linear_velocities[i].tolist(),
                "angular_velocity": w.angular_velocities[i].tolist()}

    def _replace(self, rid: int, kind: str) -> None:
        """Re-creates body rid with another kind, same state and id (a drag's grab and
        release: the world cannot change a body's kind in place)."""
        d, state = dict(self.defs[rid]), self._state(rid)
        owner = self.owner.get(rid)
        self._remove(rid)
        d_new = dict(d, kind=kind)  # dynamic <-> kinematic only (static bodies are never grabbed)
        self._add(d_new, state, rid)
        self.defs[rid] = d_new
        self._apply_pair_filters(only=rid)  # the new body's filters
        if owner is not None:
            self.owner[rid] = owner

    def _body(self, args: dict) -> int:
        rid = args.get("id")
        if isinstance(rid, bool) or not isinstance(rid, int):
            raise EditError("bad_args", f"id must be an integer body id, got {rid!r}")
        if rid not in self.bodies:
            raise EditError("unknown_body", f"no body with id {rid}")
        return rid

    def _owned_check(self, rid: int, client: str) -> None:
        who = self.owner.get(rid)
        if who is not None and who != client:
            raise EditError("not_owner", f"body {rid} is being dragged by client {who}")

    @staticmethod
    def _check_settings(settings: dict) -> None:
        for k, v in settings.items():
            if k not in SETTINGS:
                raise EditError("bad_args", f"unknown setting {k!r} (settable: {', '.join(SETTINGS)})")
            t = SETTINGS[k]
            if k == "collision_groups_off":
                _group_pairs(v)
            elif k == "collision_pairs_off":
                _id_pairs(v)
            elif t is list:
                _vec(k, v)
            elif t is bool:
                if not isinstance(v, bool):
                    raise EditError("bad_args", f"{k} must be true or false, got {v!r}")
            elif t is int:
                _int(k, v, 0, 1000)
            elif t is str:
                if not isinstance(v, str):
                    raise EditError("bad_args", f"{k} must be a string, got {v!r}")
            else:
                _finite(k, v)
        try:  # the World's own checks (ranges, caps), on a throwaway world
            kw = {k: v for k, v in settings.items() if k not in SCENE_SETTINGS}
            if "gravity" in kw:
                kw["gravity"] = tuple(kw["gravity"])
            _core.World(**kw)
        except (ValueError, TypeError) as e:
            raise EditError("bad_args", f"settings: {e}")

    # ---- edits ----

    def apply(self, op: str, args: dict, client: str = "server") -> Any:
        """Applies one edit; returns its result (msgpack-able; None for most). Raises
        EditError (scene unchanged) for a bad edit."""
        fn = OPS.get(op)
        if fn is None:
            raise EditError("unknown_op", f"unknown op {op!r} (known: {', '.join(OPS)})")
        if not isinstance(args, dict):
            raise EditError("bad_args", f"args must be a map, got {type(args).__name__}")
        return fn(self, args, client)

    def _op_add_body(self, args: dict, client: str) -> dict:
        _check_keys("add_body", args, ("shape", "position", "orientation", "linear_velocity", "angular_velocity")
                    + tuple(BODY_FIELDS))
        if len(self.bodies) >= MAX_BODIES:
            raise EditError("limit", f"the scene holds {len(self.bodies)} bodies, the cap is {MAX_BODIES}")
        d = self._normalise_def(args)
        state = {}
        for k in ("position", "linear_velocity", "angular_velocity"):
            if args.get(k) is not None:
                state[k] = _vec(k, args[k])
        if args.get("orientation") is not None:
            state["orientation"] = _quat("orientation", args["orientation"])
        return {"id": self._add(d, state)}

    def _op_remove_body(self, args: dict, client: str) -> None:
        _check_keys("remove_body", args, ("id",))
        rid = self._body(args)
        self._owned_check(rid, client)
        self._remove(rid)
        pairs = self.settings.get("collision_pairs_off")
        if pairs:  # the body's filters go with it (its id is never reused)
            self.settings["collision_pairs_off"] = [p for p in pairs if rid not in p]

    def _op_set_pose(self, args: dict, client: str) -> None:
        _check_keys("set_pose", args, ("id", "position", "orientation"))
        rid = self._body(args)
        self._owned_check(rid, client)
        p = _vec("position", args["position"]) if args.get("position") is not None else None
        q = _quat("orientation", args["orientation"]) if args.get("orientation") is not None else None
        body = self.bodies[rid]
        if p is not None:
            body.position = p
        if q is not None:
            body.orientation = q

    def _op_set_velocity(self, args: dict, client: str) -> None:
        _check_keys("set_velocity", args, ("id", "linear", "angular"))
        rid = self._body(args)
        self._owned_check(rid, client)
        v = _vec("linear", args["linear"]) if args.get("linear") is not None else None
        w = _vec("angular", args["angular"]) if args.get("angular") is not None else None
        body = self.bodies[rid]
        if body.kind == "static" and (v is not None or w is not None):
            raise EditError("bad_args", f"body {rid} is static: it has no velocity")
        if v is not None:
            body.linear_velocity = v
        if w is not None:
            body.angular_velocity = w

    def _op_apply_impulse(self, args: dict, client: str) -> None:
        _check_keys("apply_impulse", args, ("id", "impulse", "point"))
        rid = self._body(args)
        self._owned_check(rid, client)
        j = _vec("impulse", args.get("impulse"))
        body = self.bodies[rid]
        point = _vec("point", args["point"]) if args.get("point") is not None else body.position.tolist()
        if body.kind != "dynamic":
            raise EditError("bad_args", f"body {rid} is {body.kind}: impulses move dynamic bodies only")
        self.world.apply_impulse(body, j, point)

    def _op_grab(self, args: dict, client: str) -> None:
        _check_keys("grab", args, ("id",))
        rid = self._body(args)
        self._owned_check(rid, client)
        if self.defs[rid]["kind"] == "static":
            raise EditError("bad_args", f"body {rid} is static: it cannot be dragged")
        if self.owner.get(rid) == client:
            return
        self.defs[rid]["grabbed_from"] = self.defs[rid]["kind"]
        self.owner[rid] = client
        if self.defs[rid]["kind"] == "dynamic":
            self._replace(rid, "kinematic")
            self.defs[rid]["grabbed_from"] = "dynamic"

    def _op_release(self, args: dict, client: str) -> None:
        _check_keys("release", args, ("id", "linear_velocity"))
        rid = self._body(args)
        if self.owner.get(rid) != client:
            raise EditError("not_owner", f"body {rid} is not dragged by client {client}")
        v = _vec("linear_velocity", args["linear_velocity"]) if args.get("linear_velocity") is not None else None
        self._release(rid)
        if v is not None and self.bodies[rid].kind != "static":
            self.bodies[rid].linear_velocity = v

    def _release(self, rid: int) -> None:
        back = self.defs[rid].pop("grabbed_from", self.defs[rid]["kind"])
        self.owner.pop(rid, None)
        if back != self.defs[rid]["kind"]:
            self._replace(rid, back)

    def release_all(self, client: str) -> list[int]:
        """Releases every body `client` drags (its connection closed); returns their ids.
        Not an edit of its own: the server journals it as one `release` per body."""
        ids = sorted(r for r, c in self.owner.items() if c == client)
        for rid in ids:
            self._release(rid)
        return ids

    def _op_pause(self, args: dict, client: str) -> None:
        _check_keys("pause", args, ())
        self.paused = True

    def _op_resume(self, args: dict, client: str) -> None:
        _check_keys("resume", args, ())
        self.paused = False

    def _op_step(self, args: dict, client: str) -> dict:
        _check_keys("step", args, ("n",))
        if not self.paused:
            raise EditError("not_paused", "step is for a paused scene; pause it first")
        n = _int("n", args.get("n", 1), 1, MAX_STEPS_PER_EDIT)
        self.step(n)
        return {"step": self.step_count}

    def _op_reset(self, args: dict, client: str) -> None:
        _check_keys("reset", args, ())
        self._load(self.base_scene, self.base_settings)

    def _op_load_scene(self, args: dict, client: str) -> None:
        _check_keys("load_scene", args, ("name", "settings"))
        name = args.get("name")
        settings = args.get("settings") or {}
        if not isinstance(settings, dict):
            raise EditError("bad_args", f"settings must be a map, got {settings!r}")
        if name not in SCENE_BUILDERS:
            raise EditError("bad_args", f"name must be one of {', '.join(SCENE_BUILDERS)}, got {name!r}")
        self._check_settings({**SCENE_BUILDERS[name]()[0], **settings})
        self._load(name, settings)

    def _op_set_settings(self, args: dict, client: str) -> None:
        merged = {**self.settings, **args}
        self._check_settings(merged)
        for i, (a, b) in enumerate(args.get("collision_pairs_off", ())):
            for r in (a, b):
                if r not in self.bodies:
                    raise EditError("unknown_body", f"collision_pairs_off[{i}]: no body with id {r}")
            if a == b:
                raise EditError("bad_args", f"collision_pairs_off[{i}]: a body is not paired with itself ({a})")
        self.rebuild(merged)

    def rebuild(self, settings: dict) -> None:
        """A new world with `settings` holding the same bodies (ids, definitions, owners,
        current states). Contact warm-start data starts afresh."""
        old = [(rid, self.defs[rid], self._state(rid)) for rid in sorted(self.bodies)]
        owners = dict(self.owner)
        self._new_world(settings)
        self.world.reserve(len(old))
        for rid, d, state in old:
            self._add(d, state, rid)
        self._apply_pair_filters()
        self.owner = owners

    def step(self, n: int = 1) -> None:
        """Simulates n steps (the GIL is released while the world steps)."""
        self.world.step(n)
        self.step_count += n
        self.sim_time += n * self.world.dt

    # ---- reading ----

    @property
    def order(self) -> np.ndarray:
        """World indices of the bodies in ascending id order."""
        if self._order is None:
            self._order = np.argsort(self._ids_by_index, kind="stable")
        return self._order

    def ids(self) -> np.ndarray:
        """(N,) uint32 body ids, ascending."""
        return self._ids_by_index[self.order]

    def describe(self) -> dict:
        """Bodies by id: definition (shape spec and fields) and owner, and the settings:
        what a client needs besides the snapshots to mirror the scene."""
        return {"settings": self.settings, "scene": self.base_scene, "paused": self.paused,
                "edit_seq": self.edit_seq, "next_id": self.next_id,
                "bodies": {rid: {**self.defs[rid], "owner": self.owner.get(rid)} for rid in sorted(self.bodies)}}

    def to_document(self) -> dict:
        """Everything needed to rebuild this scene (msgpack-able)."""
        w, order = self.world, self.order
        ids = self.ids()
        return {"format": 1, "edit_seq": self.edit_seq, "next_id": self.next_id, "paused": self.paused,
                "base_scene": self.base_scene, "base_settings": self.base_settings, "settings": self.settings,
                "step": self.step_count, "sim_time": self.sim_time, "ids": ids.tolist(),
                "defs": [self.defs[int(r)] for r in ids], "owner": {str(k): v for k, v in self.owner.items()},
                "positions": np.asarray(w.positions)[order].tobytes(),
                "orientations": np.asarray(w.orientations)[order].tobytes(),
                "linear_velocities": np.asarray(w.linear_velocities)[order].tobytes(),
                "angular_velocities": np.asarray(w.angular_velocities)[order].tobytes()}

    @classmethod
    def from_document(cls, doc: dict) -> "SceneModel":
        """The scene `to_document` described (current states bit for bit)."""
        if doc.get("format") != 1:
            raise ValueError(f"scene document format must be 1, got {doc.get('format')!r}")
        m = cls.__new__(cls)
        m.paused = bool(doc["paused"])
        m.edit_seq = int(doc["edit_seq"])
        m.step_count = int(doc["step"])
        m.sim_time = float(doc["sim_time"])
        m.base_scene, m.base_settings = doc["base_scene"], dict(doc["base_settings"])
        m._new_world(dict(doc["settings"]))
        n = len(doc["ids"])
        arr = {k: np.frombuffer(doc[k], dtype=np.float64).reshape(n, -1)
               for k in ("positions", "orientations", "linear_velocities", "angular_velocities")}
        m.world.reserve(n)
        for i, (rid, d) in enumerate(zip(doc["ids"], doc["defs"])):
            m._add(d, {"position": arr["positions"][i], "orientation": arr["orientations"][i],
                       "linear_velocity": arr["linear_velocities"][i] if d["kind"] != "static" else None,
                       "angular_velocity": arr["angular_velocities"][i] if d["kind"] != "static" else None},
                   int(rid))
        # The arrays again, bit for bit (add_body renormalises orientations).
        order = m.order
        for k in arr:
            getattr(m.world, k)[order] = arr[k]
        m._apply_pair_filters()
        m.owner = {int(k): v for k, v in doc["owner"].items()}
        m.next_id = int(doc["next_id"])
        return m


OPS: dict[str, Callable[[SceneModel, dict, str], Any]] = {
    "add_body": SceneModel._op_add_body,
    "remove_body": SceneModel._op_remove_body,
    "set_pose": SceneModel._op_set_pose,
    "set_velocity": SceneModel._op_set_velocity,
    "apply_impulse": SceneModel._op_apply_impulse,
    "grab": SceneModel._op_grab,
    "release": SceneModel._op_release,
    "pause": SceneModel._op_pause,
    "resume": SceneModel._op_resume,
    "step": SceneModel._op_step,
    "reset": SceneModel._op_reset,
    "load_scene": SceneModel._op_load_scene,
    "set_settings": SceneModel._op_set_settings,
}
