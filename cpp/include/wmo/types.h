// WMO query result types and THE convention, stated once.
//
// Convention for every pair query (collide, distance, closest points, penetration,
// time of impact):
//   * Low-level pair routines `<operation>_<shape>_<shape>(a, b, b_in_a, ...)` take the
//     pose of B expressed in A's frame and return every point and normal in A's frame.
//     Working relative to A keeps coordinates small, so shapes 10 km from the origin
//     still resolve 0.1 mm.
//   * Top-level queries (`wmo::collide(a, pose_a, b, pose_b)` and friends, and the
//     Python API) take world poses and return world-space results.
//   * The contact normal is a unit vector pointing from A to B: moving B by
//     `depth * normal` separates the pair.
//   * `depth` is positive when the shapes overlap and negative when they are apart
//     (speculative contacts within a margin).
//   * `point_a` lies on the surface of A, `point_b` on the surface of B; for an
//     overlapping pair point_b = point_a - depth * normal.
#pragma once

#include <array>
#include <cstdint>
#include <vector>

#include "wmo/math.h"

namespace wmo {

/// Outcome of a query.
enum class QueryStatus : std::uint8_t {
  kOk = 0,             ///< the answer is valid
  kUnsupported = 1,    ///< no routine exists for this shape pair: nothing was computed
  kMaxIterations = 2,  ///< an iterative method hit its cap; the answer is the best so far
  kDegenerate = 3,     ///< the input was degenerate; the answer is a safe fallback
};

const char* to_string(QueryStatus s);

/// Tolerances and caps for GJK (van den Bergen 2001/2003).
struct GjkSettings {
  /// Relative termination tolerance: stop when the lower and upper bounds on the
  /// squared distance agree within `tolerance * |v|^2` (van den Bergen's eps_rel).
  /// 1e-10 is close to double precision's useful limit for this test; 1e-6 is enough for
  /// contact generation.
  Real tolerance = 1e-10;
  /// Iteration cap. GJK converges in a handful of iterations on polytopes; curved
  /// shapes converge linearly, so the cap only guards against cycling.
  int max_iterations = 128;
};

/// Tolerances and caps for EPA (van den Bergen 2001, "Proximity queries and
/// penetration depth computation on 3D game objects").
struct EpaSettings {
  /// Stop when the support distance along the closest face normal exceeds the face
  /// distance by less than `tolerance * face distance` (relative) ...
  Real tolerance = 1e-10;
  /// ... or by less than this absolute bound (metres), for near-zero depths.
  Real absolute_tolerance = 1e-12;
  /// Iteration cap (one support point each). EPA converges in a few dozen iterations
  /// on polytopes; on curved cores it needs more: a capsule through a cylinder whose
  /// axis is 0.45 degrees off the capsule's converges in 148 (the old cap, 128, stopped
  /// it 8e-5 m short). 256, as Bullet's 255; a query that reaches it still answers
  /// with a valid upper bound (EpaResult).
  int max_iterations = 256;
  /// Cap on the polytope size; EPA stops (kMaxIterations) rather than grow further.
  /// Each iteration adds about two faces net, so 1024 leaves room for max_iterations.
  int max_faces = 1024;
};

/// One contact point of a manifold. All vectors in the frame stated by the query.
struct ContactPoint {
  Vec3 point_a = Vec3::Zero();  ///< on the surface of A
  Vec3 point_b = Vec3::Zero();  ///< on the surface of B
  Real depth = 0;               ///< > 0 overlapping, < 0 separated (speculative)
  /// Persistent feature id: stays the same while the same pair of features (face,
  /// edge or vertex of A and of B) generates this point, so the solver can match
  /// points across steps for warm starting. 0 is a valid id.
  std::uint32_t feature_id = 0;
};

constexpr int kMaxManifoldPoints = 4;

/// A contact manifold: up to 4 points sharing one normal (from A to B).
struct Manifold {
  Vec3 normal = Vec3::UnitZ();
  int count = 0;
  std::array<ContactPoint, kMaxManifoldPoints> points{};
  /// For composite shapes (triangle mesh, compound): which child of A / of B produced
  /// this manifold (triangle index or compound child index), -1 for a plain shape.
  std::int32_t child_a = -1;
  std::int32_t child_b = -1;

  void add(const Vec3& pa, const Vec3& pb, Real depth, std::uint32_t id) {
    if (count < kMaxManifoldPoints) points[count++] = ContactPoint{pa, pb, depth, id};
  }
  Real max_depth() const {
    Real d = -kInf;
    for (int i = 0; i < count; ++i) d = std::max(d, points[i].depth);
    return d;
  }
};

/// Result of a distance / closest-points query.
struct DistanceResult {
  QueryStatus status = QueryStatus::kOk;
  /// Signed distance: >= 0 when apart; when the shapes overlap, 0 from a plain distance
  /// query, or minus the penetration depth from closest_points / penetration.
  Real distance = 0;
  bool intersecting = false;
  Vec3 point_a = Vec3::Zero();  ///< closest (or deepest) point on A
  Vec3 point_b = Vec3::Zero();  ///< closest (or deepest) point on B
  /// Unit vector from A to B (the separating direction, or the penetration normal).
  /// Zero when it is undefined (touching at a single point with no overlap info).
  Vec3 normal = Vec3::Zero();
  int iterations = 0;
};

/// Result of a ray cast.
struct RayHit {
  bool hit = false;
  Real distance = 0;        ///< along the ray, in units of the ray direction's length (metres for a unit direction)
  Vec3 point = Vec3::Zero();
  Vec3 normal = Vec3::Zero();  ///< outward surface normal at the hit
  std::int32_t child = -1;     ///< triangle / child index for composite shapes
  QueryStatus status = QueryStatus::kOk;
};

}  // namespace wmo
