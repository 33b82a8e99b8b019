// A histogram of tile latencies for irradcast-load's progress line: 8 buckets per octave of
// microseconds, added to from every I/O thread, read (p99 of what came since) once a second.
#pragma once

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <cstdint>

namespace irradcast {

class LatencyHistogram {
 public:
  static constexpr int kBuckets = 8 * 32;
  void add(double us) {
    const int b = std::clamp(static_cast<int>(std::log2(us + 1.0) * 8.0), 0, kBuckets - 1);
    counts_[static_cast<std::size_t>(b)].fetch_add(1, std::memory_order_relaxed);
  }
  // p99 in ms of what was added since the last call.
  double take_p99_ms() {
    std::array<std::uint64_t, kBuckets> now{};
    std::uint64_t total = 0;
    for (int b = 0; b < kBuckets; ++b) {
      const auto i = static_cast<std::size_t>(b);
      now[i] = counts_[i].load(std::memory_order_relaxed) - seen_[i];
      seen_[i] += now[i];
      total += now[i];
    }
    if (total == 0) return 0.0;
    const auto rank = static_cast<std::uint64_t>(std::ceil(0.99 * static_cast<double>(total)));
    std::uint64_t acc = 0;
    for (int b = 0; b < kBuckets; ++b) {
      acc += now[static_cast<std::size_t>(b)];
      if (acc >= rank) return (std::exp2((b + 1) / 8.0) - 1.0) / 1000.0;  // bucket's upper edge
    }
    return 0.0;
  }

 private:
  std::array<std::atomic<std::uint64_t>, kBuckets> counts_{};
  std::array<std::uint64_t, kBuckets> seen_{};
};

}  // namespace irradcast
