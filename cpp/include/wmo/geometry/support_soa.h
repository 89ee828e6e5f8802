// Support search over a point set stored as coordinate arrays (x[n], y[n], z[n]):
// the index of the point maximising dot(p, d), vectorised (SSE2, two points a step)
// and branch-free. ConvexHull::support_index uses it for hulls up to 32 vertices
// (ConvexHull::vertex_coords), and so does the hull-hull SAT's face queries; the
// batched form (support_indices_soa) runs many directions in one pass over the points.
#pragma once

#ifdef __SSE2__
#include <emmintrin.h>
#endif

#include "wmo/math.h"

namespace wmo::detail {

/// Index of the point maximising dot(p, d) over p_i = (x[i], y[i], z[i]), i < n (n >= 1,
/// finite coordinates): the FIRST such index on ties, with the same arithmetic as
/// Vec3::dot ((x dx + y dy) + z dz), so bit for bit the point a scalar scan keeping the
/// first strict maximum returns. Writes the maximum to *max_dot if given.
inline int support_index_soa(const Real* __restrict x, const Real* __restrict y, const Real* __restrict z,
                             int n, const Vec3& d, Real* max_dot = nullptr) {
  const Real dx = d.x(), dy = d.y(), dz = d.z();
  // The running maximum and its index per lane (a strict > keeps each lane's first
  // maximum), then the better lane, the lower index on a tie.
  int i = 0;
  Real max_d = -kInf;
  int best = 0;
#ifdef __SSE2__
  if (n >= 2) {
    const __m128d vdx = _mm_set1_pd(dx), vdy = _mm_set1_pd(dy), vdz = _mm_set1_pd(dz);
    __m128d m2 = _mm_set1_pd(-kInf);
    __m128d idx2 = _mm_set_pd(1.0, 0.0), best2 = idx2;
    const __m128d two = _mm_set1_pd(2.0);
    for (; i + 2 <= n; i += 2) {
      const __m128d t = _mm_add_pd(_mm_add_pd(_mm_mul_pd(_mm_loadu_pd(x + i), vdx),
                                              _mm_mul_pd(_mm_loadu_pd(y + i), vdy)),
                                   _mm_mul_pd(_mm_loadu_pd(z + i), vdz));
      const __m128d gt = _mm_cmpgt_pd(t, m2);
      m2 = _mm_max_pd(m2, t);
      best2 = _mm_or_pd(_mm_and_pd(gt, idx2), _mm_andnot_pd(gt, best2));
      idx2 = _mm_add_pd(idx2, two);
    }
    const Real m_lo = _mm_cvtsd_f64(m2), m_hi = _mm_cvtsd_f64(_mm_unpackhi_pd(m2, m2));
    const int b_lo = static_cast<int>(_mm_cvtsd_f64(best2));
    const int b_hi = static_cast<int>(_mm_cvtsd_f64(_mm_unpackhi_pd(best2, best2)));
    const bool hi_wins = m_hi > m_lo || (m_hi == m_lo && b_hi < b_lo);
    max_d = hi_wins ? m_hi : m_lo;
    best = hi_wins ? b_hi : b_lo;
  }
#endif
  for (; i < n; ++i) {
    const Real t = (x[i] * dx + y[i] * dy) + z[i] * dz;
    if (t > max_d) {
      max_d = t;
      best = i;
    }
  }
  if (max_dot) *max_dot = max_d;
  return best;
}

/// support_index_soa for `count` directions at once: idx[k] = the first index
/// maximising dot(p, dirs[k]), max_dot[k] = that maximum, bit for bit as
/// support_index_soa. Vectorised across directions (4 a step with AVX2 where the CPU
/// has it, checked once at run time; 2 with SSE2), which suits many directions against
/// a small point set, such as a hull's face normals against another hull's vertices.
void support_indices_soa(const Real* x, const Real* y, const Real* z, int n, const Vec3* dirs, int count,
                         int* idx, Real* max_dot);

/// The same on the path support_indices_soa takes without AVX2 (SSE2, or scalar where
/// there is no SSE2), callable on any CPU, so tests check both paths on a machine with
/// AVX2.
void support_indices_soa_sse2(const Real* x, const Real* y, const Real* z, int n, const Vec3* dirs, int count,
                              int* idx, Real* max_dot);

}  // namespace wmo::detail
