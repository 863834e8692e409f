// SectionThread (include/kdspace/detail/section_thread.hpp): the threads of parallel_for and fork_join
// run their work once, are waited for, start on another processor than their parent's where the
// process may use more than one, and then may run anywhere the parent may.
#include <atomic>
#include <catch2/catch.hpp>
#include <chrono>
#include <stdexcept>
#include <thread>
#include <utility>
#include <vector>

#include "kdspace/detail/section_thread.hpp"
#include "kdspace/points/detail/parallel.hpp"

#if defined(KDSPACE_PLACED_THREADS)
#include <sched.h>
#endif

using kdspace::detail::SectionThread;

TEST_CASE("a SectionThread runs its work once and is waited for, moved or not", "[threads]") {
  std::atomic<int> runs{0};
  {
    SectionThread a([&] { runs.fetch_add(1); });
    a.join();
    REQUIRE(runs.load() == 1);
    a.join();  // nothing to wait for
  }
  std::vector<SectionThread> threads;
  threads.reserve(2);
  for (int i = 0; i < 3; ++i) threads.emplace_back([&] { runs.fetch_add(1); });  // grows: moves
  SectionThread moved = std::move(threads.back());
  threads.pop_back();
  threads.clear();  // the destructors wait
  moved.join();
  REQUIRE(runs.load() == 4);
}

namespace {
// Counts its destructions: a body holding one by value shows when the body was destroyed.
struct Destructions {
  std::atomic<int>* count;
  explicit Destructions(std::atomic<int>* c) : count(c) {}
  Destructions(const Destructions& other) : count(other.count) {}
  ~Destructions() { count->fetch_add(1); }
};
}  // namespace

TEST_CASE("a SectionThread's finish() returns once its body has returned", "[threads]") {
  // finish() does not wait for the thread's exit, only for the body; what the body wrote is seen after
  // it, whether the body ends within the spin or long after. The body itself (what it holds) is
  // destroyed with the SectionThread, on the parent's side.
  for (int round = 0; round < 300; ++round) {
    std::atomic<int> destroyed{0};
    std::atomic<bool> go{false};
    int written = 0;  // plain memory: finish() must order the body's write before the read below
    int before = 0;
    {
      SectionThread t([&written, &go, held = Destructions(&destroyed)] {
        while (!go.load()) std::this_thread::yield();
        written = 1 + (held.count != nullptr);
      });
      before = destroyed.load();  // the copies made while starting; the body's is still held
      go.store(true);
      t.finish();
      REQUIRE(written == 2);
      t.finish();  // nothing left to wait for
      t.join();
      REQUIRE(destroyed.load() == before);
    }
    REQUIRE(destroyed.load() == before + 1);
  }
  int late = 0;
  SectionThread slow([&late] {
    std::this_thread::sleep_for(std::chrono::milliseconds(20));  // far longer than finish()'s spin
    late = 1;
  });
  slow.finish();
  REQUIRE(late == 1);
  SectionThread moved = std::move(slow);
  slow.finish();  // moved from: nothing
  moved.finish();
}

TEST_CASE("parallel_for and fork_join still hand back the first error, on their threads", "[threads]") {
  REQUIRE_THROWS_WITH(kdspace::detail::fork_join([] { throw std::runtime_error("left"); }, [] {}), "left");
  REQUIRE_THROWS_WITH(kdspace::detail::fork_join([] {}, [] { throw std::runtime_error("right"); }), "right");
  std::atomic<int> items{0};
  REQUIRE_THROWS_WITH(kdspace::detail::parallel_for(64, 4, 1,
                                                    [&](std::size_t begin, std::size_t, unsigned) {
                                                      items.fetch_add(1);
                                                      if (begin == 5) throw std::runtime_error("item 5");
                                                    }),
                      "item 5");
  REQUIRE(items.load() <= 64);
}

#if defined(KDSPACE_PLACED_THREADS)
TEST_CASE("a SectionThread starts on another processor than its parent's, then may use the parent's set",
          "[threads]") {
  cpu_set_t parents{};
  REQUIRE(sched_getaffinity(0, sizeof parents, &parents) == 0);
  const int trials = 20;
  int elsewhere = 0;
  for (int trial = 0; trial < trials; ++trial) {
    const int parent_cpu = sched_getcpu();
    int child_cpu = -1;
    cpu_set_t childs{};
    SectionThread child([&] {
      child_cpu = sched_getcpu();
      (void)sched_getaffinity(0, sizeof childs, &childs);
    });
    child.join();
    // It takes back every processor the parent may use, its own included.
    REQUIRE(CPU_EQUAL(&childs, &parents));
    elsewhere += child_cpu != parent_cpu;
  }
  // Where the process may use more than one processor the child starts off the parent's (the parent
  // could move between reading its processor and starting the child: almost never).
  if (CPU_COUNT(&parents) > 1) CHECK(elsewhere >= trials * 3 / 4);
}
#endif
