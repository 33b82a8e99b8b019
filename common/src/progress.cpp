#include "irradcast/common/progress.h"

#include <unistd.h>

#include <cstdio>

namespace irradcast {
namespace {
std::atomic<bool> g_enabled{true};
}

void Progress::set_enabled(bool enabled) {
  g_enabled = enabled;
}

Progress::Progress(std::string label, std::uint64_t total, std::string unit)
    : label_(std::move(label)),
      unit_(std::move(unit)),
      total_(total),
      start_(std::chrono::steady_clock::now()),
      last_(start_),
      tty_(isatty(STDERR_FILENO) != 0) {}

Progress::~Progress() {
  finish();
}

void Progress::advance(std::uint64_t n) {
  done_ += n;
  if (!g_enabled) return;
  auto now = std::chrono::steady_clock::now();
  auto interval = tty_ ? std::chrono::milliseconds(200) : std::chrono::milliseconds(5000);
  std::unique_lock lock(mutex_, std::try_to_lock);
  if (!lock.owns_lock() || now - last_ < interval) return;
  last_ = now;
  print(false);
}

void Progress::finish() {
  std::lock_guard lock(mutex_);
  if (finished_) return;
  finished_ = true;
  if (g_enabled) print(true);
}

void Progress::print(bool final) {
  double secs = std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
  std::uint64_t done = done_.load();
  double pct = total_ ? 100.0 * static_cast<double>(done) / static_cast<double>(total_) : 100.0;
  double eta = done > 0 && done < total_
                   ? secs * static_cast<double>(total_ - done) / static_cast<double>(done)
                   : 0.0;
  char line[256];
  if (final)
    std::snprintf(line, sizeof line, "%s: %llu %s done in %.1f s", label_.c_str(),
                  static_cast<unsigned long long>(done), unit_.c_str(), secs);
  else
    std::snprintf(line, sizeof line, "%s: %5.1f%% (%llu/%llu %s) %.1f s, ~%.0f s left",
                  label_.c_str(), pct, static_cast<unsigned long long>(done),
                  static_cast<unsigned long long>(total_), unit_.c_str(), secs, eta);
  if (tty_)
    std::fprintf(stderr, "\r\033[K%s%s", line, final ? "\n" : "");
  else
    std::fprintf(stderr, "%s\n", line);
  std::fflush(stderr);
}

}  // namespace irradcast
