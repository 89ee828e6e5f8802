"""wmo.io.obj: Wavefront OBJ meshes in.

Bullet's mesh files (../shared/assets/obj, see SOURCE.md there) load as a static mesh,
a convex hull and a convex decomposition; trimesh is the reference for counts and
volumes. Malformed text must raise ValueError naming the line, never anything else.
"""
from __future__ import annotations

import resource
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

import wmo
import wmo.io
from wmo.io import SceneFormatError

trimesh = pytest.importorskip("trimesh", reason="trimesh is the reference mesh reader for these tests")

ASSETS = Path(__file__).resolve().parents[2].parent / "shared" / "assets" / "obj"
needs_assets = pytest.mark.skipif(not ASSETS.is_dir(), reason=f"shared OBJ assets not found at {ASSETS}")


def _ref(name):
    return trimesh.load(ASSETS / name, force="mesh", process=False)


@needs_assets
def test_bunny_as_static_mesh_keeps_every_vertex_and_triangle():
    r = wmo.io.load(ASSETS / "bunny.obj")
    ref = _ref("bunny.obj")
    shape = r.specs["bunny"]["shape"]
    assert isinstance(shape, wmo.TriangleMesh)
    assert r.bodies["bunny"].kind == "static"
    assert (r.info["vertices"], r.info["triangles"]) == (453, 902) == (len(ref.vertices), len(ref.faces))
    assert shape.vertices.shape == (453, 3) and shape.triangles.shape == (902, 3)
    np.testing.assert_allclose(shape.vertices, ref.vertices, atol=1e-9)
    np.testing.assert_array_equal(shape.triangles, ref.faces)
    assert r.warnings == []


@needs_assets
def test_duck_as_convex_hull_matches_trimesh_volume():
    r = wmo.io.load(ASSETS / "duck.obj", as_="convex_hull", density=500.0)
    shape = r.specs["duck"]["shape"]
    assert isinstance(shape, wmo.ConvexHull)
    assert (r.info["vertices"], r.info["triangles"]) == (2108, 4212)
    # trimesh's own hull needs scipy (not a WMO dependency), so check the hull by its
    # definition: its vertices are file vertices, it contains every vertex, and its
    # volume is at least the closed duck's (trimesh, divergence theorem) and not much more.
    ref = _ref("duck.obj")
    verts = np.asarray(ref.vertices)
    d = verts @ shape.face_normals.T - shape.face_offsets
    assert d.max() < 1e-9
    dist = np.linalg.norm(shape.vertices[:, None, :] - verts[None, :, :], axis=2).min(axis=1)
    assert dist.max() < 1e-12
    vol = shape.mass_properties(1.0).volume
    assert ref.volume < vol < 1.5 * ref.volume
    assert r.bodies["duck"].mass == pytest.approx(500.0 * vol, rel=1e-9)


@needs_assets
@pytest.mark.parametrize("name,parts", [("cup_vhacd", 14), ("duck_vhacd", 5)])
def test_vhacd_groups_become_a_compound_of_hulls(name, parts):
    # Each `o` group of a V-HACD file is already convex (every vertex lies on its own
    # hull), so the groups are the parts: no decomposition is run.
    r = wmo.io.load(ASSETS / f"{name}.obj", as_="convex_decomposition")
    shape = r.specs[name]["shape"]
    assert isinstance(shape, wmo.Compound) and len(shape) == parts
    assert r.info["parts_from"] == "groups"
    scene = trimesh.load(ASSETS / f"{name}.obj", process=False)
    geoms = list(scene.geometry.values()) if hasattr(scene, "geometry") else [scene]
    # Each group is a closed convex piece: its own volume (divergence theorem) is its hull's.
    total = sum(abs(g.volume) for g in geoms)
    assert sum(c.mass_properties(1.0).volume for c, _ in shape.children) == pytest.approx(total, rel=1e-3)


@needs_assets
@pytest.mark.parametrize("as_", ["convex_decomposition", "convex_hull"])
def test_cup_holds_a_ball_that_a_single_hull_would_not(as_):
    # The cup file is Z-up (its opening faces +Z); stand it up in a Y-up world and drop a
    # 1 cm ball 3 cm above the rim: inside the compound it sinks to the cup's bottom
    # (~3.6 cm); on a single hull it rests on the lid the hull puts over the opening.
    r = wmo.io.load(ASSETS / "cup_vhacd.obj", as_=as_, kind="static", up="z")
    lo, hi = r.specs["cup_vhacd"]["shape"].local_aabb()
    centre = 0.5 * (lo + hi)
    ball = r.world.add_body(wmo.Sphere(0.01), position=(centre[0], hi[1] + 0.03, centre[2]), density=100.0)
    r.world.step(240)
    if as_ == "convex_decomposition":
        assert lo[1] < ball.position[1] < 0.5 * (lo[1] + hi[1])
    else:
        assert ball.position[1] == pytest.approx(hi[1] + 0.01, abs=0.002)
    assert np.all(ball.position[[0, 2]] > lo[[0, 2]]) and np.all(ball.position[[0, 2]] < hi[[0, 2]])


@needs_assets
def test_bunny_convex_decomposition_with_coacd_is_bounded():
    pytest.importorskip("coacd", reason="coacd decomposes concave meshes")
    import time
    t = time.perf_counter()
    r = wmo.io.load(ASSETS / "bunny.obj", as_="convex_decomposition")
    assert time.perf_counter() - t < 20
    shape = r.specs["bunny"]["shape"]
    assert r.info["parts_from"] == "coacd"
    assert isinstance(shape, wmo.Compound) and 2 <= len(shape) <= 16
    vol = sum(c.mass_properties(1.0).volume for c, _ in shape.children)
    ref = _ref("bunny.obj")
    hull = wmo.io.load(ASSETS / "bunny.obj", as_="convex_hull").specs["bunny"]["shape"]
    # The pieces cover the bunny without exceeding its hull by much.
    assert 0.9 * ref.volume < vol < 1.1 * hull.mass_properties(1.0).volume


def _write(tmp_path, text, name="m.obj"):
    p = tmp_path / name
    p.write_text(text)
    return p


TETRA = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 2\nf 1 3 2\nf 1 2 4\nf 2 3 4\nf 3 1 4\n"


def test_units_and_axis_options(tmp_path):
    p = _write(tmp_path, TETRA)
    r = wmo.io.load(p, as_="convex_hull", scale=0.01, up="z", world_up="y", position=(1, 2, 3))
    hull = r.specs["m"]["shape"]
    # z-up file to y-up world: (x, y, z) -> (x, z, -y); then cm to m.
    lo, hi = hull.local_aabb()
    np.testing.assert_allclose(lo, (0, 0, -0.01), atol=1e-12)
    np.testing.assert_allclose(hi, (0.01, 0.02, 0), atol=1e-12)
    np.testing.assert_allclose(r.bodies["m"].position, (1, 2, 3))
    assert r.bodies["m"].kind == "dynamic"
    r2 = wmo.io.load(p, as_="convex_hull", up="y", world_up="z")
    lo, hi = r2.specs["m"]["shape"].local_aabb()
    np.testing.assert_allclose(lo, (0, -2, 0), atol=1e-12)  # (x, y, z) -> (x, -z, y)
    np.testing.assert_allclose(hi, (1, 0, 1), atol=1e-12)
    with pytest.raises(ValueError, match="must be static"):
        wmo.io.load(p, kind="dynamic")
    with pytest.raises(ValueError, match="scale"):
        wmo.io.load(p, scale=-1.0)


def test_one_sided_static_mesh(tmp_path):
    p = _write(tmp_path, TETRA)
    assert not wmo.io.load(p).specs["m"]["shape"].one_sided
    assert wmo.io.load(p, one_sided=True).specs["m"]["shape"].one_sided
    with pytest.raises(ValueError, match="one_sided applies to"):
        wmo.io.load(p, as_="convex_hull", one_sided=True)
    with pytest.raises(TypeError, match="one_sided"):
        wmo.io.load(p, one_sided="yes")


def test_negative_indices_polygons_and_skipped_statements(tmp_path):
    text = ("mtllib missing.mtl\no quad\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvn 0 0 1\n"
            "usemtl red\ns off\nf -4/1/1 -3/1/1 -2/1/1 -1/1/1\n")
    r = wmo.io.load(_write(tmp_path, text))
    assert r.specs["m"]["shape"].triangles.shape == (2, 3)


@pytest.mark.parametrize("text,match", [
    ("v 0 0 0\nv 1 0 0\nv 0 1 0\nthis is garbage\nf 1 2 3\n", r"m\.obj:4: unknown OBJ statement"),
    ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 7\n", r"m\.obj:4: vertex index 7 out of range"),
    ("v 0 0 0\nv 1 nan 0\nv 0 1 0\nf 1 2 3\n", r"m\.obj:2: vertex is not finite"),
    ("v 0 0 0\nv 1 0\n", r"m\.obj:2: 'v' needs 3"),
    ("v 0 0 0\nv 1 0 x\n", r"m\.obj:2: bad number"),
    ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2\n", r"m\.obj:4: a face needs"),
    ("v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n", r"m\.obj: every face has zero area"),
    ("v 0 0 0\n", r"m\.obj: no faces"),
])
def test_malformed_obj_names_the_line(tmp_path, text, match):
    with pytest.raises(SceneFormatError, match=match):
        wmo.io.load(_write(tmp_path, text))


def test_coplanar_hull_and_missing_file(tmp_path):
    flat = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\n"
    with pytest.raises(ValueError, match="coplanar"):
        wmo.io.load(_write(tmp_path, flat), as_="convex_hull")
    with pytest.raises(ValueError, match="nope.obj"):
        wmo.io.load(tmp_path / "nope.obj")
    (tmp_path / "bin.obj").write_bytes(b"v 0 0 0\n\xff\xfe\x00garbage\n")
    with pytest.raises(ValueError, match=r"bin\.obj:2"):
        wmo.io.load(tmp_path / "bin.obj")


_tokens = st.sampled_from(["v", "f", "o", "g", "vt", "vn", "#", "s", "usemtl", "x", "1", "-1", "0", "2",
                           "0.5", "nan", "inf", "1e308", "1/2/3", "-2//1", "3/", "", "a", "1e-300"])
_lines = st.lists(_tokens, min_size=0, max_size=6).map(" ".join)


@settings(max_examples=100, deadline=None)
@given(st.lists(_lines, max_size=25), st.sampled_from(["static_mesh", "convex_hull", "convex_decomposition"]))
def test_random_obj_text_loads_or_raises_value_error(tmp_path_factory, lines, as_):
    # Loads or raises ValueError, never anything else, and memory stays bounded: the
    # process's peak resident size grows by less than 256 MiB over all examples (tiny
    # files; a reader that believed an absurd number would blow far past it).
    peak_before = _FUZZ_PEAK.setdefault("kib", resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)
    path = tmp_path_factory.mktemp("fuzz") / "r.obj"
    path.write_text("\n".join(lines))
    try:
        r = wmo.io.load(path, as_=as_, coacd_options={"max_convex_hull": 2, "mcts_iterations": 10,
                                                     "resolution": 200, "preprocess_resolution": 10})
        assert len(r.bodies) == 1
    except ValueError:
        pass
    assert resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - peak_before < 256 * 1024


_FUZZ_PEAK: dict = {}


def test_absurd_obj_lines_raise_with_bounded_memory(tmp_path):
    # Indices and numbers far beyond the file's data: refused (ValueError naming the
    # line) under a 2 GiB address-space limit, so nothing tries to allocate what they claim.
    cases = {"index.obj": "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 99999999999999999999999\n",
             "negative.obj": "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 -4000000000\n",
             "overflow.obj": "v 0 0 0\nv 1e400 0 0\nv 0 1 0\nf 1 2 3\n",
             "huge.obj": "v 0 0 0\nv 1e308 0 0\nv 0 1e308 0\nv 0 0 1e308\nf 1 2 3\nf 1 3 4\nf 1 4 2\nf 2 4 3\n"}
    for name, text in cases.items():
        (tmp_path / name).write_text(text)
    script = f"""
import resource
resource.setrlimit(resource.RLIMIT_AS, (2 << 30, 2 << 30))
import wmo.io
for name, as_ in [(n, a) for n in {sorted(cases)!r} for a in ("static_mesh", "convex_hull")]:
    try:
        wmo.io.load({str(tmp_path)!r} + "/" + name, as_=as_)
    except ValueError as e:
        print(name, as_, "ValueError", str(e)[:200])
    else:
        print(name, as_, "LOADED")
"""
    r = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr[-2000:]
    out = r.stdout.splitlines()
    assert len(out) == 8, r.stdout
    for line in out:
        name, as_, verdict = line.split(" ", 2)
        assert verdict.startswith("ValueError") and (f"{name}:4" in verdict or f"{name}:2" in verdict), line
    assert "beyond +-1e+15" in [v for v in out if v.startswith("huge.obj")][0]


@needs_assets
def test_a_server_hosts_the_vhacd_cup_and_it_still_holds_the_ball(tmp_path):
    # Remote scenes hold compounds: Bullet's V-HACD cup (14 convex parts), saved with a
    # ball above it and registered as a file scene, is hosted part for part, and the
    # ball still sinks into the cup (the test above, through a server's scene model).
    pytest.importorskip("msgpack")
    pytest.importorskip("websockets")
    from wmo.remote import SceneModel
    from wmo.remote.scene import SCENE_BUILDERS, register_file_scene

    r = wmo.io.load(ASSETS / "cup_vhacd.obj", as_="convex_decomposition", kind="static", up="z")
    lo, hi = r.specs["cup_vhacd"]["shape"].local_aabb()
    centre = 0.5 * (lo + hi)
    r.world.add_body(wmo.Sphere(0.01), position=(centre[0], hi[1] + 0.03, centre[2]), density=100.0)
    wmo.save(r.world, tmp_path / "cup.usda")
    name, warnings = register_file_scene(tmp_path / "cup.usda")
    try:
        assert warnings == []
        model = SceneModel(name)
        cup_spec = model.defs[1]["shape"]
        assert cup_spec["type"] == "compound" and len(cup_spec["children"]) == 14
        model.step(240)
        ball = model.bodies[2]
        assert lo[1] < ball.position[1] < 0.5 * (lo[1] + hi[1])
    finally:
        SCENE_BUILDERS.pop(name, None)
