// The benches' shared helpers (irradcast_bench_util): wall and CPU time, minimum and medians, the
// machine description and load average for the reports, the quiet start of a run, comma-separated
// option lists, the TBB thread limit, and writing a JSON report. Each bench is one tool; this is
// what they share.
#pragma once

#include <tbb/global_control.h>
#include <time.h>

#include <chrono>
#include <cstdio>
#include <exception>
#include <filesystem>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

namespace irradcast::bench {

namespace fs = std::filesystem;
using json = nlohmann::json;
using Clock = std::chrono::steady_clock;

// Wall seconds since t0.
double seconds_since(Clock::time_point t0);

// Wall time from construction (or the last restart()).
class Stopwatch {
 public:
  double seconds() const { return seconds_since(start_); }
  void restart() { start_ = Clock::now(); }

 private:
  Clock::time_point start_ = Clock::now();
};

// CPU seconds of a clock: all threads of the process, or the calling thread only.
double cpu_seconds(clockid_t id);
double process_cpu_seconds();
double thread_cpu_seconds();

// The smallest value (0 for none).
double minimum(const std::vector<double>& v);
// The median, the mean of the two middle values for an even count (0 for none).
double median(std::vector<double> v);
// The upper median: the value at index size/2 once sorted (0 for none).
double upper_median(std::vector<double> v);

// "model name" of /proc/cpuinfo ("unknown" if absent).
std::string cpu_model();
// The three load averages of /proc/loadavg, space separated.
std::string load_average();
// The shared part of a report's "machine" object: cpu, hardware_threads, tbb_threads and
// load_average_at_start.
nlohmann::json machine_json(int tbb_threads);

// printf of one number into a string.
std::string fmt(const char* format, double v);
// The non-empty items of a comma-separated list.
std::vector<std::string> split_list(const std::string& text);
// Same, as integers.
std::vector<int> parse_ints(const std::string& text);

// Limits TBB to `threads` workers while the result lives (0: no limit, all cores).
std::unique_ptr<tbb::global_control> limit_threads(int threads);
// TBB's current worker limit.
int tbb_threads();

// The start of a bench run: no progress lines, and only warnings and errors logged (with
// `verbose`, info too).
void quiet_run(bool verbose = false);

// The start of a bench run that writes into out_dir: quiet_run(), the thread limit (hold the
// result for the run), out_dir created, and an empty json_path set to out_dir/json_name.
std::unique_ptr<tbb::global_control> start_run(int threads, const std::string& out_dir,
                                               std::string& json_path, const char* json_name);

// Runs body() and returns its exit status; an exception is printed to stderr as prefix + what()
// and a newline, and gives 1.
template <typename Body>
int run_guarded(const char* prefix, Body&& body) {
  try {
    return body();
  } catch (const std::exception& e) {
    std::fprintf(stderr, "%s%s\n", prefix, e.what());
    return 1;
  }
}

// Writes j, indented by `indent`, and a newline to path.
void write_json(const std::string& path, const nlohmann::json& j, int indent = 2);

}  // namespace irradcast::bench
