// The engine's threads (its own and the TBB workers that help it) run niced, so the network
// threads come first.
#include <gtest/gtest.h>
#include <tbb/parallel_for.h>
#include <unistd.h>

#include <atomic>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "irradcast/common/builtin.h"
#include "irradcast/common/log.h"
#include "irradcast/common/progress.h"
#include "irradcast/service/engine_host.h"
#include "irradcast/service/thread_priority.h"

namespace irradcast::test_thread_priority {

namespace fs = std::filesystem;

namespace {

struct ThreadInfo {
  pid_t tid = 0;
  std::string name;
  int nice = 0;
  double cpu_ticks = 0.0;
};

std::vector<ThreadInfo> threads_of_this_process() {
  std::vector<ThreadInfo> out;
  for (const auto& e : fs::directory_iterator("/proc/self/task")) {
    std::ifstream f(e.path() / "stat");
    std::string line;
    if (!std::getline(f, line)) continue;
    const auto open = line.find('('), close = line.rfind(')');
    ThreadInfo t;
    t.tid = static_cast<pid_t>(std::stoi(e.path().filename().string()));
    t.name = line.substr(open + 1, close - open - 1);
    std::istringstream rest(line.substr(close + 2));
    std::vector<std::string> fields;
    for (std::string x; rest >> x;) fields.push_back(x);
    // After the name: state is field 3; utime 14, stime 15, nice 19.
    t.cpu_ticks = std::stod(fields[11]) + std::stod(fields[12]);
    t.nice = std::stoi(fields[16]);
    out.push_back(t);
  }
  return out;
}

}  // namespace

TEST(ThreadPriority, TheEngineThreadAndItsTbbWorkersRunNiced) {
  Progress::set_enabled(false);
  log::set_level(log::Level::Warn);
  EngineHostOptions o;
  o.atlas.texels_per_scene = 64.0f;
  o.max_updates = 3;
  o.engine_nice = 7;
  EngineHost host(make_cornell_box(), "cornell", o);
  host.start();
  host.wait_for_updates(3);
  host.stop();
  int engine = 0, niced_workers = 0;
  for (const ThreadInfo& t : threads_of_this_process()) {
    if (t.name == "irradcast-eng") ++engine;  // joined: gone by now
    if (t.name != "irradcast-eng" && t.nice == 7 && t.cpu_ticks > 0) ++niced_workers;
  }
  EXPECT_EQ(engine, 0);
  if (std::thread::hardware_concurrency() > 1) {
    EXPECT_GE(niced_workers, 1) << "no TBB worker that did engine work runs at nice 7";
  }
  // The main thread (not the engine's) keeps its priority.
  for (const ThreadInfo& t : threads_of_this_process()) {
    if (t.tid == getpid()) {
      EXPECT_EQ(t.nice, 0);
    }
  }
}

TEST(ThreadPriority, ThreadNamesShowInProc) {
  std::thread t([] {
    set_thread_name("irradcast-a-very-long-name");
    bool found = false;
    for (const ThreadInfo& i : threads_of_this_process())
      found = found || i.name == "irradcast-a-ver";  // 15 characters
    EXPECT_TRUE(found);
  });
  t.join();
}

// An engine thread's arena outlives it: the next one of the same nice value takes it over
// (destroying an observed TBB arena could leak TBB's observer proxy, caught by LeakSanitizer),
// and two engines at once each have their own.
TEST(ThreadPriority, ArenasAreReusedOneAfterAnotherAndApartWhenConcurrent) {
  const auto parallel_sum = [] {
    std::atomic<long> sum = 0;
    tbb::parallel_for(0, 10000, [&](int i) { sum += i; });
    return sum.load();
  };
  // 11 has no other user in this test program: the counts below are this test's own.
  const std::size_t before = NiceArena::arenas_made();
  for (int i = 0; i < 20; ++i) {
    NiceArena arena(11);
    long sum = 0;
    arena.execute([&] { sum = parallel_sum(); });
    EXPECT_EQ(sum, 49995000);
  }
  EXPECT_EQ(NiceArena::arenas_made(), before + 1) << "one after another: one arena";

  std::vector<std::thread> engines;
  std::atomic<int> inside = 0;
  std::atomic<long> total = 0;
  for (int e = 0; e < 2; ++e) {
    engines.emplace_back([&] {
      NiceArena arena(11);
      arena.execute([&] {
        ++inside;
        while (inside.load() < 2) std::this_thread::yield();  // both arenas alive at once
        total += parallel_sum();
      });
    });
  }
  for (std::thread& t : engines) t.join();
  EXPECT_EQ(total.load(), 2 * 49995000L);
  EXPECT_EQ(NiceArena::arenas_made(), before + 2) << "two at once: a second arena";
}

}  // namespace irradcast::test_thread_priority
