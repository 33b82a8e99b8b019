// Scheduling priority of the engine's threads. The server serves clients first and refines the
// irradiance with what CPU is left: the engine thread and the TBB workers it uses run at a
// higher nice value than the network threads, so a burst of tiles to many clients is not
// delayed by a running update (Linux: nice is per thread; elsewhere these do nothing).
#pragma once

#include <cstddef>
#include <functional>

namespace irradcast {

// Names the calling thread (at most 15 characters show) for top, perf and /proc/PID/task.
void set_thread_name(const char* name);

// Sets the calling thread's nice value (only ever raised: lowering needs privileges). Returns
// false when the system refused.
bool set_thread_nice(int nice);

// A TBB arena whose threads run at `nice` while they work in it: the engine runs its updates
// in one (EngineHost), so the TBB workers that help it are niced too. (A worker keeps its nice
// value after it leaves: raising a thread's priority again needs privileges. In the server all
// TBB work is the engine's.) The arena itself is kept for the process and handed to the next
// NiceArena of the same nice value (see thread_priority.cpp for why it is never destroyed).
class NiceArena {
 public:
  explicit NiceArena(int nice);
  ~NiceArena();
  NiceArena(const NiceArena&) = delete;
  NiceArena& operator=(const NiceArena&) = delete;

  void execute(const std::function<void()>& work);

  // How many arenas this process has made: one per NiceArena alive at the same time.
  static std::size_t arenas_made();

  struct Impl;

 private:
  Impl* impl_ = nullptr;  // the pool's
};

}  // namespace irradcast
