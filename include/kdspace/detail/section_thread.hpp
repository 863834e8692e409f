// SectionThread: a thread that works beside its parent in a parallel section, started on another
// processor than the parent's.
//
// Linux may start a new thread on its parent's processor, where it waits for the parent (or the
// parent for it) until the load balancer moves one of them. On the 2-core test machine that happened
// in 3 to 7 of 8 fresh processes, and the move came later than a section of a millisecond or two ends:
// a 1e6-point index's two-thread load check then ran one piece after another on one processor. So
// where the system lets a thread be placed (Linux with glibc), the thread is created allowed on every
// processor its parent may use but the one the parent runs on, and its first act is to take back the
// parent's whole set: it starts elsewhere, and the scheduler may move it anywhere afterwards. Where
// the parent may use one processor only, or the affinity cannot be read, it starts as any thread.
//
// A section ends with finish(), not join(): a thread's exit after its body has returned (glibc's and
// the kernel's, then waking the joiner) took 48-75 microseconds on the test machine, one tenth of an
// index's load. finish() waits for the body alone, spinning briefly since the body's end is usually
// near when the parent asks, and lets the thread's exit run on without it.
#pragma once

#include <atomic>
#include <chrono>
#include <exception>
#include <memory>
#include <system_error>
#include <thread>
#include <type_traits>
#include <utility>

#if defined(__linux__) && defined(__GLIBC__)
#include <pthread.h>
#include <sched.h>
#define KDSPACE_PLACED_THREADS 1
#endif

namespace kdspace::detail {

class SectionThread {
 public:
  /// Starts body() on a new thread. Throws std::system_error where no thread can be had. (Not for a
  /// SectionThread itself: copying one is deleted, moving one is the move constructor.)
  template <class Body, std::enable_if_t<!std::is_same_v<std::decay_t<Body>, SectionThread>, int> = 0>
  explicit SectionThread(Body&& body) : task_(std::make_unique<Task<std::decay_t<Body>>>(std::forward<Body>(body))) {
    TaskBase* task = task_.get();
#if defined(KDSPACE_PLACED_THREADS)
    pthread_attr_t attr;
    if (const int error = pthread_attr_init(&attr)) throw std::system_error(error, std::generic_category());
    place_elsewhere(attr, *task);
    const int error = pthread_create(&handle_, &attr, &run_task, task);
    pthread_attr_destroy(&attr);
    if (error) throw std::system_error(error, std::generic_category(), "cannot start a thread");
    joinable_ = true;
#else
    thread_ = std::thread([task] { run_body(*task); });
#endif
  }
  SectionThread(const SectionThread&) = delete;
  SectionThread& operator=(const SectionThread&) = delete;
  SectionThread(SectionThread&& other) noexcept {
    *this = std::move(other);
  }
  SectionThread& operator=(SectionThread&& other) noexcept {
    if (this != &other) {
      join();
#if defined(KDSPACE_PLACED_THREADS)
      handle_ = other.handle_;
      joinable_ = std::exchange(other.joinable_, false);
#else
      thread_ = std::move(other.thread_);
#endif
      task_ = std::move(other.task_);
    }
    return *this;
  }
  /// Waits for the thread (the destructor does too).
  ~SectionThread() {
    join();
  }

  /// Waits for body() to return, and no longer: the thread then ends on its own. Spins (yielding now
  /// and then, should the body need this processor) for up to `spin` before it sleeps in a join.
  void finish(std::chrono::microseconds spin = std::chrono::microseconds(200)) {
    if (!task_) return;
    const auto give_up = std::chrono::steady_clock::now() + spin;
    for (unsigned tries = 1; !task_->done.load(std::memory_order_acquire); ++tries)
      if (tries % 64 == 0) {
        if (std::chrono::steady_clock::now() > give_up) return join();
        std::this_thread::yield();
      }
#if defined(KDSPACE_PLACED_THREADS)
    if (joinable_) pthread_detach(handle_);
    joinable_ = false;
#else
    if (thread_.joinable()) thread_.detach();
#endif
  }

  /// Waits for body() to return and the thread to end; nothing once it has been waited for.
  void join() {
#if defined(KDSPACE_PLACED_THREADS)
    if (joinable_) pthread_join(handle_, nullptr);
    joinable_ = false;
#else
    if (thread_.joinable()) thread_.join();
#endif
  }

 private:
  struct TaskBase {
    virtual ~TaskBase() = default;
    virtual void call() = 0;
    std::atomic<bool> done{false};  // set once the body has returned
#if defined(KDSPACE_PLACED_THREADS)
    cpu_set_t parents_set;  // the processors the parent may use, taken back first thing
    bool take_back = false;
#endif
  };
  template <class Body>
  struct Task : TaskBase {
    explicit Task(Body&& b) : body(std::move(b)) {}
    explicit Task(const Body& b) : body(b) {}
    void call() override { body(); }
    Body body;
  };

#if defined(KDSPACE_PLACED_THREADS)
  // Allows the thread every processor of the parent's set but the parent's own, where that leaves one.
  static void place_elsewhere(pthread_attr_t& attr, TaskBase& task) {
    if (sched_getaffinity(0, sizeof task.parents_set, &task.parents_set) != 0) return;
    const int here = sched_getcpu();
    if (here < 0 || here >= CPU_SETSIZE || !CPU_ISSET(here, &task.parents_set)) return;
    cpu_set_t others = task.parents_set;
    CPU_CLR(here, &others);
    if (CPU_COUNT(&others) == 0) return;
    task.take_back = pthread_attr_setaffinity_np(&attr, sizeof others, &others) == 0;
  }
  static void* run_task(void* p) {
    TaskBase& task = *static_cast<TaskBase*>(p);
    if (task.take_back)
      (void)pthread_setaffinity_np(pthread_self(), sizeof task.parents_set, &task.parents_set);
    run_body(task);
    return nullptr;
  }
#endif

  // Runs the body, then says so: after that the thread touches nothing of the parent's, not even the
  // task, which the SectionThread owns and destroys (freeing it here made the thread's first call to
  // the allocator, which set up an arena of its own: some 20 microseconds before `done`).
  static void run_body(TaskBase& task) {
    try {
      task.call();
    } catch (...) {
      std::terminate();  // as for an exception out of a std::thread's function
    }
    task.done.store(true, std::memory_order_release);
  }

#if defined(KDSPACE_PLACED_THREADS)
  pthread_t handle_{};
  bool joinable_ = false;
#else
  std::thread thread_;
#endif
  std::unique_ptr<TaskBase> task_;  // the body and its flag; null once moved from
};

}  // namespace kdspace::detail
