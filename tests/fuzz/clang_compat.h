// Forced into every translation unit of the clang fuzz build (-DFLEXBENCH_FUZZ=ON, -include):
// GCC's __builtin_shuffle (estimators/lie/se3.h) spelt with clang's vector subscripts. Same
// semantics as GCC's: element i of the result is a[m[i] mod N] (one vector) or, with two,
// element m[i] mod 2N of the concatenation a:b. The normal (GCC) build never sees this file.
#pragma once

#if defined(__clang__) && defined(__cplusplus)
template <class V, class M>
inline V FlexbenchClangShuffle(V a, M m) {
  constexpr int n = sizeof(V) / sizeof(a[0]);
  V r = a;
  for (int i = 0; i < n; ++i) r[i] = a[static_cast<int>(m[i]) & (n - 1)];
  return r;
}
template <class V, class M>
inline V FlexbenchClangShuffle(V a, V b, M m) {
  constexpr int n = sizeof(V) / sizeof(a[0]);
  V r = a;
  for (int i = 0; i < n; ++i) {
    const int k = static_cast<int>(m[i]) & (2 * n - 1);
    r[i] = k < n ? a[k] : b[k - n];
  }
  return r;
}
#define __builtin_shuffle FlexbenchClangShuffle
#endif
