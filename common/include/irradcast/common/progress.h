// Progress of long work on stderr: a live line on a terminal, a line every few seconds otherwise.
#pragma once

#include <atomic>
#include <chrono>
#include <cstdint>
#include <mutex>
#include <string>

namespace irradcast {

class Progress {
 public:
  Progress(std::string label, std::uint64_t total, std::string unit = "");
  ~Progress();
  Progress(const Progress&) = delete;
  Progress& operator=(const Progress&) = delete;

  void advance(std::uint64_t n = 1);  // thread-safe
  void finish();
  static void set_enabled(bool enabled);  // e.g. off in tests and with --quiet

 private:
  void print(bool final);
  std::string label_, unit_;
  std::uint64_t total_;
  std::atomic<std::uint64_t> done_{0};
  std::chrono::steady_clock::time_point start_, last_;
  std::mutex mutex_;
  bool finished_ = false;
  bool tty_;
};

}  // namespace irradcast
