#include "irradcast/service/thread_priority.h"

#include <tbb/task_arena.h>
#include <tbb/task_scheduler_observer.h>

#include <mutex>
#include <vector>

#if defined(__linux__)
#include <pthread.h>
#include <sys/resource.h>
#include <sys/syscall.h>
#include <unistd.h>
#endif

namespace irradcast {

void set_thread_name(const char* name) {
#if defined(__linux__)
  char shortened[16] = {};
  for (int i = 0; i < 15 && name[i]; ++i) shortened[i] = name[i];
  pthread_setname_np(pthread_self(), shortened);
#else
  (void)name;
#endif
}

bool set_thread_nice(int nice) {
#if defined(__linux__)
  const auto tid = static_cast<id_t>(syscall(SYS_gettid));
  return setpriority(PRIO_PROCESS, tid, nice) == 0;
#else
  (void)nice;
  return false;
#endif
}

struct NiceArena::Impl {
  struct Observer : tbb::task_scheduler_observer {
    Observer(tbb::task_arena& a, int n) : tbb::task_scheduler_observer(a), nice(n) {
      observe(true);
    }
    void on_scheduler_entry(bool) override { set_thread_nice(nice); }
    int nice;
  };
  explicit Impl(int n) : observer(arena, n) {}
  tbb::task_arena arena;
  Observer observer;
};

namespace {

// The arenas a NiceArena hands out, kept for the life of the process and never destroyed:
// TBB (2021.8) allocates a proxy for each observer, and when an observed arena is destroyed
// while one of its workers still holds that proxy as the last observer it notified, the proxy
// is never freed (LeakSanitizer caught it in CI, now and then, as the engine thread ended).
// A NiceArena takes an idle arena of its nice value from here and gives it back when it ends,
// so there are only as many as there were engines running at once.
struct ArenaPool {
  std::mutex mutex;
  std::vector<NiceArena::Impl*> idle;
  std::size_t made = 0;
};

ArenaPool& arena_pool() {
  static auto* pool = new ArenaPool;  // never destroyed: TBB's workers may outlive main()
  return *pool;
}

}  // namespace

NiceArena::NiceArena(int nice) {
  ArenaPool& pool = arena_pool();
  std::lock_guard lock(pool.mutex);
  for (auto it = pool.idle.begin(); it != pool.idle.end(); ++it) {
    if ((*it)->observer.nice != nice) continue;
    impl_ = *it;
    pool.idle.erase(it);
    return;
  }
  impl_ = new Impl(nice);  // owned by the pool from now on
  ++pool.made;
}

NiceArena::~NiceArena() {
  ArenaPool& pool = arena_pool();
  std::lock_guard lock(pool.mutex);
  pool.idle.push_back(impl_);
}

void NiceArena::execute(const std::function<void()>& work) {
  impl_->arena.execute(work);
}

std::size_t NiceArena::arenas_made() {
  ArenaPool& pool = arena_pool();
  std::lock_guard lock(pool.mutex);
  return pool.made;
}

}  // namespace irradcast
