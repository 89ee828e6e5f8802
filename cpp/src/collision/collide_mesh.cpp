// Triangle mesh A against convex B: one contact manifold per touching triangle, with
// internal-edge handling.
//
// Pipeline, all in the mesh's frame (B's pose b_in_a, types.h):
//   1. Broad step: B's bounding box in the mesh frame, fattened by the margin, queried
//      against the mesh's BVH (mesh_bvh.h).
//   2. Per candidate triangle T (face normal n): the signed distance / penetration of T
//      against B by GJK / EPA on B's core plus radius (triangle_convex in
//      convex_queries.h). Triangles further than the margin are skipped.
//   3. Internal-edge handling (below): the normal N is checked against the normals T
//      may legitimately produce given its neighbours, and replaced where it may not.
//   4. Manifold: B's supporting face along -N is clipped against T's side planes (T as
//      the reference face), or T against B's face (B as reference), Sutherland-Hodgman
//      (Ericson 8.3.4 / Gregorius, "Robust Contact Creation for Physics Simulations",
//      GDC 2015); with T as the reference, B's support points along -N tilted 45 degrees
//      four ways are added where they lie over T within the margin (speculative rim
//      points, add_rim_points); points deeper than -margin are kept and reduced to 4
//      (manifold_reduce.h).
//      When neither face produced N (an edge-edge or vertex contact), the single
//      GJK / EPA point pair is the manifold.
//
// Internal edges ("ghost collisions"). A smooth surface cut into triangles has edges
// that are not features of the surface: a box sliding over a flat grid meets, at every
// triangle it partly overlaps, a penetration whose shortest way out is sideways through
// that triangle's edge, and those sideways normals stop the box. Bullet
// (btAdjustInternalEdgeContacts) clamps such normals using the stored angle of the
// nearest edge; Jolt (InternalEdgeRemovingCollector and its "active edges") replaces
// normals from inactive edges with the face normal. The rule here is in that spirit:
//   * Side: the contact is on T's front if N.n > 0 and on its back if N.n < 0 (meshes
//     are two-sided). Near 0 (|N.n| <= sin 1e-6) both sides are tried and N is kept if
//     either allows it; otherwise the side of B's centre is used. m = +n or -n is the
//     normal of that side. An edge is a real feature for a side if it is a boundary
//     edge or convex seen from that side (TriangleMesh::edge_is_convex / _from_back);
//     flat and concave edges are internal.
//   * T's feature that supports N (the vertices maximising N.v, ties within an angle of
//     1e-6 rad) is T's normal cone that N lies in: the face, an edge or a vertex.
//       - face: N := m (it is m already, up to round-off);
//       - internal edge: N := m;
//       - real edge with a neighbour (normal m'): N must lie in the wedge between m and
//         m' (the edge's Voronoi cone); beyond m' it is clamped to m'. A boundary edge
//         allows its whole half-space;
//       - vertex: internal (N := m) if both of T's edges at it are internal. Otherwise N
//         may tilt from m by no more than the neighbour across a real edge at the vertex
//         does (any tilt for a boundary edge), and, if one of the two edges is
//         internal, must not lean out through it (N.u <= sin 1e-6 for its in-plane
//         outward normal u); else N := m.
//   * The depth along the new normal is recomputed by the clipping of step 4 (each point's
//     depth along N against T's plane). A triangle whose new manifold is empty (B lies
//     over the neighbour, not over T) gives no contact: the neighbour reports it.
// One-sided meshes (TriangleMesh::one_sided: the surface of a solid behind it). Before the
// rule above, a contact whose normal does not point out through T's front (N.n <= sin
// 1e-6) is dropped if B does not overlap T and lies wholly behind T's plane, and
// otherwise turned into T's face normal: B is pushed out through the front, the depths
// along n from the clipping (a body apart from T but reaching in front of its plane, such
// as one sliding into a valley towards the rising face ahead, gets that face's
// speculative points; dropped, a 2 cm disc sliding at 6.5 m/s met the face only once
// it was wholly behind it, and fell; a world passes its contact cache, so that a body
// that touched T at the last step and was pushed wholly behind it within one step, as a
// thin plate under a box landing on it, is pushed back out rather than dropped). The
// rule then runs for the front side only, and where it
// turns N into the face normal the side is always the front. A two-sided ground lets a
// body whose centre was driven through it (a 2 g sliver spinning at 415 rad/s landing
// at 16 m/s; a pile pressing a hull down) be pushed out below and fall away: a random-
// scene fuzz lost a body through a two-sided mesh ground in ~20% of its scenes.
// With a caller's contact history (CollideSettings::touched_before) a two-sided triangle
// that the pair touched at the last step keeps the side it was touched from, as a
// one-sided mesh keeps its front: a body pressed past the sheet's middle within one
// step is pushed back (scripts/fuzz_worlds.py, two-sided ground, CCD on every body:
// 95 of 200 scenes lost a body before, 5 after). What it cannot mend is a body already
// on the wrong side: it keeps that side too. (A world keeps the history of a sleeping
// body's pairs, so a triangle keeps its side across a sleep.) Without history, a
// speculative contact (B apart from T) whose side by the rule below (the larger part
// of B, T's plane taken whole) is not the side of B's nearest point gives no contact:
// that plane then cuts through B beyond T's edge and neither side is safe (seeds 1-200
// of that fuzz: 5 lost a body before, 0 after; 201-400: 9 before, 2 after). Without
// history, an overlap whose normal is not T's face normal takes the side of B's centre
// relative to the sheet where the centre lies (sheet_side), not the lean of the
// normal, which near an edge is the way out past it (seed 2305: a hull in a valley was
// pushed down through the next triangle), nor T's plane taken whole, which a ridge
// makes cut through a body resting beside it (seed 3113).
// The rule is local to T and its three neighbours, so it is deterministic and needs no
// second pass over the triangles (Jolt's collector needs one); its known limit is a
// vertex whose two edges in T are internal while another edge at that vertex (in other
// triangles) is convex: T reports the face normal and the triangles owning the convex
// edge report the edge.
//
// Feature ids (ContactPoint::feature_id, per triangle since child_a identifies T):
// (B's supporting feature << 14) | (mode << 12) | local, with mode 0 = T is the
// reference face, 1 = B's face is the reference, 2 = single point; local names the two
// polygon edges (incident edges or clip planes) that meet at the clipped point, or for
// a single point the triangle vertices of its feature.
//
// No heap allocation: fixed-size arrays throughout (only `out` grows), and the GJK / EPA
// workspace is per thread (gjk.h).
#include <algorithm>
#include <array>
#include <cmath>

#include "manifold_reduce.h"
#include "wmo/collision/narrowphase.h"
#include "wmo/geometry/convex_queries.h"
#include "wmo/geometry/mesh_bvh.h"

namespace wmo {

namespace {

// Angle (rad) within which two normals, or a normal and a plane, count as aligned when
// classifying features. GJK / EPA normals carry errors around 1e-8 (their relative
// tolerances are 1e-10); 1e-6 rad is well above that and far below any angle a mesh
// edge or a contact could meaningfully have.
constexpr Real kFeatureAngle = 1e-6;

// A face (of T or of B) is used as the reference face of the clipping when its normal is
// within this angle (rad) of N. Face contacts from EPA/GJK match their face normal to
// ~1e-8 (snapped normals exactly); edge-edge contacts are off every face normal by the
// angle between the edges' faces, which for a contact worth a clipped manifold is far
// more than 1e-3 rad.
constexpr Real kReferenceAngle = 1e-3;
const Real kReferenceCos = std::cos(kReferenceAngle);

// Clipped polygons: B's face (up to kMaxFaceVertices) gains at most one vertex per clip
// plane of the triangle (3); T (3 vertices) gains at most one per plane of B's face.
constexpr int kMaxClip = kMaxFaceVertices + 8;

// A vertex of a clipped polygon is the intersection of its two polygon edges, so it is
// named by their labels: incident edge k (0..31, the edge from incident vertex k to
// k + 1) or clip plane j (32 + j). The pair is stable while the same features meet,
// which is what a feature id must be.
struct ClipVertex {
  Vec3 p;
  std::uint8_t in;   // label of the edge arriving at the vertex
  std::uint8_t out;  // label of the edge leaving it
  std::uint32_t id() const { return static_cast<std::uint32_t>(in) * 64u + out; }
};

struct Polygon {
  int count = 0;
  std::array<ClipVertex, kMaxClip> v{};
};

// Incident polygon from points: vertex k has in-edge k - 1 and out-edge k. A segment's
// two ends get (1, 0) and (0, 1); a point (0, 0).
void make_polygon(const Vec3* pts, int n, Polygon& poly) {
  poly.count = n;
  for (int k = 0; k < n; ++k) {
    const int in = n == 2 ? 1 - k : (k + n - 1) % std::max(n, 1);
    poly.v[k] = ClipVertex{pts[k], static_cast<std::uint8_t>(in), static_cast<std::uint8_t>(k)};
  }
}

// Points up to this far (m) outside a clip plane count as inside. A point exactly on an
// edge shared by two triangles must survive in at least one of them, but the two
// triangles evaluate its side with different round-off (a few DBL_EPSILON times the
// coordinates: ~1e-12 m at 1e4 m); 1e-9 m is far above that and far below anything
// physical. Points this close to an edge may then appear in both triangles' manifolds,
// which is harmless.
constexpr Real kClipSlack = 1e-9;

// Sutherland-Hodgman against the half-space c.(x - o) <= kClipSlack, c the unit outward
// normal of clip plane `plane`. A 1- or 2-vertex input is a point or a segment (no
// closing edge).
void clip(const Polygon& in, const Vec3& c, const Vec3& o, int plane, Polygon& out) {
  out.count = 0;
  const int n = in.count;
  if (n == 0) return;
  const auto label = static_cast<std::uint8_t>(32 + plane);
  auto push = [&](const Vec3& p, std::uint8_t a, std::uint8_t b) {
    if (out.count < kMaxClip) out.v[out.count++] = ClipVertex{p, a, b};
  };
  if (n == 1) {
    if (c.dot(in.v[0].p - o) <= kClipSlack) out.v[out.count++] = in.v[0];
    return;
  }
  const int edges = n == 2 ? 1 : n;
  for (int i = 0; i < n; ++i) {
    const ClipVertex& a = in.v[i];
    const Real da = c.dot(a.p - o) - kClipSlack;
    if (da <= 0) push(a.p, a.in, a.out);
    if (i >= edges) break;
    const ClipVertex& b = in.v[(i + 1) % n];
    const Real db = c.dot(b.p - o) - kClipSlack;
    const Vec3 x = a.p + (da / (da - db)) * (b.p - a.p);
    if (da < 0 && db > 0) push(x, a.out, label);  // leaving: continue along the plane
    if (da > 0 && db < 0) push(x, label, a.out);  // entering: continue along edge a.out
  }
}

// Clips `poly` against the side planes of the reference polygon ref[0..nr) (nr >= 3,
// convex, in a plane), the side planes containing each edge and the direction N.
// Result in `poly` (scratch used as the double buffer).
void clip_against_sides(Polygon& poly, Polygon& scratch, const Vec3* ref, int nr, const Vec3& n) {
  Vec3 centre = Vec3::Zero();
  for (int k = 0; k < nr; ++k) centre += ref[k];
  centre /= nr;
  for (int k = 0; k < nr && poly.count > 0; ++k) {
    const Vec3& a = ref[k];
    const Vec3& b = ref[(k + 1) % nr];
    Vec3 c = (b - a).cross(n);
    const Real len = c.norm();
    if (!(len > 0)) continue;  // edge parallel to N (or zero): no side plane
    c /= len;
    if (c.dot(centre - a) > 0) c = -c;  // outward: away from the polygon
    clip(poly, c, a, k, scratch);
    std::swap(poly, scratch);
  }
}

// Closest points of segments p0-p1 and q0-q1 (Ericson 5.1.9).
void closest_segments(const Vec3& p0, const Vec3& p1, const Vec3& q0, const Vec3& q1, Vec3& cp,
                      Vec3& cq) {
  const Vec3 d1 = p1 - p0, d2 = q1 - q0, r = p0 - q0;
  const Real a = d1.squaredNorm(), e = d2.squaredNorm(), f = d2.dot(r);
  Real s = 0, t = 0;
  if (a <= 0 && e <= 0) {
  } else if (a <= 0) {
    t = std::clamp(f / e, Real(0), Real(1));
  } else {
    const Real c = d1.dot(r);
    if (e <= 0) {
      s = std::clamp(-c / a, Real(0), Real(1));
    } else {
      const Real b = d1.dot(d2), den = a * e - b * b;
      s = den > 0 ? std::clamp((b * f - c * e) / den, Real(0), Real(1)) : Real(0);
      t = (b * s + f) / e;
      if (t < 0) {
        t = 0;
        s = std::clamp(-c / a, Real(0), Real(1));
      } else if (t > 1) {
        t = 1;
        s = std::clamp((b - c) / a, Real(0), Real(1));
      }
    }
  }
  cp = p0 + s * d1;
  cq = q0 + t * d2;
}

// Per-call context: B in the mesh frame.
struct MeshContext {
  const TriangleMesh& mesh;
  const ConvexShape& b;
  const Pose& b_in_a;
  Mat3 rot;
  const CollideSettings& settings;
};

// Which of T's vertices support direction `n` (bit mask): those within kFeatureAngle of
// the maximum of n.v, measured as an angle from the edge to the best vertex.
int support_mask(const std::array<Vec3, 3>& v, const Vec3& n) {
  const Real h0 = n.dot(v[0]), h1 = n.dot(v[1]), h2 = n.dot(v[2]);
  int best = 0;
  if (h1 > h0) best = 1;
  if (h2 > std::max(h0, h1)) best = 2;
  const Real hb = n.dot(v[best]);
  const Real sin_tol = std::sin(kFeatureAngle);
  int mask = 1 << best;
  for (int i = 0; i < 3; ++i) {
    if (i == best) continue;
    if (hb - n.dot(v[i]) <= sin_tol * (v[i] - v[best]).norm()) mask |= 1 << i;
  }
  return mask;
}

// Edge index (0..2) from a two-vertex mask: edge e joins vertices e and e + 1.
int edge_of_mask(int mask) {
  if (mask == 3) return 0;  // vertices 0, 1
  if (mask == 6) return 1;  // vertices 1, 2
  return 2;                 // vertices 2, 0
}

bool edge_real(const TriangleMesh& mesh, int t, int e, int side) {
  return side > 0 ? mesh.edge_is_convex(t, e) : mesh.edge_is_convex_from_back(t, e);
}

// In-plane outward normal of edge e of T (unit, perpendicular to the edge, in T's plane,
// pointing away from T's interior).
Vec3 edge_outward(const std::array<Vec3, 3>& v, const Vec3& n, int e) {
  const Vec3 d = v[(e + 1) % 3] - v[e];
  return d.cross(n).normalized();  // CCW about n: d x n points out
}

// Applies the internal-edge rule (file comment) for one side (+1 front, -1 back).
// Returns true if N is allowed as it is; otherwise `adjusted` is the replacement.
bool allowed_on_side(const MeshContext& ctx, int t, const std::array<Vec3, 3>& v, const Vec3& n,
                     int side, const Vec3& N, Vec3& adjusted) {
  const Vec3 m = side * n;
  adjusted = m;
  const int mask = support_mask(v, N);
  const int bits = (mask & 1) + ((mask >> 1) & 1) + ((mask >> 2) & 1);
  if (bits == 3) return false;  // the face: N := m (a no-op up to round-off)
  const Real sin_tol = std::sin(kFeatureAngle);
  if (bits == 2) {
    const int e = edge_of_mask(mask);
    if (!edge_real(ctx.mesh, t, e, side)) return false;
    const int u = ctx.mesh.neighbor(t, e);
    const Vec3 out = edge_outward(v, n, e);
    const Real theta = std::atan2(N.dot(out), N.dot(m));
    if (theta < -kFeatureAngle) return false;  // leans into T's face region
    if (u < 0) return true;                    // boundary: its whole half-space
    const Vec3 mu = side * ctx.mesh.triangle_normal(u);
    const Real theta_u = std::atan2(mu.dot(out), mu.dot(m));
    if (theta <= theta_u + kFeatureAngle) return true;
    adjusted = mu;  // beyond the neighbour's normal: clamp to it
    return false;
  }
  // A vertex i lies on edges i (i -> i+1) and i+2 (i+2 -> i).
  const int i = mask == 1 ? 0 : (mask == 2 ? 1 : 2);
  const int ea = i, eb = (i + 2) % 3;
  const bool ra = edge_real(ctx.mesh, t, ea, side), rb = edge_real(ctx.mesh, t, eb, side);
  if (!ra && !rb) return false;
  // N may tilt away from m by no more than the neighbour across a real edge at the
  // vertex tilts (a boundary edge allows any tilt): the vertex's normal cone, bounded by
  // what T's adjacency knows.
  Real min_cos = 1;
  for (const int e : {ea, eb}) {
    if (!edge_real(ctx.mesh, t, e, side)) continue;
    const int u = ctx.mesh.neighbor(t, e);
    min_cos = std::min(min_cos, u < 0 ? Real(-1) : m.dot(side * ctx.mesh.triangle_normal(u)));
  }
  if (m.dot(N) < min_cos - sin_tol) return false;
  if (ra && rb) return true;
  const int internal = ra ? eb : ea;
  return N.dot(edge_outward(v, n, internal)) <= sin_tol;
}

// The side (+1 front, -1 back) of B's centre relative to the sheet where the centre
// lies: T's plane if the centre projects onto T; beyond an edge of T (the one it lies
// farthest beyond, in T's plane), the plane of the neighbour across that edge, whose
// front agrees with T's (neighbours are consistently wound, TriangleMesh); T's plane
// again beyond a boundary edge. Near T's edges T's plane, extended past them, can
// misjudge the side: a ridge puts a body resting beside it behind the next flank's
// plane (seed 3113: a 1.8 m capsule lying across a ridge, its centre 2 cm behind it).
int sheet_side(const MeshContext& ctx, int t, const std::array<Vec3, 3>& v, const Vec3& n) {
  // B's centre: the middle of its local bounding box (a hull's origin, which its
  // points need not surround, may lie outside it).
  const Aabb box = ctx.b.local_aabb();
  const Vec3 c = ctx.b_in_a.transform_point(0.5 * (box.min + box.max));
  int beyond = -1;
  Real farthest = 0;
  for (int e = 0; e < 3; ++e) {
    const Real d = edge_outward(v, n, e).dot(c - v[e]);
    if (d > farthest) {
      farthest = d;
      beyond = e;
    }
  }
  const int u = beyond >= 0 ? ctx.mesh.neighbor(t, beyond) : -1;
  if (u < 0) return n.dot(c - v[0]) >= 0 ? 1 : -1;
  const Vec3& pu = ctx.mesh.vertices()[ctx.mesh.triangles()[u][0]];
  return ctx.mesh.triangle_normal(u).dot(c - pu) >= 0 ? 1 : -1;
}

// Speculative rim points. The manifold on T's face is B's supporting face along -N
// clipped to T: for a rounded hull (a disc of many small facets) that face is one small
// facet, and the rest of B's underside, however close to T, has no point. A flat hull
// landing on a corner is then spun up by the corner's impulse (measured: ~100 rad/s for
// a 15 cm disc at 10 m/s, 1.7 rad a step at 60 Hz) with nothing to stop its far side,
// which passes T's plane within the step; on a zero-thickness mesh the disc is lost.
// So B's support points along -N tilted by 45 degrees towards +-t1 and +-t2 (t1, t2
// spanning T's plane) are added where they lie over T within the margin: on a disc, its
// rim on four sides; on a box or hull lying flat, corners of the face already there
// (skipped as duplicates). They are speculative (negative depth) until the body turns
// onto them, and bound that turn as any speculative point bounds an approach. Only for
// a polygonal supporting face (hulls, boxes, cylinder caps): a sphere or capsule
// touches at one point or segment, which its supporting feature already gives.
// Feature ids: mode 3, the tilt direction's index.
constexpr int kRimPoints = 4;

void add_rim_points(const MeshContext& ctx, const std::array<Vec3, 3>& v, const Vec3& n, const Vec3& N, Real nN,
                    Real margin, ContactPoint* pts, int& np) {
  Vec3 t1, t2;
  orthonormal_basis(N, t1, t2);
  const std::array<Vec3, kRimPoints> dirs{-N + t1, -N - t1, -N + t2, -N - t2};
  // Inside-T test: the point's offset from each edge against the edge's in-plane
  // outward normal, with the clipping's slack.
  std::array<Vec3, 3> out_normals;
  for (int e = 0; e < 3; ++e) out_normals[e] = edge_outward(v, n, e);
  for (int k = 0; k < kRimPoints; ++k) {
    const Vec3 p = ctx.b_in_a.transform_point(ctx.b.support(ctx.rot.transpose() * dirs[k]));
    const Real depth = n.dot(v[0] - p) / nN;
    if (!(depth >= -margin)) continue;
    const Vec3 q = p + depth * N;  // on T's plane
    bool inside = true;
    for (int e = 0; e < 3; ++e) inside = inside && out_normals[e].dot(q - v[e]) <= kClipSlack;
    if (!inside) continue;
    bool duplicate = false;
    for (int j = 0; j < np && !duplicate; ++j) duplicate = (pts[j].point_b - p).squaredNorm() <= 1e-18;
    if (duplicate) continue;
    pts[np++] = ContactPoint{q, p, depth, (3u << 12) | static_cast<std::uint32_t>(k)};
  }
}

// The side (+1 front, -1 back) from which the caller's history says B touched triangle t
// at its last step, or one of its edge neighbours (a body pushed through a surface near
// an edge may end up behind the next triangle); 0 if none (CollideSettings::
// touched_before).
int touched_near(const MeshContext& ctx, int t) {
  const CollideSettings& s = ctx.settings;
  if (!s.touched_before) return 0;
  if (const int side = s.touched_before(s.touched_context, t)) return side;
  for (int e = 0; e < 3; ++e) {
    const int u = ctx.mesh.neighbor(t, e);
    if (u < 0) continue;
    if (const int side = s.touched_before(s.touched_context, u)) return side;
  }
  return 0;
}

// Contact of triangle t with B; appends a manifold to `out` if it touches within the
// margin.
void collide_triangle(const MeshContext& ctx, int t, std::vector<Manifold>& out) {
  const TriangleMesh& mesh = ctx.mesh;
  const auto& tri = mesh.triangles()[t];
  const std::array<Vec3, 3> v{mesh.vertices()[tri[0]], mesh.vertices()[tri[1]],
                              mesh.vertices()[tri[2]]};
  const Vec3& n = mesh.triangle_normal(t);
  const Real margin = ctx.settings.margin;

  const DistanceResult r = triangle_convex(v[0], v[1], v[2], ctx.b, ctx.b_in_a, true,
                                           ctx.settings.gjk, ctx.settings.epa, margin);
  if (!(r.distance <= margin)) return;  // apart (or NaN: never report it)

  // Side of B's centre, used when N does not decide it.
  const int centre_side = n.dot(ctx.b_in_a.position - v[0]) >= 0 ? 1 : -1;
  Vec3 N = r.normal;
  bool modified = false;
  const Real nn = N.norm();
  const bool one_sided = mesh.one_sided();
  // The side B must be pushed out through: a one-sided mesh's front; for a two-sided
  // one the side the pair touched T (or a neighbour) from at the caller's last step
  // (CollideSettings::touched_before); 0: free, the rules below choose.
  const int front = one_sided ? 1 : touched_near(ctx, t);
  auto reach = [&](const Vec3& d) {  // max over B of d.x, mesh frame (radius included)
    return d.dot(ctx.b_in_a.transform_point(ctx.b.support_core(ctx.rot.transpose() * d))) + ctx.b.radius();
  };
  const Real offset = n.dot(v[0]);  // T's plane: {x : n.x = offset}
  if (!(nn > 0.5) || !N.allFinite()) {  // unit or zero by contract; zero: degenerate
    N = (front != 0 ? front : centre_side) * n;
    modified = true;
  } else if (!one_sided && front != 0 && !(N.dot(front * n) > std::sin(kFeatureAngle))) {
    // Two-sided, touched from `front` at the last step: B was pressed past the sheet
    // within one step; out the way it came, as a one-sided mesh would push it.
    N = front * n;
    modified = true;
  } else if (one_sided && !(N.dot(n) > std::sin(kFeatureAngle))) {
    // One-sided (file comment): a contact whose way out is not through T's front.
    // Apart from T with all of B behind T's plane: B is behind the solid's surface, no
    // contact, unless the caller's history says B touched T (or a neighbour) at its
    // last step (CollideSettings::touched_before: pushed through within a step).
    // Otherwise (overlapping T, or apart from it and reaching in front of its plane,
    // as a body sliding into a valley is beside the rising face ahead of it): out
    // through the front, along the face normal; the clipping below keeps what lies
    // over T within the margin and gives the depths.
    if (r.distance > 0 && reach(n) < offset && touched_near(ctx, t) == 0) return;
    N = n;
    modified = true;
  }
  if (ctx.settings.remove_internal_edges && !modified) {
    const Real sin_tol = std::sin(kFeatureAngle);
    const Real nd = N.dot(n);
    Vec3 adjusted;
    if (std::abs(nd) <= sin_tol) {  // (never for a one-sided mesh: handled above)
      Vec3 other;
      const bool ok = allowed_on_side(ctx, t, v, n, 1, N, adjusted) ||
                      allowed_on_side(ctx, t, v, n, -1, N, other);
      if (!ok) {
        if (centre_side < 0) adjusted = other;
        N = adjusted;
        modified = true;
      }
    } else {
      // The side N leans to, except for an overlap of a two-sided T that no history
      // has pinned (front == 0): there N may be the way out past one of T's edges,
      // whose lean says nothing about the side (seed 2305: a hull in a valley,
      // overlapping the next triangle by 8 mm past the valley's edge, EPA's normal
      // leaning 17 degrees to the back, was pushed 0.33 m down through the ground), and
      // the side is that of B's centre relative to the sheet (sheet_side).
      const int side = !one_sided && front == 0 && r.distance <= 0 ? sheet_side(ctx, t, v, n)
                                                                 : (nd > 0 ? 1 : -1);
      if (!allowed_on_side(ctx, t, v, n, side, N, adjusted)) {
        N = adjusted;
        modified = true;
      }
    }
    if (modified && std::abs(N.dot(n)) >= 1 - sin_tol) {
      // N became T's face normal (a face, internal edge or internal vertex feature), on
      // the side the leaning of GJK / EPA's normal chose. That normal is the shortest
      // way out of T alone, often sideways through an internal edge, and its slight
      // lean up or down says nothing about which side B is on: a capsule tilted
      // across a flat grid, its centre 0.1 m above it and its core through it, was
      // pushed down, through the ground (depth 0.59 m instead of 0.39), and the two
      // triangles by the diagonal it crossed chose opposite sides, so that neither
      // kept a point and the capsule fell through. The side is the one through which
      // less of B must pass, T's plane taken whole: the depth of B's lowest point below
      // it against that of its highest point above it (support points, radius
      // included); B's centre decides a tie. Every triangle of a flat patch then
      // agrees.
      int side = front;  // a one-sided mesh's is always the front; a touched one's kept
      if (side == 0) {
        const Real below = offset + reach(-n);  // how far B reaches below T's plane
        const Real above = reach(n) - offset;   // ... and above it
        const Real tie = 1e-9 * (std::abs(below) + std::abs(above));
        side = below < above - tie ? 1 : (above < below - tie ? -1 : centre_side);
        // Apart from T (a speculative contact), B's nearest point lies on the side
        // GJK's normal points to. Where that is not the side of the larger part, the
        // plane taken whole is no guide (it cuts through B beyond T's edge), and
        // neither side is safe: no contact from T (B's other triangles, and T itself
        // once B overlaps it, report it). Either choice lost bodies in fuzz scenes: the
        // larger part's side put a 1.8 m box 6 cm above a ridge's flank (the flank's
        // plane, extended past the crest, cutting through the box) under it, its points
        // in front of the plane taken as depths of up to 0.5 m along the back normal,
        // and it was driven through; the nearest point's side pushed down a compound
        // whose child, overlapping the next triangle from above, reached 1 cm below
        // the plane of the one beside it.
        if (r.distance > 0 && std::abs(nd) > sin_tol && (nd > 0 ? 1 : -1) != side) return;
      }
      N = side * n;
    }
  }

  // ---- Manifold along N. ----
  SupportingFace face;
  ctx.b.supporting_face(ctx.rot.transpose() * (-N), face);
  const int nb = std::clamp(face.count, 0, kMaxFaceVertices);
  std::array<Vec3, kMaxFaceVertices> fb;
  for (int k = 0; k < nb; ++k) fb[k] = ctx.rot * face.vertices[k] + ctx.b_in_a.position;
  const std::uint32_t fid = face.feature << 14;

  ContactScratch<kMaxClip + kRimPoints> pts;
  int np = 0;
  Manifold m;
  m.normal = N;
  m.child_a = t;

  // B's face normal (outward from B, about -N), when its face is a polygon.
  Vec3 nbf = Vec3::Zero();
  if (nb >= 3) {
    for (int k = 0; k < nb; ++k) nbf += fb[k].cross(fb[(k + 1) % nb]);  // Newell
    const Real l = nbf.norm();
    nbf = l > 0 ? Vec3(nbf / l) : Vec3::Zero();
    if (nbf.dot(N) > 0) nbf = -nbf;
  }
  const Real tri_cos = std::abs(n.dot(N));
  const Real b_cos = -nbf.dot(N);

  Polygon poly, scratch;
  if (tri_cos >= kReferenceCos && tri_cos >= b_cos) {
    // T is the reference face: clip B's face against T's side planes, depth along N to
    // T's plane.
    make_polygon(fb.data(), nb, poly);
    clip_against_sides(poly, scratch, v.data(), 3, N);
    const Real nN = n.dot(N);
    for (int k = 0; k < poly.count; ++k) {
      const Vec3& p = poly.v[k].p;
      const Real depth = n.dot(v[0] - p) / nN;
      if (!(depth >= -margin)) continue;
      pts[np++] = ContactPoint{p + depth * N, p, depth, fid | poly.v[k].id()};
    }
    if (margin > 0 && nb >= 3) add_rim_points(ctx, v, n, N, nN, margin, pts.data(), np);
  } else if (nb >= 3 && b_cos >= kReferenceCos) {
    // B's face is the reference: clip T against its side planes, depth along N to it.
    make_polygon(v.data(), 3, poly);
    clip_against_sides(poly, scratch, fb.data(), nb, N);
    const Real nN = nbf.dot(N);
    for (int k = 0; k < poly.count; ++k) {
      const Vec3& p = poly.v[k].p;
      const Real depth = -nbf.dot(fb[0] - p) / nN;
      if (!(depth >= -margin)) continue;
      pts[np++] = ContactPoint{p, p - depth * N, depth, fid | (1u << 12) | poly.v[k].id()};
    }
  } else {
    // Edge / vertex contact: one point.
    Vec3 pa = r.point_a, pb = r.point_b;
    Real depth = -r.distance;
    std::uint32_t local = 0;
    if (modified && nb > 0) {
      // N changed (clamped onto a neighbour's normal): recompute the closest features
      // along it. T's supporting edge / vertex against B's supporting feature.
      const int mask = support_mask(v, N);
      int i0 = mask & 1 ? 0 : (mask & 2 ? 1 : 2), i1 = i0;
      for (int k = 0; k < 3; ++k)
        if ((mask >> k) & 1 && k != i0) i1 = k;
      // B's side: the (one or two) vertices of its supporting feature deepest along -N.
      int j0 = 0;
      for (int k = 1; k < nb; ++k)
        if (N.dot(fb[k]) < N.dot(fb[j0])) j0 = k;
      int j1 = j0;
      for (int k = 0; k < nb; ++k)
        if (k != j0 && N.dot(fb[k] - fb[j0]) <= std::sin(kFeatureAngle) * (fb[k] - fb[j0]).norm())
          j1 = k;
      const Vec3& q0 = fb[j0];
      const Vec3& q1 = fb[j1];
      closest_segments(v[i0], v[i1], q0, q1, pa, pb);
      depth = N.dot(pa - pb);
      pb = pa - depth * N;
      local = static_cast<std::uint32_t>(4 * i0 + i1);
    }
    if (nb > 0 && depth >= -margin && pa.allFinite() && pb.allFinite())
      pts[np++] = ContactPoint{pa, pb, depth, fid | (2u << 12) | local};
  }
  if (np == 0) return;
  reduce_to_4(pts.data(), np, N, m);
  out.push_back(m);
}

}  // namespace

void collide_mesh_convex(const TriangleMesh& a, const ConvexShape& b, const Pose& b_in_a,
                         const CollideSettings& settings, std::vector<Manifold>& out) {
  const Real margin = std::max(settings.margin, Real(0));
  const MeshContext ctx{a, b, b_in_a, b_in_a.matrix(), settings};
  const Aabb box = b.world_aabb(b_in_a).fattened(margin);
  a.bvh().query_aabb(box, [&](int t) { collide_triangle(ctx, t, out); });
}

}  // namespace wmo
