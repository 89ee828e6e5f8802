// Conversions between Python / NumPy values and WMO's Eigen types (see common.h).
#include <cmath>
#include <cstring>

#include "common.h"

namespace wmo::bindings {

std::string shape_string(const py::array& a) {
  std::string s = "(";
  for (py::ssize_t i = 0; i < a.ndim(); ++i) {
    if (i) s += ", ";
    s += std::to_string(a.shape(i));
  }
  if (a.ndim() == 1) s += ",";
  return s + ")";
}

std::string repr_real(Real x) { return py::repr(py::float_(x)).cast<std::string>(); }

std::string repr_vec(const Vec3& v) {
  return "(" + repr_real(v.x()) + ", " + repr_real(v.y()) + ", " + repr_real(v.z()) + ")";
}

std::string repr_quat(const Quat& q) {
  return "(" + repr_real(q.x()) + ", " + repr_real(q.y()) + ", " + repr_real(q.z()) + ", " +
         repr_real(q.w()) + ")";
}

namespace {

// What the user passed, for an error message: the type name for non-arrays, the dtype
// for arrays of the wrong kind.
std::string describe(py::handle obj) {
  return std::string(Py_TYPE(obj.ptr())->tp_name);
}

}  // namespace

RealArray to_real_array(py::handle obj, const std::string& field, const std::string& expected) {
  const std::string what = field + " must be a real-valued array of shape " + expected;
  py::array raw = py::array::ensure(obj);
  if (!raw) throw py::type_error(what + ", got " + describe(obj));
  // Integers are accepted (positions written as ints are common); booleans, complex
  // numbers, strings and objects are rejected rather than silently cast.
  const char kind = raw.dtype().kind();
  if (kind != 'f' && kind != 'i' && kind != 'u') {
    if (py::isinstance<py::array>(obj))
      throw py::type_error(what + ", got an array of dtype " +
                           py::str(raw.dtype()).cast<std::string>());
    throw py::type_error(what + ", got " + describe(obj));
  }
  RealArray arr = RealArray::ensure(raw);
  if (!arr) throw py::type_error(what + ", got " + describe(obj));
  return arr;
}

void throw_shape_error(const std::string& field, const std::string& expected,
                       const py::array& got) {
  throw py::type_error(field + " must have shape " + expected + ", got shape " +
                       shape_string(got));
}

Vec3 to_vec3(py::handle obj, const std::string& field) {
  RealArray a = to_real_array(obj, field, "(3,)");
  if (a.ndim() != 1 || a.shape(0) != 3) throw_shape_error(field, "(3,)", a);
  const double* p = a.data();
  return Vec3(p[0], p[1], p[2]);
}

Quat to_quat_xyzw(py::handle obj, const std::string& field) {
  RealArray a = to_real_array(obj, field, "(4,)");
  if (a.ndim() != 1 || a.shape(0) != 4) throw_shape_error(field, "(4,)", a);
  const double* p = a.data();
  return Quat(p[3], p[0], p[1], p[2]);  // Eigen's constructor takes (w, x, y, z)
}

std::vector<Vec3> to_points(py::handle obj, const std::string& field) {
  RealArray a = to_real_array(obj, field, "(N, 3)");
  if (a.ndim() != 2 || a.shape(1) != 3) throw_shape_error(field, "(N, 3)", a);
  std::vector<Vec3> out(static_cast<size_t>(a.shape(0)));
  const double* p = a.data();
  for (size_t i = 0; i < out.size(); ++i) out[i] = Vec3(p[3 * i], p[3 * i + 1], p[3 * i + 2]);
  return out;
}

Pose to_pose(py::handle obj, const std::string& field) {
  if (py::isinstance<Pose>(obj)) return obj.cast<Pose>();
  if ((py::isinstance<py::tuple>(obj) || py::isinstance<py::list>(obj)) && py::len(obj) == 2) {
    py::sequence seq = py::reinterpret_borrow<py::sequence>(obj);
    return Pose::checked(to_vec3(seq[0], field + ".position"),
                         to_quat_xyzw(seq[1], field + ".orientation"), field.c_str());
  }
  throw py::type_error(field + " must be a wmo.Pose or a (position, orientation) pair, got " +
                       describe(obj));
}

PoseArray parse_pose_array(py::handle obj, const std::string& field) {
  PoseArray in;
  in.field = field;
  if (py::isinstance<Pose>(obj)) {
    in.single.push_back(obj.cast<Pose>());
    in.broadcast = true;
    return in;
  }
  const char* expected = "(N, 7) [x, y, z, qx, qy, qz, qw] or (7,)";
  in.array = to_real_array(obj, field, expected);
  if (in.array.ndim() == 1 && in.array.shape(0) == 7) {
    in.broadcast = true;
  } else if (!(in.array.ndim() == 2 && in.array.shape(1) == 7)) {
    throw_shape_error(field, expected, in.array);
  }
  return in;
}

PoseBatch validate_pose_array(const PoseArray& in) {
  PoseBatch batch;
  batch.broadcast = in.broadcast;
  if (!in.single.empty()) {
    batch.poses = in.single;  // already validated by its constructor
    return batch;
  }
  const py::ssize_t n = in.rows();
  batch.poses.resize(static_cast<size_t>(n));
  const double* p = in.array.data();
  for (py::ssize_t i = 0; i < n; ++i, p += 7) {
    const Vec3 pos(p[0], p[1], p[2]);
    const Quat q(p[6], p[3], p[4], p[5]);
    const Real norm = q.coeffs().norm();
    // Fast path without building an error string per row; the slow path lets
    // Pose::checked produce the one message format WMO uses for bad poses.
    if (pos.allFinite() && std::isfinite(norm) && std::abs(norm - 1) <= kUnitQuatTolerance) {
      batch.poses[i] = Pose(pos, Quat(q.coeffs() / norm));
    } else {
      const std::string row = in.broadcast ? in.field : in.field + "[" + std::to_string(i) + "]";
      batch.poses[i] = Pose::checked(pos, q, row.c_str());
    }
  }
  return batch;
}

PoseBatch to_pose_batch(py::handle obj, const std::string& field) {
  return validate_pose_array(parse_pose_array(obj, field));
}

py::array read_only(py::array a) {
  a.attr("flags").attr("writeable") = false;
  return a;
}

py::array to_array(const Vec3& v) {
  py::array_t<double> a(3);
  std::memcpy(a.mutable_data(), v.data(), 3 * sizeof(double));
  return read_only(a);
}

py::array to_array(const Quat& q) {
  py::array_t<double> a(4);
  std::memcpy(a.mutable_data(), q.coeffs().data(), 4 * sizeof(double));  // (x, y, z, w)
  return read_only(a);
}

py::array to_array(const Mat3& m) {
  py::array_t<double> a({3, 3});
  double* p = a.mutable_data();
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) p[3 * r + c] = m(r, c);  // row-major, as NumPy
  return read_only(a);
}

py::array vec3_view(std::span<const Vec3> points, py::handle owner) {
  // Eigen's Vector3d is three packed doubles (no alignment padding), so a vector of
  // them is an (N, 3) C-contiguous block.
  static_assert(sizeof(Vec3) == 3 * sizeof(double), "Vec3 must be packed");
  static const double kEmpty[3] = {0, 0, 0};
  const double* data = points.empty() ? kEmpty : points.front().data();
  py::array_t<double> a({static_cast<py::ssize_t>(points.size()), py::ssize_t{3}},
                        {static_cast<py::ssize_t>(sizeof(Vec3)),
                         static_cast<py::ssize_t>(sizeof(double))},
                        data, owner);
  return read_only(a);
}

}  // namespace wmo::bindings
