// The contact solver's passes on lane groups (WideContacts, contact_solver.h).
//
// Each group holds up to eight constraints with no dynamic body in common; a pass
// gathers the group's bodies into 8-wide registers (one lane per constraint), runs the
// rows of contact_solver.cpp for all lanes at once, and scatters the velocities back.
// The rows are the same arithmetic as the scalar solver's (normal rows of points 0..3,
// then their friction rows, per constraint), in single precision, written out
// component by component so that eight constraints share each instruction. Within one
// constraint every row depends on the previous one; across lanes nothing does, which
// is where the parallelism is (Box2D v3's "wide" contact solver; SCENES.md measures
// scalar code on the pyramid's contact graph at 6.6x below an 8-wide version).
//
// The bodies the passes touch are copied into a compact array of 32-byte rows (v, w in
// float), numbered in the order the groups first use them, so a pass reads half a cache
// line per body instead of a 208-byte double state; masses and inertias travel with
// the constraints (they are fixed for the step). The motion since the step began (dp,
// dq) changes only between passes: set_motion turns each point's anchors with it once
// (turn_groups), and the passes read the turned anchors, separations and masses.
//
// On x86-64 the kernels are compiled twice (GCC target_clones): for AVX2 (8 floats per
// instruction) and for the baseline (SSE2, two halves); the loader picks one for the
// processor. No fused multiply-add is enabled in either, so both compute the same
// bits. Other processors get one portable build of the same source.
#include <algorithm>
#include <atomic>
#include <bit>
#include <cmath>
#include <cstring>
#include <thread>

#include "wmo/dynamics/contact_solver.h"

namespace wmo {
namespace {

typedef float v8 __attribute__((vector_size(32)));
typedef int m8 __attribute__((vector_size(32)));
constexpr int L = WideContacts::kLanes;
using Group = WideContacts::Group;
using Row = WideContacts::Row;
using MotionRow = WideContacts::MotionRow;

/// A body the passes change; the others (zero inverse mass: static and kinematic) only
/// receive exact zeros, so constraints may share them. The level order and the grouping
/// use the same test, so that the groups fill.
inline bool moves(const BodyState& s) { return s.inv_mass > 0; }

#define WMO_INLINE inline __attribute__((always_inline))
// Two builds of each kernel on x86-64 (AVX2 and the baseline), picked at load time;
// one elsewhere (aarch64: NEON 4-wide halves), or when WMO_WIDE_NO_CLONES asks for the
// baseline alone (the test that runs that build on AVX2 machines too).
#if defined(__x86_64__) && !defined(WMO_WIDE_NO_CLONES)
#define WMO_CLONES __attribute__((target_clones("avx2", "default")))
#else
#define WMO_CLONES
#endif

WMO_INLINE v8 ld(const float* p) {
  v8 r;
  std::memcpy(&r, p, sizeof r);
  return r;
}
WMO_INLINE void st(float* p, v8 v) { std::memcpy(p, &v, sizeof v); }
WMO_INLINE v8 splat(float x) { return v8{x, x, x, x, x, x, x, x}; }
/// std::max(a, b) lane by lane: (a < b) ? b : a.
WMO_INLINE v8 vmax(v8 a, v8 b) { return a < b ? b : a; }
/// std::min(a, b) lane by lane: (a < b) ? a : b.
WMO_INLINE v8 vmin(v8 a, v8 b) { return a < b ? a : b; }
/// Square root lane by lane. This file is compiled without errno for the math
/// functions (CMakeLists.txt), so the loop becomes one vector square root (correctly
/// rounded, as std::sqrt).
WMO_INLINE v8 vsqrt(v8 x) {
  v8 r;
  for (int l = 0; l < L; ++l) r[l] = __builtin_sqrtf(x[l]);
  return r;
}
/// True if any lane of the mask is set.
WMO_INLINE bool any(m8 m) {
  // Halves folded onto each other (three shuffles), not eight lane extractions.
  m8 r = m | __builtin_shufflevector(m, m, 4, 5, 6, 7, 0, 1, 2, 3);
  r = r | __builtin_shufflevector(r, r, 2, 3, 0, 1, 6, 7, 4, 5);
  r = r | __builtin_shufflevector(r, r, 1, 0, 3, 2, 5, 4, 7, 6);
  return r[0] != 0;
}

struct V3 {
  v8 x, y, z;
};
WMO_INLINE V3 ld3(const float (*p)[L]) { return V3{ld(p[0]), ld(p[1]), ld(p[2])}; }
WMO_INLINE V3 operator+(const V3& a, const V3& b) { return V3{a.x + b.x, a.y + b.y, a.z + b.z}; }
WMO_INLINE V3 operator-(const V3& a, const V3& b) { return V3{a.x - b.x, a.y - b.y, a.z - b.z}; }
WMO_INLINE V3 operator*(v8 s, const V3& a) { return V3{s * a.x, s * a.y, s * a.z}; }
WMO_INLINE v8 dot(const V3& a, const V3& b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
WMO_INLINE V3 cross(const V3& a, const V3& b) {
  return V3{a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}

/// Symmetric inverse inertia, lane by lane (xx, yy, zz, xy, xz, yz).
struct Inertia {
  v8 xx, yy, zz, xy, xz, yz;
};
WMO_INLINE Inertia ld_inertia(const float (*p)[L]) {
  return Inertia{ld(p[0]), ld(p[1]), ld(p[2]), ld(p[3]), ld(p[4]), ld(p[5])};
}
WMO_INLINE V3 mul(const Inertia& m, const V3& x) {
  return V3{m.xx * x.x + m.xy * x.y + m.xz * x.z, m.xy * x.x + m.yy * x.y + m.yz * x.z,
            m.xz * x.x + m.yz * x.y + m.zz * x.z};
}

/// A group's inverse masses and world inverse inertias, lane by lane (fixed for the step).
struct Masses {
  v8 ima, imb;
  Inertia ia, ib;
};
WMO_INLINE Masses ld_masses(const Group& g) {
  return Masses{ld(g.inv_mass_a), ld(g.inv_mass_b), ld_inertia(g.ia), ld_inertia(g.ib)};
}
/// The effective mass (kg) of a row along `dir` at anchors ra, rb: 1 / (inverse masses
/// plus angular terms), effective_mass() of contact_solver.cpp; 0 where the row moves
/// nothing.
WMO_INLINE v8 effective_mass(const Masses& m, const V3& ra, const V3& rb, const V3& dir) {
  const V3 cra = cross(ra, dir), crb = cross(rb, dir);
  const v8 k = m.ima + m.imb + dot(cra, mul(m.ia, cra)) + dot(crb, mul(m.ib, crb));
  const v8 zero = splat(0);
  return k > zero ? splat(1) / k : zero;
}

/// An 8 x 8 transpose: on return c[j][l] = r[l][j] (the AVX 8 x 8 float transpose:
/// unpack pairs, shuffle quads, swap 128-bit halves). In place.
WMO_INLINE void transpose8(v8 (&r)[8]) {
  v8 t[8], u[8];
  for (int k = 0; k < 8; k += 2) {
    t[k] = __builtin_shufflevector(r[k], r[k + 1], 0, 8, 1, 9, 4, 12, 5, 13);
    t[k + 1] = __builtin_shufflevector(r[k], r[k + 1], 2, 10, 3, 11, 6, 14, 7, 15);
  }
  for (int k = 0; k < 8; k += 4) {
    u[k] = __builtin_shufflevector(t[k], t[k + 2], 0, 1, 8, 9, 4, 5, 12, 13);
    u[k + 1] = __builtin_shufflevector(t[k], t[k + 2], 2, 3, 10, 11, 6, 7, 14, 15);
    u[k + 2] = __builtin_shufflevector(t[k + 1], t[k + 3], 0, 1, 8, 9, 4, 5, 12, 13);
    u[k + 3] = __builtin_shufflevector(t[k + 1], t[k + 3], 2, 3, 10, 11, 6, 7, 14, 15);
  }
  for (int k = 0; k < 4; ++k) {
    r[k] = __builtin_shufflevector(u[k], u[k + 4], 0, 1, 2, 3, 8, 9, 10, 11);
    r[k + 4] = __builtin_shufflevector(u[k], u[k + 4], 4, 5, 6, 7, 12, 13, 14, 15);
  }
}

/// The 8 rows of 8 floats (32 bytes) at idx, transposed: c[j] holds float j of every
/// lane's row.
template <class R>
WMO_INLINE void gather_rows(const std::array<int, L>& idx, const R* rows, v8 (&c)[8]) {
  static_assert(sizeof(R) == 32, "one row is one 8-float register");
  for (int l = 0; l < L; ++l) std::memcpy(&c[l], rows + idx[l], 32);
  transpose8(c);
}

/// One side of a group: its bodies' velocities, lane by lane.
struct Bodies {
  V3 v, w;
};

WMO_INLINE Bodies gather_velocities(const std::array<int, L>& idx, const Row* rows) {
  v8 c[8];
  gather_rows(idx, rows, c);
  return Bodies{V3{c[0], c[1], c[2]}, V3{c[3], c[4], c[5]}};
}

/// Writes each lane's velocities to its row in `idx` (Group::write_a / write_b: a sink
/// row for the lanes of static, kinematic and padding bodies, which the rows change by
/// exact zeros).
WMO_INLINE void scatter(const std::array<int, L>& idx, const Bodies& b, Row* rows) {
  const v8 zero = splat(0);
  v8 c[8] = {b.v.x, b.v.y, b.v.z, b.w.x, b.w.y, b.w.z, zero, zero};
  transpose8(c);
  for (int l = 0; l < L; ++l) std::memcpy(rows + idx[l], &c[l], 32);
}

/// One side of a group: its bodies' motion since the step began, lane by lane.
struct Motion {
  V3 dp;
  v8 qx, qy, qz, qw;  // dq
  v8 turn2;           // |dq.xyz|^2
};

WMO_INLINE Motion gather_motion(const std::array<int, L>& idx, const MotionRow* rows) {
  v8 c[8];
  gather_rows(idx, rows, c);
  return Motion{V3{c[0], c[1], c[2]}, c[3], c[4], c[5], c[6], c[7]};
}

/// dq * r - r, the anchor's displacement by the rotation since the step began (Eigen's
/// quaternion-vector product without its leading r: uv = 2 q x r, w uv + q x uv), so
/// that no large anchor is added and cancelled again.
WMO_INLINE V3 rotation_offset(const Motion& m, const V3& r) {
  const V3 q{m.qx, m.qy, m.qz};
  V3 uv = cross(q, r);
  uv = uv + uv;
  return m.qw * uv + cross(q, uv);
}

/// apply() of contact_solver.cpp: impulse p at anchors ra (on a) and rb (on b).
WMO_INLINE void apply(Bodies& a, Bodies& b, const Masses& m, const V3& ra, const V3& rb, const V3& p) {
  a.v = a.v - m.ima * p;
  a.w = a.w - mul(m.ia, cross(ra, p));
  b.v = b.v + m.imb * p;
  b.w = b.w + mul(m.ib, cross(rb, p));
}

WMO_INLINE V3 relative_velocity(const Bodies& a, const Bodies& b, const V3& ra, const V3& rb) {
  return (b.v + cross(b.w, rb)) - (a.v + cross(a.w, ra));
}

/// row_mass() of contact_solver.h, lane by lane: the step's effective mass `stale`
/// unless the lane turned (`lane_turned`) and the one at the turned anchors, `current`,
/// differs from it by more than 10%. A padding point (a lane with fewer points, or a
/// padding lane) has a stale mass of 0 and keeps it: it pushes nothing.
WMO_INLINE v8 lane_row_mass(v8 stale, v8 current, m8 lane_turned) {
  const v8 diff = stale - current;
  const m8 keep = (vmax(diff, -diff) <= splat(0.1f) * current) | (stale == splat(0)) | ~lane_turned;
  return keep ? stale : current;
}

/// What the passes read of the motion, for the motion in `rows` (WideContacts::
/// set_motion): per point its anchors turned with the bodies about their centres of
/// curvature (current_anchors of contact_solver.cpp), its separation now (at the step's
/// start plus the change the motion made) and its effective mass (row_mass). The
/// motion changes only between passes (integrate_positions), so the passes share these
/// instead of each turning the anchors again.
WMO_CLONES void turn_groups(Group* groups, int count, const MotionRow* rows, bool centroid_rows) {
  const v8 zero = splat(0);
  for (int k = 0; k < count; ++k) {
    Group& g = groups[k];
    const Motion a = gather_motion(g.row_a, rows), b = gather_motion(g.row_b, rows);
    const Masses m = ld_masses(g);
    const V3 n = ld3(g.n), t1 = ld3(g.t1), t2 = ld3(g.t2);
    const V3 dp = b.dp - a.dp;
    // Lanes whose bodies turned by more than kRowMassTurn since the step began (the
    // others keep the step's effective mass, row_mass()); none: the turned masses are
    // not evaluated at all.
    const m8 lane_turned = vmax(a.turn2, b.turn2) > splat(static_cast<float>(kRowMassTurnSin2));
    const bool turned = any(lane_turned);
    const v8 points = ld(g.count);
    V3 sum_a{zero, zero, zero}, sum_b{zero, zero, zero};
    for (int j = 0; j < g.points; ++j) {
      Group::Point& p = g.p[j];
      const V3 ra0 = ld3(p.ra), rb0 = ld3(p.rb);
      const V3 ra = ra0 + rotation_offset(a, ra0 + ld(p.ca_n) * n);
      const V3 rb = rb0 + rotation_offset(b, rb0 + ld(p.cb_n) * n);
      const V3 d = dp + ((rb - rb0) - (ra - ra0));
      st(p.separation, dot(n, d) + ld(p.base_separation));
      // The normal row's mass at the turned anchors (lane_row_mass).
      const v8 normal_mass = ld(p.normal_mass);
      st(p.mass_now, turned ? lane_row_mass(normal_mass, effective_mass(m, ra, rb, n), lane_turned) : normal_mass);
      if (turned && g.friction) {
        // The tangent rows' masses by the same rule, kept in place: the passes read
        // them from tangent_mass (padding points keep their 0).
        for (int r = 0; r < 2; ++r)
          st(p.tangent_mass[r],
             lane_row_mass(ld(p.tangent_mass[r]), effective_mass(m, ra, rb, r == 0 ? t1 : t2), lane_turned));
      }
      for (int r = 0; r < 3; ++r) {
        st(p.ra_now[r], r == 0 ? ra.x : r == 1 ? ra.y : ra.z);
        st(p.rb_now[r], r == 0 ? rb.x : r == 1 ? rb.y : rb.z);
      }
      if (centroid_rows) {
        const m8 real = splat(static_cast<float>(j)) < points;
        const v8 w = real ? splat(1) : zero;
        sum_a = sum_a + w * ra;
        sum_b = sum_b + w * rb;
      }
    }
    if (!centroid_rows) continue;
    // The centroid row's anchors and coupling (solve_groups).
    const v8 inv_points = points > zero ? splat(1) / points : zero;
    const V3 ca = cross(inv_points * sum_a, n), cb = cross(inv_points * sum_b, n);
    st(g.coupling, points * points * (m.ima + m.imb + dot(ca, mul(m.ia, ca)) + dot(cb, mul(m.ib, cb))));
    for (int r = 0; r < 3; ++r) {
      st(g.cn_a[r], r == 0 ? ca.x : r == 1 ? ca.y : ca.z);
      st(g.cn_b[r], r == 0 ? cb.x : r == 1 ? cb.y : cb.z);
    }
  }
}

/// prepare_contacts() of contact_solver.cpp, lane by lane: each point's effective
/// masses along n, t1 and t2 at the step's anchors and its approach velocity n.(v_b -
/// v_a) at the velocities in `rows`. Padding points (past a lane's count, and padding
/// lanes) get masses of 0: they push nothing.
WMO_CLONES void prepare_groups(Group* groups, int count, const Row* rows) {
  const v8 zero = splat(0);
  for (int k = 0; k < count; ++k) {
    Group& g = groups[k];
    const Bodies a = gather_velocities(g.row_a, rows), b = gather_velocities(g.row_b, rows);
    const Masses m = ld_masses(g);
    const V3 n = ld3(g.n), t1 = ld3(g.t1), t2 = ld3(g.t2);
    const v8 points = ld(g.count);
    auto mass = [&](const V3& ra, const V3& rb, const V3& dir, m8 real) {
      return real ? effective_mass(m, ra, rb, dir) : zero;
    };
    for (int j = 0; j < g.points; ++j) {
      Group::Point& p = g.p[j];
      const m8 real = splat(static_cast<float>(j)) < points;
      const V3 ra = ld3(p.ra), rb = ld3(p.rb);
      st(p.normal_mass, mass(ra, rb, n, real));
      st(p.tangent_mass[0], mass(ra, rb, t1, real));
      st(p.tangent_mass[1], mass(ra, rb, t2, real));
      st(p.relative_velocity, dot(n, relative_velocity(a, b, ra, rb)));
    }
  }
}

WMO_CLONES void warm_start_groups(const Group* groups, int count, Row* rows) {
  for (int k = 0; k < count; ++k) {
    const Group& g = groups[k];
    Bodies a = gather_velocities(g.row_a, rows), b = gather_velocities(g.row_b, rows);
    const Masses m = ld_masses(g);
    const V3 n = ld3(g.n), t1 = ld3(g.t1), t2 = ld3(g.t2);
    for (int j = 0; j < g.points; ++j) {
      const Group::Point& p = g.p[j];
      const V3 imp = ld(p.normal_impulse) * n + ld(p.tangent_impulse[0]) * t1 + ld(p.tangent_impulse[1]) * t2;
      apply(a, b, m, ld3(p.ra_now), ld3(p.rb_now), imp);
    }
    scatter(g.write_a, a, rows);
    scatter(g.write_b, b, rows);
  }
}

/// One softness (Softness), as the passes read it.
struct SoftLanes {
  float bias_rate, mass_scale, impulse_scale, a2;
};

WMO_CLONES void solve_groups(Group* groups, int count, Row* rows, SoftLanes dyn, SoftLanes fix, float inv_h,
                             float push_max, bool use_bias, bool reverse, bool centroid_rows) {
  const v8 zero = splat(0), one = splat(1), vinv_h = splat(inv_h);
  const v8 neg_push = splat(-push_max);
  const v8 bias_rate_dyn = splat(dyn.bias_rate), bias_rate_fix = splat(fix.bias_rate);
  const v8 soft_mass_dyn = splat(use_bias ? dyn.mass_scale : 1), soft_mass_fix = splat(use_bias ? fix.mass_scale : 1);
  const v8 soft_impulse_dyn = splat(use_bias ? dyn.impulse_scale : 0);
  const v8 soft_impulse_fix = splat(use_bias ? fix.impulse_scale : 0);
  const v8 a2_dyn = splat(dyn.a2), a2_fix = splat(fix.a2);
  // 1 / a2 for the centroid row's regularisation of the biased rows (0 for a rigid
  // spring, and in the relax passes).
  const v8 inv_a2_dyn = splat(use_bias && dyn.a2 > 0 ? 1 / dyn.a2 : 0);
  const v8 inv_a2_fix = splat(use_bias && fix.a2 > 0 ? 1 / fix.a2 : 0);
  for (int kk = 0; kk < count; ++kk) {
    const int k = reverse ? count - 1 - kk : kk;
    Group& g = groups[k];
    const m8 fixed = ld(g.fixed) != zero;
    const v8 bias_rate = fixed ? bias_rate_fix : bias_rate_dyn;
    const v8 soft_mass = fixed ? soft_mass_fix : soft_mass_dyn;
    const v8 soft_impulse = fixed ? soft_impulse_fix : soft_impulse_dyn;
    const v8 a2 = fixed ? a2_fix : a2_dyn;
    const v8 inv_a2 = fixed ? inv_a2_fix : inv_a2_dyn;
    Bodies a = gather_velocities(g.row_a, rows), b = gather_velocities(g.row_b, rows);
    const Masses m = ld_masses(g);
    const V3 n = ld3(g.n);
    const v8 allow = ld(g.allow);
    // soft_bias() of contact_solver.cpp: the spring's, and past the allowance the
    // excess within the substep, under push_max.
    auto lane_bias = [&](v8 s) { return vmax(vmin(bias_rate * s, (s + allow) * vinv_h), neg_push); };
    if (centroid_rows && g.points >= 2) {
      // The centroid row (centroid_row() of contact_solver.cpp, which says why): one
      // impulse increment d at every point of the manifold that meets the rows'
      // targets on average, d = -(sum vn + sum bias + sum g l) / (sum K_ij + sum g),
      // before the point rows correct the rest. Lanes with fewer than two points or a
      // speculative point (s > 0) are left out.
      const v8 cnt = ld(g.count);
      m8 ok = cnt > one;
      v8 sum = zero, sum_g = zero, min_l = splat(3.0e38f);
      // g_i = K_ii impulse_scale / mass_scale = K_ii / (L a2) for the biased rows'
      // spring; 0 for the relax passes' rigid rows.
      const v8 g_scale = use_bias ? ld(g.inv_stiffening) * inv_a2 : zero;
      for (int j = 0; j < g.points; ++j) {
        const Group::Point& p = g.p[j];
        const m8 real = splat(static_cast<float>(j)) < cnt;
        const v8 ni = ld(p.normal_impulse);
        const v8 s = ld(p.separation);
        ok = ok & (~real | (s <= zero));
        min_l = real & (ni < min_l) ? ni : min_l;
        if (use_bias) {
          const v8 mass = ld(p.mass_now);
          const v8 gi = real & (mass > zero) ? g_scale / mass : zero;
          sum = sum + (real ? lane_bias(s) : zero) + gi * ni;
          sum_g = sum_g + gi;
        }
      }
      // vn at the centroid: n.(v_b - v_a) + w_b.(rc_b x n) - w_a.(rc_a x n).
      const V3 cna = ld3(g.cn_a), cnb = ld3(g.cn_b);
      const v8 vnc = dot(n, b.v - a.v) + dot(b.w, cnb) - dot(a.w, cna);
      const v8 denom = ld(g.coupling) + sum_g;
      const m8 live = ok & (denom > zero);
      v8 d = -(cnt * vnc + sum) / (live ? denom : one);
      d = vmax(d, -min_l);
      d = live ? d : zero;
      m8 first[4], first_any = m8{};
      for (int j = 0; j < g.points; ++j) {
        Group::Point& p = g.p[j];
        const m8 real = splat(static_cast<float>(j)) < cnt;
        const v8 dj = real ? d : zero;
        st(p.normal_impulse, ld(p.normal_impulse) + dj);
        const v8 max_ni = ld(p.max_normal_impulse);
        first[j] = (dj > zero) & (max_ni == zero);
        first_any = first_any | first[j];
        st(p.max_normal_impulse, vmax(max_ni, dj));
      }
      // record_push() for the points this row pushes first: the approach at the
      // centroid stands for every point's (rare: a contact's first push in the step).
      if (any(first_any)) {
        for (int j = 0; j < g.points; ++j) {
          Group::Point& p = g.p[j];
          st(p.relative_velocity, first[j] ? vnc : ld(p.relative_velocity));
          st(p.push_gap, first[j] ? zero : ld(p.push_gap));
        }
      }
      // apply() of cnt d n at the centroid: cross(rc, cnt d n) = cnt d (rc x n).
      const v8 push = cnt * d;
      a.v = a.v - (m.ima * push) * n;
      a.w = a.w - push * mul(m.ia, cna);
      b.v = b.v + (m.imb * push) * n;
      b.w = b.w + push * mul(m.ib, cnb);
    }
    // A backward pass visits the points backward too (symmetric Gauss-Seidel within the
    // manifold as across the constraints; solve_contacts does the same).
    for (int jj = 0; jj < g.points; ++jj) {
      const int j = reverse ? g.points - 1 - jj : jj;
      Group::Point& p = g.p[j];
      // The anchors, separation and effective mass at the current motion (turn_groups).
      const V3 ra = ld3(p.ra_now), rb = ld3(p.rb_now);
      const v8 s = ld(p.separation);
      const v8 normal_mass = ld(p.mass_now);
      // s > 0: speculative (bias s / h, full mass, no decay); otherwise the soft bias
      // when use_bias, else none.
      const m8 spec = s > zero;
      const v8 soft_bias = use_bias ? lane_bias(s) : zero;
      const v8 bias = spec ? s * vinv_h : soft_bias;
      v8 row_mass_scale = soft_mass, row_impulse_scale = soft_impulse;
      if (use_bias && g.stiffened) {  // row_target() of contact_solver.cpp
        const v8 stiff = ld(g.stiffening);
        const m8 stiffened = stiff > one;
        const v8 la2 = stiff * a2;
        const v8 is = one / (one + la2);
        row_mass_scale = stiffened ? la2 * is : row_mass_scale;
        row_impulse_scale = stiffened ? is : row_impulse_scale;
      }
      const v8 mass_scale = spec ? one : row_mass_scale;
      const v8 impulse_scale = spec ? zero : row_impulse_scale;
      const v8 vn = dot(n, relative_velocity(a, b, ra, rb));
      const v8 ni = ld(p.normal_impulse);
      v8 impulse = -normal_mass * mass_scale * (vn + bias) - impulse_scale * ni;
      const v8 next = vmax(ni + impulse, zero);
      impulse = next - ni;
      st(p.normal_impulse, next);
      const v8 max_ni = ld(p.max_normal_impulse);
      const m8 first = (impulse > zero) & (max_ni == zero);
      st(p.relative_velocity, first ? vn : ld(p.relative_velocity));
      st(p.push_gap, first ? vmax(s, zero) : ld(p.push_gap));
      st(p.max_normal_impulse, vmax(max_ni, impulse));
      apply(a, b, m, ra, rb, impulse * n);
    }
    if (g.friction) {
      const V3 t1 = ld3(g.t1), t2 = ld3(g.t2);
      const v8 mu = ld(g.mu);
      const m8 has_mu = mu != zero;
      for (int jj = 0; jj < g.points; ++jj) {
        const int j = reverse ? g.points - 1 - jj : jj;  // backward in a backward pass
        Group::Point& p = g.p[j];
        const V3 ra = ld3(p.ra_now), rb = ld3(p.rb_now);
        const V3 dv = relative_velocity(a, b, ra, rb);
        const v8 ti0 = ld(p.tangent_impulse[0]), ti1 = ld(p.tangent_impulse[1]);
        v8 x0 = ti0 - ld(p.tangent_mass[0]) * dot(t1, dv);
        v8 x1 = ti1 - ld(p.tangent_mass[1]) * dot(t2, dv);
        // Coulomb cone (solve_contacts): back onto the circle of radius mu lambda_n.
        const v8 limit = mu * ld(p.normal_impulse);
        const v8 len2 = x0 * x0 + x1 * x1;
        const m8 over = len2 > limit * limit;
        // Where over, len2 > limit^2 >= 0, so the root is positive; the other lanes'
        // quotients (possibly 0 / 0) are discarded.
        if (any(over)) {
          const v8 scale = limit / vsqrt(len2);
          x0 = over ? x0 * scale : x0;
          x1 = over ? x1 * scale : x1;
        }
        // Lanes without friction keep their tangent impulses, as the scalar pass skips
        // their friction rows.
        x0 = has_mu ? x0 : ti0;
        x1 = has_mu ? x1 : ti1;
        const v8 d0 = x0 - ti0, d1 = x1 - ti1;
        st(p.tangent_impulse[0], x0);
        st(p.tangent_impulse[1], x1);
        apply(a, b, m, ra, rb, d0 * t1 + d1 * t2);
      }
    }
    scatter(g.write_a, a, rows);
    scatter(g.write_b, b, rows);
  }
}

/// A symmetric inverse inertia into lane `lane` of a Group's ia or ib (xx, yy, zz, xy,
/// xz, yz).
void pack_inertia(const Mat3& m, float (*out)[L], int lane) {
  out[0][lane] = static_cast<float>(m(0, 0));
  out[1][lane] = static_cast<float>(m(1, 1));
  out[2][lane] = static_cast<float>(m(2, 2));
  out[3][lane] = static_cast<float>(m(0, 1));
  out[4][lane] = static_cast<float>(m(0, 2));
  out[5][lane] = static_cast<float>(m(1, 2));
}

/// A team runs the passes only with at least this many groups per thread.
constexpr int kParallelMinGroups = 64;
/// How many constraints past the first unplaced one build examines to fill a group:
/// enough to fill the pyramid's (measured below), few enough that a long run of
/// conflicting constraints costs little.
constexpr int kLookahead = 32;

/// All threads of a team wait here until every one has arrived; what each wrote
/// before is then visible to all. Spins (a pass's regions take a few hundred
/// microseconds on a large pile), then yields, so a thread the system has descheduled
/// is not spun against indefinitely.
class SpinBarrier {
 public:
  explicit SpinBarrier(int threads) : threads_(threads) {}
  void wait() {
    const unsigned gen = generation_.load(std::memory_order_acquire);
    if (arrived_.fetch_add(1, std::memory_order_acq_rel) == threads_ - 1) {
      arrived_.store(0, std::memory_order_relaxed);
      generation_.store(gen + 1, std::memory_order_release);
      return;
    }
    for (int spins = 0; generation_.load(std::memory_order_acquire) == gen; ++spins) {
      if (spins < 2048) {
#if defined(__x86_64__) || defined(__i386__)
        __builtin_ia32_pause();
#endif
      } else {
        std::this_thread::yield();
      }
    }
  }

 private:
  const int threads_;
  std::atomic<int> arrived_{0};
  std::atomic<unsigned> generation_{0};
};

/// region_band_order's per-thread scratch: the bodies whose colour masks to clear at
/// a band's end, and a band's constraints while they are sorted by colour.
std::vector<int>& scratch_touched() {
  thread_local std::vector<int> v;
  return v;
}
std::vector<int>& scratch_buffer() {
  thread_local std::vector<int> v;
  return v;
}

}  // namespace

void region_band_order(const std::vector<ContactConstraint>& cs, const std::vector<BodyState>& states,
                       const std::vector<int>& region, int regions, const std::vector<Real>& height,
                       const std::vector<Real>& band, std::vector<int>& order, std::vector<int>& starts,
                       std::vector<std::uint64_t>& scratch) {
  // scratch: [0, bodies) the colours each body has taken in the current band (a bit
  // mask), then each constraint's colour (a byte per constraint, by index).
  const std::size_t total = cs.size(), bodies = states.size();
  scratch.assign(bodies + total / 8 + 1, 0);
  std::uint64_t* used = scratch.data();
  std::uint8_t* colour_of = reinterpret_cast<std::uint8_t*>(used + bodies);
  starts.assign(static_cast<std::size_t>(regions) + 2, 0);
  for (std::size_t k = 0; k < total; ++k) ++starts[static_cast<std::size_t>(region[k]) + 1];
  for (int r = 0; r <= regions; ++r) starts[static_cast<std::size_t>(r) + 1] += starts[static_cast<std::size_t>(r)];
  order.resize(total);
  {
    std::vector<int> next(starts.begin(), starts.end() - 1);
    for (std::size_t k = 0; k < total; ++k) order[static_cast<std::size_t>(next[static_cast<std::size_t>(region[k])]++)] = static_cast<int>(k);
  }
  // Per band (a run of the region's sequence), a counting sort by colour, stable.
  std::vector<int>& touched = scratch_touched();
  std::vector<int>& buffer = scratch_buffer();
  std::array<int, 65> bucket;
  auto sort_band = [&](int begin, int end) {
    bucket.fill(0);
    for (int q = begin; q < end; ++q) ++bucket[colour_of[order[static_cast<std::size_t>(q)]] + 1u];
    for (int c = 0; c < 64; ++c) bucket[static_cast<std::size_t>(c) + 1] += bucket[static_cast<std::size_t>(c)];
    buffer.resize(static_cast<std::size_t>(end - begin));
    for (int q = begin; q < end; ++q) {
      const int k = order[static_cast<std::size_t>(q)];
      buffer[static_cast<std::size_t>(bucket[colour_of[k]]++)] = k;
    }
    std::copy(buffer.begin(), buffer.end(), order.begin() + begin);
  };
  for (int r = 0; r <= regions; ++r) {
    const int begin = starts[static_cast<std::size_t>(r)], end = starts[static_cast<std::size_t>(r) + 1];
    Real top = 0, width = 0;
    int band_begin = begin;
    for (int q = begin; q < end; ++q) {
      const int k = order[static_cast<std::size_t>(q)];
      if (q == begin || !(height[static_cast<std::size_t>(k)] >= top - width)) {  // a NaN height opens a band
        if (q > band_begin) sort_band(band_begin, q);
        band_begin = q;
        for (const int body : touched) used[body] = 0;
        touched.clear();
        top = height[static_cast<std::size_t>(k)];
        width = band[static_cast<std::size_t>(k)];
      }
      const ContactConstraint& c = cs[static_cast<std::size_t>(k)];
      const bool da = moves(states[c.body_a]), db = moves(states[c.body_b]);
      const std::uint64_t taken = (da ? used[c.body_a] : 0) | (db ? used[c.body_b] : 0);
      const int colour = taken == ~std::uint64_t(0) ? 63 : std::countr_one(taken);
      colour_of[k] = static_cast<std::uint8_t>(colour);
      for (const int body : {da ? c.body_a : -1, db ? c.body_b : -1}) {
        if (body < 0) continue;
        if (!used[body]) touched.push_back(body);
        used[body] |= std::uint64_t(1) << colour;
      }
    }
    if (end > band_begin) sort_band(band_begin, end);
    for (const int body : touched) used[body] = 0;
    touched.clear();
  }
}

void dependency_level_order(const std::vector<ContactConstraint>& cs, const std::vector<BodyState>& states,
                            std::vector<int>& order, std::vector<int>& scratch) {
  // scratch: [0, bodies) next free level per body, then one level per constraint, then
  // the level starts of the counting sort.
  const std::size_t total = cs.size(), bodies = states.size();
  scratch.assign(bodies + total, 0);
  int* body_level = scratch.data();
  int levels = 0;
  for (std::size_t k = 0; k < total; ++k) {
    const ContactConstraint& c = cs[k];
    const bool da = moves(states[c.body_a]), db = moves(states[c.body_b]);
    const int level = std::max(da ? body_level[c.body_a] : 0, db ? body_level[c.body_b] : 0);
    if (da) body_level[c.body_a] = level + 1;
    if (db) body_level[c.body_b] = level + 1;
    scratch[bodies + k] = level;
    levels = std::max(levels, level + 1);
  }
  // Counting sort by level, stable.
  scratch.resize(bodies + total + levels + 1);
  int* start = scratch.data() + bodies + total;
  std::fill(start, start + levels + 1, 0);
  const int* level_of = scratch.data() + bodies;
  for (std::size_t k = 0; k < total; ++k) ++start[level_of[k] + 1];
  for (int l = 0; l < levels; ++l) start[l + 1] += start[l];
  order.resize(total);
  for (std::size_t k = 0; k < total; ++k) order[start[level_of[k]]++] = static_cast<int>(k);
}

void WideContacts::build(const std::vector<ContactConstraint>& cs, const std::vector<int>& order,
                         const std::vector<BodyState>& states, int dummy, const ContactSoftness& soft,
                         Real max_sag, Real h, bool centroid_rows, const std::vector<int>& starts) {
  centroid_rows_ = centroid_rows;
  groups_.clear();
  source_.clear();
  // Rows: 0 for the padding lanes, then a sink row per region (every other row, so
  // that no two share a cache line; see Group::write_a), then the bodies in the order
  // the groups use them.
  const int sinks = std::max(1, static_cast<int>(starts.size()) - 1);
  row_of_.assign(states.size(), -1);
  row_state_.assign(static_cast<std::size_t>(1 + 2 * sinks), dummy);
  row_moves_.assign(static_cast<std::size_t>(1 + 2 * sinks), 0);
  row_of_[dummy] = 0;
  auto row = [&](int body) {
    int& r = row_of_[body];
    if (r < 0) {
      r = static_cast<int>(row_state_.size());
      row_state_.push_back(body);
      row_moves_.push_back(moves(states[body]) ? 1 : 0);
    }
    return r;
  };
  const int count = static_cast<int>(order.size());
  // Region boundaries (starts): each recorded as the index of the group it opens; a
  // group never reaches past the next one.
  region_start_.clear();
  std::size_t next_start = 0;
  auto record_starts = [&](int q) {
    for (; next_start < starts.size() && starts[next_start] <= q; ++next_start) region_start_.push_back(group_count());
  };
  // Filling a group: the first constraint not yet placed opens it, and up to
  // kLookahead more are examined after it. One joins unless it shares a dynamic body
  // with the group (no two lanes may) or with one examined and passed over before it
  // in this group (for every body the constraints keep their order, so the passes
  // compute what the given order computes, bit for bit: constraints with no dynamic
  // body in common commute). In a region's level order the levels of a wide pile
  // hold a few constraints each; taking only the run up to the first conflict left
  // the pyramid's groups a fifth emptier when it was cut into regions.
  placed_.assign(static_cast<std::size_t>(count), 0);
  in_group_.assign(states.size(), -1);
  passed_over_.assign(states.size(), -1);
  for (int q = 0; q < count;) {
    record_starts(q);
    const int limit = next_start < starts.size() ? starts[next_start] : count;
    const int gid = group_count();
    const int sink = 1 + 2 * std::max(0, static_cast<int>(region_start_.size()) - 1);
    Group& g = groups_.emplace_back();
    g.body_a.fill(dummy);
    g.body_b.fill(dummy);
    g.row_a.fill(0);
    g.row_b.fill(0);
    g.write_a.fill(sink);
    g.write_b.fill(sink);
    int lanes = 0;
    for (int at = q, examined = 0; lanes < L && at < limit && examined <= kLookahead; ++at) {
      if (placed_[static_cast<std::size_t>(at)]) continue;
      ++examined;
      const int k = order[at];
      const ContactConstraint& c = cs[k];
      const bool ma = moves(states[c.body_a]), mb = moves(states[c.body_b]);
      if ((ma && (in_group_[c.body_a] == gid || passed_over_[c.body_a] == gid)) ||
          (mb && (in_group_[c.body_b] == gid || passed_over_[c.body_b] == gid))) {
        if (ma) passed_over_[c.body_a] = gid;
        if (mb) passed_over_[c.body_b] = gid;
        continue;
      }
      placed_[static_cast<std::size_t>(at)] = 1;
      if (ma) in_group_[c.body_a] = gid;
      if (mb) in_group_[c.body_b] = gid;
      const BodyState& sa = states[c.body_a];
      const BodyState& sb = states[c.body_b];
      g.body_a[lanes] = c.body_a;
      g.body_b[lanes] = c.body_b;
      g.row_a[lanes] = row(c.body_a);
      g.row_b[lanes] = row(c.body_b);
      if (ma) g.write_a[lanes] = g.row_a[lanes];
      if (mb) g.write_b[lanes] = g.row_b[lanes];
      g.inv_mass_a[lanes] = static_cast<float>(sa.inv_mass);
      g.inv_mass_b[lanes] = static_cast<float>(sb.inv_mass);
      pack_inertia(sa.inv_inertia, g.ia, lanes);
      pack_inertia(sb.inv_inertia, g.ib, lanes);
      for (int r = 0; r < 3; ++r) {
        g.n[r][lanes] = static_cast<float>(c.normal[r]);
        g.t1[r][lanes] = static_cast<float>(c.tangent1[r]);
        g.t2[r][lanes] = static_cast<float>(c.tangent2[r]);
      }
      g.mu[lanes] = static_cast<float>(c.friction);
      g.allow[lanes] = static_cast<float>(c.allow);
      g.fixed[lanes] = !moves(sa) || !moves(sb) ? 1.0f : 0.0f;
      g.count[lanes] = static_cast<float>(c.count);
      g.friction = g.friction || c.friction != 0;
      g.points = std::max(g.points, c.count);
      for (int j = 0; j < c.count; ++j) {
        const ContactConstraintPoint& cp = c.points[j];
        Group::Point& p = g.p[j];
        for (int r = 0; r < 3; ++r) {
          p.ra[r][lanes] = static_cast<float>(cp.ra[r]);
          p.rb[r][lanes] = static_cast<float>(cp.rb[r]);
        }
        p.ca_n[lanes] = static_cast<float>(cp.ca_n);
        p.cb_n[lanes] = static_cast<float>(cp.cb_n);
        // In double: adjusted_separation carries -n.(rb - ra), which may be large (an
        // anchor far out on a big ground box) where the separation itself is small.
        p.base_separation[lanes] = static_cast<float>(cp.adjusted_separation + c.normal.dot(cp.rb - cp.ra));
        p.normal_impulse[lanes] = static_cast<float>(cp.normal_impulse);
        p.tangent_impulse[0][lanes] = static_cast<float>(cp.tangent_impulse[0]);
        p.tangent_impulse[1][lanes] = static_cast<float>(cp.tangent_impulse[1]);
        p.push_gap[lanes] = static_cast<float>(cp.push_gap);
      }
      if (max_sag > 0 && c.load > 0) {
        // The manifold's stiffening from its load (prepare_contacts does the same for
        // the scalar passes), with the step's effective masses in double.
        Real mass = 0;
        for (int j = 0; j < c.count; ++j) {
          const ContactConstraintPoint& cp = c.points[j];
          const Vec3 cra = cp.ra.cross(c.normal), crb = cp.rb.cross(c.normal);
          const Real k = sa.inv_mass + sb.inv_mass + cra.dot(sa.inv_inertia * cra) + crb.dot(sb.inv_inertia * crb);
          if (k > 0) mass += 1 / k;
        }
        const Softness& row_soft = !moves(sa) || !moves(sb) ? soft.fixed : soft.dynamic;
        const float stiff = static_cast<float>(stiffening(row_soft, max_sag, mass, c.load * h));
        g.stiffening[lanes] = stiff;
        g.inv_stiffening[lanes] = 1 / stiff;
        g.stiffened = g.stiffened || stiff > 1;
      } else {
        g.stiffening[lanes] = g.inv_stiffening[lanes] = 1;
      }
      source_.push_back(k);
      ++lanes;
    }
    for (int l = lanes; l < L; ++l) source_.push_back(-1);
    while (q < limit && placed_[static_cast<std::size_t>(q)]) ++q;
  }
  record_starts(count);
  rows_.assign(row_state_.size(), Row{});
  loaded_.assign(row_state_.size(), Row{});
  motion_.assign(row_state_.size(), MotionRow{});
  load(states);
  for_groups([&](int begin, int end) { prepare_groups(groups_.data() + begin, end - begin, rows_.data()); });
  set_motion(states);
}

void WideContacts::refresh_inertia(const std::vector<BodyState>& states, const std::vector<int>& bodies) {
  if (bodies.empty()) return;
  refresh_.assign(row_state_.size(), 0);
  for (const int body : bodies)
    if (body >= 0 && body < static_cast<int>(row_of_.size()) && row_of_[body] > 0) refresh_[row_of_[body]] = 1;
  for (Group& g : groups_)
    for (int l = 0; l < L; ++l) {
      if (refresh_[g.row_a[l]]) pack_inertia(states[g.body_a[l]].inv_inertia, g.ia, l);
      if (refresh_[g.row_b[l]]) pack_inertia(states[g.body_b[l]].inv_inertia, g.ib, l);
    }
}

void WideContacts::set_motion(const std::vector<BodyState>& states) {
  const int n = static_cast<int>(row_state_.size());
  for (int r = 0; r < n; ++r) {
    const BodyState& s = states[row_state_[r]];
    MotionRow& x = motion_[r];
    for (int c = 0; c < 3; ++c) x.dp[c] = static_cast<float>(s.dp[c]);
    x.dq[0] = static_cast<float>(s.dq.x());
    x.dq[1] = static_cast<float>(s.dq.y());
    x.dq[2] = static_cast<float>(s.dq.z());
    x.dq[3] = static_cast<float>(s.dq.w());
    x.turn2 = static_cast<float>(s.dq.vec().squaredNorm());
  }
  for_groups([&](int begin, int end) {
    turn_groups(groups_.data() + begin, end - begin, motion_.data(), centroid_rows_);
  });
}

void WideContacts::load(const std::vector<BodyState>& states) {
  const int n = static_cast<int>(row_state_.size());
  for (int r = 0; r < n; ++r) {
    const BodyState& s = states[row_state_[r]];
    Row& x = rows_[r];
    for (int c = 0; c < 3; ++c) {
      x.v[c] = static_cast<float>(s.v[c]);
      x.w[c] = static_cast<float>(s.w[c]);
    }
    loaded_[r] = x;
  }
}

void WideContacts::store(std::vector<BodyState>& states) const {
  const int n = static_cast<int>(row_state_.size());
  for (int r = 1; r < n; ++r) {
    if (!row_moves_[r]) continue;
    BodyState& s = states[row_state_[r]];
    const Row& x = rows_[r];
    const Row& x0 = loaded_[r];
    // The change, not the float value: an untouched body keeps its velocity exactly.
    for (int c = 0; c < 3; ++c) {
      s.v[c] += static_cast<Real>(x.v[c] - x0.v[c]);
      s.w[c] += static_cast<Real>(x.w[c] - x0.w[c]);
    }
  }
}

template <class F>
void WideContacts::for_groups(F&& f) const {
  const int threads = team_ ? team_->size() : 1;
  const int count = group_count();
  if (threads < 2 || count < kParallelMinGroups * threads) {
    f(0, count);
    return;
  }
  team_->run([&](int t) { f(count * t / threads, count * (t + 1) / threads); });
}

template <class F>
void WideContacts::run_groups(bool reverse, F&& f) {
  const int threads = team_ ? team_->size() : 1;
  const int regions = region_count();
  if (threads < 2 || regions < 2 || group_count() < kParallelMinGroups * threads) {
    f(0, group_count());  // the same order: regions one after another, then the boundary
    return;
  }
  SpinBarrier barrier(threads);
  team_->run([&](int t) {
    auto own_regions = [&] {
      for (int r = t; r < regions; r += threads) f(region_start(r), region_start(r + 1));
    };
    auto boundary = [&] {
      if (t == 0) f(region_start(regions), region_start(regions + 1));
    };
    if (!reverse) {
      own_regions();
      barrier.wait();
      boundary();
    } else {
      boundary();
      barrier.wait();
      own_regions();
    }
  });
}

void WideContacts::warm_start(std::vector<BodyState>& states) {
  load(states);
  run_groups(false, [&](int begin, int end) {
    warm_start_groups(groups_.data() + begin, end - begin, rows_.data());
  });
  store(states);
}

void WideContacts::solve(std::vector<BodyState>& states, const ContactSoftness& soft, Real inv_h,
                         Real push_max, bool use_bias, bool reverse, bool centroid_rows) {
  load(states);
  auto lanes = [](const Softness& x) {
    return SoftLanes{static_cast<float>(x.bias_rate), static_cast<float>(x.mass_scale),
                     static_cast<float>(x.impulse_scale), static_cast<float>(x.a2)};
  };
  const SoftLanes dyn = lanes(soft.dynamic), fix = lanes(soft.fixed);
  const bool centroid = centroid_rows && centroid_rows_;
  run_groups(reverse, [&](int begin, int end) {
    solve_groups(groups_.data() + begin, end - begin, rows_.data(), dyn, fix, static_cast<float>(inv_h),
                 static_cast<float>(push_max), use_bias, reverse, centroid);
  });
  store(states);
}

void WideContacts::unpack(std::vector<ContactConstraint>& cs) const {
  // Each constraint is in one lane of one group: the parts write disjoint entries.
  for_groups([&](int begin, int end) { unpack_groups(cs, begin, end); });
}

void WideContacts::unpack_groups(std::vector<ContactConstraint>& cs, int begin, int end) const {
  for (int gi = begin; gi < end; ++gi) {
    const Group& g = groups_[gi];
    for (int l = 0; l < L; ++l) {
      const int k = source_[static_cast<std::size_t>(gi) * L + l];
      if (k < 0) continue;
      ContactConstraint& c = cs[k];
      for (int j = 0; j < c.count; ++j) {
        ContactConstraintPoint& cp = c.points[j];
        const Group::Point& p = g.p[j];
        cp.normal_impulse = p.normal_impulse[l];
        cp.tangent_impulse = {p.tangent_impulse[0][l], p.tangent_impulse[1][l]};
        cp.max_normal_impulse = p.max_normal_impulse[l];
        cp.relative_velocity = p.relative_velocity[l];
        cp.push_gap = p.push_gap[l];
        cp.normal_mass = p.normal_mass[l];
      }
    }
  }
}

}  // namespace wmo
