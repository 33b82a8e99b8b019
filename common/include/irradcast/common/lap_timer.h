// Lap times for a log line: each lap() adds "what N ms" (the milliseconds since the previous lap,
// or since the timer was made) to a comma-separated list, as in "world 1 ms, ray scene 3 ms".
#pragma once

#include <chrono>
#include <string>
#include <utility>

namespace irradcast {

class LapTimer {
 public:
  // Goes on from the laps in `so_far` (another LapTimer's text()).
  explicit LapTimer(std::string so_far = {}) : text_(std::move(so_far)) {}
  void lap(const std::string& what) {
    const auto now = std::chrono::steady_clock::now();
    text_ += (text_.empty() ? "" : ", ") + what + " " +
             std::to_string(
                 static_cast<int>(1e3 * std::chrono::duration<double>(now - start_).count())) +
             " ms";
    start_ = now;
  }
  const std::string& text() const { return text_; }

 private:
  std::string text_;
  std::chrono::steady_clock::time_point start_ = std::chrono::steady_clock::now();
};

}  // namespace irradcast
