// parallel_for: the one loop that spreads independent work items over threads.
#pragma once

#include <algorithm>
#include <atomic>
#include <cstddef>
#include <thread>
#include <vector>

namespace kdspace::detail {

inline unsigned resolve_threads(unsigned threads) {
  return threads == 0 ? std::max(1u, std::thread::hardware_concurrency()) : threads;
}

/// Calls body(begin, end, worker) over [0, n) in chunks taken from a shared counter, on up to
/// `threads` threads (0 = all hardware threads). `worker` < the number of threads used, so a body may
/// keep per-worker state. Each item is processed exactly once, whatever the thread count.
template <class Body>
void parallel_for(std::size_t n, unsigned threads, std::size_t chunk, Body&& body) {
  const unsigned workers = static_cast<unsigned>(
      std::min<std::size_t>(resolve_threads(threads), std::max<std::size_t>(1, (n + chunk - 1) / chunk)));
  if (workers <= 1) {
    if (n > 0) body(std::size_t{0}, n, 0u);
    return;
  }
  std::atomic<std::size_t> next{0};
  auto run = [&](unsigned worker) {
    for (;;) {
      const std::size_t begin = next.fetch_add(chunk);
      if (begin >= n) return;
      body(begin, std::min(n, begin + chunk), worker);
    }
  };
  std::vector<std::thread> pool;
  pool.reserve(workers - 1);
  for (unsigned w = 1; w < workers; ++w) pool.emplace_back(run, w);
  run(0);
  for (auto& t : pool) t.join();
}

}  // namespace kdspace::detail
