// Pair queries (cpp/include/wmo/geometry/queries.h, collision/narrowphase.h) and their
// batched forms. Conventions (types.h): world poses in, world-space results out; the
// normal points from A to B; depth > 0 when overlapping.
//
// Batched queries validate and convert every input with the GIL held, then release the
// GIL around a plain C++ loop that writes into preallocated NumPy arrays, so other
// Python threads run while a batch is computed. The loop never calls back into Python.
#include <pybind11/stl.h>

#include <algorithm>
#include <cmath>
#include <limits>

#include "common.h"
#include "wmo/collision/narrowphase.h"
#include "wmo/geometry/queries.h"

namespace wmo::bindings {

namespace {

/// The manifold returned to Python: wmo::Manifold plus the query status.
struct PyManifold {
  Manifold m;
  QueryStatus status = QueryStatus::kOk;
};

const char* status_name(QueryStatus s) { return to_string(s); }

GjkSettings make_gjk(Real tolerance, int max_iterations) {
  require_positive("gjk_tolerance", tolerance);
  if (max_iterations < 1)
    throw InvalidArgument("gjk_max_iterations must be >= 1, got " + std::to_string(max_iterations));
  GjkSettings s;
  s.tolerance = tolerance;
  s.max_iterations = max_iterations;
  return s;
}

EpaSettings make_epa(Real tolerance, int max_iterations) {
  require_positive("epa_tolerance", tolerance);
  if (max_iterations < 1)
    throw InvalidArgument("epa_max_iterations must be >= 1, got " + std::to_string(max_iterations));
  EpaSettings s;
  s.tolerance = tolerance;
  s.max_iterations = max_iterations;
  return s;
}

CollideSettings make_collide(Real margin, bool special, Real gjk_tol, int gjk_iter, Real epa_tol,
                             int epa_iter) {
  require_non_negative("margin", margin);
  CollideSettings s;
  s.margin = margin;
  s.use_special_routines = special;
  s.gjk = make_gjk(gjk_tol, gjk_iter);
  s.epa = make_epa(epa_tol, epa_iter);
  return s;
}

/// An (N, 3) array, or one (3,) row shared by every query (`one` = true); TypeError
/// naming `field` otherwise.
RealArray vec3_rows(py::handle obj, const char* field, bool& one) {
  RealArray arr = to_real_array(obj, field, "(N, 3) or (3,)");
  one = arr.ndim() == 1 && arr.shape(0) == 3;
  if (!one && !(arr.ndim() == 2 && arr.shape(1) == 3)) throw_shape_error(field, "(N, 3) or (3,)", arr);
  return arr;
}

/// Validated time-of-impact settings (ValueError naming the field), and the duration.
ToiSettings make_toi(Real duration, Real tolerance, int max_iterations, Real gjk_tol, int gjk_iter) {
  if (!(duration >= 0) || !std::isfinite(duration))
    throw InvalidArgument("duration must be finite and >= 0, got " + repr_real(duration));
  if (!(tolerance > 0) || !std::isfinite(tolerance))
    throw InvalidArgument("tolerance must be finite and > 0, got " + repr_real(tolerance));
  if (max_iterations < 1)
    throw InvalidArgument("max_iterations must be >= 1, got " + std::to_string(max_iterations));
  ToiSettings st;
  st.tolerance = tolerance;
  st.max_iterations = max_iterations;
  st.gjk = make_gjk(gjk_tol, gjk_iter);
  return st;
}

void check_max_distance(Real max_distance) {
  if (std::isnan(max_distance) || max_distance < 0)
    throw InvalidArgument("max_distance must be >= 0 (inf allowed), got " + repr_real(max_distance));
}

void check_direction(const Vec3& d, const std::string& field) {
  if (!d.allFinite() || d.squaredNorm() == 0)
    throw InvalidArgument(field + " must be finite and non-zero, got " + to_string(d));
}

/// "field" for a broadcast (single) input, "field[i]" for row i of an array.
std::string row_name(const char* field, bool single, py::ssize_t i) {
  std::string s(field);
  if (!single) s.append("[").append(std::to_string(i)).append("]");
  return s;
}

/// The single manifold `collide` reports: the one with the deepest point (composite
/// shapes give one manifold per touching child); an empty one (count 0, zero normal)
/// when apart or unsupported.
PyManifold pick_deepest(const std::vector<Manifold>& all, QueryStatus status) {
  PyManifold out;
  out.status = status;
  out.m.normal = Vec3::Zero();
  Real best = -kInf;
  for (const Manifold& m : all) {
    if (m.count > 0 && m.max_depth() > best) {
      best = m.max_depth();
      out.m = m;
    }
  }
  return out;
}

// Python default values mirror the C++ defaults so there is one source of truth.
const GjkSettings kGjk{};
const EpaSettings kEpa{};

// ---- Batch plumbing ----

/// The two pose arguments of a pair batch. Every shape is checked (TypeError) before
/// any value (ValueError naming the row). One side may broadcast (a Pose or a (7,) row);
/// two arrays must have the same length.
struct PairPoses {
  PoseBatch a, b;
  py::ssize_t n = 0;
};
PairPoses to_pair_poses(py::handle poses_a, py::handle poses_b) {
  const PoseArray in_a = parse_pose_array(poses_a, "poses_a");
  const PoseArray in_b = parse_pose_array(poses_b, "poses_b");
  PairPoses out;
  if (in_a.broadcast) {
    out.n = in_b.rows();
  } else if (in_b.broadcast) {
    out.n = in_a.rows();
  } else if (in_a.rows() != in_b.rows()) {
    throw py::type_error("poses_b must have shape (" + std::to_string(in_a.rows()) +
                         ", 7) to match poses_a, got (" + std::to_string(in_b.rows()) + ", 7)");
  } else {
    out.n = in_a.rows();
  }
  out.a = validate_pose_array(in_a);
  out.b = validate_pose_array(in_b);
  return out;
}

template <class T>
T* data_of(py::array_t<T>& a) {
  return a.mutable_data();
}

py::array_t<double> vec_array(py::ssize_t n) { return py::array_t<double>({n, py::ssize_t{3}}); }

inline void put(double* dst, const Vec3& v) {
  dst[0] = v.x();
  dst[1] = v.y();
  dst[2] = v.z();
}

/// Shared body of distance_batch / closest_points_batch / penetration_batch.
template <class Query>
py::dict distance_like_batch(const Shape& a, const Shape& b, py::handle poses_a,
                             py::handle poses_b, Query query) {
  const PairPoses poses = to_pair_poses(poses_a, poses_b);
  const PoseBatch& pa = poses.a;
  const PoseBatch& pb = poses.b;
  const py::ssize_t n = poses.n;
  py::array_t<double> distance(n), point_a = vec_array(n), point_b = vec_array(n),
      normal = vec_array(n);
  py::array_t<bool> intersecting(n);
  py::array_t<std::uint8_t> status(n);
  py::array_t<std::int32_t> iterations(n);
  double* d = data_of(distance);
  double* qa = data_of(point_a);
  double* qb = data_of(point_b);
  double* nr = data_of(normal);
  bool* in = data_of(intersecting);
  std::uint8_t* st = data_of(status);
  std::int32_t* it = data_of(iterations);
  {
    py::gil_scoped_release release;
    for (py::ssize_t i = 0; i < n; ++i) {
      const DistanceResult r = query(a, pa[i], b, pb[i]);
      d[i] = r.distance;
      put(qa + 3 * i, r.point_a);
      put(qb + 3 * i, r.point_b);
      put(nr + 3 * i, r.normal);
      in[i] = r.intersecting;
      st[i] = static_cast<std::uint8_t>(r.status);
      it[i] = r.iterations;
    }
  }
  py::dict out;
  out["distance"] = distance;
  out["point_a"] = point_a;
  out["point_b"] = point_b;
  out["normal"] = normal;
  out["intersecting"] = intersecting;
  out["status"] = status;
  out["iterations"] = iterations;
  return out;
}

}  // namespace

void bind_queries(py::module_& m, py::module_& g) {
  // ---- Result types (top-level in _core, re-exported by wmo.geometry) ----
  py::class_<DistanceResult>(m, "DistanceResult", R"doc(
Result of distance / closest_points / penetration (world frame).

Attributes:
    distance: signed distance in metres: >= 0 when apart; when overlapping 0 from
        distance() and minus the penetration depth from closest_points() and
        penetration().
    intersecting: True when the shapes overlap or touch.
    point_a, point_b: (3,) closest (or deepest) points on A and on B.
    normal: (3,) unit vector from A to B; zero when undefined.
    status: 'ok', 'unsupported', 'max_iterations' or 'degenerate' (wmo.geometry.QueryStatus).
    iterations: GJK / EPA iterations used.
)doc")
      .def_readonly("distance", &DistanceResult::distance)
      .def_readonly("intersecting", &DistanceResult::intersecting)
      .def_readonly("iterations", &DistanceResult::iterations)
      .def_property_readonly("point_a", [](const DistanceResult& r) { return to_array(r.point_a); })
      .def_property_readonly("point_b", [](const DistanceResult& r) { return to_array(r.point_b); })
      .def_property_readonly("normal", [](const DistanceResult& r) { return to_array(r.normal); })
      .def_property_readonly("status",
                             [](const DistanceResult& r) { return std::string(status_name(r.status)); })
      .def("__repr__", [](const DistanceResult& r) {
        return "DistanceResult(distance=" + repr_real(r.distance) +
               ", intersecting=" + (r.intersecting ? "True" : "False") +
               ", point_a=" + repr_vec(r.point_a) + ", point_b=" + repr_vec(r.point_b) +
               ", normal=" + repr_vec(r.normal) + ", status='" + status_name(r.status) + "')";
      });

  py::class_<PyManifold>(m, "Manifold", R"doc(
A contact manifold (world frame): up to 4 points sharing one normal.

Attributes:
    normal: (3,) unit normal from A to B (moving B by depth * normal separates the
        pair); zeros when there is no contact.
    points_a, points_b: (count, 3) contact points on the surfaces of A and B;
        points_b = points_a - depths[:, None] * normal.
    depths: (count,) penetration depths in metres, > 0 overlapping, < 0 separated
        (speculative contacts within the margin).
    feature_ids: (count,) uint32 ids that persist while the same features touch.
    count: number of points (also len(manifold)).
    child_a, child_b: triangle / compound child index that produced this manifold, -1
        for a plain shape.
    status: 'ok', 'unsupported', 'max_iterations' or 'degenerate'.
)doc")
      .def_property_readonly("normal", [](const PyManifold& p) { return to_array(p.m.normal); })
      .def_property_readonly("count", [](const PyManifold& p) { return p.m.count; })
      .def_property_readonly("points_a",
                             [](const PyManifold& p) {
                               py::array_t<double> a = vec_array(p.m.count);
                               for (int i = 0; i < p.m.count; ++i)
                                 put(a.mutable_data() + 3 * i, p.m.points[i].point_a);
                               return read_only(a);
                             })
      .def_property_readonly("points_b",
                             [](const PyManifold& p) {
                               py::array_t<double> a = vec_array(p.m.count);
                               for (int i = 0; i < p.m.count; ++i)
                                 put(a.mutable_data() + 3 * i, p.m.points[i].point_b);
                               return read_only(a);
                             })
      .def_property_readonly("depths",
                             [](const PyManifold& p) {
                               py::array_t<double> a(p.m.count);
                               for (int i = 0; i < p.m.count; ++i)
                                 a.mutable_data()[i] = p.m.points[i].depth;
                               return read_only(a);
                             })
      .def_property_readonly("feature_ids",
                             [](const PyManifold& p) {
                               py::array_t<std::uint32_t> a(p.m.count);
                               for (int i = 0; i < p.m.count; ++i)
                                 a.mutable_data()[i] = p.m.points[i].feature_id;
                               return read_only(a);
                             })
      .def_property_readonly("max_depth",
                             [](const PyManifold& p) { return p.m.max_depth(); },
                             "Largest depth, -inf when count == 0.")
      .def_property_readonly("child_a", [](const PyManifold& p) { return p.m.child_a; })
      .def_property_readonly("child_b", [](const PyManifold& p) { return p.m.child_b; })
      .def_property_readonly("status",
                             [](const PyManifold& p) { return std::string(status_name(p.status)); })
      .def("__len__", [](const PyManifold& p) { return p.m.count; })
      .def("__bool__", [](const PyManifold& p) { return p.m.count > 0; },
           "True if the manifold has at least one point.")
      .def("__repr__", [](const PyManifold& p) {
        std::string s = "Manifold(count=" + std::to_string(p.m.count) +
                        ", normal=" + repr_vec(p.m.normal) + ", depths=[";
        for (int i = 0; i < p.m.count; ++i) {
          if (i) s += ", ";
          s += repr_real(p.m.points[i].depth);
        }
        return s + "], status='" + status_name(p.status) + "')";
      });

  py::class_<RayHit>(m, "RayHit", R"doc(
Result of a ray cast (world frame).

Attributes:
    hit: True if the ray hit within max_distance.
    distance: along the ray, in units of |direction| (metres for a unit direction).
    point: (3,) hit point. normal: (3,) outward surface normal at the hit (zero for a
        ray starting inside a solid shape, which hits at distance 0).
    child: triangle / compound child index for composite shapes, else -1.
    status: 'ok', 'unsupported', ...
)doc")
      .def_readonly("hit", &RayHit::hit)
      .def_readonly("distance", &RayHit::distance)
      .def_readonly("child", &RayHit::child)
      .def_property_readonly("point", [](const RayHit& r) { return to_array(r.point); })
      .def_property_readonly("normal", [](const RayHit& r) { return to_array(r.normal); })
      .def_property_readonly("status", [](const RayHit& r) { return std::string(status_name(r.status)); })
      .def("__bool__", [](const RayHit& r) { return r.hit; })
      .def("__repr__", [](const RayHit& r) {
        return "RayHit(hit=" + std::string(r.hit ? "True" : "False") +
               ", distance=" + repr_real(r.distance) + ", point=" + repr_vec(r.point) +
               ", normal=" + repr_vec(r.normal) + ", child=" + std::to_string(r.child) +
               ", status='" + status_name(r.status) + "')";
      });

  // Defaults of the keyword arguments, read by wmo.geometry so they cannot drift.
  g.attr("GJK_TOLERANCE") = kGjk.tolerance;
  g.attr("GJK_MAX_ITERATIONS") = kGjk.max_iterations;
  g.attr("EPA_TOLERANCE") = kEpa.tolerance;
  g.attr("EPA_MAX_ITERATIONS") = kEpa.max_iterations;

  // ---- Single queries ----
  g.def(
      "status_names",
      [] {
        py::list names;
        for (int s = 0; s <= static_cast<int>(QueryStatus::kDegenerate); ++s)
          names.append(status_name(static_cast<QueryStatus>(s)));
        return names;
      },
      "Status names indexed by the uint8 codes of the batch queries.");

  g.def(
      "distance",
      [](const Shape& a, py::handle pa, const Shape& b, py::handle pb, Real gjk_tol, int gjk_iter) {
        return distance(a, to_pose(pa, "pose_a"), b, to_pose(pb, "pose_b"),
                        make_gjk(gjk_tol, gjk_iter));
      },
      py::arg("a"), py::arg("pose_a"), py::arg("b"), py::arg("pose_b"), py::kw_only(),
      py::arg("gjk_tolerance") = kGjk.tolerance, py::arg("gjk_max_iterations") = kGjk.max_iterations);

  g.def(
      "closest_points",
      [](const Shape& a, py::handle pa, const Shape& b, py::handle pb, Real gjk_tol, int gjk_iter,
         Real epa_tol, int epa_iter) {
        return closest_points(a, to_pose(pa, "pose_a"), b, to_pose(pb, "pose_b"),
                              make_gjk(gjk_tol, gjk_iter), make_epa(epa_tol, epa_iter));
      },
      py::arg("a"), py::arg("pose_a"), py::arg("b"), py::arg("pose_b"), py::kw_only(),
      py::arg("gjk_tolerance") = kGjk.tolerance, py::arg("gjk_max_iterations") = kGjk.max_iterations,
      py::arg("epa_tolerance") = kEpa.tolerance, py::arg("epa_max_iterations") = kEpa.max_iterations);

  g.def(
      "penetration",
      [](const Shape& a, py::handle pa, const Shape& b, py::handle pb, Real gjk_tol, int gjk_iter,
         Real epa_tol, int epa_iter) {
        return penetration(a, to_pose(pa, "pose_a"), b, to_pose(pb, "pose_b"),
                           make_gjk(gjk_tol, gjk_iter), make_epa(epa_tol, epa_iter));
      },
      py::arg("a"), py::arg("pose_a"), py::arg("b"), py::arg("pose_b"), py::kw_only(),
      py::arg("gjk_tolerance") = kGjk.tolerance, py::arg("gjk_max_iterations") = kGjk.max_iterations,
      py::arg("epa_tolerance") = kEpa.tolerance, py::arg("epa_max_iterations") = kEpa.max_iterations);

  g.def(
      "intersect",
      [](const Shape& a, py::handle pa, const Shape& b, py::handle pb, Real gjk_tol, int gjk_iter) {
        return intersect(a, to_pose(pa, "pose_a"), b, to_pose(pb, "pose_b"),
                         make_gjk(gjk_tol, gjk_iter));
      },
      py::arg("a"), py::arg("pose_a"), py::arg("b"), py::arg("pose_b"), py::kw_only(),
      py::arg("gjk_tolerance") = kGjk.tolerance, py::arg("gjk_max_iterations") = kGjk.max_iterations);

  g.def(
      "raycast",
      [](const Shape& s, py::handle pose, py::handle origin, py::handle direction, Real max_distance) {
        const Pose p = to_pose(pose, "pose");
        const Vec3 o = to_vec3(origin, "origin");
        const Vec3 d = to_vec3(direction, "direction");
        require_finite("origin", o);
        check_direction(d, "direction");
        check_max_distance(max_distance);
        return raycast(s, p, o, d, max_distance);
      },
      py::arg("shape"), py::arg("pose"), py::arg("origin"), py::arg("direction"),
      py::arg("max_distance") = kInf);

  g.def(
      "collide_supported",
      [](const Shape& a, const Shape& b) { return collide_supported(a.type(), b.type()); },
      py::arg("a"), py::arg("b"));

  g.def(
      "collide_all",
      [](const Shape& a, py::handle pa, const Shape& b, py::handle pb, Real margin, bool special,
         Real gjk_tol, int gjk_iter, Real epa_tol, int epa_iter) {
        const CollideSettings s = make_collide(margin, special, gjk_tol, gjk_iter, epa_tol, epa_iter);
        std::vector<Manifold> all;
        const QueryStatus st = collide(a, to_pose(pa, "pose_a"), b, to_pose(pb, "pose_b"), all, s);
        std::vector<PyManifold> out;
        if (st == QueryStatus::kUnsupported) {
          // One empty manifold carrying the status: an unsupported pair is never a
          // silent empty list.
          PyManifold u;
          u.status = st;
          u.m.normal = Vec3::Zero();
          out.push_back(u);
          return out;
        }
        for (const Manifold& mf : all) out.push_back(PyManifold{mf, st});
        return out;
      },
      py::arg("a"), py::arg("pose_a"), py::arg("b"), py::arg("pose_b"), py::kw_only(),
      py::arg("margin") = 0.0, py::arg("special") = true, py::arg("gjk_tolerance") = kGjk.tolerance,
      py::arg("gjk_max_iterations") = kGjk.max_iterations, py::arg("epa_tolerance") = kEpa.tolerance,
      py::arg("epa_max_iterations") = kEpa.max_iterations);

  g.def(
      "collide",
      [](const Shape& a, py::handle pa, const Shape& b, py::handle pb, Real margin, bool special,
         Real gjk_tol, int gjk_iter, Real epa_tol, int epa_iter) {
        const CollideSettings s = make_collide(margin, special, gjk_tol, gjk_iter, epa_tol, epa_iter);
        std::vector<Manifold> all;
        const QueryStatus st = collide(a, to_pose(pa, "pose_a"), b, to_pose(pb, "pose_b"), all, s);
        return pick_deepest(all, st);
      },
      py::arg("a"), py::arg("pose_a"), py::arg("b"), py::arg("pose_b"), py::kw_only(),
      py::arg("margin") = 0.0, py::arg("special") = true, py::arg("gjk_tolerance") = kGjk.tolerance,
      py::arg("gjk_max_iterations") = kGjk.max_iterations, py::arg("epa_tolerance") = kEpa.tolerance,
      py::arg("epa_max_iterations") = kEpa.max_iterations);

  // ---- Batched queries ----
  g.def(
      "distance_batch",
      [](const Shape& a, const Shape& b, py::handle poses_a, py::handle poses_b, Real gjk_tol,
         int gjk_iter) {
        const GjkSettings gjk = make_gjk(gjk_tol, gjk_iter);
        return distance_like_batch(a, b, poses_a, poses_b,
                                   [&](const Shape& x, const Pose& px, const Shape& y, const Pose& py_) {
                                     return distance(x, px, y, py_, gjk);
                                   });
      },
      py::arg("a"), py::arg("b"), py::arg("poses_a"), py::arg("poses_b"), py::kw_only(),
      py::arg("gjk_tolerance") = kGjk.tolerance, py::arg("gjk_max_iterations") = kGjk.max_iterations);

  g.def(
      "closest_points_batch",
      [](const Shape& a, const Shape& b, py::handle poses_a, py::handle poses_b, Real gjk_tol,
         int gjk_iter, Real epa_tol, int epa_iter) {
        const GjkSettings gjk = make_gjk(gjk_tol, gjk_iter);
        const EpaSettings epa = make_epa(epa_tol, epa_iter);
        return distance_like_batch(a, b, poses_a, poses_b,
                                   [&](const Shape& x, const Pose& px, const Shape& y, const Pose& py_) {
                                     return closest_points(x, px, y, py_, gjk, epa);
                                   });
      },
      py::arg("a"), py::arg("b"), py::arg("poses_a"), py::arg("poses_b"), py::kw_only(),
      py::arg("gjk_tolerance") = kGjk.tolerance, py::arg("gjk_max_iterations") = kGjk.max_iterations,
      py::arg("epa_tolerance") = kEpa.tolerance, py::arg("epa_max_iterations") = kEpa.max_iterations);

  g.def(
      "penetration_batch",
      [](const Shape& a, const Shape& b, py::handle poses_a, py::handle poses_b, Real gjk_tol,
         int gjk_iter, Real epa_tol, int epa_iter) {
        const GjkSettings gjk = make_gjk(gjk_tol, gjk_iter);
        const EpaSettings epa = make_epa(epa_tol, epa_iter);
        return distance_like_batch(a, b, poses_a, poses_b,
                                   [&](const Shape& x, const Pose& px, const Shape& y, const Pose& py_) {
                                     return penetration(x, px, y, py_, gjk, epa);
                                   });
      },
      py::arg("a"), py::arg("b"), py::arg("poses_a"), py::arg("poses_b"), py::kw_only(),
      py::arg("gjk_tolerance") = kGjk.tolerance, py::arg("gjk_max_iterations") = kGjk.max_iterations,
      py::arg("epa_tolerance") = kEpa.tolerance, py::arg("epa_max_iterations") = kEpa.max_iterations);

  g.def(
      "collide_batch",
      [](const Shape& a, const Shape& b, py::handle poses_a, py::handle poses_b, Real margin,
         bool special, Real gjk_tol, int gjk_iter, Real epa_tol, int epa_iter) {
        const CollideSettings s = make_collide(margin, special, gjk_tol, gjk_iter, epa_tol, epa_iter);
        const PairPoses poses = to_pair_poses(poses_a, poses_b);
        const PoseBatch& pa = poses.a;
        const PoseBatch& pb = poses.b;
        const py::ssize_t n = poses.n;
        constexpr py::ssize_t K = kMaxManifoldPoints;
        py::array_t<std::int32_t> count(n), child_a(n), child_b(n);
        py::array_t<double> normal = vec_array(n), max_depth(n), depths({n, K});
        py::array_t<double> points_a({n, K, py::ssize_t{3}}), points_b({n, K, py::ssize_t{3}});
        py::array_t<std::uint32_t> feature_ids({n, K});
        py::array_t<std::uint8_t> status(n);
        std::int32_t* cnt = data_of(count);
        std::int32_t* ca = data_of(child_a);
        std::int32_t* cb = data_of(child_b);
        double* nr = data_of(normal);
        double* md = data_of(max_depth);
        double* dp = data_of(depths);
        double* qa = data_of(points_a);
        double* qb = data_of(points_b);
        std::uint32_t* fid = data_of(feature_ids);
        std::uint8_t* st = data_of(status);
        {
          py::gil_scoped_release release;
          std::vector<Manifold> all;
          for (py::ssize_t i = 0; i < n; ++i) {
            all.clear();
            const QueryStatus q = collide(a, pa[i], b, pb[i], all, s);
            const PyManifold best = pick_deepest(all, q);
            const Manifold& mf = best.m;
            cnt[i] = mf.count;
            ca[i] = mf.child_a;
            cb[i] = mf.child_b;
            st[i] = static_cast<std::uint8_t>(q);
            put(nr + 3 * i, mf.normal);
            md[i] = mf.max_depth();
            for (py::ssize_t k = 0; k < K; ++k) {
              // Unused slots are zero-filled; `count` says how many are valid.
              const bool used = k < mf.count;
              const ContactPoint& c = mf.points[k];
              put(qa + 3 * (K * i + k), used ? c.point_a : Vec3::Zero());
              put(qb + 3 * (K * i + k), used ? c.point_b : Vec3::Zero());
              dp[K * i + k] = used ? c.depth : 0.0;
              fid[K * i + k] = used ? c.feature_id : 0u;
            }
          }
        }
        py::dict out;
        out["count"] = count;
        out["normal"] = normal;
        out["max_depth"] = max_depth;
        out["points_a"] = points_a;
        out["points_b"] = points_b;
        out["depths"] = depths;
        out["feature_ids"] = feature_ids;
        out["child_a"] = child_a;
        out["child_b"] = child_b;
        out["status"] = status;
        return out;
      },
      py::arg("a"), py::arg("b"), py::arg("poses_a"), py::arg("poses_b"), py::kw_only(),
      py::arg("margin") = 0.0, py::arg("special") = true, py::arg("gjk_tolerance") = kGjk.tolerance,
      py::arg("gjk_max_iterations") = kGjk.max_iterations, py::arg("epa_tolerance") = kEpa.tolerance,
      py::arg("epa_max_iterations") = kEpa.max_iterations);

  g.def(
      "raycast_batch",
      [](const Shape& s, py::handle pose, py::handle origins, py::handle directions,
         Real max_distance) {
        // Shapes first (TypeError), then values (ValueError).
        // (N, 3) or (3,) (one origin / direction for every ray).
        bool one_o = false, one_d = false;
        RealArray o_arr = vec3_rows(origins, "origins", one_o);
        RealArray d_arr = vec3_rows(directions, "directions", one_d);
        const py::ssize_t no = one_o ? 1 : o_arr.shape(0), nd = one_d ? 1 : d_arr.shape(0);
        if (!one_o && !one_d && no != nd)
          throw py::type_error("directions must have shape (" + std::to_string(no) +
                               ", 3) to match origins, got (" + std::to_string(nd) + ", 3)");
        const py::ssize_t n = one_o ? nd : no;
        const Pose p = to_pose(pose, "pose");
        check_max_distance(max_distance);
        const double* o = o_arr.data();
        const double* d = d_arr.data();
        auto row = [](const double* base, bool one, py::ssize_t i) {
          const double* r = base + (one ? 0 : 3 * i);
          return Vec3(r[0], r[1], r[2]);
        };
        for (py::ssize_t i = 0; i < no; ++i) {
          const Vec3 v = row(o, false, i);
          if (!v.allFinite())
            throw InvalidArgument(row_name("origins", one_o, i) + " must be finite, got " +
                                  to_string(v));
        }
        for (py::ssize_t i = 0; i < nd; ++i)
          check_direction(row(d, false, i), row_name("directions", one_d, i));
        py::array_t<bool> hit(n);
        py::array_t<double> distance(n), point = vec_array(n), normal = vec_array(n);
        py::array_t<std::int32_t> child(n);
        py::array_t<std::uint8_t> status(n);
        bool* h = data_of(hit);
        double* dist = data_of(distance);
        double* pt = data_of(point);
        double* nr = data_of(normal);
        std::int32_t* ch = data_of(child);
        std::uint8_t* st = data_of(status);
        {
          py::gil_scoped_release release;
          for (py::ssize_t i = 0; i < n; ++i) {
            const RayHit r = raycast(s, p, row(o, one_o, i), row(d, one_d, i), max_distance);
            h[i] = r.hit;
            dist[i] = r.distance;
            put(pt + 3 * i, r.point);
            put(nr + 3 * i, r.normal);
            ch[i] = r.child;
            st[i] = static_cast<std::uint8_t>(r.status);
          }
        }
        py::dict out;
        out["hit"] = hit;
        out["distance"] = distance;
        out["point"] = point;
        out["normal"] = normal;
        out["child"] = child;
        out["status"] = status;
        return out;
      },
      py::arg("shape"), py::arg("pose"), py::arg("origins"), py::arg("directions"),
      py::arg("max_distance") = kInf);

  // ---- Time of impact ----
  py::class_<ToiResult>(m, "ToiResult", R"doc(
Result of time_of_impact (world frame).

Attributes:
    hit: True if the shapes come within `tolerance` of each other during the interval.
    time: seconds from the start: the first time found with distance <= tolerance (never
        later than the true first contact); `duration` on a miss.
    initially_overlapping: True if the shapes overlap at the start (time 0).
    distance: at `time` (on a miss: at the last time evaluated), metres; minus the
        penetration depth when overlapping.
    point_a, point_b: (3,) closest points on A and on B then.
    normal: (3,) unit vector from A to B then.
    status: 'ok'; 'unsupported' (no distance routine for the pair, or a spinning plane);
        'max_iterations' (the cap stopped the search: hit is True at the last safe time).
    iterations: distance evaluations made.
)doc")
      .def_readonly("hit", &ToiResult::hit)
      .def_readonly("time", &ToiResult::time)
      .def_readonly("initially_overlapping", &ToiResult::initially_overlapping)
      .def_readonly("distance", &ToiResult::distance)
      .def_property_readonly("point_a", [](const ToiResult& r) { return to_array(r.point_a); })
      .def_property_readonly("point_b", [](const ToiResult& r) { return to_array(r.point_b); })
      .def_property_readonly("normal", [](const ToiResult& r) { return to_array(r.normal); })
      .def_property_readonly("status", [](const ToiResult& r) { return std::string(status_name(r.status)); })
      .def_readonly("iterations", &ToiResult::iterations)
      .def("__bool__", [](const ToiResult& r) { return r.hit; })
      .def("__repr__", [](const ToiResult& r) {
        return "ToiResult(hit=" + std::string(r.hit ? "True" : "False") + ", time=" + repr_real(r.time) +
               ", distance=" + repr_real(r.distance) + ", normal=" + repr_vec(r.normal) + ", status='" +
               status_name(r.status) + "', iterations=" + std::to_string(r.iterations) + ")";
      });

  g.attr("TOI_TOLERANCE") = ToiSettings{}.tolerance;
  g.attr("TOI_MAX_ITERATIONS") = ToiSettings{}.max_iterations;

  g.def(
      "time_of_impact",
      [](const Shape& a, py::handle pa, const Shape& b, py::handle pb, py::handle va, py::handle wa,
         py::handle vb, py::handle wb, py::handle ca, py::handle cb, Real duration, Real tolerance,
         Real target_distance, int max_iterations, Real gjk_tol, int gjk_iter) {
        auto motion = [](py::handle pose, py::handle v, py::handle w, py::handle c, const char* side) {
          const std::string s(side);
          Motion mo;
          mo.start = to_pose(pose, "pose_" + s);
          mo.linear_velocity = to_vec3(v, "velocity_" + s);
          mo.angular_velocity = to_vec3(w, "angular_velocity_" + s);
          mo.center = to_vec3(c, "center_" + s);
          require_finite(("velocity_" + s).c_str(), mo.linear_velocity);
          require_finite(("angular_velocity_" + s).c_str(), mo.angular_velocity);
          require_finite(("center_" + s).c_str(), mo.center);
          return mo;
        };
        const Motion ma = motion(pa, va, wa, ca, "a");
        const Motion mb = motion(pb, vb, wb, cb, "b");
        ToiSettings st = make_toi(duration, tolerance, max_iterations, gjk_tol, gjk_iter);
        if (!std::isfinite(target_distance))
          throw InvalidArgument("target_distance must be finite, got " + repr_real(target_distance));
        st.target_distance = target_distance;
        return time_of_impact(a, ma, b, mb, duration, st);
      },
      py::arg("a"), py::arg("pose_a"), py::arg("b"), py::arg("pose_b"), py::kw_only(),
      py::arg("velocity_a"), py::arg("angular_velocity_a"), py::arg("velocity_b"),
      py::arg("angular_velocity_b"), py::arg("center_a"), py::arg("center_b"), py::arg("duration"),
      py::arg("tolerance"), py::arg("target_distance") = 0.0, py::arg("max_iterations"),
      py::arg("gjk_tolerance") = kGjk.tolerance,
      py::arg("gjk_max_iterations") = kGjk.max_iterations);

  g.def(
      "time_of_impact_batch",
      [](const Shape& a, const Shape& b, py::handle poses_a, py::handle poses_b, py::handle va,
         py::handle wa, py::handle vb, py::handle wb, Real duration, Real tolerance, int max_iterations,
         Real gjk_tol, int gjk_iter) {
        // Every shape first (TypeError), then every value (ValueError naming the row).
        const PairPoses poses = to_pair_poses(poses_a, poses_b);
        struct Rows {
          RealArray arr;
          bool one = false;
          const char* field;
        };
        auto parse = [](py::handle obj, const char* field) {
          Rows r{RealArray(), false, field};
          r.arr = vec3_rows(obj, field, r.one);
          return r;
        };
        Rows rows[4] = {parse(va, "velocities_a"), parse(wa, "angular_velocities_a"),
                        parse(vb, "velocities_b"), parse(wb, "angular_velocities_b")};
        // N from the array arguments; (7,) poses and (3,) rows broadcast.
        py::ssize_t n = poses.a.broadcast && poses.b.broadcast ? -1 : poses.n;
        const char* n_from = poses.a.broadcast ? "poses_b" : "poses_a";
        for (const Rows& r : rows) {
          if (r.one) continue;
          if (n < 0) {
            n = r.arr.shape(0);
            n_from = r.field;
          } else if (r.arr.shape(0) != n) {
            throw py::type_error(std::string(r.field) + " must have shape (" + std::to_string(n) +
                                 ", 3) or (3,) to match " + n_from + ", got (" +
                                 std::to_string(r.arr.shape(0)) + ", 3)");
          }
        }
        if (n < 0) n = 1;
        auto row = [](const Rows& r, py::ssize_t i) {
          const double* p = r.arr.data() + (r.one ? 0 : 3 * i);
          return Vec3(p[0], p[1], p[2]);
        };
        for (const Rows& r : rows)
          for (py::ssize_t i = 0; i < (r.one ? 1 : n); ++i)
            if (!row(r, i).allFinite())
              throw InvalidArgument(row_name(r.field, r.one, i) + " must be finite, got " +
                                    to_string(row(r, i)));
        const ToiSettings st = make_toi(duration, tolerance, max_iterations, gjk_tol, gjk_iter);
        py::array_t<bool> hit(n), overlapping(n);
        py::array_t<double> time(n), distance(n), point_a = vec_array(n), point_b = vec_array(n),
            normal = vec_array(n);
        py::array_t<std::uint8_t> status(n);
        py::array_t<std::int32_t> iterations(n);
        bool* h = data_of(hit);
        bool* ov = data_of(overlapping);
        double* tm = data_of(time);
        double* d = data_of(distance);
        double* qa = data_of(point_a);
        double* qb = data_of(point_b);
        double* nr = data_of(normal);
        std::uint8_t* stt = data_of(status);
        std::int32_t* it = data_of(iterations);
        {
          py::gil_scoped_release release;
          for (py::ssize_t i = 0; i < n; ++i) {
            Motion ma, mb;
            ma.start = poses.a[poses.a.broadcast ? 0 : i];
            mb.start = poses.b[poses.b.broadcast ? 0 : i];
            ma.linear_velocity = row(rows[0], i);
            ma.angular_velocity = row(rows[1], i);
            mb.linear_velocity = row(rows[2], i);
            mb.angular_velocity = row(rows[3], i);
            const ToiResult r = time_of_impact(a, ma, b, mb, duration, st);
            h[i] = r.hit;
            ov[i] = r.initially_overlapping;
            tm[i] = r.time;
            d[i] = r.distance;
            put(qa + 3 * i, r.point_a);
            put(qb + 3 * i, r.point_b);
            put(nr + 3 * i, r.normal);
            stt[i] = static_cast<std::uint8_t>(r.status);
            it[i] = r.iterations;
          }
        }
        py::dict out;
        out["hit"] = hit;
        out["time"] = time;
        out["initially_overlapping"] = overlapping;
        out["distance"] = distance;
        out["point_a"] = point_a;
        out["point_b"] = point_b;
        out["normal"] = normal;
        out["status"] = status;
        out["iterations"] = iterations;
        return out;
      },
      py::arg("a"), py::arg("b"), py::arg("poses_a"), py::arg("poses_b"), py::kw_only(),
      py::arg("velocities_a"), py::arg("angular_velocities_a"), py::arg("velocities_b"),
      py::arg("angular_velocities_b"), py::arg("duration"), py::arg("tolerance"),
      py::arg("max_iterations"), py::arg("gjk_tolerance") = kGjk.tolerance,
      py::arg("gjk_max_iterations") = kGjk.max_iterations);
}

}  // namespace wmo::bindings
