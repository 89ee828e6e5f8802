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
// Separation: a ball around each vertex centroid (ConvexHull::outer_radius) settles far
// pairs first, in a few flops. Then the SAT decides: any face or edge axis separating
// the hulls by more than the margin ends it (no contact), so for margin 0 the verdict
// is the SAT's own (exact, up to round-off at touching). For margin > 0, a pair that no
// axis proves penetrating may still be farther apart than the margin with every axis
// separating it by less (corner against corner); GJK (gjk_distance with cull = margin,
// whose lower bound v.w / |v| proves a distance) then decides, and a pair farther
// apart has no speculative points, as CollideSettings::margin says. Penetrating pairs
// never pay for GJK. (Until this version GJK ran first on every pair not settled by
// the balls, to prove separated pairs apart before the SAT; once the edge queries
// became cheap (edge_bound) that cost the overlapping pairs more, ~0.5 us a call out
// of cache, than it saved the separated ones, 0.1-0.2 us.)
//
// Feature ids: clip::face_contact_id / clip::edge_contact_id (clip.h) with hull face
// indices (faces()) and edge indices (edges()).
//
// Cost: O(F_A V_B + F_B V_A) for the face queries (less with hill-climbing support),
// then for each edge of B, unless a bound rules it out (edge_bound: its axes cannot
// beat the best face axis), a walk over A's Gauss map along its arc (see the edge
// queries): Gauss-map tests on the edges around the few vertices of A it passes,
// instead of on all E_A edges (brute force only for degenerate arcs). Scratch
// arrays live in a per-thread workspace that keeps its capacity (no allocation once
// warm); ConvexHull is final, so its calls are direct. For hulls up to 32 vertices
// the support searches run on coordinate arrays (detail::support_index_soa, vectorised,
// the same vertex as ConvexHull::support_index), A's face queries skip faces whose
// cheap upper bound cannot win (exact pruning, kPruneSlack), B's skip the transform of
// the support point likewise. The edge records, the rings of edges around each vertex
// and the vertex centroid are the hull's own (ConvexHull::edge_arcs, vertex_edges,
// vertex_centroid, built once at construction). All the pruning is exact: the results
// are bit-identical to the unpruned test.
//
// Measured on the narrowphase benchmark's hull_hull pairs (20-vertex hulls, 4000
// configurations, a different pair of hulls every call, out of cache;
// `WMO_BENCH_METHODS=wmo_special,fcl,libccd_mpr bench_narrowphase out 4000 hull_hull`,
// 8 runs): 6.6 us a query before the changes below, 2.0-2.3 us after (FCL, whose
// libccd MPR depth is off by up to 0.3 m here, 1.6-2.2 us; 1.03-1.10x in four runs,
// 1.10-1.38x in four later ones on a busier machine, 2.2-2.4 us against 1.6-2.1).
// Deep overlaps went from 12.0 to ~2.8 us, far pairs from 0.24 to 0.09
// (WMO_BENCH_BY_CLASS=1). In cache (200 configurations) it is level with FCL,
// 0.89-1.05x: the rest of the loss is the ~120 lines of hull data a pair reads (see
// touch_hull), where MPR reads the two vertex arrays. What did it: the
// edge bound (Gauss-map tests 139 -> 5 a deep call, no square root for edge axes below
// the bar), the vectorised support searches, GJK only where the margin needs it, the
// centroid balls, touch_hull, and (2026-12-07) the hull's arrays packed into one block
// (ConvexHull's storage): 3.7 -> 3.1 us a query, the median of 9 runs each interleaved
// with the build before (spread 3.1-4.7 -> 2.5-3.7), against FCL 1.10x -> 1.01x
// (1.00-1.31 -> 0.76-1.15). Tried and dropped (no gain or slower, measured): a
// branch-free edge pre-pass and face candidate lists, the face with the best centroid
// bound first, a third point in A's face bound, centroid-bound pruning of B's faces
// and edges before their support searches, a per-face vertex list instead of the
// half-edges for clipping, a GJK iteration cap.

#include <cmath>
#include <vector>

#include "clip.h"
#include "manifold_reduce.h"
#include "wmo/collision/narrowphase.h"
#include "wmo/geometry/gjk.h"
#include "wmo/geometry/support_soa.h"

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

/// Upper bound on the separation along every axis an edge of B can form with edges of
/// A (A's frame). The edge runs through q0; c, d are the negated outward normals of its
/// two faces; sep_c, sep_d those faces' separations; p_c, p_d A's support vertices along
/// c and d. The edge's candidate axes are the unit vectors n on the arc from c to d, and
/// for each, B's support along -n lies on the edge, so the separation is
/// n.q0 - h_A(n) with h_A A's support function. Along m(t) = (1 - t) c + t d, t in
/// [0, 1], S(t) = m.q0 - h_A(m) is concave (h_A is convex) with S(0) = sep_c,
/// S(1) = sep_d, and its slopes at the ends are at most (d - c).(q0 - p_c) and
/// (c - d).(q0 - p_d) (p_c lies in A's support set along c, so the directional derivative
/// of h_A there is at least p_c.(d - c)). A concave function lies below its tangents, so
/// S(t) <= min(sep_c + t k0, sep_d + (1 - t) k1), whose largest value on [0, 1] is at an
/// end or where the two lines cross. The separation is S(t) / |m(t)| with
/// |m(t)| in [sqrt((1 + c.d) / 2), 1]: a positive bound is divided by that. Exact up
/// to round-off (the caller subtracts kPruneSlack * its scale); +inf when the faces are
/// back to back within round-off (c.d near -1).
inline Real edge_bound(Real sep_c, Real sep_d, const Vec3& c, const Vec3& d, const Vec3& q0,
                       const Vec3& p_c, const Vec3& p_d) {
  const Vec3 dc = d - c;
  const Real k0 = dc.dot(q0 - p_c);
  const Real k1 = -dc.dot(q0 - p_d);
  // f1(t) = sep_c + t k0, f2(t) = sep_d + (1 - t) k1.
  Real m = std::max(std::min(sep_c, sep_d + k1), std::min(sep_c + k0, sep_d));
  // min(f1, f2) is concave: its maximum is at an end or at the crossing t* of the
  // lines, f1(t*) = f2(t*), where f1 - f2 = gap + t slope vanishes.
  const Real slope = k0 + k1;
  const Real gap = sep_c - sep_d - k1;
  if (slope != 0) {
    const Real t_star = -gap / slope;
    if (t_star > 0 && t_star < 1) m = std::max(m, sep_c + t_star * k0);
  }
  if (m <= 0) return m;
  const Real h = 0.5 * (1 + c.dot(d));
  return h > 1e-12 ? m / std::sqrt(h) : kInf;
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

/// Slack of the face-query pruning bound, relative to the scene's size (hull size plus
/// the distance between the origins): the bound and the separation it bounds are
/// computed along different paths (A's frame vs B's frame, centroid vs vertex) and may
/// differ by round-off, a few DBL_EPSILON (2.2e-16) times that size; 1e-9 is ~10^6
/// times more, so a face is only skipped when it provably cannot win, and it costs
/// nothing measurable in pruning power.
constexpr Real kPruneSlack = 1e-9;

/// ConvexHull::support_index finds the support vertex by brute force up to this many
/// vertices (kBruteForceSupportMax in convex_hull.cpp) and by hill climbing above,
/// which may pick another vertex on ties. The face queries replicate the brute force
/// (VertexSoA) only where the hull uses it, so the chosen vertices, and so the
/// results, are the same as with the hull's own support.
constexpr std::size_t kBruteSupportMax = 32;

/// A hull's vertices as three coordinate arrays (ConvexHull::vertex_coords), so the
/// face queries' dot products over all vertices vectorise (detail::support_index_soa;
/// a scalar scan behind a data-dependent branch was two thirds of this routine's time
/// for 20-vertex hulls).
struct VertexSoA {
  int n = 0;
  const Real *x = nullptr, *y = nullptr, *z = nullptr;
  void assign(const ConvexHull& h) {
    n = static_cast<int>(h.vertices().size());
    x = h.vertex_coords().data();
    y = x + n;
    z = y + n;
  }
  /// Index of the vertex maximising dot(v, d), the first on ties: the vertex
  /// ConvexHull::support_index returns for hulls up to 32 vertices, bit for bit.
  int support_index(const Vec3& d, Real* max_dot = nullptr) const {
    return detail::support_index_soa(x, y, z, n, d, max_dot);
  }
};

/// Loads one byte of every cache line of the arrays the queries below read from h
/// (coordinates, faces, vertices, edge records and, for A, the rings of edges around
/// its vertices that the edge walk follows), all at once. A broadphase's pairs are
/// rarely in cache, and these loads are independent, so their misses overlap, where
/// the queries' own loads come one after another (support, then the edge records, then
/// their faces...). Measured on the narrowphase benchmark's overlapping hull pairs (20
/// vertices, a different pair every call, out of cache): 4.8-5.2 -> 3.9-4.1 us; A's
/// rings and edge records, which only the few walked edges read (one dependent miss
/// after another), another 5-15% on overlapping pairs (a few percent more on separated
/// ones); _mm_prefetch on the same lines changed nothing measurable. Not the
/// half-edges: only the two clipped faces' loops read them, a few of the 27 lines a
/// 20-vertex hull's take (2.50 -> 2.34 us a query over all classes, 20,000
/// configurations). Leaving out A's vertices and edge records as well, which the walk
/// reads only in part, was slower (deep pairs 3.6 -> 4.0 us); so was nothing gained by
/// reading vertices from the coordinate arrays and planes from a 32-byte array instead
/// of the 40-byte faces (26 fewer lines a pair).
inline void touch_hull(const ConvexHull& h, bool rings) {
  unsigned acc = 0;
  auto lines = [&acc](const void* p, std::size_t bytes) {
    const unsigned char* c = static_cast<const unsigned char*>(p);
    for (std::size_t o = 0; o < bytes; o += 64) acc += c[o];
  };
  lines(h.vertex_coords().data(), h.vertex_coords().size() * sizeof(Real));
  lines(h.faces().data(), h.faces().size() * sizeof(ConvexHull::Face));
  lines(h.vertices().data(), h.vertices().size() * sizeof(Vec3));
  lines(h.edge_arcs().data(), h.edge_arcs().size() * sizeof(ConvexHull::EdgeArc));
  if (rings) {
    lines(h.vertex_edges().data(), h.vertex_edges().size() * sizeof(ConvexHull::VertexEdge));
    lines(h.vertex_edge_begin().data(), h.vertex_edge_begin().size() * sizeof(int));
  }
#if defined(__GNUC__)
  asm volatile("" : : "r"(acc));  // keep the loads: their values are not used
#else
  static volatile unsigned sink;
  sink = acc;
#endif
}

/// Per-thread scratch space: its vectors keep their capacity, so after the first
/// calls (the largest hulls seen) collide_hull_hull allocates nothing.
struct Workspace {
  std::vector<int> support_a;  ///< per face of B: A's support vertex along -normal
  std::vector<Real> sep_b;     ///< per face of B: its separation (up to round-off)
  std::vector<Real> max_dot_a; ///< per face of B: dot(A's support vertex, -normal)
  VertexSoA verts_a, verts_b;        ///< A's and B's vertices, each in its own frame
  std::vector<Vec3> verts_b_in_a;    ///< B's vertices moved into A's frame
  std::vector<Vec3> neg_normals_b;   ///< B's face normals, negated, in A's frame
};

Workspace& workspace() {
  thread_local Workspace ws;
  return ws;
}

}  // namespace

bool collide_hull_hull(const ConvexHull& a, const ConvexHull& b, const Pose& b_in_a, Real margin,
                       Manifold& m) {
  const Real reach = a.radius() + b.radius() + margin;  // hulls have no radius today
  // ---- Separation first, by GJK (see the header): a pair it proves farther apart than
  // `reach` has no contact, and the SAT below is not needed.
  // B's vertex centroid in A's frame: GJK's first direction here, the pruning bound of
  // A's face queries below.
  const Vec3 centroid_b = b_in_a.transform_point(b.vertex_centroid());
  // Balls around the centroids first: outer balls farther apart than `reach` prove the
  // hulls are. The factor keeps round-off (~1e-16 relative) on the safe side.
  const Vec3 centres = centroid_b - a.vertex_centroid();
  const Real centre_dist = centres.norm();
  if (centre_dist > (a.outer_radius() + b.outer_radius() + reach) * (1 + 1e-9)) return false;
  touch_hull(a, true);
  touch_hull(b, false);
  const Mat3 R = b_in_a.matrix();
  const Pose a_in_b = b_in_a.inverse();
  const Real size = std::max(a.local_aabb().half_extents().maxCoeff(),
                             b.local_aabb().half_extents().maxCoeff());
  const auto& fa = a.faces();
  const auto& fb = b.faces();

  // B's vertices and negated face normals in A's frame, once: the queries below use
  // each several times (a vertex per edge it ends, a normal per edge it borders), and
  // the matrix product is cheaper than a quaternion rotation.
  Workspace& ws = workspace();
  const Vec3 t = b_in_a.position;
  ws.verts_b_in_a.resize(b.vertices().size());
  for (std::size_t i = 0; i < b.vertices().size(); ++i) ws.verts_b_in_a[i] = R * b.vertices()[i] + t;
  ws.neg_normals_b.resize(fb.size());
  for (std::size_t g = 0; g < fb.size(); ++g) ws.neg_normals_b[g] = -(R * fb[g].normal);
  const std::vector<Vec3>& qb = ws.verts_b_in_a;
  const std::vector<Vec3>& nb = ws.neg_normals_b;

  // ---- Face queries of A.
  const bool brute_a = a.vertices().size() <= kBruteSupportMax;
  const bool brute_b = b.vertices().size() <= kBruteSupportMax;
  if (brute_a) ws.verts_a.assign(a);
  if (brute_b) ws.verts_b.assign(b);
  //
  // Pruning (exact): s_f = min over B's vertices v of n_f.v - offset_f is at most
  // n_f.x - offset_f for any point x of B, e.g. B's vertex centroid and the deepest
  // vertex found so far (the support point of the current best face). A face whose
  // bound is below the best separation so far by more than kPruneSlack cannot become
  // the best (the selection takes a strictly larger separation) nor end the test (the
  // best is <= reach, or it would have), so its support search is skipped: most faces
  // then cost two dot products instead of V_B. Results are unchanged.
  const Real prune_slack = kPruneSlack * (size + b_in_a.position.norm());
  Vec3 deepest_b = centroid_b;
  Real sep_a = -kInf;
  int face_a = 0;
  for (int f = 0; f < static_cast<int>(fa.size()); ++f) {
    const Vec3& nf = fa[f].normal;
    if (std::min(nf.dot(centroid_b), nf.dot(deepest_b)) - fa[f].offset < sep_a - prune_slack) continue;
    const Vec3& p = qb[brute_b ? ws.verts_b.support_index(R.transpose() * -nf) : b.support_index(R.transpose() * -nf)];
    const Real s = nf.dot(p) - fa[f].offset;
    if (s > reach) return false;
    if (s > sep_a) {
      sep_a = s;
      face_a = f;
      deepest_b = p;
    }
  }
  // ---- Face queries of B (in B's frame). A's support vertex along each face's
  // -normal is kept for the edge queries.
  ws.support_a.resize(fb.size());
  ws.sep_b.resize(fb.size());
  // All of them at once, vectorised across the faces (detail::support_indices_soa):
  // the edge queries need every one.
  if (brute_a) {
    ws.max_dot_a.resize(fb.size());
    detail::support_indices_soa(ws.verts_a.x, ws.verts_a.y, ws.verts_a.z, ws.verts_a.n, nb.data(),
                                static_cast<int>(fb.size()), ws.support_a.data(), ws.max_dot_a.data());
  }
  Real sep_b = -kInf;
  int face_b = 0;
  for (int g = 0; g < static_cast<int>(fb.size()); ++g) {
    Real max_dot = kInf;
    int va;
    if (brute_a) {
      va = ws.support_a[g];
      max_dot = ws.max_dot_a[g];
    } else {
      va = ws.support_a[g] = a.support_index(nb[g]);
    }
    // Pruning (exact), as for A's faces: s below is, up to round-off, -max_dot +
    // n_g.(a_in_b.position) - offset_g; if even that plus the slack can neither beat
    // the best nor exceed reach, the exact value (a quaternion transform) is not needed.
    if (max_dot < kInf) {
      const Real approx = -max_dot + fb[g].normal.dot(a_in_b.position) - fb[g].offset;
      ws.sep_b[g] = approx;
      if (approx + prune_slack < sep_b && approx + prune_slack < reach) continue;
    }
    const Real s = fb[g].normal.dot(a_in_b.transform_point(a.vertices()[va])) - fb[g].offset;
    ws.sep_b[g] = s;
    if (s > reach) return false;
    if (s > sep_b) {
      sep_b = s;
      face_b = g;
    }
  }
  // The better face axis (A's unless B's is clearly better, clip::sat_better). An edge
  // axis only matters if its separation exceeds edge_floor: above `edge_bar` it beats
  // the face axis, above `reach` it separates the pair (and edge_bar may exceed reach
  // when the best face separation is near it). Edge axes that provably stay at or
  // below edge_floor are left out below (exactly: they could change nothing).
  AxisKind kind = AxisKind::kFaceA;
  Real best = sep_a;
  if (clip::sat_better(sep_b, best, size)) {
    kind = AxisKind::kFaceB;
    best = sep_b;
  }
  const Real edge_bar = best + clip::kSatRelTolerance * std::abs(best) + clip::kSatAbsTolerance * size;
  const Real edge_floor = std::min(edge_bar, reach) - prune_slack;
  // ---- Edge queries with Gauss-map pruning, in A's frame.
  //
  // On A's Gauss map the directions whose support vertex is v form a spherically
  // convex region bounded by the arcs of v's edges. The arc (c, d) of an edge of B (its
  // face normals negated) runs from the region of A's support vertex along c to that
  // along d, and the arcs of A it crosses, i.e. the edges of A that build a Minkowski
  // face with it, are exactly the region boundaries it passes on the way: a geodesic
  // arc meets a convex region in one piece, so it leaves each region through one edge
  // of that region's vertex into the neighbouring vertex's region. So instead of
  // testing every edge of A (E_A E_B tests, Gregorius's brute force), each edge of B
  // walks that path: from the support vertex along c, test the edges around the
  // current vertex (not the one it came in by) for a crossing, cross it, until the
  // support vertex along d is reached. Both support vertices come from the face
  // queries of B. An edge of B whose two are the same vertex crosses nothing (the
  // arc stays in one region) and is skipped. The cost is the number of crossings
  // times the vertex degree instead of E_A.
  //
  // Degenerate arcs (through a corner of the Gauss map, i.e. a face of A parallel to
  // the edge of B, or starting on a region boundary because of a tie in the support)
  // can leave the walk without a proper crossing to follow, or make it run longer than
  // V_A steps; such an edge of B falls back to testing every edge of A. The walk only
  // ever evaluates pairs that pass the Gauss-map test, so it never adds a wrong axis;
  // the fallback makes sure none is missed.
  const Vec3& centroid_a = a.vertex_centroid();
  const ConvexHull::EdgeArc* arcs_b = b.edge_arcs().data();
  const int n_vert_a = static_cast<int>(a.vertices().size());
  const int n_edge_a = static_cast<int>(a.edges().size());
  const ConvexHull::EdgeArc* arcs_a = a.edge_arcs().data();
  const Vec3* verts_a = a.vertices().data();
  const ConvexHull::VertexEdge* ring_a = a.vertex_edges().data();
  const int* ring_begin_a = a.vertex_edge_begin().data();
  Real sep_e = -kInf;
  int edge_a = -1, edge_b = -1;
  Vec3 n_e = Vec3::UnitX();
  for (int jb = 0; jb < static_cast<int>(b.edges().size()); ++jb) {
    const ConvexHull::EdgeArc& eb = arcs_b[jb];
    const int g1 = eb.face1, g2 = eb.face2;
    const int v_start = ws.support_a[g1], v_end = ws.support_a[g2];
    if (v_start == v_end) continue;
    const Vec3& q0 = qb[eb.tail];
    const Vec3& q1 = qb[eb.head];
    const Vec3& c = nb[g1];
    const Vec3& d = nb[g2];
    if (edge_bound(ws.sep_b[g1], ws.sep_b[g2], c, d, q0, verts_a[v_start], verts_a[v_end]) < edge_floor)
      continue;
    const Vec3 dxc = d.cross(c);
    const Vec3 e2 = q1 - q0;
    const Real e2_len2 = e2.squaredNorm();
    // Gauss-map test of A's edge k against this edge of B; for a Minkowski face, the
    // separation along its normal (false: separated beyond the margin, stop).
    bool separated = false;
    auto crosses = [&](int k) {
      const ConvexHull::EdgeArc& ea = arcs_a[k];
      const Vec3& n1 = fa[ea.face1].normal;
      const Vec3& n2 = fa[ea.face2].normal;
      if (!is_minkowski_face(n1, n2, n2.cross(n1), c, d, dxc)) return false;
      const Vec3& p0 = verts_a[ea.tail];
      const Vec3 dir = verts_a[ea.head] - p0;
      Vec3 n = dir.cross(e2);
      // The separation along n is raw / |n| (oriented away from A's centroid); an axis
      // that cannot exceed edge_floor needs neither the square root nor the division.
      const Real len2 = n.squaredNorm();
      const bool flip = n.dot(p0 - centroid_a) < 0;
      const Real raw = flip ? -n.dot(q0 - p0) : n.dot(q0 - p0);
      if (edge_floor > 0 ? (raw <= 0 || raw * raw <= edge_floor * edge_floor * len2)
                         : (raw < 0 && raw * raw >= edge_floor * edge_floor * len2))
        return true;
      const Real len = std::sqrt(len2);
      if (len > kParallelSin * std::sqrt(dir.squaredNorm() * e2_len2)) {
        n /= flip ? -len : len;
        const Real s = n.dot(q0 - p0);
        if (s > reach) separated = true;
        if (s > sep_e) {
          sep_e = s;
          edge_a = k;
          edge_b = jb;
          n_e = n;
        }
      }
      return true;
    };
    int v = v_start, came_by = -1;
    bool walked = true;
    for (int step = 0; v != v_end; ++step) {
      if (step >= n_vert_a) {
        walked = false;
        break;
      }
      // Around v: its edges in ring order (ConvexHull::vertex_edges).
      int next_v = -1;
      for (int j = ring_begin_a[v], end = ring_begin_a[v + 1]; j < end; ++j) {
        const int k = ring_a[j].edge;
        if (k != came_by && crosses(k)) {
          came_by = k;
          next_v = ring_a[j].other;
          break;
        }
      }
      if (separated) return false;
      if (next_v < 0) {
        walked = false;
        break;
      }
      v = next_v;
    }
    if (!walked) {
      for (int k = 0; k < n_edge_a; ++k) crosses(k);
      if (separated) return false;
    }
  }

  // A pair that no axis proves penetrating (some axis may separate it by up to
  // `reach`) goes to GJK: if its distance exceeds reach, there is no contact (see the
  // header). Edge axes left out above separate by less than edge_floor.
  const bool penetrating = sep_a <= 0 && sep_b <= 0 && (edge_a < 0 || sep_e <= 0) && edge_floor <= 0;
  if (!penetrating && reach > 0 &&
      gjk_distance(CoreSupport<ConvexHull>(a), CoreSupport<ConvexHull>(b), b_in_a, GjkSettings{}, centres, reach)
          .culled)
    return false;
  if (edge_a >= 0 && clip::sat_better(sep_e, best, size)) kind = AxisKind::kEdge;

  if (kind == AxisKind::kEdge) {
    const ConvexHull::EdgeArc& ea = arcs_a[edge_a];
    const ConvexHull::EdgeArc& eb = arcs_b[edge_b];
    Vec3 pa, pb;
    clip::closest_points_segments(a.vertices()[ea.tail], a.vertices()[ea.head],
                                  b_in_a.transform_point(b.vertices()[eb.tail]),
                                  b_in_a.transform_point(b.vertices()[eb.head]), pa, pb);
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
  ContactScratch<clip::kMaxClipVertices + 1> pts;
  const Vec3 ref_normal = ref_on_a ? N : Vec3(-N);  // the reference face's own plane normal
  int n = clip::clip_features(ref, nr, ref_on_a, inc, ni, N, 0, 0, margin, id_base, pts.data(),
                              &ref_normal);
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
  reduce_to_4(pts.data(), n, N, m);
  return true;
}

}  // namespace wmo
