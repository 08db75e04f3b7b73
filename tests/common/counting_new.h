// Counts the heap allocations of the test binary that includes this header: it replaces the
// global operator new/delete with versions that count and forward to malloc/free (so sanitizers
// still see every allocation). Include it in exactly one source file of a binary (the
// replacement functions cannot be inline); the hot loops' no-allocation tests use it.
#pragma once

#include <atomic>
#include <cstddef>
#include <cstdlib>
#include <new>

namespace flexbench::testing {

inline std::atomic<long> g_allocations{0};

inline void* CountedAlloc(std::size_t size) {
  g_allocations.fetch_add(1, std::memory_order_relaxed);
  if (void* p = std::malloc(size == 0 ? 1 : size)) return p;
  throw std::bad_alloc();
}

inline void* CountedAlignedAlloc(std::size_t size, std::align_val_t align) {
  g_allocations.fetch_add(1, std::memory_order_relaxed);
  const std::size_t a = static_cast<std::size_t>(align);
  const std::size_t rounded = (size + a - 1) / a * a;
  if (void* p = std::aligned_alloc(a, rounded == 0 ? a : rounded)) return p;
  throw std::bad_alloc();
}

// The allocations made while running f.
template <class F>
long CountAllocations(const F& f) {
  const long before = g_allocations.load();
  f();
  return g_allocations.load() - before;
}

}  // namespace flexbench::testing

void* operator new(std::size_t size) { return flexbench::testing::CountedAlloc(size); }
void* operator new[](std::size_t size) { return flexbench::testing::CountedAlloc(size); }
void* operator new(std::size_t size, std::align_val_t a) {
  return flexbench::testing::CountedAlignedAlloc(size, a);
}
void* operator new[](std::size_t size, std::align_val_t a) {
  return flexbench::testing::CountedAlignedAlloc(size, a);
}
void operator delete(void* p) noexcept { std::free(p); }
void operator delete[](void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }
void operator delete[](void* p, std::size_t) noexcept { std::free(p); }
void operator delete(void* p, std::align_val_t) noexcept { std::free(p); }
void operator delete[](void* p, std::align_val_t) noexcept { std::free(p); }
void operator delete(void* p, std::size_t, std::align_val_t) noexcept { std::free(p); }
void operator delete[](void* p, std::size_t, std::align_val_t) noexcept { std::free(p); }
