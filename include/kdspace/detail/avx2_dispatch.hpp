// Code compiled twice, for the baseline instruction set (SSE2 on x86-64) and for AVX2, with the
// choice made at run time: the joins' leaf-pair base cases and the ray traversal's leaf tests. Both
// compilations perform the same operations in the same order (AVX2 adds no fused multiply-add), so
// they give the same answers bit for bit; AVX2 only takes more lanes per instruction.
#pragma once

#include <cstdlib>

#if (defined(__x86_64__) || defined(__i386__)) && (defined(__GNUC__) || defined(__clang__))
#define KDSPACE_AVX2_DISPATCH 1
#endif

namespace kdspace::detail {

/// Whether the AVX2 compilations run: the processor has AVX2 and the environment variable
/// KDSPACE_NO_AVX2 is not set (both read once per process). The tests run once more with it set, so
/// the baseline compilations are checked on AVX2 machines too (ctest entries `baseline_without_avx2_*`).
inline bool avx2_dispatch() {
#if defined(KDSPACE_AVX2_DISPATCH)
  static const bool yes = __builtin_cpu_supports("avx2") && std::getenv("KDSPACE_NO_AVX2") == nullptr;
  return yes;
#else
  return false;
#endif
}

#if defined(KDSPACE_AVX2_DISPATCH)
/// f() compiled for AVX2: `flatten` inlines what f calls into this function, so that all of it is
/// compiled for this target.
template <class F>
__attribute__((target("avx2"), flatten)) void with_avx2(F&& f) {
  f();
}
#endif

}  // namespace kdspace::detail
