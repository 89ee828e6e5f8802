// collide(): the narrowphase dispatcher.
//
// A [ShapeType][ShapeType] table of function pointers (Box2D's b2_registers, parry's
// dispatcher) picks the routine for a pair. Each entry takes world poses, runs an
// A-frame routine on B's pose relative to A, and appends world-space manifolds:
//   * special routines (collide_sphere_box, ...) where one exists for (A, B);
//   * the mirrored special routine, run as (B, A) and flipped, where only that exists
//     (box-sphere, convex-plane, ...): points a/b swapped, normal negated, child_a and
//     child_b swapped. Feature ids are kept as the routine made them: they stay stable
//     per feature pair, which is all the solver needs;
//   * collide_convex_convex (GJK/EPA + clipping) for the other convex pairs;
//   * collide_mesh_convex for mesh-convex (and mirrored for convex-mesh);
//   * a loop over the children for a compound (child index in child_a / child_b);
//   * kUnsupported, appending nothing, for plane-plane, mesh-mesh, mesh-plane and
//     plane-mesh: none of them can move, and no routine exists.
// With CollideSettings::use_special_routines = false a second table sends every convex
// pair, sphere-sphere and box-box included, to collide_convex_convex. Plane-convex
// stays on collide_plane_convex there: a plane is not a ConvexShape (it has no support
// point), so the generic path cannot take it.
//
// The table is built at compile time; a call costs one indexed load and one indirect
// call, and the special routines themselves make no virtual call and allocate nothing
// (only the caller's `out` vector may grow).

#include <array>
#include <cstddef>

#include "wmo/collision/narrowphase.h"

namespace wmo {
namespace {

constexpr int kTypes = static_cast<int>(ShapeType::kCount);

using PairFn = QueryStatus (*)(const Shape& a, const Pose& pose_a, const Shape& b,
                               const Pose& pose_b, const CollideSettings& settings,
                               std::vector<Manifold>& out);

/// Pose of B in A's frame from world poses. Subtracting the positions before rotating
/// (rather than composing with A's inverse) keeps the full precision of the difference
/// for shapes far from the origin: q^-1 * (p_b - p_a) has one rounding of the small
/// difference, while -(q^-1 p_a) + q^-1 p_b cancels two large terms.
inline Pose relative_pose(const Pose& pose_a, const Pose& pose_b) {
  const Quat qi = pose_a.rotation.conjugate();
  return Pose(qi * (pose_b.position - pose_a.position), qi * pose_b.rotation);
}

/// Manifold from `frame`'s local coordinates to its parent (world) coordinates.
inline void to_parent(Manifold& m, const Pose& frame) {
  // One matrix for up to nine rotated vectors (a matrix product each, where a
  // quaternion rotation costs twice that).
  const Mat3 r = frame.rotation.toRotationMatrix();
  m.normal = r * m.normal;
  for (int i = 0; i < m.count; ++i) {
    m.points[i].point_a = r * m.points[i].point_a + frame.position;
    m.points[i].point_b = r * m.points[i].point_b + frame.position;
  }
}

/// A manifold of (B, A) turned into one of (A, B): depths are symmetric, so only the
/// roles and the normal change.
inline void flip(Manifold& m) {
  m.normal = -m.normal;
  for (int i = 0; i < m.count; ++i) std::swap(m.points[i].point_a, m.points[i].point_b);
  std::swap(m.child_a, m.child_b);
}

template <class SA, class SB>
using SpecialFn = bool (*)(const SA&, const SB&, const Pose&, Real, Manifold&);

/// The SAT-based routines (capsule-box, hull-hull) measure a separated pair
/// along their best separating axis, which is only a lower bound on the distance, and
/// clipping may then report a gap that is too large or too small. A pair that is
/// separated but within the margin (every point's depth < 0) is therefore handed to the
/// generic path, whose GJK distance is exact, so speculative contacts carry the true
/// gap. Overlapping pairs, the common case in a resting pile, stay on SAT.
///
/// Box-box decides this itself (collide_box_box: exact for separated face contacts,
/// which are most of a resting pile's speculative pairs, generic otherwise).
template <bool kExactSpeculative, class SA, class SB>
bool refine_separated(const SA& a, const SB& b, const Pose& b_in_a,
                      const CollideSettings& settings, Manifold& m) {
  if constexpr (kExactSpeculative) {
    if (m.max_depth() < 0) {
      m = Manifold{};
      return collide_convex_convex(a, b, b_in_a, settings, m);
    }
  }
  return true;
}

/// Special routine for (SA, SB) called as is.
template <class SA, class SB, SpecialFn<SA, SB> Fn, bool kExactSpeculative = false>
QueryStatus special(const Shape& a, const Pose& pose_a, const Shape& b, const Pose& pose_b,
                    const CollideSettings& settings, std::vector<Manifold>& out) {
  Manifold m;
  const Pose b_in_a = relative_pose(pose_a, pose_b);
  const auto& sa = static_cast<const SA&>(a);
  const auto& sb = static_cast<const SB&>(b);
  if (Fn(sa, sb, b_in_a, settings.margin, m) &&
      refine_separated<kExactSpeculative>(sa, sb, b_in_a, settings, m)) {
    to_parent(m, pose_a);
    out.push_back(m);
  }
  return QueryStatus::kOk;
}

/// Special routine for (SA, SB) used for the pair (SB, SA): run in B's frame, flipped.
template <class SA, class SB, SpecialFn<SA, SB> Fn, bool kExactSpeculative = false>
QueryStatus special_swapped(const Shape& a, const Pose& pose_a, const Shape& b,
                            const Pose& pose_b, const CollideSettings& settings,
                            std::vector<Manifold>& out) {
  Manifold m;
  const Pose a_in_b = relative_pose(pose_b, pose_a);
  const auto& sb = static_cast<const SA&>(b);
  const auto& sa = static_cast<const SB&>(a);
  if (Fn(sb, sa, a_in_b, settings.margin, m) &&
      refine_separated<kExactSpeculative>(sb, sa, a_in_b, settings, m)) {
    to_parent(m, pose_b);
    flip(m);
    out.push_back(m);
  }
  return QueryStatus::kOk;
}

QueryStatus convex_convex(const Shape& a, const Pose& pose_a, const Shape& b, const Pose& pose_b,
                          const CollideSettings& settings, std::vector<Manifold>& out) {
  Manifold m;
  QueryStatus status = QueryStatus::kOk;
  if (collide_convex_convex(static_cast<const ConvexShape&>(a),
                            static_cast<const ConvexShape&>(b), relative_pose(pose_a, pose_b),
                            settings, m, &status)) {
    to_parent(m, pose_a);
    out.push_back(m);
  }
  return status;
}

QueryStatus mesh_convex(const Shape& a, const Pose& pose_a, const Shape& b, const Pose& pose_b,
                        const CollideSettings& settings, std::vector<Manifold>& out) {
  const std::size_t first = out.size();
  collide_mesh_convex(static_cast<const TriangleMesh&>(a), static_cast<const ConvexShape&>(b),
                      relative_pose(pose_a, pose_b), settings, out);
  for (std::size_t i = first; i < out.size(); ++i) to_parent(out[i], pose_a);
  return QueryStatus::kOk;
}

QueryStatus convex_mesh(const Shape& a, const Pose& pose_a, const Shape& b, const Pose& pose_b,
                        const CollideSettings& settings, std::vector<Manifold>& out) {
  const std::size_t first = out.size();
  collide_mesh_convex(static_cast<const TriangleMesh&>(b), static_cast<const ConvexShape&>(a),
                      relative_pose(pose_b, pose_a), settings, out);
  for (std::size_t i = first; i < out.size(); ++i) {
    to_parent(out[i], pose_b);
    flip(out[i]);
  }
  return QueryStatus::kOk;
}

/// Worse of two statuses for a composite query: any unsupported or iteration-capped
/// child marks the whole answer.
inline QueryStatus worse(QueryStatus s, QueryStatus t) {
  return static_cast<int>(t) > static_cast<int>(s) ? t : s;
}

/// Compound A: each child against B, skipping children whose bounding box (fattened by
/// the margin) misses B's. The children are convex, so each call is a plain pair.
QueryStatus compound_any(const Shape& a, const Pose& pose_a, const Shape& b, const Pose& pose_b,
                         const CollideSettings& settings, std::vector<Manifold>& out) {
  const auto& children = static_cast<const Compound&>(a).children();
  const Aabb box_b = b.world_aabb(pose_b).fattened(settings.margin);
  QueryStatus status = QueryStatus::kOk;
  for (std::size_t i = 0; i < children.size(); ++i) {
    const Pose pose_child = pose_a * children[i].pose;
    if (!children[i].shape->world_aabb(pose_child).overlaps(box_b)) continue;
    const std::size_t first = out.size();
    status = worse(status, collide(*children[i].shape, pose_child, b, pose_b, out, settings));
    for (std::size_t k = first; k < out.size(); ++k) out[k].child_a = static_cast<std::int32_t>(i);
  }
  return status;
}

/// Compound B (A is not a compound): mirror of compound_any.
QueryStatus any_compound(const Shape& a, const Pose& pose_a, const Shape& b, const Pose& pose_b,
                         const CollideSettings& settings, std::vector<Manifold>& out) {
  const auto& children = static_cast<const Compound&>(b).children();
  const Aabb box_a = a.world_aabb(pose_a).fattened(settings.margin);
  QueryStatus status = QueryStatus::kOk;
  for (std::size_t i = 0; i < children.size(); ++i) {
    const Pose pose_child = pose_b * children[i].pose;
    if (!children[i].shape->world_aabb(pose_child).overlaps(box_a)) continue;
    const std::size_t first = out.size();
    status = worse(status, collide(a, pose_a, *children[i].shape, pose_child, out, settings));
    for (std::size_t k = first; k < out.size(); ++k) out[k].child_b = static_cast<std::int32_t>(i);
  }
  return status;
}

QueryStatus unsupported(const Shape&, const Pose&, const Shape&, const Pose&,
                        const CollideSettings&, std::vector<Manifold>&) {
  return QueryStatus::kUnsupported;
}

constexpr int idx(ShapeType t) { return static_cast<int>(t); }

constexpr bool is_convex_type(int t) { return t <= idx(ShapeType::kConvexHull); }

using Table = std::array<std::array<PairFn, kTypes>, kTypes>;

/// The dispatch table; `special_routines` selects the fast routines for convex pairs.
constexpr Table make_table(bool special_routines) {
  Table t{};
  constexpr int S = idx(ShapeType::kSphere), B = idx(ShapeType::kBox),
                C = idx(ShapeType::kCapsule), H = idx(ShapeType::kConvexHull),
                M = idx(ShapeType::kTriangleMesh), P = idx(ShapeType::kPlane),
                K = idx(ShapeType::kCompound);
  for (int i = 0; i < kTypes; ++i) {
    for (int j = 0; j < kTypes; ++j) {
      PairFn f = &unsupported;
      if (i == K) f = &compound_any;
      else if (j == K) f = &any_compound;
      else if (is_convex_type(i) && is_convex_type(j)) f = &convex_convex;
      else if (i == M && is_convex_type(j)) f = &mesh_convex;
      else if (is_convex_type(i) && j == M) f = &convex_mesh;
      else if (i == P && is_convex_type(j))
        f = &special<Plane, ConvexShape, collide_plane_convex>;
      else if (is_convex_type(i) && j == P)
        f = &special_swapped<Plane, ConvexShape, collide_plane_convex>;
      t[i][j] = f;
    }
  }
  if (special_routines) {
    t[S][S] = &special<Sphere, Sphere, collide_sphere_sphere>;
    t[S][B] = &special<Sphere, Box, collide_sphere_box>;
    t[B][S] = &special_swapped<Sphere, Box, collide_sphere_box>;
    t[S][C] = &special<Sphere, Capsule, collide_sphere_capsule>;
    t[C][S] = &special_swapped<Sphere, Capsule, collide_sphere_capsule>;
    t[C][C] = &special<Capsule, Capsule, collide_capsule_capsule>;
    t[C][B] = &special<Capsule, Box, collide_capsule_box, true>;
    t[B][C] = &special_swapped<Capsule, Box, collide_capsule_box, true>;
    t[B][B] = &special<Box, Box, collide_box_box>;
    t[H][H] = &special<ConvexHull, ConvexHull, collide_hull_hull, true>;
  }
  return t;
}

constexpr Table kSpecialTable = make_table(true);
constexpr Table kGenericTable = make_table(false);

inline bool valid_type(ShapeType t) { return idx(t) >= 0 && idx(t) < kTypes; }

}  // namespace

QueryStatus collide(const Shape& a, const Pose& pose_a, const Shape& b, const Pose& pose_b,
                    std::vector<Manifold>& out, const CollideSettings& settings) {
  if (!valid_type(a.type()) || !valid_type(b.type())) return QueryStatus::kUnsupported;
  const Table& table = settings.use_special_routines ? kSpecialTable : kGenericTable;
  return table[idx(a.type())][idx(b.type())](a, pose_a, b, pose_b, settings, out);
}

bool collide_supported(ShapeType a, ShapeType b) {
  if (!valid_type(a) || !valid_type(b)) return false;
  return kSpecialTable[idx(a)][idx(b)] != &unsupported;
}

}  // namespace wmo
