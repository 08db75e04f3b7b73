// A counting heap for peak-memory measurements (bench_identify, the identify tests): every
// malloc family call of the process (Eigen allocates through malloc, the standard library
// through operator new, which calls malloc) passes through these wrappers of glibc's own
// functions; the bytes in use and their peak are counted by malloc_usable_size.
// It replaces malloc for the whole binary: include it in exactly one translation unit.
#pragma once
#include <malloc.h>
#include <sys/resource.h>

#include <atomic>
#include <cstddef>

extern "C" {
void* __libc_malloc(size_t);
void* __libc_calloc(size_t, size_t);
void* __libc_realloc(void*, size_t);
void* __libc_memalign(size_t, size_t);
void __libc_free(void*);
}

namespace flexbench::testing {

inline std::atomic<long> heap_in_use{0};
inline std::atomic<long> heap_peak{0};

inline void* Counted(void* p) {
  if (!p) return p;
  const long n = static_cast<long>(malloc_usable_size(p));
  const long now = heap_in_use.fetch_add(n) + n;
  long peak = heap_peak.load();
  while (now > peak && !heap_peak.compare_exchange_weak(peak, now)) {
  }
  return p;
}
inline void Uncount(void* p) {
  if (p) heap_in_use.fetch_sub(static_cast<long>(malloc_usable_size(p)));
}

// Peak heap bytes above the level at construction, while it lives (one at a time); and the
// process's peak resident set's growth (getrusage; 0 unless this run set a new peak).
class PeakMemory {
 public:
  PeakMemory() : base_(heap_in_use.load()), rss_kb_(MaxRssKb()) { heap_peak.store(base_); }
  double HeapBytes() const { return static_cast<double>(heap_peak.load() - base_); }
  // Bytes in use now above the level at construction.
  double InUseBytes() const { return static_cast<double>(heap_in_use.load() - base_); }
  double RssBytes() const { return 1024.0 * static_cast<double>(MaxRssKb() - rss_kb_); }

 private:
  static long MaxRssKb() {
    rusage u{};
    getrusage(RUSAGE_SELF, &u);
    return u.ru_maxrss;
  }
  long base_;
  long rss_kb_;
};

}  // namespace flexbench::testing

extern "C" {
void* malloc(size_t n) noexcept { return flexbench::testing::Counted(__libc_malloc(n)); }
void* calloc(size_t n, size_t m) noexcept {
  return flexbench::testing::Counted(__libc_calloc(n, m));
}
void free(void* p) noexcept {
  flexbench::testing::Uncount(p);
  __libc_free(p);
}
void* realloc(void* p, size_t n) noexcept {
  flexbench::testing::Uncount(p);
  return flexbench::testing::Counted(__libc_realloc(p, n));
}
void* memalign(size_t a, size_t n) noexcept {
  return flexbench::testing::Counted(__libc_memalign(a, n));
}
void* aligned_alloc(size_t a, size_t n) noexcept {
  return flexbench::testing::Counted(__libc_memalign(a, n));
}
int posix_memalign(void** out, size_t a, size_t n) noexcept {
  *out = flexbench::testing::Counted(__libc_memalign(a, n));
  return *out ? 0 : 12;  // ENOMEM
}
}
