// Convex hull of a point cloud: Quickhull (Barber, Dobkin, Huhdanpaa 1996, "The
// Quickhull algorithm for convex hulls", ACM TOMS 22(4)), followed by merging of
// coplanar triangles into polygonal faces and a half-edge mesh for SAT and clipping.
//
// Robustness (Barber et al. 1996 section 4; Gregorius, "Implementing Quickhull",
// GDC 2014). Quickhull goes wrong when a plane is computed badly enough that the
// visibility tests contradict each other. Here:
//  * Every triangle's normal is computed in double-double arithmetic (Dekker 1971;
//    exact differences by TwoSum, products by FMA), then rounded. A plain double cross
//    product of a sliver (apex h from a base of length L) has an error of
//    DBL_EPSILON * L / h radians, which for h near round-off is no normal at all; the
//    double-double one is accurate to about 1 ulp for any h above ~1e-30 L. So every
//    point-plane distance is accurate to the round-off of its own evaluation,
//        eps_round = 3 * DBL_EPSILON * (max|x| + max|y| + max|z|)
//    (qhull's DISTround bound for a point-plane distance).
//  * tol = 2 eps_round: a point becomes an eye only when it is more than tol above a
//    face, so no eye is chosen on noise; points within tol of the hull count as on it
//    and are dropped. A face is visible from the eye when the eye is above its plane by
//    more than eps_round (Quickhull's rule, up to the distance's round-off): an eye on
//    the line of an edge, or in the plane of a face, then never sees that face by
//    round-off (which would create a zero-area triangle), hidden faces have the eye at
//    most eps_round above their plane, and the hull only ever grows, so a dropped point
//    stays within tol of it.
//  * Visible faces are collected by a flood fill from the eye's face, so the set is
//    connected; the horizon is checked to be one simple loop before anything changes.
//    If round-off breaks that (an eye within round-off of several planes), the fill is
//    retried with faces the eye is at most tol above counted hidden, then with faces it
//    is at most tol below counted visible, and only then is the eye dropped.
//  * With the eye within round-off of two nearly coplanar faces, one may test visible
//    and the other hidden although the eye lies over the hidden one; the new triangle
//    would then fold back over it. Such hidden faces are detected (the new triangle's
//    accurate normal opposes theirs) and removed as well.
//  * A new face next to a hidden face the eye is within tol of takes that face's plane
//    (Barber et al.'s merge of a "coplanar horizon" facet): the two are one face up to
//    tol, and sharing the plane keeps later tests consistent.
//  * Afterwards, triangles whose vertices all lie within 2 tol of the plane of the
//    largest triangle of their group are merged into one polygonal face. Measuring
//    against one seed plane (not neighbour to neighbour) stops chains of nearly
//    coplanar triangles from drifting into a curved "face"; a triangle is only added
//    while the face stays convex (points bulging out by a little more than the
//    tolerance leave a few nearly coplanar faces instead). A vertex then left between
//    exactly two faces lies on both planes within 2 tol, i.e. on the line where they
//    meet, and is removed, so every vertex is a corner.
//  * The result is validated: closed, genus 0, convex faces, every vertex of degree 3
//    or more, and every input point on or behind every face plane (within 8 tol). If
//    round-off still defeated the build (input degenerate within a few ulps, e.g. lattice
//    points with noise near tol), it is rebuilt with tol x 1e3, then x 1e6, and the
//    tolerance used is reported by tolerance(); failing that, the input is rejected.
//    So a returned hull is always convex within its tolerance.
//  * Input whose initial simplex is thinner than sqrt(DBL_EPSILON) * extent (extent:
//    the largest distance between axis-extreme points) is rejected as coincident,
//    colinear or coplanar: such a solid's inertia has a condition number
//    (length / thickness)^2 above 1 / DBL_EPSILON, which no solver can invert usefully.
#include <algorithm>
#include <cfloat>
#include <cmath>
#include <memory>
#include <new>
#include <numeric>
#include <span>
#include <sstream>
#include <stdexcept>
#include <string>
#include <unordered_map>

#include "wmo/geometry/shapes.h"
#include "wmo/geometry/support_soa.h"

namespace wmo {

namespace {

std::string fmt(Real x) {
  std::ostringstream s;
  s.precision(6);
  s << x;
  return s.str();
}

// Hulls with at most this many vertices use a brute-force support search. A linear
// scan over 32 vertices is 32 multiply-adds over contiguous memory with no data-
// dependent branches worth mispredicting; hill climbing visits O(sqrt(V)) vertices but
// each step chases neighbour lists through memory, so it only pays off on larger hulls
// (Jolt and Bullet use similar cut-offs).
constexpr int kBruteForceSupportMax = 32;

struct BuildFace {
  std::array<int, 3> v{};    // vertex (point) indices, CCW seen from outside
  std::array<int, 3> adj{};  // adj[i]: face across edge v[i] -> v[(i + 1) % 3]
  Vec3 n = Vec3::Zero();     // outward unit normal
  Real d = 0;                // plane offset: dot(n, x) = d
  bool alive = true;
  int stamp = -1;            // iteration in which the visibility flood fill reached it
  bool visible = false;      // valid when stamp == current iteration
  std::vector<int> outside;  // conflict list: points above this face by more than tol
};

// Double-double helpers (Dekker 1971; Shewchuk 1997, "Adaptive precision floating-point
// arithmetic"): a value is hi + lo with |lo| <= ulp(hi) / 2.
struct DD {
  Real hi, lo;
};
DD two_diff(Real a, Real b) {
  const Real s = a - b;
  const Real bb = s - a;
  return {s, (a - (s - bb)) - (b + bb)};
}
DD fast_two_sum(Real a, Real b) {
  const Real s = a + b;
  return {s, b - (s - a)};
}
DD dd_mul(DD x, DD y) {
  const Real p = x.hi * y.hi;
  const Real e = std::fma(x.hi, y.hi, -p) + (x.hi * y.lo + x.lo * y.hi);
  return fast_two_sum(p, e);
}
DD dd_sub(DD x, DD y) {
  const Real s = x.hi - y.hi;
  const Real bb = s - x.hi;
  const Real e = (x.hi - (s - bb)) - (y.hi + bb);
  return fast_two_sum(s, e + x.lo - y.lo);
}

// (b - a) x (c - a) evaluated in double-double and rounded to double: accurate to about
// one ulp per component even for slivers (file comment).
Vec3 accurate_normal_dir(const Vec3& a, const Vec3& b, const Vec3& c) {
  const DD ux = two_diff(b.x(), a.x()), uy = two_diff(b.y(), a.y()), uz = two_diff(b.z(), a.z());
  const DD vx = two_diff(c.x(), a.x()), vy = two_diff(c.y(), a.y()), vz = two_diff(c.z(), a.z());
  const DD nx = dd_sub(dd_mul(uy, vz), dd_mul(uz, vy));
  const DD ny = dd_sub(dd_mul(uz, vx), dd_mul(ux, vz));
  const DD nz = dd_sub(dd_mul(ux, vy), dd_mul(uy, vx));
  return Vec3(nx.hi + nx.lo, ny.hi + ny.lo, nz.hi + nz.lo);
}

// Plane through a, b, c with normal along (b - a) x (c - a); offset at the centroid.
void set_plane(BuildFace& f, const std::vector<Vec3>& p, const Vec3& fallback) {
  const Vec3& a = p[f.v[0]];
  const Vec3& b = p[f.v[1]];
  const Vec3& c = p[f.v[2]];
  Vec3 n = accurate_normal_dir(a, b, c);
  const Real len = n.norm();
  // Exactly colinear vertices (an eye exactly on a horizon edge's line, which the
  // visibility tolerance excludes) would give no normal; keep the replaced face's.
  n = (len > 0 && std::isfinite(len)) ? Vec3(n / len) : fallback;
  f.n = n;
  f.d = (n.dot(a) + n.dot(b) + n.dot(c)) / 3.0;
}

class QuickhullBuilder {
 public:
  QuickhullBuilder(const std::vector<Vec3>& pts, Real eps) : p_(pts), eps_(eps) {}

  // Builds the hull from the initial tetrahedron (i0, i1, i2, i3); (i0, i1, i2) must be
  // CCW seen from the side opposite i3.
  void build(int i0, int i1, int i2, int i3) {
    faces_.reserve(4 * p_.size());
    const int tri[4][3] = {{i0, i1, i2}, {i0, i3, i1}, {i1, i3, i2}, {i2, i3, i0}};
    for (auto& t : tri) {
      BuildFace f;
      f.v = {t[0], t[1], t[2]};
      set_plane(f, p_, Vec3::UnitZ());
      faces_.push_back(std::move(f));
    }
    link_adjacency_initial();
    std::vector<int> rest;
    for (int i = 0; i < static_cast<int>(p_.size()); ++i)
      if (i != i0 && i != i1 && i != i2 && i != i3) rest.push_back(i);
    assign(rest, {0, 1, 2, 3});
    for (int f = 0; f < 4; ++f)
      if (!faces_[f].outside.empty()) work_.push_back(f);

    // Every iteration removes one point from a conflict list for good (it becomes a
    // hull vertex or is dropped), so the loop ends after at most |points| iterations.
    int iteration = 0;
    const int max_iterations = static_cast<int>(p_.size()) + 1;
    while (!work_.empty() && iteration < max_iterations) {
      const int f = work_.back();
      work_.pop_back();
      if (!faces_[f].alive || faces_[f].outside.empty()) continue;
      add_point(f);
      ++iteration;
      if (faces_[f].alive && !faces_[f].outside.empty()) work_.push_back(f);
    }
  }

  const std::vector<BuildFace>& faces() const { return faces_; }

 private:
  Real dist(const BuildFace& f, int i) const { return f.n.dot(p_[i]) - f.d; }

  void link_adjacency_initial() {
    for (int f = 0; f < 4; ++f)
      for (int e = 0; e < 3; ++e) {
        const int a = faces_[f].v[e], b = faces_[f].v[(e + 1) % 3];
        for (int g = 0; g < 4; ++g)
          if (g != f && edge_index(faces_[g], b, a) >= 0) faces_[f].adj[e] = g;
      }
  }

  static int edge_index(const BuildFace& f, int a, int b) {
    for (int e = 0; e < 3; ++e)
      if (f.v[e] == a && f.v[(e + 1) % 3] == b) return e;
    return -1;
  }

  // Gives each point to the candidate face it lies furthest above (by more than tol);
  // points above none are inside the hull (within tol) and are dropped. Choosing the
  // furthest face rather than the first keeps conflict lists on the faces the point
  // will actually see, which keeps new faces well shaped.
  void assign(const std::vector<int>& pts, const std::vector<int>& candidates) {
    for (int i : pts) {
      int best = -1;
      Real best_d = eps_;
      for (int f : candidates) {
        const Real d = dist(faces_[f], i);
        if (d > best_d) {
          best_d = d;
          best = f;
        }
      }
      if (best >= 0) faces_[best].outside.push_back(i);
    }
  }

  void add_point(int f0) {
    BuildFace& start = faces_[f0];
    // Eye point: the furthest point of the conflict list (Barber et al. 1996).
    int eye_slot = 0;
    Real far = -kInf;
    for (int k = 0; k < static_cast<int>(start.outside.size()); ++k) {
      const Real d = dist(start, start.outside[k]);
      if (d > far) {
        far = d;
        eye_slot = k;
      }
    }
    const int eye = start.outside[eye_slot];
    start.outside.erase(start.outside.begin() + eye_slot);
    // Quickhull's visibility up to the round-off of the distance (eps_round = tol / 2)
    // first; on a broken horizon retry with the eye's tolerance band counted hidden,
    // then visible; failing all, the eye is dropped.
    for (Real threshold : {0.5 * eps_, eps_, -eps_})
      if (add_point_with(f0, eye, threshold)) return;
  }

  // Adds `eye` (above face f0 by more than tol) to the hull, removing the faces it is
  // more than `threshold` above. Returns false, changing nothing, if the horizon is not
  // one simple loop.
  bool add_point_with(int f0, int eye, Real threshold) {
    struct Horizon {
      int a, b, face, edge;  // edge a -> b of visible face `face`, crossed to a hidden face
    };
    std::vector<int> visible, loop, forced;
    std::vector<Horizon> horizon;
    // A few rounds at most: each adds the hidden faces a new triangle would fold over.
    constexpr int kMaxRounds = 8;
    for (int round = 0;; ++round) {
      const int iteration = ++flood_stamp_;
      // Flood fill of the faces the eye sees, from f0 (which it sees by construction).
      visible.assign(1, f0);
      horizon.clear();
      loop.clear();
      std::vector<int> stack{f0};
      faces_[f0].stamp = iteration;
      faces_[f0].visible = true;
      while (!stack.empty()) {
        const int f = stack.back();
        stack.pop_back();
        for (int e = 0; e < 3; ++e) {
          const int g = faces_[f].adj[e];
          BuildFace& fg = faces_[g];
          if (fg.stamp != iteration) {
            fg.stamp = iteration;
            fg.visible = dist(fg, eye) > threshold ||
                         std::find(forced.begin(), forced.end(), g) != forced.end();
            if (fg.visible) {
              visible.push_back(g);
              stack.push_back(g);
            }
          }
          if (!fg.visible) horizon.push_back({faces_[f].v[e], faces_[f].v[(e + 1) % 3], f, e});
        }
      }

      // The horizon must be one simple loop: each vertex starts exactly one horizon
      // edge and following them visits every edge once.
      std::unordered_map<int, int> from;
      from.reserve(horizon.size() * 2);
      bool ok = horizon.size() >= 3;
      for (int k = 0; ok && k < static_cast<int>(horizon.size()); ++k)
        ok = from.emplace(horizon[k].a, k).second;
      if (ok) {
        int k = 0;
        for (std::size_t step = 0; step < horizon.size(); ++step) {
          loop.push_back(k);
          auto it = from.find(horizon[k].b);
          if (it == from.end()) {
            ok = false;
            break;
          }
          k = it->second;
        }
        ok = ok && k == 0;
      }
      // Round-off made the visible region something other than a disc (file comment).
      if (!ok) return false;

      // A new triangle (a, b, eye) next to a hidden face the eye is within tol of must
      // lie beyond the edge a-b, not fold back over the hidden face. In exact
      // arithmetic it cannot fold; with the eye within round-off of two nearly coplanar
      // faces it can, and then the hidden face is removed too.
      bool folded = false;
      for (const Horizon& h : horizon) {
        const int hidden = faces_[h.face].adj[h.edge];
        if (dist(faces_[hidden], eye) <= -eps_) continue;
        const Vec3 n = accurate_normal_dir(p_[h.a], p_[h.b], p_[eye]);
        if (n.dot(faces_[hidden].n) <= 0) {
          forced.push_back(hidden);
          folded = true;
        }
      }
      if (!folded) break;
      if (round + 1 == kMaxRounds) return false;
    }

    // Cone of new faces from the horizon to the eye, in loop order so that face k's
    // edge b -> eye is shared with face k + 1.
    const int first_new = static_cast<int>(faces_.size());
    const int m = static_cast<int>(loop.size());
    for (int j = 0; j < m; ++j) {
      const Horizon& h = horizon[loop[j]];
      const int hidden = faces_[h.face].adj[h.edge];
      BuildFace nf;
      nf.v = {h.a, h.b, eye};
      nf.adj = {hidden, first_new + (j + 1) % m, first_new + (j + m - 1) % m};
      if (dist(faces_[hidden], eye) > -eps_) {
        // The eye is within tol of the hidden face's plane: the new face is coplanar
        // with it up to tol and is merged with it later (file comment).
        nf.n = faces_[hidden].n;
        nf.d = faces_[hidden].d;
      } else {
        set_plane(nf, p_, faces_[h.face].n);
      }
      const int back = edge_index(faces_[hidden], h.b, h.a);
      faces_[hidden].adj[back] = first_new + j;
      faces_.push_back(std::move(nf));
    }

    // Orphaned points of the visible faces can only be outside the new cone.
    std::vector<int> orphans;
    for (int g : visible) {
      BuildFace& fg = faces_[g];
      orphans.insert(orphans.end(), fg.outside.begin(), fg.outside.end());
      fg.outside.clear();
      fg.outside.shrink_to_fit();
      fg.alive = false;
    }
    std::vector<int> cone(m);
    std::iota(cone.begin(), cone.end(), first_new);
    assign(orphans, cone);
    for (int c : cone)
      if (!faces_[c].outside.empty()) work_.push_back(c);
    return true;
  }

  const std::vector<Vec3>& p_;
  Real eps_;
  std::vector<BuildFace> faces_;
  std::vector<int> work_;
  int flood_stamp_ = 0;
};

/// Vertex indices of face f's loop (ConvexHull::face_vertices), on the arrays being
/// built as on the packed ones.
std::vector<int> loop_of(std::span<const ConvexHull::Face> faces, std::span<const ConvexHull::HalfEdge> half_edges,
                         int f) {
  if (f < 0 || f >= static_cast<int>(faces.size()))
    throw std::out_of_range("face_vertices: face " + std::to_string(f) + " out of range");
  const ConvexHull::Face& face = faces[f];
  std::vector<int> out;
  out.reserve(face.vertex_count);
  int h = face.first_edge;
  for (int k = 0; k < face.vertex_count; ++k) {
    out.push_back(half_edges[h].origin);
    h = half_edges[h].next;
  }
  return out;
}

}  // namespace

void ConvexHull::AlignedDelete::operator()(std::byte* p) const { ::operator delete[](p, std::align_val_t(64)); }

ConvexHull::ConvexHull(const std::vector<Vec3>& points) : ConvexShape(ShapeType::kConvexHull) {
  radius_ = 0;
  // The arrays are built here, then copied into one block (storage_, see the header).
  struct {
    std::vector<Vec3> vertices;
    std::vector<Face> faces;
    std::vector<HalfEdge> half_edges;
    std::vector<int> edges;
    std::vector<EdgeArc> edge_arcs;
    std::vector<VertexEdge> vertex_edges;
    std::vector<int> vertex_edge_begin;
    std::vector<Real> vertex_coords;
  } build;
  if (points.size() < 4)
    throw InvalidArgument("points must contain at least 4 points, got " +
                          std::to_string(points.size()));
  for (std::size_t i = 0; i < points.size(); ++i)
    if (!points[i].allFinite())
      throw InvalidArgument("points[" + std::to_string(i) + "] must be finite, got " +
                            to_string(points[i]));

  // Exact duplicates removed; sorting also makes the result independent of input order
  // for clouds that differ only by permutation.
  std::vector<Vec3> p = points;
  auto less = [](const Vec3& a, const Vec3& b) {
    return std::lexicographical_compare(a.data(), a.data() + 3, b.data(), b.data() + 3);
  };
  std::sort(p.begin(), p.end(), less);
  p.erase(std::unique(p.begin(), p.end(), [](const Vec3& a, const Vec3& b) { return a == b; }),
          p.end());
  const int n = static_cast<int>(p.size());
  if (n < 4)
    throw InvalidArgument("points must contain at least 4 distinct points, got " +
                          std::to_string(n));

  Vec3 max_abs = Vec3::Zero();
  for (const Vec3& q : p) max_abs = max_abs.cwiseMax(q.cwiseAbs());
  const Real eps_round = 3 * DBL_EPSILON * max_abs.sum();

  // Initial simplex. i0, i1: the most distant pair among the 6 axis-extreme points.
  std::array<int, 6> ext{};
  for (int axis = 0; axis < 3; ++axis)
    for (int i = 0; i < n; ++i) {
      if (p[i][axis] < p[ext[2 * axis]][axis]) ext[2 * axis] = i;
      if (p[i][axis] > p[ext[2 * axis + 1]][axis]) ext[2 * axis + 1] = i;
    }
  int i0 = ext[0], i1 = ext[1];
  Real extent = 0;
  for (int a = 0; a < 6; ++a)
    for (int b = a + 1; b < 6; ++b) {
      const Real d = (p[ext[a]] - p[ext[b]]).norm();
      if (d > extent) {
        extent = d;
        i0 = ext[a];
        i1 = ext[b];
      }
    }
  const Real base_tol = 2 * eps_round;  // file comment
  const Real thin = std::max(base_tol, std::sqrt(DBL_EPSILON) * extent);
  if (!(extent > thin))
    throw InvalidArgument("points must span a volume, got " + std::to_string(n) +
                          " distinct points that are coincident (extent " + fmt(extent) + " m)");
  // i2: furthest from the line i0-i1.
  const Vec3 axis = (p[i1] - p[i0]).normalized();
  int i2 = -1;
  Real width = 0;
  for (int i = 0; i < n; ++i) {
    const Real d = (p[i] - p[i0]).cross(axis).norm();
    if (d > width) {
      width = d;
      i2 = i;
    }
  }
  if (!(width > thin))
    throw InvalidArgument("points must span a volume, got points that are colinear (all within " +
                          fmt(width) + " m of a line)");
  // i3: furthest from the plane i0-i1-i2.
  const Vec3 normal = (p[i1] - p[i0]).cross(p[i2] - p[i0]).normalized();
  int i3 = -1;
  Real thickness = 0;
  for (int i = 0; i < n; ++i) {
    const Real d = std::abs(normal.dot(p[i] - p[i0]));
    if (d > thickness) {
      thickness = d;
      i3 = i;
    }
  }
  if (!(thickness > thin))
    throw InvalidArgument(
        "points must span a volume, got points that are coplanar (all within " + fmt(thickness) +
        " m of a plane)");
  // Base triangle CCW seen from outside, i.e. from the side away from i3.
  if (normal.dot(p[i3] - p[i0]) > 0) std::swap(i1, i2);

  // One build at tolerance `tol`, validated afterwards; false if the result is not a
  // closed convex polytope within the tolerance (see the file comment).
  auto attempt = [&](const Real tol) -> bool {
    build.vertices.clear();
    build.faces.clear();
    build.half_edges.clear();
    build.edges.clear();
    QuickhullBuilder qh(p, tol);
    qh.build(i0, i1, i2, i3);

    // ---- Merge coplanar triangles into polygonal faces. ----
    const auto& bf = qh.faces();
    std::vector<int> tri_of(bf.size(), -1);  // build face -> alive triangle index
    std::vector<int> tris;
    for (int f = 0; f < static_cast<int>(bf.size()); ++f)
      if (bf[f].alive) {
        tri_of[f] = static_cast<int>(tris.size());
        tris.push_back(f);
      }
    const int nt = static_cast<int>(tris.size());
    std::vector<Real> area(nt);
    for (int t = 0; t < nt; ++t) {
      const BuildFace& f = bf[tris[t]];
      area[t] = (p[f.v[1]] - p[f.v[0]]).cross(p[f.v[2]] - p[f.v[0]]).norm();
    }
    std::vector<int> order(nt);
    std::iota(order.begin(), order.end(), 0);
    std::stable_sort(order.begin(), order.end(), [&](int a, int b) { return area[a] > area[b]; });

    const Real eps_merge = 2 * tol;  // concave edges up to tol, plus the plane's round-off
    std::vector<int> group(nt, -1);
    std::vector<std::vector<int>> members;
    // Left turn u -> v -> w about n, up to v lying eps_merge on the reflex side.
    auto convex_turn = [&](int u, int v, int w, const Vec3& n) {
      return (p[v] - p[u]).cross(p[w] - p[v]).dot(n) >= -eps_merge * (p[w] - p[u]).norm();
    };
    for (int seed : order) {
      if (group[seed] >= 0) continue;
      const int g = static_cast<int>(members.size());
      members.emplace_back();
      const BuildFace& s = bf[tris[seed]];
      group[seed] = g;
      // The group's boundary loop, kept convex as triangles are added (a union of
      // nearly coplanar triangles need not be convex when some points bulge out by
      // more than the tolerance; such triangles stay separate faces).
      std::unordered_map<int, int> nxt, prv;
      for (int k = 0; k < 3; ++k) {
        nxt[s.v[k]] = s.v[(k + 1) % 3];
        prv[s.v[(k + 1) % 3]] = s.v[k];
      }
      std::vector<int> queue{seed};
      for (std::size_t qi = 0; qi < queue.size(); ++qi) {
        const int t = queue[qi];
        members[g].push_back(t);
        for (int e = 0; e < 3; ++e) {
          const int u = tri_of[bf[tris[t]].adj[e]];
          if (group[u] >= 0) continue;
          const BuildFace& fu = bf[tris[u]];
          bool coplanar = fu.n.dot(s.n) > 0;
          for (int k = 0; coplanar && k < 3; ++k)
            coplanar = std::abs(s.n.dot(p[fu.v[k]]) - s.d) <= eps_merge;
          if (!coplanar) continue;
          // Boundary edge a -> b of the group, crossed into triangle u with apex c.
          const int a = bf[tris[t]].v[e], b = bf[tris[t]].v[(e + 1) % 3];
          auto it = nxt.find(a);
          if (it == nxt.end() || it->second != b) continue;
          int c = -1;
          for (int k = 0; k < 3; ++k)
            if (fu.v[k] != a && fu.v[k] != b) c = fu.v[k];
          const bool c_on = nxt.count(c) > 0;
          if (!c_on) {
            // a -> b becomes a -> c -> b.
            if (!convex_turn(prv[a], a, c, s.n) || !convex_turn(a, c, b, s.n) ||
                !convex_turn(c, b, nxt[b], s.n))
              continue;
            nxt[a] = c, nxt[c] = b, prv[c] = a, prv[b] = c;
          } else if (nxt[b] == c && prv[a] != c) {
            // u fills the notch a -> b -> c: the boundary becomes a -> c, b goes inside.
            if (!convex_turn(prv[a], a, c, s.n) || !convex_turn(a, c, nxt[c], s.n)) continue;
            nxt[a] = c, prv[c] = a;
            nxt.erase(b), prv.erase(b);
          } else if (prv[a] == c && nxt[b] != c) {
            // u fills the notch c -> a -> b: the boundary becomes c -> b, a goes inside.
            if (!convex_turn(prv[c], c, b, s.n) || !convex_turn(c, b, nxt[b], s.n)) continue;
            nxt[c] = b, prv[b] = c;
            nxt.erase(a), prv.erase(a);
          } else {
            continue;  // would pinch the boundary or close a hole
          }
          group[u] = g;
          queue.push_back(u);
        }
      }
    }

    // Boundary loop of each group. A group whose boundary is not one simple loop (it could
    // only arise from round-off) is split back into its triangles.
    std::vector<std::vector<int>> loops;
    std::vector<Vec3> loop_normal;  // the seed triangle's (accurate) normal of each loop
    auto triangle_loop = [&](int t) {
      const BuildFace& f = bf[tris[t]];
      return std::vector<int>{f.v[0], f.v[1], f.v[2]};
    };
    for (const auto& mem : members) {
      if (mem.size() == 1) {
        loops.push_back(triangle_loop(mem[0]));
        loop_normal.push_back(bf[tris[mem[0]]].n);
        continue;
      }
      const int g = group[mem[0]];
      std::unordered_map<int, int> next;  // boundary edge a -> b, keyed by a
      bool ok = true;
      int start = -1;
      for (int t : mem)
        for (int e = 0; e < 3; ++e) {
          const BuildFace& f = bf[tris[t]];
          if (group[tri_of[f.adj[e]]] == g) continue;
          ok = ok && next.emplace(f.v[e], f.v[(e + 1) % 3]).second;
          start = f.v[e];
        }
      std::vector<int> loop;
      if (ok && start >= 0) {
        int v = start;
        for (std::size_t step = 0; step < next.size(); ++step) {
          loop.push_back(v);
          auto it = next.find(v);
          if (it == next.end()) break;
          v = it->second;
        }
        ok = v == start && loop.size() == next.size() && loop.size() >= 3;
      } else {
        ok = false;
      }
      if (ok) {
        loops.push_back(std::move(loop));
        loop_normal.push_back(bf[tris[mem[0]]].n);  // members[g][0] is the seed
      } else {
        for (int t : mem) {
          loops.push_back(triangle_loop(t));
          loop_normal.push_back(bf[tris[t]].n);
        }
      }
    }

    // Remove vertices shared by exactly two faces. Such a vertex lies within eps_merge of
    // both faces' planes (every face's vertices do), i.e. on the line where they meet up
    // to the tolerance: colinear points on an edge between two merged faces, or a point
    // that bulged out of an edge by a little more than tol. A subset of a convex loop's
    // vertices is still a convex loop. Never leave a face with fewer than 3 vertices.
    std::vector<int> degree(n, 0);
    for (const auto& l : loops)
      for (int v : l) ++degree[v];
    std::vector<char> drop(n, 0);
    for (int v = 0; v < n; ++v) drop[v] = degree[v] == 2;
    for (int pass = 0; pass < 4; ++pass) {  // each pass only un-drops; 4 passes suffice in practice
      bool changed = false;
      for (const auto& l : loops) {
        int keep = 0;
        for (int v : l) keep += !drop[v];
        if (keep < 3)
          for (int v : l)
            if (drop[v]) {
              drop[v] = 0;
              changed = true;
            }
      }
      if (!changed) break;
    }
    for (auto& l : loops) l.erase(std::remove_if(l.begin(), l.end(), [&](int v) { return drop[v]; }), l.end());

    // ---- Half-edge mesh over the used vertices. ----
    std::vector<int> new_index(n, -1);
    for (const auto& l : loops)
      for (int v : l)
        if (new_index[v] < 0) {
          new_index[v] = static_cast<int>(build.vertices.size());
          build.vertices.push_back(p[v]);
        }
    std::unordered_map<long long, int> edge_of;  // (origin, dest) -> half-edge
    auto key = [](int a, int b) { return (static_cast<long long>(a) << 32) | static_cast<unsigned>(b); };
    for (const auto& l : loops) {
      const int f = static_cast<int>(build.faces.size());
      const int m = static_cast<int>(l.size());
      const int first = static_cast<int>(build.half_edges.size());
      // The seed triangle's accurate normal (a Newell sum over a sliver would be as bad as
      // a plain cross product). The offset is the largest over the loop: every vertex of
      // the face is on or behind its plane (by at most 2 eps_merge), and over each merged
      // triangle the plane is no lower than the triangle's, so points dropped within tol
      // of a triangle stay within tol of the face.
      const Vec3 nn = loop_normal[f];
      Real off = -kInf;
      for (int v : l) off = std::max(off, nn.dot(p[v]));
      build.faces.push_back(Face{nn, off, first, m});
      for (int k = 0; k < m; ++k) {
        const int a = new_index[l[k]], b = new_index[l[(k + 1) % m]];
        edge_of[key(a, b)] = first + k;
        build.half_edges.push_back(HalfEdge{a, -1, first + (k + 1) % m, f});
      }
    }
    for (int h = 0; h < static_cast<int>(build.half_edges.size()); ++h) {
      const int a = build.half_edges[h].origin, b = build.half_edges[build.half_edges[h].next].origin;
      auto it = edge_of.find(key(b, a));
      build.half_edges[h].twin = it == edge_of.end() ? -1 : it->second;
      if (it != edge_of.end() && h < it->second) build.edges.push_back(h);
    }
    std::vector<int> out_degree(build.vertices.size(), 0);  // half-edges leaving each vertex
    for (const HalfEdge& h : build.half_edges) ++out_degree[h.origin];

    // Validation: closed (every half-edge has a twin), genus 0, vertices of degree >= 3,
    // every face loop convex
    // and CCW about its normal, and every vertex of each neighbouring face on or behind
    // the face's plane. Local convexity of a closed surface implies global convexity.
    const Real check = 4 * eps_merge;
    for (const int d : out_degree)
      if (d < 3) return false;  // every vertex a corner
    for (int h = 0; h < static_cast<int>(build.half_edges.size()); ++h) {
      const int t = build.half_edges[h].twin;
      if (t < 0 || build.half_edges[t].twin != h) return false;
    }
    const int ne = static_cast<int>(build.edges.size());
    if (2 * ne != static_cast<int>(build.half_edges.size())) return false;
    if (static_cast<int>(build.vertices.size()) - ne + static_cast<int>(build.faces.size()) != 2) return false;
    for (int f = 0; f < static_cast<int>(build.faces.size()); ++f) {
      const std::vector<int> l = loop_of(build.faces, build.half_edges, f);
      const int m = static_cast<int>(l.size());
      const Face& face = build.faces[f];
      for (int k = 0; k < m; ++k) {
        const Vec3& a = build.vertices[l[k]];
        const Vec3& b = build.vertices[l[(k + 1) % m]];
        const Vec3& c = build.vertices[l[(k + 2) % m]];
        if ((b - a).cross(c - b).dot(face.normal) < -check * (c - a).norm()) return false;
      }
    }
    for (const HalfEdge& h : build.half_edges) {
      const Face& face = build.faces[h.face];
      int e = build.half_edges[h.twin].next;
      for (int k = 0; k < build.faces[build.half_edges[h.twin].face].vertex_count; ++k, e = build.half_edges[e].next)
        if (face.normal.dot(build.vertices[build.half_edges[e].origin]) - face.offset > check) return false;
    }
    // Local convexity does not exclude a surface that wraps around twice, and dropped
    // points must stay within the tolerance: check every input point against every face
    // while that costs at most ~1e7 multiply-adds (a few ms; hulls used for simulation
    // are far smaller than that allows). Beyond it, only the hull's vertices are checked.
    const std::vector<Vec3>& all =
        static_cast<double>(p.size()) * build.faces.size() <= 1e7 ? p : build.vertices;
    if (static_cast<double>(all.size()) * build.faces.size() <= 1e7)
      for (const Face& face : build.faces)
        for (const Vec3& v : all)
          if (face.normal.dot(v) - face.offset > check) return false;
    return true;
  };

  // Tolerance escalation: round-off can still defeat the build for input within a few
  // ulps of degenerate (for example lattice points with noise at the tolerance); a
  // coarser tolerance absorbs such noise. 1e6 * tol is still ~1e-9 of the coordinates.
  bool built = false;
  for (const Real factor : {1.0, 1e3, 1e6})
    if ((built = attempt(factor * base_tol))) {
      tolerance_ = factor * base_tol;
      break;
    }
  if (!built)
    throw InvalidArgument(
        "points could not be built into a convex hull: the cloud is degenerate within "
        "round-off (" + std::to_string(n) + " distinct points)");
  for (const Vec3& v : build.vertices) aabb_.grow(v);

  // What the separating axis test reads (collide_hull_hull.cpp), precomputed once.
  const int nv = static_cast<int>(build.vertices.size());
  const int nh = static_cast<int>(build.half_edges.size());
  std::vector<int> edge_of_half(nh, -1);
  build.edge_arcs.resize(build.edges.size());
  for (int k = 0; k < static_cast<int>(build.edges.size()); ++k) {
    const int h = build.edges[k];
    const HalfEdge& he = build.half_edges[h];
    edge_of_half[h] = k;
    edge_of_half[he.twin] = k;
    build.edge_arcs[k] = EdgeArc{he.face, build.half_edges[he.twin].face, he.origin, build.half_edges[he.next].origin};
  }
  std::vector<int> out_half(nv, -1);
  for (int h = 0; h < nh; ++h) out_half[build.half_edges[h].origin] = h;  // the highest per vertex
  build.vertex_edge_begin.assign(nv + 1, 0);
  build.vertex_edges.clear();
  build.vertex_edges.reserve(nh);
  for (int v = 0; v < nv; ++v) {
    build.vertex_edge_begin[v] = static_cast<int>(build.vertex_edges.size());
    const int h0 = out_half[v];
    int h = h0;
    for (int guard = 0; guard < nh; ++guard) {
      build.vertex_edges.push_back(VertexEdge{edge_of_half[h], build.half_edges[build.half_edges[h].twin].origin});
      h = build.half_edges[build.half_edges[h].twin].next;
      if (h == h0) break;
    }
  }
  build.vertex_edge_begin[nv] = static_cast<int>(build.vertex_edges.size());
  build.vertex_coords.resize(3 * static_cast<std::size_t>(nv));
  for (int i = 0; i < nv; ++i)
    for (int axis = 0; axis < 3; ++axis) build.vertex_coords[axis * nv + i] = build.vertices[i][axis];
  for (const Vec3& v : build.vertices) vertex_centroid_ += v;
  vertex_centroid_ /= static_cast<Real>(nv);
  outer_radius_ = 0;
  for (const Vec3& v : build.vertices) outer_radius_ = std::max(outer_radius_, (v - vertex_centroid_).norm());

  // ---- One block, each array on its own cache line, in the order collide_hull_hull
  // reads them.
  std::size_t bytes = 0;
  auto place = [&bytes](const auto& v) {
    const std::size_t at = bytes;
    bytes += (v.size() * sizeof(v[0]) + 63) / 64 * 64;
    return at;
  };
  const std::size_t at_coords = place(build.vertex_coords), at_faces = place(build.faces),
                    at_vertices = place(build.vertices), at_arcs = place(build.edge_arcs),
                    at_ring = place(build.vertex_edges), at_ring_begin = place(build.vertex_edge_begin),
                    at_half = place(build.half_edges), at_edges = place(build.edges);
  storage_.reset(static_cast<std::byte*>(::operator new[](bytes, std::align_val_t(64))));
  auto copy = [this](const auto& v, std::size_t at) {
    using T = std::decay_t<decltype(v[0])>;
    T* out = reinterpret_cast<T*>(storage_.get() + at);
    std::uninitialized_copy(v.begin(), v.end(), out);
    return std::span<const T>(out, v.size());
  };
  vertex_coords_ = copy(build.vertex_coords, at_coords);
  faces_ = copy(build.faces, at_faces);
  vertices_ = copy(build.vertices, at_vertices);
  edge_arcs_ = copy(build.edge_arcs, at_arcs);
  vertex_edges_ = copy(build.vertex_edges, at_ring);
  vertex_edge_begin_ = copy(build.vertex_edge_begin, at_ring_begin);
  half_edges_ = copy(build.half_edges, at_half);
  edges_ = copy(build.edges, at_edges);
}

std::vector<int> ConvexHull::face_vertices(int f) const { return loop_of(faces_, half_edges_, f); }

int ConvexHull::support_index(const Vec3& dir) const {
  const int n = static_cast<int>(vertices_.size());
  if (n <= kBruteForceSupportMax) {
    // The first vertex of largest dot(v, dir), on the coordinate arrays (vectorised,
    // branch-free; the same vertex and bits as a scalar scan over vertices_).
    const Real* x = vertex_coords_.data();
    return detail::support_index_soa(x, x + n, x + 2 * n, n, dir);
  }
  // Hill climbing on the vertex graph (Cameron 1997, "Enhancing GJK"): on a convex
  // polytope a vertex with no better neighbour is a global maximum of dot(x, dir).
  // Each move strictly increases the value, so it visits every vertex at most once.
  // A vertex's neighbours are the other ends of the edges around it (vertex_edges_).
  int cur = 0;
  Real cur_d = vertices_[0].dot(dir);
  for (int step = 0; step < n; ++step) {
    int best = cur;
    for (int j = vertex_edge_begin_[cur], end = vertex_edge_begin_[cur + 1]; j < end; ++j) {
      const int nb = vertex_edges_[j].other;
      const Real d = vertices_[nb].dot(dir);
      if (d > cur_d) {
        cur_d = d;
        best = nb;
      }
    }
    if (best == cur) break;
    cur = best;
  }
  return cur;
}

Vec3 ConvexHull::support_core(const Vec3& dir) const { return vertices_[support_index(dir)]; }

void ConvexHull::supporting_face(const Vec3& dir, SupportingFace& face) const {
  int best = 0;
  Real best_d = -kInf;
  for (int f = 0; f < static_cast<int>(faces_.size()); ++f) {
    const Real d = faces_[f].normal.dot(dir);
    if (d > best_d) {
      best_d = d;
      best = f;
    }
  }
  face.feature = static_cast<std::uint32_t>(best);
  const Face& fc = faces_[best];
  face.normal = fc.normal;
  const int m = fc.vertex_count;
  // A face with more than kMaxFaceVertices vertices is replaced by kMaxFaceVertices of
  // its vertices spread evenly along the loop. A subset of a convex polygon's vertices
  // in loop order is a convex polygon inside it, so clipping stays valid; only slivers
  // of contact area near the skipped vertices are lost, and the manifold keeps 4
  // points anyway.
  const int count = std::min(m, kMaxFaceVertices);
  face.count = count;
  // Walk the loop once (no allocation: this runs per contact pair), keeping loop index
  // floor(k m / count) as the k-th vertex.
  int h = fc.first_edge;
  for (int idx = 0, k = 0; idx < m && k < count; ++idx, h = half_edges_[h].next)
    if (idx == static_cast<int>(static_cast<long long>(k) * m / count))
      face.vertices[k++] = vertices_[half_edges_[h].origin];
}

MassProperties ConvexHull::mass_properties(Real density) const {
  require_positive("density", density);
  // Sum over tetrahedra (reference point, face fan triangle); for a tetrahedron with
  // vertices 0, a, b, c and D = det[a b c]: volume D / 6, first moment D (a + b + c) / 24,
  // second moment int x x^T dV = D / 120 (a a^T + b b^T + c c^T + s s^T), s = a + b + c
  // (Tonon 2004, "Explicit exact formulas for the 3-D tetrahedron inertia tensor";
  // Eberly, "Polyhedral Mass Properties (Revisited)"). The reference point is the
  // vertex centroid, inside the hull, so every D is positive and the sums do not cancel.
  Vec3 ref = Vec3::Zero();
  for (const Vec3& v : vertices_) ref += v;
  ref /= static_cast<Real>(vertices_.size());
  Real vol = 0;
  Vec3 first = Vec3::Zero();
  Mat3 second = Mat3::Zero();
  for (int f = 0; f < static_cast<int>(faces_.size()); ++f) {
    const std::vector<int> l = face_vertices(f);
    const Vec3 a = vertices_[l[0]] - ref;
    for (std::size_t k = 1; k + 1 < l.size(); ++k) {
      const Vec3 b = vertices_[l[k]] - ref;
      const Vec3 c = vertices_[l[k + 1]] - ref;
      const Real det = a.dot(b.cross(c));
      const Vec3 s = a + b + c;
      vol += det / 6;
      first += det / 24 * s;
      second += det / 120 *
                (a * a.transpose() + b * b.transpose() + c * c.transpose() + s * s.transpose());
    }
  }
  MassProperties mp;
  mp.volume = vol;
  mp.mass = density * vol;
  const Vec3 d = first / vol;  // centre of mass relative to ref
  mp.center_of_mass = ref + d;
  const Mat3 c_com = second - vol * d * d.transpose();  // second moment about the COM
  mp.inertia = density * (c_com.trace() * Mat3::Identity() - c_com);
  mp.inertia = 0.5 * (mp.inertia + mp.inertia.transpose()).eval();
  return mp;
}

}  // namespace wmo
