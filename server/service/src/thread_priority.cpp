#include "irradcast/service/thread_priority.h"

#include <tbb/task_arena.h>
#include <tbb/task_scheduler_observer.h>

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
    ~Observer() override { observe(false); }
    void on_scheduler_entry(bool) override { set_thread_nice(nice); }
    int nice;
  };
  explicit Impl(int n) : observer(arena, n) {}
  tbb::task_arena arena;
  Observer observer;
};

NiceArena::NiceArena(int nice) : impl_(std::make_unique<Impl>(nice)) {}

NiceArena::~NiceArena() = default;

void NiceArena::execute(const std::function<void()>& work) {
  impl_->arena.execute(work);
}

}  // namespace irradcast
