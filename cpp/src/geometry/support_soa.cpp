// Batched support searches (wmo/geometry/support_soa.h): one pass over the points per
// group of directions, the directions in the vector lanes. Each lane keeps its running
// maximum and index with a strict > (the first maximum, in point order), so no
// reduction across lanes is needed and the result is that of a scalar scan. The dot
// is (x dx + y dy) + z dz, as Vec3::dot, with separate multiplies and adds (the AVX2
// path enables no FMA), so both paths give the same bits.
#include "wmo/geometry/support_soa.h"

#if defined(__x86_64__) || defined(__i386__)
#include <immintrin.h>
#define WMO_SUPPORT_AVX2 1
#endif

namespace wmo::detail {
namespace {

void scalar_one(const Real* x, const Real* y, const Real* z, int n, const Vec3& d, int& idx, Real& m) {
  idx = support_index_soa(x, y, z, n, d, &m);
}

/// The `lanes` results of one group of directions from k on, out of the stored lane
/// registers: maxima mv, indices bv (small whole numbers, exact as doubles).
void write_lanes(int lanes, const double* mv, const double* bv, int k, int* idx, Real* max_dot) {
  for (int l = 0; l < lanes; ++l) {
    idx[k + l] = static_cast<int>(bv[l]);
    max_dot[k + l] = mv[l];
  }
}

}  // namespace

void support_indices_soa_sse2(const Real* x, const Real* y, const Real* z, int n, const Vec3* dirs, int count,
                              int* idx, Real* max_dot) {
#ifdef __SSE2__
  int k = 0;
  for (; k + 2 <= count; k += 2) {
    const __m128d dx = _mm_set_pd(dirs[k + 1].x(), dirs[k].x());
    const __m128d dy = _mm_set_pd(dirs[k + 1].y(), dirs[k].y());
    const __m128d dz = _mm_set_pd(dirs[k + 1].z(), dirs[k].z());
    __m128d m = _mm_add_pd(_mm_add_pd(_mm_mul_pd(_mm_set1_pd(x[0]), dx), _mm_mul_pd(_mm_set1_pd(y[0]), dy)),
                           _mm_mul_pd(_mm_set1_pd(z[0]), dz));
    __m128d best = _mm_setzero_pd();
    for (int i = 1; i < n; ++i) {
      const __m128d t = _mm_add_pd(_mm_add_pd(_mm_mul_pd(_mm_set1_pd(x[i]), dx), _mm_mul_pd(_mm_set1_pd(y[i]), dy)),
                                   _mm_mul_pd(_mm_set1_pd(z[i]), dz));
      const __m128d gt = _mm_cmpgt_pd(t, m);
      m = _mm_or_pd(_mm_and_pd(gt, t), _mm_andnot_pd(gt, m));
      best = _mm_or_pd(_mm_and_pd(gt, _mm_set1_pd(static_cast<double>(i))), _mm_andnot_pd(gt, best));
    }
    alignas(16) double mv[2], bv[2];
    _mm_store_pd(mv, m);
    _mm_store_pd(bv, best);
    write_lanes(2, mv, bv, k, idx, max_dot);
  }
  for (; k < count; ++k) scalar_one(x, y, z, n, dirs[k], idx[k], max_dot[k]);
#else
  for (int k = 0; k < count; ++k) scalar_one(x, y, z, n, dirs[k], idx[k], max_dot[k]);
#endif
}

namespace {

#ifdef WMO_SUPPORT_AVX2
__attribute__((target("avx2"))) void batch_avx2(const Real* x, const Real* y, const Real* z, int n,
                                                const Vec3* dirs, int count, int* idx, Real* max_dot) {
  int k = 0;
  for (; k + 4 <= count; k += 4) {
    const __m256d dx = _mm256_set_pd(dirs[k + 3].x(), dirs[k + 2].x(), dirs[k + 1].x(), dirs[k].x());
    const __m256d dy = _mm256_set_pd(dirs[k + 3].y(), dirs[k + 2].y(), dirs[k + 1].y(), dirs[k].y());
    const __m256d dz = _mm256_set_pd(dirs[k + 3].z(), dirs[k + 2].z(), dirs[k + 1].z(), dirs[k].z());
    __m256d m = _mm256_add_pd(
        _mm256_add_pd(_mm256_mul_pd(_mm256_set1_pd(x[0]), dx), _mm256_mul_pd(_mm256_set1_pd(y[0]), dy)),
        _mm256_mul_pd(_mm256_set1_pd(z[0]), dz));
    __m256d best = _mm256_setzero_pd();
    for (int i = 1; i < n; ++i) {
      const __m256d t = _mm256_add_pd(
          _mm256_add_pd(_mm256_mul_pd(_mm256_set1_pd(x[i]), dx), _mm256_mul_pd(_mm256_set1_pd(y[i]), dy)),
          _mm256_mul_pd(_mm256_set1_pd(z[i]), dz));
      const __m256d gt = _mm256_cmp_pd(t, m, _CMP_GT_OQ);
      m = _mm256_blendv_pd(m, t, gt);
      best = _mm256_blendv_pd(best, _mm256_set1_pd(static_cast<double>(i)), gt);
    }
    alignas(32) double mv[4], bv[4];
    _mm256_store_pd(mv, m);
    _mm256_store_pd(bv, best);
    write_lanes(4, mv, bv, k, idx, max_dot);
  }
  for (; k < count; ++k) scalar_one(x, y, z, n, dirs[k], idx[k], max_dot[k]);
}

bool cpu_has_avx2() {
  static const bool has = [] {
    __builtin_cpu_init();  // in case the first call comes from a static initialiser
    return __builtin_cpu_supports("avx2") != 0;
  }();
  return has;
}
#endif

}  // namespace

void support_indices_soa(const Real* x, const Real* y, const Real* z, int n, const Vec3* dirs, int count,
                         int* idx, Real* max_dot) {
#ifdef WMO_SUPPORT_AVX2
  if (cpu_has_avx2()) return batch_avx2(x, y, z, n, dirs, count, idx, max_dot);
#endif
  support_indices_soa_sse2(x, y, z, n, dirs, count, idx, max_dot);
}

}  // namespace wmo::detail
