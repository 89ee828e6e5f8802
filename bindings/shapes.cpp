// Shapes (cpp/include/wmo/geometry/shapes.h). Every shape is held by std::shared_ptr so
// one shape can be shared by compounds, bodies and Python at once; the bound class
// hierarchy mirrors C++ (Shape <- ConvexShape <- Sphere, ...) so isinstance works.
// Array properties of large shapes (hull and mesh vertices, triangles) are read-only
// zero-copy views that keep the shape alive.
#include <pybind11/stl.h>

#include <climits>

#include "common.h"
#include "wmo/geometry/shapes.h"

namespace wmo::bindings {

namespace {

py::tuple aabb_tuple(const Aabb& b) { return py::make_tuple(to_array(b.min), to_array(b.max)); }

std::vector<std::array<int, 3>> to_triangles(py::handle obj, py::ssize_t vertex_count) {
  const char* field = "triangles";
  py::array raw = py::array::ensure(obj);
  const char kind = raw ? raw.dtype().kind() : 'O';
  // Integer dtype required: a float index array is almost always a mistake.
  if (!raw || (kind != 'i' && kind != 'u'))
    throw py::type_error(std::string(field) + " must be an integer array of shape (T, 3), got " +
                         (raw ? "an array of dtype " + py::str(raw.dtype()).cast<std::string>()
                              : std::string(Py_TYPE(obj.ptr())->tp_name)));
  auto a = py::array_t<long long, py::array::c_style | py::array::forcecast>::ensure(raw);
  if (!a || a.ndim() != 2 || a.shape(1) != 3) throw_shape_error(field, "(T, 3)", raw);
  std::vector<std::array<int, 3>> tris(static_cast<size_t>(a.shape(0)));
  const long long* p = a.data();
  for (size_t t = 0; t < tris.size(); ++t) {
    for (int k = 0; k < 3; ++k) {
      const long long v = p[3 * t + k];
      // Checked here because values beyond int's range would wrap before the C++
      // constructor could see them.
      if (v < 0 || v >= vertex_count)
        throw InvalidArgument("triangles[" + std::to_string(t) + "] has vertex index " +
                              std::to_string(v) + " outside [0, " +
                              std::to_string(vertex_count) + ")");
      tris[t][k] = static_cast<int>(v);
    }
  }
  return tris;
}

py::array int3_view(const std::vector<std::array<int, 3>>& tris, py::handle owner) {
  static_assert(sizeof(std::array<int, 3>) == 3 * sizeof(int), "packed index triples");
  static const int kEmpty[3] = {0, 0, 0};
  const int* data = tris.empty() ? kEmpty : tris.front().data();
  py::array_t<int> a({static_cast<py::ssize_t>(tris.size()), py::ssize_t{3}},
                     {static_cast<py::ssize_t>(sizeof(std::array<int, 3>)),
                      static_cast<py::ssize_t>(sizeof(int))},
                     data, owner);
  return read_only(a);
}

}  // namespace

void bind_shapes(py::module_& m) {
  py::class_<MassProperties>(m, "MassProperties", R"doc(
Mass properties of a solid of uniform density.

Attributes:
    volume: m^3.
    mass: kg (density * volume).
    center_of_mass: (3,) m, in the shape's local frame.
    inertia: (3, 3) kg m^2, about the centre of mass, in local axes.
)doc")
      .def_readonly("volume", &MassProperties::volume)
      .def_readonly("mass", &MassProperties::mass)
      .def_property_readonly("center_of_mass",
                             [](const MassProperties& p) { return to_array(p.center_of_mass); })
      .def_property_readonly("inertia",
                             [](const MassProperties& p) { return to_array(p.inertia); })
      .def("__repr__", [](const MassProperties& p) {
        return "MassProperties(volume=" + repr_real(p.volume) + ", mass=" + repr_real(p.mass) +
               ", center_of_mass=" + repr_vec(p.center_of_mass) + ", inertia_diagonal=" +
               repr_vec(p.inertia.diagonal()) + ")";
      });

  py::class_<Shape, std::shared_ptr<Shape>>(m, "Shape", R"doc(
Base class of every shape. Shapes are immutable and live in their own local frame
(metres); a Pose places them in the world. Capsules and cylinders are aligned with the
local Y axis.
)doc")
      .def_property_readonly(
          "type", [](const Shape& s) { return std::string(to_string(s.type())); },
          "Shape type name: 'sphere', 'box', 'capsule', 'cylinder', 'convex_hull', "
          "'triangle_mesh', 'plane' or 'compound'.")
      .def_property_readonly("is_convex", &Shape::is_convex,
                             "True for sphere, box, capsule, cylinder and convex hull.")
      .def_property_readonly("is_solid", &Shape::is_solid,
                             "True if the shape encloses a volume (not for planes and meshes).")
      .def(
          "local_aabb", [](const Shape& s) { return aabb_tuple(s.local_aabb()); },
          "Bounding box in the local frame as (min, max), two (3,) arrays in metres. "
          "Unbounded shapes (planes) are clipped at +-1e9 m.")
      .def(
          "aabb",
          [](const Shape& s, py::handle pose) { return aabb_tuple(s.world_aabb(to_pose(pose, "pose"))); },
          py::arg("pose"), "World bounding box (min, max) of the shape placed at `pose`.")
      .def(
          "mass_properties", [](const Shape& s, Real density) { return s.mass_properties(density); },
          py::arg("density") = 1000.0,
          "Mass properties for a uniform density in kg/m^3 (default: water). Raises "
          "ValueError for non-solid shapes (plane, triangle mesh) or a density that is not "
          "finite and > 0.");

  py::class_<ConvexShape, Shape, std::shared_ptr<ConvexShape>>(m, "ConvexShape", R"doc(
A convex shape: a core inflated by a convex radius (sphere, box, capsule, cylinder,
convex hull).
)doc")
      .def(
          "support",
          [](const ConvexShape& s, py::handle d) { return to_array(s.support(to_vec3(d, "direction"))); },
          py::arg("direction"),
          "Point of the shape furthest along `direction` (local frame, need not be unit). "
          "For a zero direction any point of the shape is returned.")
      .def_property_readonly("convex_radius", &ConvexShape::radius,
                             "The radius the core is inflated by (metres).");

  py::class_<Sphere, ConvexShape, std::shared_ptr<Sphere>>(m, "Sphere",
                                                           "Sphere centred at the origin.")
      .def(py::init([](Real radius) { return std::make_shared<Sphere>(radius); }),
           py::arg("radius"), "radius: metres, finite and > 0.")
      .def_property_readonly("radius", &Sphere::radius, "Radius in metres.")
      .def("__repr__",
           [](const Sphere& s) { return "Sphere(radius=" + repr_real(s.radius()) + ")"; });

  py::class_<Box, ConvexShape, std::shared_ptr<Box>>(m, "Box", R"doc(
Box centred at the origin with half extents (hx, hy, hz) in metres, optionally with
rounded edges: the outer surface stays at the half extents and edges are rounded with
radius `rounding` (0 <= rounding < smallest half extent).
)doc")
      .def(py::init([](py::handle half_extents, Real rounding) {
             return std::make_shared<Box>(to_vec3(half_extents, "half_extents"), rounding);
           }),
           py::arg("half_extents"), py::arg("rounding") = 0.0)
      .def_property_readonly(
          "half_extents", [](const Box& b) { return to_array(b.half_extents()); },
          "(3,) half extents in metres.")
      .def_property_readonly("rounding", &Box::radius, "Edge rounding radius in metres.")
      .def("__repr__", [](const Box& b) {
        return "Box(half_extents=" + repr_vec(b.half_extents()) +
               ", rounding=" + repr_real(b.radius()) + ")";
      });

  py::class_<Capsule, ConvexShape, std::shared_ptr<Capsule>>(m, "Capsule", R"doc(
Capsule along local Y: the segment from (0, -half_height, 0) to (0, half_height, 0)
inflated by `radius` (metres). Total length 2 * (half_height + radius).
)doc")
      .def(py::init([](Real radius, Real half_height) {
             return std::make_shared<Capsule>(radius, half_height);
           }),
           py::arg("radius"), py::arg("half_height"))
      .def_property_readonly("radius", &Capsule::radius)
      .def_property_readonly("half_height", &Capsule::half_height)
      .def("__repr__", [](const Capsule& c) {
        return "Capsule(radius=" + repr_real(c.radius()) +
               ", half_height=" + repr_real(c.half_height()) + ")";
      });

  py::class_<Cylinder, ConvexShape, std::shared_ptr<Cylinder>>(m, "Cylinder", R"doc(
Solid cylinder along local Y with radius `radius`, from y = -half_height to
+half_height (metres). Sharp edges (convex radius 0).
)doc")
      .def(py::init([](Real radius, Real half_height) {
             return std::make_shared<Cylinder>(radius, half_height);
           }),
           py::arg("radius"), py::arg("half_height"))
      .def_property_readonly("radius", &Cylinder::cylinder_radius)
      .def_property_readonly("half_height", &Cylinder::half_height)
      .def("__repr__", [](const Cylinder& c) {
        return "Cylinder(radius=" + repr_real(c.cylinder_radius()) +
               ", half_height=" + repr_real(c.half_height()) + ")";
      });

  py::class_<ConvexHull, ConvexShape, std::shared_ptr<ConvexHull>>(m, "ConvexHull", R"doc(
Convex hull of a point cloud (Quickhull). Interior and duplicate points are dropped;
coplanar triangles are merged into polygonal faces.

Args:
    points: (N, 3) array, N >= 4, finite, not all coplanar.

Raises:
    TypeError: points is not an (N, 3) real array.
    ValueError: fewer than 4 points, a non-finite point, or degenerate (coplanar,
        colinear or coincident) input.
)doc")
      .def(py::init([](py::handle points) {
             return std::make_shared<ConvexHull>(to_points(points, "points"));
           }),
           py::arg("points"))
      .def_property_readonly(
          "vertices",
          [](py::handle self) {
            return vec3_view(self.cast<const ConvexHull&>().vertices(), self);
          },
          "(V, 3) hull vertices in metres (read-only view).")
      .def_property_readonly(
          "faces",
          [](const ConvexHull& h) {
            py::list faces;
            for (int f = 0; f < static_cast<int>(h.faces().size()); ++f) {
              std::vector<int> idx = h.face_vertices(f);
              py::array_t<int> a(static_cast<py::ssize_t>(idx.size()));
              std::copy(idx.begin(), idx.end(), a.mutable_data());
              faces.append(read_only(a));
            }
            return faces;
          },
          "List of faces, each an int array of vertex indices, CCW seen from outside.")
      .def_property_readonly(
          "face_normals",
          [](const ConvexHull& h) {
            py::array_t<double> a({static_cast<py::ssize_t>(h.faces().size()), py::ssize_t{3}});
            double* o = a.mutable_data();
            for (const auto& f : h.faces())
              for (int k = 0; k < 3; ++k) *o++ = f.normal[k];
            return read_only(a);
          },
          "(F, 3) outward unit face normals.")
      .def_property_readonly(
          "face_offsets",
          [](const ConvexHull& h) {
            py::array_t<double> a(static_cast<py::ssize_t>(h.faces().size()));
            double* o = a.mutable_data();
            for (const auto& f : h.faces()) *o++ = f.offset;
            return read_only(a);
          },
          "(F,) plane offsets: face f is {x : dot(face_normals[f], x) = face_offsets[f]}.")
      .def("__repr__", [](const ConvexHull& h) {
        return "ConvexHull(" + std::to_string(h.vertices().size()) + " vertices, " +
               std::to_string(h.faces().size()) + " faces)";
      });

  py::class_<TriangleMesh, Shape, std::shared_ptr<TriangleMesh>>(m, "TriangleMesh", R"doc(
Concave triangle mesh for static geometry (not solid: no mass properties).

Args:
    vertices: (V, 3) real array, metres.
    triangles: (T, 3) integer array of vertex indices, CCW seen from outside.
    one_sided: False (default): every triangle is a two-sided sheet of zero thickness,
        and a body is pushed out on whichever side less of it has passed through.
        True: the mesh is the surface of a solid lying behind it (terrain, or a closed
        mesh wound outwards): a body overlapping a triangle is always pushed out
        through its front, along its normal, however deep it is, and a body behind a
        triangle that does not touch it is ignored. Use it for ground meshes: on a
        two-sided one a body driven past the plane (fast, thin, spinning, or pressed
        by a pile) is pushed out below and falls. Ray casts and distance queries see
        both sides either way.

Raises:
    TypeError: wrong shapes or a non-integer triangles array.
    ValueError: non-finite vertices, out-of-range indices, an empty mesh or a
        degenerate (zero-area) triangle.
)doc")
      .def(py::init([](py::handle vertices, py::handle triangles, bool one_sided) {
             std::vector<Vec3> v = to_points(vertices, "vertices");
             auto t = to_triangles(triangles, static_cast<py::ssize_t>(v.size()));
             return std::make_shared<TriangleMesh>(std::move(v), std::move(t), one_sided);
           }),
           py::arg("vertices"), py::arg("triangles"), py::arg("one_sided") = false)
      .def_property_readonly("one_sided", &TriangleMesh::one_sided,
                             "True if the mesh is the surface of a solid behind it (see the constructor).")
      .def_property_readonly(
          "vertices",
          [](py::handle self) {
            return vec3_view(self.cast<const TriangleMesh&>().vertices(), self);
          },
          "(V, 3) vertices (read-only view).")
      .def_property_readonly(
          "triangles",
          [](py::handle self) {
            return int3_view(self.cast<const TriangleMesh&>().triangles(), self);
          },
          "(T, 3) int32 vertex indices (read-only view).")
      .def_property_readonly(
          "triangle_normals",
          [](const TriangleMesh& mesh) {
            const auto n = static_cast<py::ssize_t>(mesh.triangles().size());
            py::array_t<double> a({n, py::ssize_t{3}});
            double* o = a.mutable_data();
            for (int t = 0; t < n; ++t)
              for (int k = 0; k < 3; ++k) *o++ = mesh.triangle_normal(t)[k];
            return read_only(a);
          },
          "(T, 3) unit triangle normals.")
      .def("__repr__", [](const TriangleMesh& mesh) {
        return "TriangleMesh(" + std::to_string(mesh.vertices().size()) + " vertices, " +
               std::to_string(mesh.triangles().size()) + " triangles" + (mesh.one_sided() ? ", one_sided" : "") +
               ")";
      });

  py::class_<Plane, Shape, std::shared_ptr<Plane>>(m, "Plane", R"doc(
Half-space {x : dot(normal, x) <= offset} in the local frame (static, not solid).
`normal` is normalised; it must be finite and non-zero. `offset` in metres.
)doc")
      .def(py::init([](py::handle normal, Real offset) {
             return std::make_shared<Plane>(to_vec3(normal, "normal"), offset);
           }),
           py::arg("normal"), py::arg("offset") = 0.0)
      .def_property_readonly("normal", [](const Plane& p) { return to_array(p.normal()); })
      .def_property_readonly("offset", &Plane::offset)
      .def("__repr__", [](const Plane& p) {
        return "Plane(normal=" + repr_vec(p.normal()) + ", offset=" + repr_real(p.offset()) + ")";
      });

  py::class_<Compound, Shape, std::shared_ptr<Compound>>(m, "Compound", R"doc(
A rigid set of convex children, each placed by a Pose in the compound's frame.

Args:
    children: sequence of (shape, pose) pairs; shape must be convex, pose a wmo.Pose or
        a (position, orientation) pair.

Mass properties sum the children's (overlaps count twice, as in Bullet and Jolt).
)doc")
      .def(py::init([](py::iterable children) {
             std::vector<Compound::Child> kids;
             int i = 0;
             for (py::handle item : children) {
               const std::string field = "children[" + std::to_string(i++) + "]";
               if (!py::isinstance<py::sequence>(item) || py::len(item) != 2)
                 throw py::type_error(field + " must be a (shape, pose) pair");
               py::sequence pair = py::reinterpret_borrow<py::sequence>(item);
               py::object shape = pair[0];
               if (!py::isinstance<ConvexShape>(shape))
                 throw py::type_error(field + " must hold a convex shape (Sphere, Box, Capsule, "
                                      "Cylinder or ConvexHull), got " +
                                      std::string(Py_TYPE(shape.ptr())->tp_name));
               kids.push_back(Compound::Child{shape.cast<std::shared_ptr<ConvexShape>>(),
                                              to_pose(pair[1], field + ".pose")});
             }
             return std::make_shared<Compound>(std::move(kids));
           }),
           py::arg("children"))
      .def_property_readonly(
          "children",
          [](const Compound& c) {
            py::list out;
            for (const auto& child : c.children())
              out.append(py::make_tuple(std::const_pointer_cast<ConvexShape>(child.shape),
                                        child.pose));
            return out;
          },
          "List of (shape, Pose) pairs.")
      .def("__len__", [](const Compound& c) { return c.children().size(); })
      .def("__repr__", [](const Compound& c) {
        return "Compound(" + std::to_string(c.children().size()) + " children)";
      });
}

}  // namespace wmo::bindings
