"""wmo.io.tessellate and wmo.io.obj_writer: shapes as triangle meshes, worlds and meshes
written as Wavefront OBJ.

Each shape's mesh is checked against the shape itself (closed, outward, vertices on the
surface, enclosed volume against the exact volume); written files are read back with
WMO's own OBJ reader and with trimesh, the independent reference.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

import wmo
from conftest import quat_axis_angle, rot_matrix
from wmo.io.obj import load_obj, parse_obj
from wmo.io.obj_writer import save_mesh_obj, save_obj
from wmo.io.tessellate import shape_mesh

trimesh = pytest.importorskip("trimesh", reason="trimesh is the reference OBJ reader for these tests")


def _signed_volume(v, t):
    """Enclosed volume by the divergence theorem (sum of signed tetrahedra from the
    origin); positive when the triangles are counter-clockwise from outside."""
    a, b, c = (v[t[:, i]] for i in range(3))
    return float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0)


def _assert_closed_and_consistent(t):
    """Every undirected edge in exactly two triangles, every directed edge in one: a
    closed surface whose triangles all wind the same way."""
    directed = t[:, [[0, 1], [1, 2], [2, 0]]].reshape(-1, 2)
    _, counts = np.unique(np.sort(directed, axis=1), axis=0, return_counts=True)
    assert (counts == 2).all(), "an edge is not shared by exactly two triangles"
    assert len(np.unique(directed, axis=0)) == len(directed), "two triangles wind an edge the same way"


# ---- Closed forms: signed distance to the surface (negative inside) and surface area.


def _sd_core(shape, p):
    """Signed distance of points p (shape frame) to a convex shape (exact; a hull's is
    the largest face-plane distance, zero exactly on the surface)."""
    if isinstance(shape, wmo.Sphere):
        return np.linalg.norm(p, axis=1) - shape.radius
    if isinstance(shape, wmo.Box):
        q = np.abs(p) - (shape.half_extents - shape.rounding)
        return (np.linalg.norm(np.maximum(q, 0), axis=1) + np.minimum(q.max(axis=1), 0)) - shape.rounding
    if isinstance(shape, wmo.Capsule):
        axis_point = np.clip(p[:, 1], -shape.half_height, shape.half_height)
        return np.linalg.norm(p - np.outer(axis_point, [0, 1, 0]), axis=1) - shape.radius
    if isinstance(shape, wmo.Cylinder):
        d = np.stack([np.hypot(p[:, 0], p[:, 2]) - shape.radius, np.abs(p[:, 1]) - shape.half_height], 1)
        return np.linalg.norm(np.maximum(d, 0), axis=1) + np.minimum(d.max(axis=1), 0)
    if isinstance(shape, wmo.ConvexHull):
        return (p @ shape.face_normals.T - shape.face_offsets).max(axis=1)
    if isinstance(shape, wmo.Compound):  # union: the nearest child
        return np.min([_sd_core(c, (p - pose.position) @ rot_matrix(pose.orientation))
                       for c, pose in shape.children], axis=0)
    raise AssertionError(shape)


def _area(shape):
    """Exact surface area (m^2) of a sphere, capsule, cylinder or (rounded) box: a rounded
    box is its core's 6 faces, 12 quarter cylinders of radius r along the core edges and
    8 eighths of a sphere."""
    if isinstance(shape, wmo.Sphere):
        return 4 * math.pi * shape.radius ** 2
    if isinstance(shape, wmo.Capsule):
        return 4 * math.pi * shape.radius ** 2 + 4 * math.pi * shape.radius * shape.half_height
    if isinstance(shape, wmo.Cylinder):
        return 4 * math.pi * shape.radius * shape.half_height + 2 * math.pi * shape.radius ** 2
    if isinstance(shape, wmo.Box):
        r = shape.rounding
        a, b, c = shape.half_extents - r
        return 8 * (a * b + b * c + c * a) + 4 * math.pi * r * (a + b + c) + 4 * math.pi * r * r
    raise AssertionError(shape)


def _gap(shape, v, t):
    """Largest gap g between a mesh face plane and the shape's support plane of the same
    normal (g = max_f n_f . support(n_f) - n_f . a_f). The mesh, the intersection of its
    face half-spaces, then contains the shape shrunk by g: in every direction its extent
    is at most g short of the shape's."""
    a, b, c = (v[t[:, i]] for i in range(3))
    n = np.cross(b - a, c - a)
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    return max(float(ni @ shape.support(ni) - ni @ ai) for ni, ai in zip(n, a))


def _volume_deficit_bound(shape, v, t):
    """Upper bound of (shape volume - mesh volume) for a mesh inscribed in a convex
    shape: the shell between the shape and the shape shrunk by g (see _gap) has volume
    <= g * area(shape), since the shrunk bodies are convex and inside the shape, so of
    smaller area. Exact geometry, set by the tessellation resolution through g."""
    return _gap(shape, v, t) * _area(shape)


_rng = np.random.default_rng(7)
CONVEX = {
    "box": wmo.Box((0.5, 1.0, 1.5)),
    "rounded_box": wmo.Box((0.5, 1.0, 1.5), rounding=0.3),
    "sphere": wmo.Sphere(0.7),
    "capsule": wmo.Capsule(0.4, 0.9),
    "cylinder": wmo.Cylinder(0.6, 0.25),
}


@pytest.mark.parametrize("name", list(CONVEX))
def test_curved_shapes_tessellate_into_closed_outward_inscribed_meshes(name):
    shape = CONVEX[name]
    v, t = shape_mesh(shape)
    assert v.dtype == np.float64 and t.dtype == np.int64 and v.shape[1] == t.shape[1] == 3
    _assert_closed_and_consistent(t)
    # On the surface to float64 rounding of unit vectors times the size (~1e-16 * 2 m).
    np.testing.assert_allclose(_sd_core(shape, v), 0.0, atol=1e-12)
    # Inscribed in a convex shape: no more volume than the shape, and no less than the
    # resolution bound (1e-12 relative slack for the summation's rounding). A positive
    # volume with consistent winding means the triangles face outwards.
    exact = shape.mass_properties().volume
    vol = _signed_volume(v, t)
    assert exact - _volume_deficit_bound(shape, v, t) <= vol <= exact * (1 + 1e-12)
    assert vol > 0


@pytest.mark.parametrize("name", ["sphere", "capsule", "cylinder", "rounded_box"])
def test_finer_tessellation_converges_to_the_exact_volume(name):
    # An inscribed mesh's volume deficit falls as the square of its edge length: 4x
    # per icosphere subdivision, 4x per doubling of the ring segments.
    shape = CONVEX[name]
    exact = shape.mass_properties().volume
    coarse = exact - _signed_volume(*shape_mesh(shape, sphere_subdivisions=2, segments=24))
    fine = exact - _signed_volume(*shape_mesh(shape, sphere_subdivisions=4, segments=96))
    assert 0 <= fine < coarse / 8  # 16x expected; 8x leaves room for the uneven icosphere


def test_a_rounded_box_has_round_edges_not_a_grown_box():
    box = CONVEX["rounded_box"]
    v, t = shape_mesh(box)
    # The corner of the rounded box is the core corner plus r along the diagonal, well
    # inside the sharp corner of the same half extents; the inscribed mesh reaches it to
    # within its resolution gap.
    diagonal = np.ones(3) / math.sqrt(3)
    corner = (box.half_extents - box.rounding) @ diagonal + box.rounding
    assert corner - _gap(box, v, t) <= (v @ diagonal).max() <= corner + 1e-12
    assert corner < box.half_extents @ diagonal - 0.1
    # Its flat faces are kept whole: the extreme vertices along +x span the core face.
    top = v[np.isclose(v[:, 0], box.half_extents[0])]
    np.testing.assert_allclose(np.ptp(top[:, 1:], axis=0), 2 * (box.half_extents[1:] - box.rounding))


def test_a_hull_is_its_own_faces_fan_triangulated():
    hull = wmo.ConvexHull(_rng.normal(size=(40, 3)))
    v, t = shape_mesh(hull)
    np.testing.assert_array_equal(v, hull.vertices)
    _assert_closed_and_consistent(t)
    assert len(t) == sum(len(f) - 2 for f in hull.faces)
    np.testing.assert_allclose(_sd_core(hull, v), 0.0, atol=1e-12)
    # The same polytope: the volume agrees to summation rounding.
    assert _signed_volume(v, t) == pytest.approx(hull.mass_properties().volume, rel=1e-12)


def test_a_compound_is_its_children_placed_by_their_poses():
    children = [(CONVEX["rounded_box"], wmo.Pose((2.0, 0, 0), quat_axis_angle((1, 2, 3), 0.7))),
                (CONVEX["capsule"], wmo.Pose((-2.0, 0.5, 0), quat_axis_angle((0, 0, 1), math.pi / 2))),
                (wmo.ConvexHull(_rng.normal(size=(20, 3)) * 0.3), wmo.Pose((0, 3.0, 0)))]
    compound = wmo.Compound(children)
    v, t = shape_mesh(compound)
    _assert_closed_and_consistent(t)
    np.testing.assert_allclose(_sd_core(compound, v), 0.0, atol=1e-12)
    # The children do not overlap, so the compound's volume is the sum of theirs; the
    # mesh falls short by at most the sum of the children's resolution bounds.
    bound = sum(_volume_deficit_bound(c, *shape_mesh(c)) for c, _ in children[:2])  # the hull's is 0
    exact = compound.mass_properties().volume
    assert exact - bound <= _signed_volume(v, t) <= exact * (1 + 1e-12)
    assert len(t) == sum(len(shape_mesh(c)[1]) for c, _ in children)


def test_a_plane_is_a_slab_below_it():
    n = np.array([1.0, 2.0, 2.0]) / 3.0
    plane = wmo.Plane(n, offset=1.5)
    v, t = shape_mesh(plane, plane_size=10.0)
    _assert_closed_and_consistent(t)
    height = v @ n - 1.5
    # Top face on the plane, the rest 1/100 of the side below, on the solid side.
    np.testing.assert_allclose(np.sort(height), [-0.1] * 4 + [0.0] * 4, atol=1e-12)
    # A 10 m square centred on the plane's point nearest the origin, facing +n.
    np.testing.assert_allclose(v.mean(axis=0), 1.5 * n - 0.05 * n, atol=1e-12)
    assert _signed_volume(v, t) == pytest.approx(10.0 * 10.0 * 0.1, rel=1e-12)


def test_a_triangle_mesh_is_written_as_it_is():
    v = _rng.normal(size=(30, 3))
    t = _rng.integers(0, 30, size=(50, 3))
    t = t[(t[:, 0] != t[:, 1]) & (t[:, 1] != t[:, 2]) & (t[:, 0] != t[:, 2])]
    mv, mt = shape_mesh(wmo.TriangleMesh(v, t))
    np.testing.assert_array_equal(mv, v)
    np.testing.assert_array_equal(mt, t)


# ---- World export.


def _world():
    w = wmo.World()
    w.add_body(wmo.Box((0.5, 0.25, 0.125)), position=(0, 2, 0), orientation=quat_axis_angle((0, 0, 1), 0.3))
    w.add_body(wmo.Sphere(0.3), position=(1.5, 1, 0.5), linear_velocity=(1, 0, 0))
    w.add_body(wmo.Capsule(0.2, 0.4), position=(-1, 1.5, 0), orientation=quat_axis_angle((1, 0, 0), 1.0))
    w.add_body(wmo.ConvexHull(_rng.normal(size=(16, 3)) * 0.3), position=(0, 1, -2), kind="kinematic")
    w.add_body(wmo.Compound([(wmo.Box((0.3, 0.1, 0.1), rounding=0.05), wmo.Pose((0.3, 0, 0))),
                             (wmo.Cylinder(0.1, 0.2), wmo.Pose((-0.3, 0, 0)))]),
               position=(2, 3, 2), orientation=quat_axis_angle((1, 1, 0), 2.0))
    # An open terrain patch (a 4 x 4 grid), static as WMO triangle meshes are.
    gx, gz = np.meshgrid(np.arange(5.0), np.arange(5.0))
    grid = np.stack([gx.ravel() - 2, 0.1 * np.sin(gx.ravel() + gz.ravel()), gz.ravel() - 2], 1)
    q = (np.arange(4)[:, None] * 5 + np.arange(4)[None, :]).ravel()
    cells = np.concatenate([np.stack([q, q + 5, q + 1], 1), np.stack([q + 1, q + 5, q + 6], 1)])
    w.add_body(wmo.TriangleMesh(grid, cells), position=(0, 0.2, 6), kind="static")
    w.add_body(wmo.Plane((0, 1, 0), 0.0), kind="static")
    w.step(10)  # the file must hold the current poses, not the initial ones
    return w


def _expected(world):
    """Each body's mesh in world space, posed with the textbook quaternion formula (not
    WMO's): [(vertices, triangles)] in row order."""
    out = []
    for k in range(world.body_count):
        v, t = shape_mesh(world.body(k).shape)
        out.append((v @ rot_matrix(world.orientations[k]).T + world.positions[k], t))
    return out


# %.9g keeps 9 significant digits: each coordinate within 5e-9 of itself, relatively.
_RTOL = 5e-9


def test_a_saved_world_reads_back_with_wmos_reader(tmp_path):
    world = _world()
    path = tmp_path / "scene.obj"
    save_obj(world, path)
    expected = _expected(world)
    mesh = parse_obj(path)
    assert [g for g, _ in mesh.groups] == [f"body_{k}" for k in range(world.body_count)]
    np.testing.assert_allclose(mesh.vertices, np.vstack([v for v, _ in expected]), rtol=_RTOL, atol=1e-300)
    offsets = np.cumsum([0] + [len(v) for v, _ in expected])
    for (name, idx), (v, t), offset in zip(mesh.groups, expected, offsets):
        np.testing.assert_array_equal(mesh.triangles[idx], t + offset, err_msg=name)
    text = path.read_text().splitlines()
    assert text[:3] == ["# wmo " + wmo.__version__, f"# bodies: {world.body_count}",
                        "# units: metres; up: +Y (WMO's world frame)"]
    assert not any(line.startswith(("vn", "vt")) for line in text)


def test_a_saved_world_reads_back_with_trimesh_one_object_per_body(tmp_path):
    world = _world()
    path = tmp_path / "scene.obj"
    save_obj(world, path)
    scene = trimesh.load(path, force="scene", process=False, split_objects=True, group_material=False)
    assert sorted(scene.geometry) == sorted(f"body_{k}" for k in range(world.body_count))
    for k, (v, t) in enumerate(_expected(world)):
        g = scene.geometry[f"body_{k}"]
        assert len(g.faces) == len(t)
        # trimesh may renumber the vertices; the triangles' corners must be the same.
        np.testing.assert_allclose(g.vertices[g.faces], v[t], rtol=_RTOL, atol=1e-300)
        if not isinstance(world.body(k).shape, wmo.TriangleMesh):
            assert g.is_watertight and g.is_winding_consistent and g.volume > 0


def test_up_z_turns_the_world_y_up_to_z_up(tmp_path):
    world = _world()
    save_obj(world, tmp_path / "y.obj")
    save_obj(world, tmp_path / "z.obj", up="z")
    y, z = parse_obj(tmp_path / "y.obj"), parse_obj(tmp_path / "z.obj")
    x_, y_, z_ = y.vertices.T
    np.testing.assert_allclose(z.vertices, np.stack([x_, -z_, y_], 1), rtol=_RTOL, atol=1e-300)
    np.testing.assert_array_equal(z.triangles, y.triangles)
    # Gravity's -Y now points along -Z: the ground slab's top is at z = 0.
    plane = dict(z.groups)[f"body_{world.body_count - 1}"]
    assert z.vertices[np.unique(z.triangles[plane]), 2].max() == 0.0
    # WMO's reader, told the file is Z up, turns it back.
    back = load_obj(tmp_path / "z.obj", up="z").specs["z"]["shape"]
    np.testing.assert_allclose(back.vertices, y.vertices, rtol=_RTOL, atol=1e-300)
    assert "up: +Z" in (tmp_path / "z.obj").read_text().splitlines()[2]


def test_an_empty_world_writes_only_the_header(tmp_path):
    save_obj(wmo.World(), tmp_path / "empty.obj")
    assert (tmp_path / "empty.obj").read_text().splitlines()[1] == "# bodies: 0"


def test_a_mesh_round_trips_through_load_obj(tmp_path):
    v, t = shape_mesh(wmo.Capsule(0.3, 0.5))
    v = v @ rot_matrix(quat_axis_angle((1, 2, 3), 0.4)).T + (1e3, -2.0, 1e-3)
    # 17 significant digits write every float64 exactly (IEEE 754's round-trip count).
    save_mesh_obj(v, t, tmp_path / "exact.obj", name="capsule", precision=17)
    r = wmo.io.load_obj(tmp_path / "exact.obj", as_="static_mesh")
    shape = r.specs["exact"]["shape"]
    assert isinstance(shape, wmo.TriangleMesh) and r.bodies["exact"].kind == "static"
    np.testing.assert_array_equal(shape.vertices, v)
    np.testing.assert_array_equal(shape.triangles, t)
    assert parse_obj(tmp_path / "exact.obj").groups[0][0] == "capsule"
    # The default 9 digits: within 5e-9 relative, the triangles unchanged.
    save_mesh_obj(v, t, tmp_path / "short.obj")
    shape = wmo.io.load_obj(tmp_path / "short.obj", as_="static_mesh").specs["short"]["shape"]
    np.testing.assert_allclose(shape.vertices, v, rtol=_RTOL, atol=1e-300)
    np.testing.assert_array_equal(shape.triangles, t)


# ---- Bad input: ValueError naming the argument, and no file left behind.

_V = np.eye(3)
_T = np.array([[0, 1, 2]])


@pytest.mark.parametrize("call, field", [
    (lambda p: save_obj(wmo.World(), p.with_suffix(".stl")), "path"),
    (lambda p: save_obj(wmo.World(), p, up="x"), "up"),
    (lambda p: save_obj(wmo.World(), p, precision=0), "precision"),
    (lambda p: save_obj(wmo.World(), p, precision=True), "precision"),
    (lambda p: save_mesh_obj(_V, _T, p.with_suffix("")), "path"),
    (lambda p: save_mesh_obj(_V[:, :2], _T, p), "vertices"),
    (lambda p: save_mesh_obj([[0, 0, math.nan]] + _V.tolist(), _T, p), "vertices"),
    (lambda p: save_mesh_obj([["a", "b", "c"]], _T, p), "vertices"),
    (lambda p: save_mesh_obj(_V, _T.astype(float), p), "triangles"),
    (lambda p: save_mesh_obj(_V, [0, 1, 2], p), "triangles"),
    (lambda p: save_mesh_obj(_V, [[0, 1, 3]], p), "triangles"),
    (lambda p: save_mesh_obj(_V, [[-1, 1, 2]], p), "triangles"),
    (lambda p: save_mesh_obj(_V, _T, p, name="two words"), "name"),
    (lambda p: save_mesh_obj(_V, _T, p, name=""), "name"),
    (lambda p: shape_mesh(wmo.Sphere(1), sphere_subdivisions=-1), "sphere_subdivisions"),
    (lambda p: shape_mesh(wmo.Sphere(1), segments=2), "segments"),
    (lambda p: shape_mesh(wmo.Sphere(1), plane_size=math.nan), "plane_size"),
    (lambda p: shape_mesh(wmo.Sphere(1), plane_size=0.0), "plane_size"),
])
def test_bad_input_raises_value_error_naming_the_field(tmp_path, call, field):
    with pytest.raises(ValueError, match=f"^{field} "):
        call(tmp_path / "out.obj")
    assert list(tmp_path.iterdir()) == []


def test_save_obj_rejects_what_is_not_a_world(tmp_path):
    with pytest.raises(TypeError, match="^world must be a wmo.World"):
        save_obj("world", tmp_path / "out.obj")
    assert list(tmp_path.iterdir()) == []


def test_wmo_save_writes_obj_by_suffix(tmp_path):
    w = wmo.scenes.tower(2)
    wmo.save(w, tmp_path / "t.obj")
    mesh = parse_obj(tmp_path / "t.obj")
    assert [name for name, _ in mesh.groups] == ["body_0", "body_1", "body_2"]
    with pytest.raises(ValueError, match="unknown suffix '.stl'"):
        wmo.save(w, tmp_path / "t.stl")


def test_shape_mesh_rejects_what_is_not_a_shape():
    with pytest.raises(TypeError, match="shape must be a wmo shape"):
        shape_mesh(np.zeros(3))


def test_a_failed_write_leaves_the_old_file_and_no_temporary(tmp_path, monkeypatch):
    path = tmp_path / "scene.obj"
    path.write_text("old\n")

    def fail(src, dst):
        raise OSError("disk full")

    monkeypatch.setattr("wmo.io.obj_writer.os.replace", fail)
    with pytest.raises(OSError, match="disk full"):
        save_obj(_world(), path)
    assert path.read_text() == "old\n"
    assert list(tmp_path.iterdir()) == [path]
