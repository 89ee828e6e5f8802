// Hull-hull contact manifold by the separating axis test on the half-edge structure
// (Gregorius, "The Separating Axis Test between Convex Polyhedra", GDC 2013, and
// "Robust Contact Creation for Physics Simulations", GDC 2015; Ericson 5.2.1).
//
//   * Face queries: for every face of A, the separation of B's support point along
//     -normal from the face plane; the same for B's faces against A.
//   * Edge queries: for every pair of edges, the cross product of their directions is
//     a candidate axis only if the two edges build a face of the Minkowski difference.
//     On the Gauss map (unit sphere of normals) an edge is the arc between its two
//     adjacent face normals; edge a of A and edge b of B build a Minkowski face iff
//     the arc of a and the arc of -b (B's normals negated) intersect. That test
//     (three sign checks on triple products) prunes most pairs before any separation is
//     computed, and guarantees the axis, oriented away from A's centroid, is the
//     outward normal of the Minkowski face, so the separation is simply
//     dot(n, p_b - p_a).
//   * The axis of largest separation wins, with the face bias of clip::sat_better
//     (clip.h): A's faces, then B's, then edges, a later kind only if clearly better.
//     Any separation above the margin ends the test: no contact.
//   * Face axis: the chosen face is the reference face, the other hull's face most
//     anti-parallel to it the incident face; the incident face is clipped against the
//     reference face's side planes, points with depth >= -margin are kept and reduced
//     to at most 4 (reduce_to_4), with the other hull's support point added where
//     the clip lost the deepest point (clip::kDeepestPointTolerance). Edge axis: one
//     point, the closest points of the two edges.
//
// Feature ids: clip::face_contact_id / clip::edge_contact_id (clip.h) with hull face
// indices (faces()) and edge indices (edges()).
//
// Cost: O(F_A V_B + F_B V_A) for the face queries (less with hill-climbing support) and
// O(E_A E_B) cheap Gauss-map tests. No allocation; ConvexHull is final, so its calls
// are direct.

#include <cmath>

#include "clip.h"
#include "manifold_reduce.h"
#include "wmo/collision/narrowphase.h"

namespace wmo {
namespace {

/// Edge pairs with |e_a x e_b| below this times |e_a| |e_b| (sine of the angle between
/// them, 1e-6 rad) are parallel: their cross product's direction is round-off, and a
/// separating axis through them is, within that angle, a face axis already tested.
constexpr Real kParallelSin = 1e-6;

/// Do the Gauss-map arcs (a, b) and (c, d) intersect? a, b: unit normals of the two
/// faces adjacent to an edge of A; c, d: the negated normals of the faces adjacent to
/// an edge of B; bxa = b x a, dxc = d x c (normals of the planes of the arcs).
/// Gregorius 2013: c and d on opposite sides of the plane of arc ab, a and b on
/// opposite sides of the plane of arc cd, and both arcs in the same hemisphere.
inline bool is_minkowski_face(const Vec3& a, const Vec3& b, const Vec3& bxa, const Vec3& c,
                              const Vec3& d, const Vec3& dxc) {
  const Real cba = c.dot(bxa), dba = d.dot(bxa);
  const Real adc = a.dot(dxc), bdc = b.dot(dxc);
  return cba * dba < 0 && adc * bdc < 0 && cba * bdc > 0;
}

/// Vertices of face f of hull h, moved by `pose` (A's frame), at most
/// kMaxFaceVertices of them spread evenly along the loop (as ConvexHull::supporting_face
/// does: a subset in loop order of a convex polygon is a convex polygon inside it).
inline int face_polygon(const ConvexHull& h, int f, const Pose* pose, Vec3* out) {
  const ConvexHull::Face& fc = h.faces()[f];
  const int m = fc.vertex_count;
  const int count = std::min(m, kMaxFaceVertices);
  int e = fc.first_edge;
  int k = 0;
  for (int idx = 0; idx < m && k < count; ++idx, e = h.half_edges()[e].next) {
    if (idx == static_cast<int>(static_cast<long long>(k) * m / count)) {
      const Vec3& v = h.vertices()[h.half_edges()[e].origin];
      out[k++] = pose ? pose->transform_point(v) : v;
    }
  }
  return k;
}

enum class AxisKind { kFaceA, kFaceB, kEdge };

}  // namespace

bool collide_hull_hull(const ConvexHull& a, const ConvexHull& b, const Pose& b_in_a, Real margin,
                       Manifold& m) {
  const Mat3 R = b_in_a.matrix();
  const Pose a_in_b = b_in_a.inverse();
  const Real reach = a.radius() + b.radius() + margin;  // hulls have no radius today
  const Real size = std::max(a.local_aabb().half_extents().maxCoeff(),
                             b.local_aabb().half_extents().maxCoeff());
  const auto& fa = a.faces();
  const auto& fb = b.faces();

  // ---- Face queries of A.
  Real sep_a = -kInf;
  int face_a = 0;
  for (int f = 0; f < static_cast<int>(fa.size()); ++f) {
    const Vec3 p = b_in_a.transform_point(b.support_core(R.transpose() * -fa[f].normal));
    const Real s = fa[f].normal.dot(p) - fa[f].offset;
    if (s > reach) return false;
    if (s > sep_a) {
      sep_a = s;
      face_a = f;
    }
  }
  // ---- Face queries of B (in B's frame).
  Real sep_b = -kInf;
  int face_b = 0;
  for (int g = 0; g < static_cast<int>(fb.size()); ++g) {
    const Vec3 q = a_in_b.transform_point(a.support_core(R * -fb[g].normal));
    const Real s = fb[g].normal.dot(q) - fb[g].offset;
    if (s > reach) return false;
    if (s > sep_b) {
      sep_b = s;
      face_b = g;
    }
  }
  // ---- Edge queries with Gauss-map pruning, in A's frame. Outer loop over B's edges
  // so each is transformed once.
  Vec3 centroid_a = Vec3::Zero();
  for (const Vec3& v : a.vertices()) centroid_a += v;
  centroid_a /= static_cast<Real>(a.vertices().size());
  const auto& ha = a.half_edges();
  const auto& hb = b.half_edges();
  Real sep_e = -kInf;
  int edge_a = -1, edge_b = -1;
  Vec3 n_e = Vec3::UnitX();
  for (int jb = 0; jb < static_cast<int>(b.edges().size()); ++jb) {
    const ConvexHull::HalfEdge& eb = hb[b.edges()[jb]];
    const Vec3 q0 = b_in_a.transform_point(b.vertices()[eb.origin]);
    const Vec3 q1 = b_in_a.transform_point(b.vertices()[hb[eb.next].origin]);
    const Vec3 c = -(R * fb[eb.face].normal);
    const Vec3 d = -(R * fb[hb[eb.twin].face].normal);
    const Vec3 dxc = d.cross(c);
    const Vec3 e2 = q1 - q0;
    for (int ia = 0; ia < static_cast<int>(a.edges().size()); ++ia) {
      const ConvexHull::HalfEdge& ea = ha[a.edges()[ia]];
      const Vec3& na = fa[ea.face].normal;
      const Vec3& nb = fa[ha[ea.twin].face].normal;
      const Vec3 bxa = nb.cross(na);
      if (!is_minkowski_face(na, nb, bxa, c, d, dxc)) continue;
      const Vec3& p0 = a.vertices()[ea.origin];
      const Vec3 e1 = a.vertices()[ha[ea.next].origin] - p0;
      Vec3 n = e1.cross(e2);
      const Real len = n.norm();
      if (!(len > kParallelSin * std::sqrt(e1.squaredNorm() * e2.squaredNorm()))) continue;
      n /= len;
      if (n.dot(p0 - centroid_a) < 0) n = -n;
      const Real s = n.dot(q0 - p0);
      if (s > reach) return false;
      if (s > sep_e) {
        sep_e = s;
        edge_a = ia;
        edge_b = jb;
        n_e = n;
      }
    }
  }

  AxisKind kind = AxisKind::kFaceA;
  Real best = sep_a;
  if (clip::sat_better(sep_b, best, size)) {
    kind = AxisKind::kFaceB;
    best = sep_b;
  }
  if (edge_a >= 0 && clip::sat_better(sep_e, best, size)) kind = AxisKind::kEdge;

  if (kind == AxisKind::kEdge) {
    const ConvexHull::HalfEdge& ea = ha[a.edges()[edge_a]];
    const ConvexHull::HalfEdge& eb = hb[b.edges()[edge_b]];
    Vec3 pa, pb;
    clip::closest_points_segments(a.vertices()[ea.origin], a.vertices()[ha[ea.next].origin],
                                  b_in_a.transform_point(b.vertices()[eb.origin]),
                                  b_in_a.transform_point(b.vertices()[hb[eb.next].origin]), pa, pb);
    const Real depth = n_e.dot(pa - pb);
    if (!(depth >= -margin)) return false;
    m.normal = n_e;
    m.count = 0;
    m.add(pa, pa - depth * n_e, depth, clip::edge_contact_id(edge_a, edge_b));
    return true;
  }

  const bool ref_on_a = kind == AxisKind::kFaceA;
  Vec3 N;
  Vec3 ref[kMaxFaceVertices], inc[kMaxFaceVertices];
  int nr, ni, ref_face, inc_face;
  if (ref_on_a) {
    N = fa[face_a].normal;
    ref_face = face_a;
    nr = face_polygon(a, face_a, nullptr, ref);
    // Incident face of B: most anti-parallel to N (B's frame: most aligned with -N).
    const Vec3 nb_dir = R.transpose() * -N;
    inc_face = 0;
    Real best_dot = -kInf;
    for (int g = 0; g < static_cast<int>(fb.size()); ++g) {
      const Real dd = fb[g].normal.dot(nb_dir);
      if (dd > best_dot) {
        best_dot = dd;
        inc_face = g;
      }
    }
    ni = face_polygon(b, inc_face, &b_in_a, inc);
  } else {
    N = -(R * fb[face_b].normal);
    ref_face = face_b;
    nr = face_polygon(b, face_b, &b_in_a, ref);
    inc_face = 0;
    Real best_dot = -kInf;
    for (int f = 0; f < static_cast<int>(fa.size()); ++f) {
      const Real dd = fa[f].normal.dot(N);
      if (dd > best_dot) {
        best_dot = dd;
        inc_face = f;
      }
    }
    ni = face_polygon(a, inc_face, nullptr, inc);
  }
  const std::uint32_t id_base = clip::face_contact_id(!ref_on_a, ref_face, inc_face);
  ContactPoint pts[clip::kMaxClipVertices + 1];
  int n = clip::clip_features(ref, nr, ref_on_a, inc, ni, N, 0, 0, margin, id_base, pts);
  // The deepest point, if the clip lost it (clip::kDeepestPointTolerance).
  Real max_clip = -kInf;
  for (int k = 0; k < n; ++k) max_clip = std::max(max_clip, pts[k].depth);
  const Real sat_depth = -best;
  if (sat_depth >= -margin && max_clip < sat_depth - clip::kDeepestPointTolerance * size) {
    const Vec3 pa = ref_on_a ? Vec3(b_in_a.transform_point(b.support_core(R.transpose() * -N)) + sat_depth * N)
                             : a.support_core(N);
    if (n == 0 || clip::in_prism(pa, ref, nr, N))
      pts[n++] = ContactPoint{pa, pa - sat_depth * N, sat_depth, id_base | clip::kFallbackLabel};
  }
  if (n == 0) return false;
  m.normal = N;
  reduce_to_4(pts, n, N, m);
  return true;
}

}  // namespace wmo
