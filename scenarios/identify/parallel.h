// Row passes of the identification on several threads (10,000 point rows). A pass
// (residuals, Jacobian columns, poses) predicts each row from that row alone and writes the
// row's own slots, so splitting the rows into contiguous chunks gives the same bits for any
// number of threads: same seed, same bytes.
#pragma once
#include <algorithm>
#include <atomic>
#include <exception>
#include <system_error>
#include <thread>
#include <vector>

namespace flexbench::identify {

// Below this many rows per thread a thread costs more than it saves (a row is ~1 us).
inline constexpr int kMinRowsPerThread = 512;

// Threads a pass over `rows` rows uses: `requested` (0: the machine's cores), at most one per
// kMinRowsPerThread rows, at least 1.
inline int PassThreads(int rows, int requested) {
  const int cores = std::max(1, static_cast<int>(std::thread::hardware_concurrency()));
  const int want = requested > 0 ? requested : cores;
  return std::max(1, std::min(want, rows / kMinRowsPerThread));
}

// Calls fn(begin, end) on contiguous chunks covering [0, rows), `threads` of them at once (the
// calling thread takes the first). An exception in any chunk is rethrown here, the first
// chunk's first, after all chunks have ended.
template <typename Fn>
void ForEachRowChunk(int rows, int threads, Fn&& fn) {
  if (threads <= 1 || rows <= 1) {
    fn(0, rows);
    return;
  }
  std::vector<std::exception_ptr> error(threads);
  const auto chunk = [&](int k) {
    try {
      fn(static_cast<int>(static_cast<long>(rows) * k / threads),
         static_cast<int>(static_cast<long>(rows) * (k + 1) / threads));
    } catch (...) {
      error[k] = std::current_exception();
    }
  };
  std::vector<std::thread> pool;
  pool.reserve(threads - 1);
  for (int k = 1; k < threads; ++k) {
    try {
      pool.emplace_back(chunk, k);
    } catch (const std::system_error&) {
      chunk(k);  // no thread to be had: this one does the chunk
    }
  }
  chunk(0);
  for (std::thread& t : pool) t.join();
  for (const std::exception_ptr& e : error) {
    if (e) std::rethrow_exception(e);
  }
}

// Threads for `tasks` independent tasks over `rows` rows: `requested` (0: the machine's cores),
// at most one per task, at least 1; 1 when the rows are enough for the passes over them to
// take the threads (PassThreads), so that tasks side by side never hold several tasks'
// per-row copies and Jacobians at once on large data.
inline int TaskThreads(int tasks, int rows, int requested) {
  if (PassThreads(rows, requested) > 1) return 1;
  const int cores = std::max(1, static_cast<int>(std::thread::hardware_concurrency()));
  return std::max(1, std::min(requested > 0 ? requested : cores, tasks));
}

// Calls fn(i) for every i in [0, tasks), `threads` at once, each thread taking the next task
// when it is done (tasks of uneven cost: whole selections, folds). Each task writes only its
// own result slot, so the results do not depend on the number of threads. An exception is
// rethrown here after all tasks have ended, the lowest task's first.
template <typename Fn>
void ForEachTask(int tasks, int threads, Fn&& fn) {
  if (threads <= 1 || tasks <= 1) {
    for (int i = 0; i < tasks; ++i) fn(i);
    return;
  }
  std::vector<std::exception_ptr> error(tasks);
  std::atomic<int> next{0};
  const auto worker = [&] {
    for (int i = next++; i < tasks; i = next++) {
      try {
        fn(i);
      } catch (...) {
        error[i] = std::current_exception();
      }
    }
  };
  std::vector<std::thread> pool;
  pool.reserve(threads - 1);
  for (int k = 1; k < threads; ++k) {
    try {
      pool.emplace_back(worker);
    } catch (const std::system_error&) {
      break;  // no thread to be had: the others take its tasks
    }
  }
  worker();
  for (std::thread& t : pool) t.join();
  for (const std::exception_ptr& e : error) {
    if (e) std::rethrow_exception(e);
  }
}

}  // namespace flexbench::identify
