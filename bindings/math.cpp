// wmo.Pose: a rigid transform (position, unit quaternion (x, y, z, w)).
#include "common.h"

namespace wmo::bindings {

namespace {

// Applies `f` to a (3,) point or to every row of an (N, 3) array of points; returns
// the same shape.
template <class F>
py::array map_points(py::handle points, const char* field, F f) {
  RealArray a = to_real_array(points, field, "(3,) or (N, 3)");
  if (a.ndim() == 1 && a.shape(0) == 3) {
    const double* p = a.data();
    return to_array(f(Vec3(p[0], p[1], p[2])));
  }
  if (a.ndim() != 2 || a.shape(1) != 3) throw_shape_error(field, "(3,) or (N, 3)", a);
  py::array_t<double> out({a.shape(0), py::ssize_t{3}});
  const double* p = a.data();
  double* o = out.mutable_data();
  for (py::ssize_t i = 0; i < a.shape(0); ++i, p += 3, o += 3) {
    const Vec3 y = f(Vec3(p[0], p[1], p[2]));
    o[0] = y.x(); o[1] = y.y(); o[2] = y.z();
  }
  return out;
}

}  // namespace

void bind_math(py::module_& m) {
  py::class_<Pose>(m, "Pose", R"doc(
A rigid transform: x_parent = rotation * x_local + position.

Args:
    position: (3,) translation in metres (parent frame).
    orientation: (4,) unit quaternion in (x, y, z, w) order, as SciPy and PyBullet.

Raises:
    TypeError: an argument is not a real array of the stated shape.
    ValueError: a position is not finite, or the quaternion is NaN or its norm differs
        from 1 by more than 1e-5 (the message names the field and the value). The
        stored quaternion is renormalised.

Poses are immutable values; the position and orientation arrays are read-only copies.
)doc")
      .def(py::init([](py::handle position, py::handle orientation) {
             return Pose::checked(to_vec3(position, "position"),
                                  to_quat_xyzw(orientation, "orientation"), "pose");
           }),
           py::arg("position") = py::make_tuple(0.0, 0.0, 0.0),
           py::arg("orientation") = py::make_tuple(0.0, 0.0, 0.0, 1.0))
      .def_static("identity", &Pose::identity, "The identity transform.")
      .def_static(
          "from_array",
          [](py::handle a) {
            PoseBatch b = to_pose_batch(a, "array");
            if (!b.broadcast) throw py::type_error("array must have shape (7,)");
            return b.poses[0];
          },
          py::arg("array"),
          "Pose from a (7,) array [x, y, z, qx, qy, qz, qw] (the row format of the batch "
          "queries).")
      .def_property_readonly(
          "position", [](const Pose& p) { return to_array(p.position); },
          "(3,) translation in metres (read-only copy).")
      .def_property_readonly(
          "orientation", [](const Pose& p) { return to_array(p.rotation); },
          "(4,) unit quaternion (x, y, z, w) (read-only copy).")
      .def("as_array",
           [](const Pose& p) {
             py::array_t<double> a(7);
             double* o = a.mutable_data();
             for (int i = 0; i < 3; ++i) o[i] = p.position[i];
             for (int i = 0; i < 4; ++i) o[3 + i] = p.rotation.coeffs()[i];
             return a;
           },
           "(7,) array [x, y, z, qx, qy, qz, qw], the row format of the batch queries.")
      .def("matrix", [](const Pose& p) { return to_array(p.matrix()); },
           "(3, 3) rotation matrix.")
      .def("inverse", &Pose::inverse, "The inverse transform (parent -> local).")
      .def(
          "__mul__", [](const Pose& a, const Pose& b) { return a * b; }, py::is_operator(),
          "Composition: (a * b) maps b's local frame into a's parent frame.")
      .def(
          "transform_point",
          [](const Pose& p, py::handle x) {
            return map_points(x, "point", [&](const Vec3& v) { return p.transform_point(v); });
          },
          py::arg("point"), "Local -> parent for a (3,) point or an (N, 3) array of points.")
      .def(
          "transform_vector",
          [](const Pose& p, py::handle x) {
            return map_points(x, "vector",
                              [&](const Vec3& v) { return p.transform_vector(v); });
          },
          py::arg("vector"), "Rotates a (3,) direction or (N, 3) directions local -> parent.")
      .def(
          "inverse_transform_point",
          [](const Pose& p, py::handle x) {
            return map_points(x, "point",
                              [&](const Vec3& v) { return p.inverse_transform_point(v); });
          },
          py::arg("point"), "Parent -> local for a (3,) point or (N, 3) points.")
      .def("__repr__",
           [](const Pose& p) {
             return "Pose(position=" + repr_vec(p.position) +
                    ", orientation=" + repr_quat(p.rotation) + ")";
           })
      .def(py::pickle(
          [](const Pose& p) {
            return py::make_tuple(to_array(p.position), to_array(p.rotation));
          },
          [](py::tuple t) {
            if (t.size() != 2) throw py::type_error("invalid Pose state");
            return to_pose(t, "pose");
          }));
}

}  // namespace wmo::bindings
