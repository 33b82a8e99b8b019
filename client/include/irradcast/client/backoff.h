// The clients' reconnect policy, shared by irradcast-view (ViewClient) and the simulated users of
// irradcast-load: capped exponential back-off with full jitter, bounded by a deadline, and which
// server Error codes mean "the connection is gone, try again" rather than "this client is wrong".
//
// Full jitter (Brooker, "Exponential Backoff And Jitter", AWS Architecture Blog, 2015): the k-th
// delay after a failure (k from 0) is uniform in [0, min(cap, initial * factor^k)]. Many clients
// that lost the same server at the same moment spread their attempts over the whole window
// instead of arriving together at every step; the random numbers come from a seeded PCG32, so a
// seed gives the same delays.
#pragma once

#include <chrono>
#include <cstdint>
#include <optional>

#include "irradcast.pb.h"
#include "irradcast/common/sampling.h"

namespace irradcast {

struct BackoffPolicy {
  std::chrono::milliseconds initial{100};  // the ceiling of the first delay
  std::chrono::milliseconds cap{2000};     // the ceiling of every delay
  double factor = 2.0;                     // the ceiling grows by this factor per attempt
  // Throws irradcast::Error for a policy that is not one (initial <= 0, cap < initial,
  // factor < 1).
  void validate() const;
};

class Backoff {
 public:
  using Clock = std::chrono::steady_clock;

  explicit Backoff(BackoffPolicy policy = {}, std::uint64_t seed = 0);

  // The next delay (full jitter under the current ceiling); the ceiling then grows.
  Clock::duration next();
  // The next delay, shortened so that it ends at `deadline` at the latest; nullopt when `now` is
  // at or past the deadline (give up: no attempt is left).
  std::optional<Clock::duration> next_before(Clock::time_point now, Clock::time_point deadline);
  // After a success: the next failure starts again from `initial`.
  void reset() { attempt_ = 0; }

  // The ceiling of the next delay.
  Clock::duration ceiling() const;
  int attempts() const { return attempt_; }  // delays drawn since the last reset
  const BackoffPolicy& policy() const { return policy_; }

 private:
  BackoffPolicy policy_;
  Rng rng_;
  int attempt_ = 0;
};

// True for the server Error codes that end a connection for reasons of the server's, not the
// client's (SERVER_SHUTDOWN, IDLE_TIMEOUT, INTERNAL, REFUSED such as "the server is full"): a
// client reconnects after them (or moves on to the next server of its --connect list). The others
// (BAD_FRAME, FRAME_TOO_LARGE, UNSUPPORTED_VERSION, UNEXPECTED_MESSAGE, BAD_REQUEST,
// PERMISSION_DENIED) say the client is wrong, and reconnecting would only repeat them.
bool server_error_is_transient(wire::ErrorCode code);

}  // namespace irradcast
