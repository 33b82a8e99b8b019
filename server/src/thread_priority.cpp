#include "irradcast/thread_priority.h"

#include <tbb/task_scheduler_observer.h>

#include <atomic>
#include <mutex>

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

namespace {

// Installed once and never removed: TBB keeps a proxy of every observer that is observing.
struct NiceObserver : tbb::task_scheduler_observer {
  explicit NiceObserver(int n) : nice(n) { observe(true); }
  void on_scheduler_entry(bool is_worker) override {
    if (is_worker) set_thread_nice(nice.load());
  }
  std::atomic<int> nice;
};

}  // namespace

void set_tbb_worker_nice(int nice) {
  static std::mutex mutex;
  static NiceObserver* observer = nullptr;
  std::lock_guard lock(mutex);
  if (observer)
    observer->nice = nice;
  else
    observer = new NiceObserver(nice);
}

}  // namespace irradcast
