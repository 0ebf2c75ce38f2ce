// Happens-before edges for ThreadSanitizer around oneTBB's parallel calls.
//
// oneTBB guarantees that everything before a parallel call happens before each of its tasks, and
// each task before the call returns (or task_group::wait). Debian's libtbb is not built with
// ThreadSanitizer, so the atomics that carry those edges inside libtbb.so are invisible to it, and
// it reports the caller's later writes as racing with the tasks' reads. Under ThreadSanitizer,
// ForkJoin states the two edges TBB provides, on two separate addresses: the tasks acquire only
// the caller's release, never each other's, so a race between two tasks is still reported.
// In every other build it does nothing and task() hands back the function itself.
//
//   auto body = [&](size_t i) { ... };             // a named function, alive during the call
//   detail::ForkJoin fj;
//   tbb::parallel_for(size_t{0}, n, fj.task(body));
//   fj.joined();
#pragma once

#include <utility>

#if defined(__SANITIZE_THREAD__)
#define ARTRACE_TSAN 1
#elif defined(__has_feature)
#if __has_feature(thread_sanitizer)
#define ARTRACE_TSAN 1
#endif
#endif

#ifdef ARTRACE_TSAN
extern "C" void __tsan_acquire(void* addr);
extern "C" void __tsan_release(void* addr);
#endif

namespace artrace::core::detail {

#ifdef ARTRACE_TSAN
class ForkJoin {
 public:
  /// f, wrapped: it runs after the caller's work so far and ends before joined(). The wrapper
  /// holds f by reference: f was made before the release, whatever copies TBB makes of the wrapper.
  template <class F>
  auto task(const F& f) {
    __tsan_release(&fork_);
    return [this, fp = &f](auto&&... args) {
      __tsan_acquire(&fork_);
      (*fp)(std::forward<decltype(args)>(args)...);
      __tsan_release(&join_);
    };
  }
  /// Call after the parallel call returns (or task_group::wait()).
  void joined() { __tsan_acquire(&join_); }

 private:
  char fork_ = 0, join_ = 0;
};
#else
class ForkJoin {
 public:
  template <class F>
  const F& task(const F& f) {
    return f;
  }
  void joined() {}
};
#endif

}  // namespace artrace::core::detail
