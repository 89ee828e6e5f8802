// Shared helpers of the pybind11 module wmo._core: NumPy <-> Eigen conversions with
// shape checks, pose parsing, read-only result arrays and repr formatting.
//
// Error policy (one place, shared/STYLE.md): an argument of the wrong type or shape
// raises TypeError naming the argument and the expected shape; a well-formed argument
// with a bad value (NaN, non-unit quaternion, negative size) raises ValueError through
// wmo::InvalidArgument, whose message names the field and the value.
#pragma once

#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <span>
#include <string>
#include <vector>

#include "wmo/math.h"
#include "wmo/types.h"

namespace wmo::bindings {

namespace py = pybind11;

using RealArray = py::array_t<double, py::array::c_style | py::array::forcecast>;

/// "(4, 3)" for an array of that shape.
std::string shape_string(const py::array& a);
/// Shortest round-trip text of a double ("0.1", "1.0", "inf"), as Python's repr.
std::string repr_real(Real x);
/// "(x, y, z)" with repr_real components.
std::string repr_vec(const Vec3& v);
/// "(x, y, z, w)".
std::string repr_quat(const Quat& q);

/// Converts `obj` (array-like) to a C-contiguous float64 array. Raises TypeError naming
/// `field` and `expected` (a shape such as "(N, 3)") if it is not a real-valued
/// (integer or floating) array. The shape is NOT checked here.
RealArray to_real_array(py::handle obj, const std::string& field, const std::string& expected);

/// Raises TypeError "<field> must have shape <expected>, got shape <actual>".
[[noreturn]] void throw_shape_error(const std::string& field, const std::string& expected,
                                    const py::array& got);

/// (3,) array-like -> Vec3. Values are not validated (NaN passes; callers validate).
Vec3 to_vec3(py::handle obj, const std::string& field);
/// (4,) array-like in (x, y, z, w) order -> Quat (not normalised, not validated).
Quat to_quat_xyzw(py::handle obj, const std::string& field);
/// (N, 3) array-like -> points. Also accepts an empty (0, 3) array.
std::vector<Vec3> to_points(py::handle obj, const std::string& field);

/// A wmo.Pose, or a (position, orientation) pair of array-likes, validated with
/// Pose::checked (ValueError naming `field` on NaN or a non-unit quaternion).
Pose to_pose(py::handle obj, const std::string& field);

/// Validated rigid transforms parsed from an (N, 7) array [x, y, z, qx, qy, qz, qw] per
/// row, a (7,) array or a wmo.Pose (both: one pose used for every query).
struct PoseBatch {
  std::vector<Pose> poses;
  bool broadcast = false;  ///< true: one pose for every query
  py::ssize_t rows() const { return static_cast<py::ssize_t>(poses.size()); }
  const Pose& operator[](py::ssize_t i) const { return poses[broadcast ? 0 : i]; }
};
/// First step of to_pose_batch: the type and shape check only (TypeError), so that a
/// caller with several array arguments can check every shape before any value.
struct PoseArray {
  std::string field;
  RealArray array;           ///< (N, 7) or (7,) when not from a Pose
  std::vector<Pose> single;  ///< the Pose, when one was passed
  bool broadcast = false;
  py::ssize_t rows() const { return broadcast ? 1 : array.shape(0); }
};
PoseArray parse_pose_array(py::handle obj, const std::string& field);
/// Second step: validates every row (ValueError naming the row, "<field>[17]", for a
/// non-finite position or a NaN / non-unit quaternion).
PoseBatch validate_pose_array(const PoseArray& in);
/// Both steps. Call with the GIL held.
PoseBatch to_pose_batch(py::handle obj, const std::string& field);

/// Marks a NumPy array read-only and returns it.
py::array read_only(py::array a);
/// Read-only float64 copies.
py::array to_array(const Vec3& v);
py::array to_array(const Quat& q);  // (x, y, z, w)
py::array to_array(const Mat3& m);
/// Read-only (N, 3) float64 view of `points` that keeps `owner` alive (zero copy).
py::array vec3_view(std::span<const Vec3> points, py::handle owner);

// Submodule registration, one per binding file.
void bind_math(py::module_& m);
void bind_shapes(py::module_& m);
void bind_queries(py::module_& m, py::module_& geometry);
void bind_world(py::module_& m);
void bind_codec(py::module_& m);

}  // namespace wmo::bindings
