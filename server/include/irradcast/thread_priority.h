// Scheduling priority of the engine's threads. The server serves clients first and refines the
// irradiance with what CPU is left: the engine thread and the TBB workers it uses run at a
// higher nice value than the network threads, so a burst of tiles to many clients is not
// delayed by a running update (Linux: nice is per thread; elsewhere these do nothing).
#pragma once

namespace irradcast {

// Names the calling thread (at most 15 characters show) for top, perf and /proc/PID/task.
void set_thread_name(const char* name);

// Sets the calling thread's nice value (only ever raised: lowering needs privileges). Returns
// false when the system refused.
bool set_thread_nice(int nice);

// From now on, every TBB worker thread of the process runs at `nice` when it joins the default
// arena (a process-wide setting: in the server all TBB work is the engine's). Later calls
// change the value for workers that join afterwards.
void set_tbb_worker_nice(int nice);

}  // namespace irradcast
