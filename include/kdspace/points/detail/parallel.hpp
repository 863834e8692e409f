// parallel_for: the one loop that spreads independent work items over threads; fork_join: two pieces of
// work side by side. Their threads are SectionThreads, started on another processor than the caller's.
#pragma once

#include <algorithm>
#include <atomic>
#include <cstddef>
#include <exception>
#include <optional>
#include <system_error>
#include <thread>
#include <vector>

#include "kdspace/detail/section_thread.hpp"

namespace kdspace::detail {

inline unsigned resolve_threads(unsigned threads) {
  return threads == 0 ? std::max(1u, std::thread::hardware_concurrency()) : threads;
}

/// Calls body(begin, end, worker) over [0, n) in chunks taken from a shared counter, on up to
/// `threads` threads (0 = all hardware threads). `worker` < the number of threads used, so a body may
/// keep per-worker state. Each item is processed exactly once, whatever the thread count. An
/// exception from body stops the work and is rethrown on the calling thread once all have joined.
template <class Body>
void parallel_for(std::size_t n, unsigned threads, std::size_t chunk, Body&& body) {
  const unsigned workers = static_cast<unsigned>(
      std::min<std::size_t>(resolve_threads(threads), std::max<std::size_t>(1, (n + chunk - 1) / chunk)));
  if (workers <= 1) {
    if (n > 0) body(std::size_t{0}, n, 0u);
    return;
  }
  std::atomic<std::size_t> next{0};
  std::vector<std::exception_ptr> errors(workers);
  auto run = [&](unsigned worker) {
    try {
      for (;;) {
        const std::size_t begin = next.fetch_add(chunk);
        if (begin >= n) return;
        body(begin, std::min(n, begin + chunk), worker);
      }
    } catch (...) {
      errors[worker] = std::current_exception();
      next.store(n);  // the others stop at their next chunk
    }
  };
  std::vector<SectionThread> pool;
  pool.reserve(workers - 1);
  try {
    for (unsigned w = 1; w < workers; ++w) pool.emplace_back([&run, w] { run(w); });
  } catch (const std::system_error&) {
    // No more threads to be had: the ones started and this one share the work.
  }
  run(0);
  for (auto& t : pool) t.finish();
  for (const auto& e : errors)
    if (e) std::rethrow_exception(e);  // the first error, on the calling thread
}

/// Runs left() on another thread and right() on this one; an exception from either is rethrown
/// here after both have finished. Without a thread to be had, runs both here.
template <class Left, class Right>
void fork_join(Left&& left, Right&& right) {
  std::exception_ptr left_error;
  std::optional<SectionThread> worker;
  try {
    worker.emplace([&] {
      try {
        left();
      } catch (...) {
        left_error = std::current_exception();
      }
    });
  } catch (const std::system_error&) {
    left();
    right();
    return;
  }
  try {
    right();
  } catch (...) {
    worker->finish();
    throw;
  }
  worker->finish();
  if (left_error) std::rethrow_exception(left_error);
}

}  // namespace kdspace::detail
