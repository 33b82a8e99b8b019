#include "irradcast/client/backoff.h"

#include <algorithm>
#include <cmath>
#include <string>

#include "irradcast/common/error.h"

namespace irradcast {

void BackoffPolicy::validate() const {
  if (initial.count() <= 0)
    throw Error("back-off: the initial delay must be positive, not " +
                std::to_string(initial.count()) + " ms");
  if (cap < initial)
    throw Error("back-off: the cap (" + std::to_string(cap.count()) +
                " ms) must not be below the initial delay (" + std::to_string(initial.count()) +
                " ms)");
  if (!(factor >= 1.0) || !std::isfinite(factor))
    throw Error("back-off: the factor must be at least 1, not " + std::to_string(factor));
}

Backoff::Backoff(BackoffPolicy policy, std::uint64_t seed) : policy_(policy), rng_(seed, 0x6261) {
  policy_.validate();
}

Backoff::Clock::duration Backoff::ceiling() const {
  const double cap = std::chrono::duration<double>(policy_.cap).count();
  // initial * factor^attempt, without overflowing for a long outage.
  const double c = std::chrono::duration<double>(policy_.initial).count() *
                   std::pow(policy_.factor, std::min(attempt_, 64));
  return std::chrono::duration_cast<Clock::duration>(
      std::chrono::duration<double>(std::min(cap, c)));
}

Backoff::Clock::duration Backoff::next() {
  const Clock::duration c = ceiling();
  ++attempt_;
  // Uniform in [0, ceiling]: 32 random bits are finer than a nanosecond under a 2 s cap.
  const double u = static_cast<double>(rng_.next_u32()) / 4294967295.0;
  return std::chrono::duration_cast<Clock::duration>(
      std::chrono::duration<double>(u * std::chrono::duration<double>(c).count()));
}

std::optional<Backoff::Clock::duration> Backoff::next_before(Clock::time_point now,
                                                             Clock::time_point deadline) {
  if (now >= deadline) return std::nullopt;
  return std::min(next(), deadline - now);
}

bool server_error_is_transient(wire::ErrorCode code) {
  switch (code) {
    case wire::SERVER_SHUTDOWN:
    case wire::IDLE_TIMEOUT:
    case wire::INTERNAL:
    case wire::REFUSED:  // full, or this address has too many sessions: another server may not be
      return true;
    default:
      return false;
  }
}

}  // namespace irradcast
