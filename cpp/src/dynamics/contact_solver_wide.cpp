// The contact solver's passes on lane groups (WideContacts, contact_solver.h).
//
// Each group holds up to four constraints with no dynamic body in common; a pass
// gathers the group's bodies into 4-wide registers (one lane per constraint), runs the
// rows of contact_solver.cpp for all lanes at once, and scatters the velocities back.
// The rows are the same arithmetic as the scalar solver's (normal rows of points 0..3,
// then their friction rows, per constraint), written out component by component so
// that four constraints share each instruction. Within one constraint every row
// depends on the previous one; across lanes nothing does, which is where the
// parallelism is (Box2D v3's "wide" contact solver; SCENES.md measures scalar code on
// the pyramid's contact graph at 6.6x below an 8-wide version).
//
// On x86-64 the kernels are compiled twice (GCC target_clones): for AVX2 (4 doubles per
// instruction) and for the baseline (SSE2, two halves); the loader picks one for the
// processor. No fused multiply-add is enabled in either, so both compute the same
// bits. Other processors get one portable build of the same source.
#include <algorithm>
#include <cmath>
#include <cstring>

#include "wmo/dynamics/contact_solver.h"

namespace wmo {
namespace {

typedef double v4 __attribute__((vector_size(32)));
typedef long long m4 __attribute__((vector_size(32)));
constexpr int L = WideContacts::kLanes;
using Group = WideContacts::Group;

/// A body the passes change; the others (zero inverse mass: static and kinematic) only
/// receive exact zeros, so constraints may share them. The level order and the grouping
/// use the same test, so that the groups fill.
inline bool moves(const BodyState& s) { return s.inv_mass > 0; }

#define WMO_INLINE inline __attribute__((always_inline))
// Two builds of each kernel on x86-64 (AVX2 and the baseline), picked at load time;
// one elsewhere (aarch64: NEON 2-wide halves), or when WMO_WIDE_NO_CLONES asks for the
// baseline alone (the test that runs that build on AVX2 machines too).
#if defined(__x86_64__) && !defined(WMO_WIDE_NO_CLONES)
#define WMO_CLONES __attribute__((target_clones("avx2", "default")))
#else
#define WMO_CLONES
#endif

WMO_INLINE v4 ld(const Real* p) {
  v4 r;
  std::memcpy(&r, p, sizeof r);
  return r;
}
WMO_INLINE void st(Real* p, v4 v) { std::memcpy(p, &v, sizeof v); }
WMO_INLINE v4 splat(Real x) { return v4{x, x, x, x}; }
/// std::max(a, b) lane by lane: (a < b) ? b : a.
WMO_INLINE v4 vmax(v4 a, v4 b) { return a < b ? b : a; }

struct V3 {
  v4 x, y, z;
};
WMO_INLINE V3 ld3(const Real (*p)[L]) { return V3{ld(p[0]), ld(p[1]), ld(p[2])}; }
WMO_INLINE V3 operator+(const V3& a, const V3& b) { return V3{a.x + b.x, a.y + b.y, a.z + b.z}; }
WMO_INLINE V3 operator-(const V3& a, const V3& b) { return V3{a.x - b.x, a.y - b.y, a.z - b.z}; }
WMO_INLINE V3 operator*(v4 s, const V3& a) { return V3{s * a.x, s * a.y, s * a.z}; }
WMO_INLINE v4 dot(const V3& a, const V3& b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
WMO_INLINE V3 cross(const V3& a, const V3& b) {
  return V3{a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}

/// The bodies of one side of a group, lane by lane.
struct Bodies {
  V3 v, w, dp;
  v4 qx, qy, qz, qw;  // dq
  v4 inv_mass;
  v4 i[3][3];  // world inverse inertia, i[row][col]
};

WMO_INLINE void gather(const std::array<int, L>& idx, const std::vector<BodyState>& s, Bodies& b) {
  const BodyState& s0 = s[idx[0]];
  const BodyState& s1 = s[idx[1]];
  const BodyState& s2 = s[idx[2]];
  const BodyState& s3 = s[idx[3]];
  auto lanes = [&](auto f) { return v4{f(s0), f(s1), f(s2), f(s3)}; };
  b.v = V3{lanes([](const BodyState& x) { return x.v.x(); }), lanes([](const BodyState& x) { return x.v.y(); }),
           lanes([](const BodyState& x) { return x.v.z(); })};
  b.w = V3{lanes([](const BodyState& x) { return x.w.x(); }), lanes([](const BodyState& x) { return x.w.y(); }),
           lanes([](const BodyState& x) { return x.w.z(); })};
  b.dp = V3{lanes([](const BodyState& x) { return x.dp.x(); }), lanes([](const BodyState& x) { return x.dp.y(); }),
            lanes([](const BodyState& x) { return x.dp.z(); })};
  b.qx = lanes([](const BodyState& x) { return x.dq.x(); });
  b.qy = lanes([](const BodyState& x) { return x.dq.y(); });
  b.qz = lanes([](const BodyState& x) { return x.dq.z(); });
  b.qw = lanes([](const BodyState& x) { return x.dq.w(); });
  b.inv_mass = lanes([](const BodyState& x) { return x.inv_mass; });
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c)
      b.i[r][c] = v4{s0.inv_inertia(r, c), s1.inv_inertia(r, c), s2.inv_inertia(r, c), s3.inv_inertia(r, c)};
}

/// Velocities back; dp and dq are not changed by the passes.
WMO_INLINE void scatter(const std::array<int, L>& idx, const Bodies& b, std::vector<BodyState>& s) {
  for (int l = 0; l < L; ++l) {
    BodyState& x = s[idx[l]];
    x.v = Vec3(b.v.x[l], b.v.y[l], b.v.z[l]);
    x.w = Vec3(b.w.x[l], b.w.y[l], b.w.z[l]);
  }
}

/// dq * r (Eigen's quaternion-vector product: uv = q x r, uv += uv, r + w uv + q x uv).
WMO_INLINE V3 rotate(const Bodies& b, const V3& r) {
  const V3 q{b.qx, b.qy, b.qz};
  V3 uv = cross(q, r);
  uv = uv + uv;
  return r + b.qw * uv + cross(q, uv);
}

WMO_INLINE V3 mul(const v4 (&m)[3][3], const V3& x) {
  return V3{m[0][0] * x.x + m[0][1] * x.y + m[0][2] * x.z, m[1][0] * x.x + m[1][1] * x.y + m[1][2] * x.z,
            m[2][0] * x.x + m[2][1] * x.y + m[2][2] * x.z};
}

/// apply() of contact_solver.cpp: impulse p at anchors ra (on a) and rb (on b).
WMO_INLINE void apply(Bodies& a, Bodies& b, const V3& ra, const V3& rb, const V3& p) {
  a.v = a.v - a.inv_mass * p;
  a.w = a.w - mul(a.i, cross(ra, p));
  b.v = b.v + b.inv_mass * p;
  b.w = b.w + mul(b.i, cross(rb, p));
}

WMO_INLINE V3 relative_velocity(const Bodies& a, const Bodies& b, const V3& ra, const V3& rb) {
  return (b.v + cross(b.w, rb)) - (a.v + cross(a.w, ra));
}

WMO_CLONES void warm_start_groups(const Group* groups, int count,
                                                                         std::vector<BodyState>& states) {
  for (int k = 0; k < count; ++k) {
    const Group& g = groups[k];
    Bodies a{}, b{};
    gather(g.body_a, states, a);
    gather(g.body_b, states, b);
    const V3 n = ld3(g.n), t1 = ld3(g.t1), t2 = ld3(g.t2);
    for (int j = 0; j < g.points; ++j) {
      const Group::Point& p = g.p[j];
      const V3 imp = ld(p.normal_impulse) * n + ld(p.tangent_impulse[0]) * t1 + ld(p.tangent_impulse[1]) * t2;
      apply(a, b, ld3(p.ra), ld3(p.rb), imp);
    }
    scatter(g.body_a, a, states);
    scatter(g.body_b, b, states);
  }
}

WMO_CLONES void solve_groups(Group* groups, int count,
                                                                    std::vector<BodyState>& states,
                                                                    const Softness& soft, Real inv_h,
                                                                    Real push_max, bool use_bias) {
  const v4 zero = splat(0), one = splat(1), vinv_h = splat(inv_h);
  const v4 bias_rate = splat(soft.bias_rate), neg_push = splat(-push_max);
  const v4 soft_mass = splat(use_bias ? soft.mass_scale : 1);
  const v4 soft_impulse = splat(use_bias ? soft.impulse_scale : 0);
  for (int k = 0; k < count; ++k) {
    Group& g = groups[k];
    Bodies a{}, b{};
    gather(g.body_a, states, a);
    gather(g.body_b, states, b);
    const V3 n = ld3(g.n);
    for (int j = 0; j < g.points; ++j) {
      Group::Point& p = g.p[j];
      const V3 ra = ld3(p.ra), rb = ld3(p.rb);
      // Separation now (solve_contacts: anchors rotated by the rotation deltas).
      const V3 d = (b.dp + rotate(b, rb)) - (a.dp + rotate(a, ra));
      const v4 s = dot(n, d) + ld(p.adjusted_separation);
      // s > 0: speculative (bias s / h, full mass, no decay); otherwise the soft bias
      // when use_bias, else none.
      const m4 spec = s > zero;
      const v4 soft_bias = use_bias ? vmax(bias_rate * s, neg_push) : zero;
      const v4 bias = spec ? s * vinv_h : soft_bias;
      const v4 mass_scale = spec ? one : soft_mass;
      const v4 impulse_scale = spec ? zero : soft_impulse;
      const v4 vn = dot(n, relative_velocity(a, b, ra, rb));
      const v4 ni = ld(p.normal_impulse);
      v4 impulse = -ld(p.normal_mass) * mass_scale * (vn + bias) - impulse_scale * ni;
      const v4 next = vmax(ni + impulse, zero);
      impulse = next - ni;
      st(p.normal_impulse, next);
      const v4 max_ni = ld(p.max_normal_impulse);
      const m4 first = (impulse > zero) & (max_ni == zero);
      st(p.relative_velocity, first ? vn : ld(p.relative_velocity));
      st(p.push_gap, first ? vmax(s, zero) : ld(p.push_gap));
      st(p.max_normal_impulse, vmax(max_ni, impulse));
      apply(a, b, ra, rb, impulse * n);
    }
    if (g.friction) {
      const V3 t1 = ld3(g.t1), t2 = ld3(g.t2);
      const v4 mu = ld(g.mu);
      const m4 has_mu = mu != zero;
      for (int j = 0; j < g.points; ++j) {
        Group::Point& p = g.p[j];
        const V3 ra = ld3(p.ra), rb = ld3(p.rb);
        const V3 dv = relative_velocity(a, b, ra, rb);
        const v4 ti0 = ld(p.tangent_impulse[0]), ti1 = ld(p.tangent_impulse[1]);
        v4 x0 = ti0 - ld(p.tangent_mass[0]) * dot(t1, dv);
        v4 x1 = ti1 - ld(p.tangent_mass[1]) * dot(t2, dv);
        // Coulomb cone (solve_contacts): back onto the circle of radius mu lambda_n.
        const v4 limit = mu * ld(p.normal_impulse);
        const v4 len2 = x0 * x0 + x1 * x1;
        const m4 over = len2 > limit * limit;
        v4 scale = one;
        for (int l = 0; l < L; ++l)
          if (over[l]) scale[l] = len2[l] > 0 ? limit[l] / std::sqrt(len2[l]) : 0;
        x0 = over ? x0 * scale : x0;
        x1 = over ? x1 * scale : x1;
        // Lanes without friction keep their tangent impulses, as the scalar pass skips
        // their friction rows.
        x0 = has_mu ? x0 : ti0;
        x1 = has_mu ? x1 : ti1;
        const v4 d0 = x0 - ti0, d1 = x1 - ti1;
        st(p.tangent_impulse[0], x0);
        st(p.tangent_impulse[1], x1);
        apply(a, b, ra, rb, d0 * t1 + d1 * t2);
      }
    }
    scatter(g.body_a, a, states);
    scatter(g.body_b, b, states);
  }
}

}  // namespace

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
                         const std::vector<BodyState>& states, int dummy) {
  groups_.clear();
  source_.clear();
  const int count = static_cast<int>(order.size());
  for (int q = 0; q < count;) {
    Group& g = groups_.emplace_back();
    g.body_a.fill(dummy);
    g.body_b.fill(dummy);
    int lanes = 0;
    while (lanes < L && q < count) {
      const int k = order[q];
      const ContactConstraint& c = cs[k];
      // A constraint joins the group unless one of its dynamic bodies is already in it.
      bool independent = true;
      for (int l = 0; l < lanes && independent; ++l)
        for (const int body : {c.body_a, c.body_b})
          if (moves(states[body]) && (body == g.body_a[l] || body == g.body_b[l])) independent = false;
      if (!independent) break;
      g.body_a[lanes] = c.body_a;
      g.body_b[lanes] = c.body_b;
      for (int r = 0; r < 3; ++r) {
        g.n[r][lanes] = c.normal[r];
        g.t1[r][lanes] = c.tangent1[r];
        g.t2[r][lanes] = c.tangent2[r];
      }
      g.mu[lanes] = c.friction;
      g.friction = g.friction || c.friction != 0;
      g.points = std::max(g.points, c.count);
      for (int j = 0; j < c.count; ++j) {
        const ContactConstraintPoint& cp = c.points[j];
        Group::Point& p = g.p[j];
        for (int r = 0; r < 3; ++r) {
          p.ra[r][lanes] = cp.ra[r];
          p.rb[r][lanes] = cp.rb[r];
        }
        p.adjusted_separation[lanes] = cp.adjusted_separation;
        p.normal_mass[lanes] = cp.normal_mass;
        p.tangent_mass[0][lanes] = cp.tangent_mass[0];
        p.tangent_mass[1][lanes] = cp.tangent_mass[1];
        p.normal_impulse[lanes] = cp.normal_impulse;
        p.tangent_impulse[0][lanes] = cp.tangent_impulse[0];
        p.tangent_impulse[1][lanes] = cp.tangent_impulse[1];
        p.max_normal_impulse[lanes] = cp.max_normal_impulse;
        p.relative_velocity[lanes] = cp.relative_velocity;
        p.push_gap[lanes] = cp.push_gap;
      }
      source_.push_back(k);
      ++lanes;
      ++q;
    }
    for (int l = lanes; l < L; ++l) source_.push_back(-1);
  }
}

void WideContacts::warm_start(std::vector<BodyState>& states) const {
  warm_start_groups(groups_.data(), group_count(), states);
}

void WideContacts::solve(std::vector<BodyState>& states, const Softness& soft, Real inv_h, Real push_max,
                         bool use_bias) {
  solve_groups(groups_.data(), group_count(), states, soft, inv_h, push_max, use_bias);
}

void WideContacts::unpack(std::vector<ContactConstraint>& cs) const {
  for (int gi = 0; gi < group_count(); ++gi) {
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
      }
    }
  }
}

}  // namespace wmo
