// What the server remembers of each peer address (an IPv4 address, or an IPv6 peer's /64): its
// sessions, its recent wrong control tokens and a ban. It decides whether a new connection is
// admitted and how long a wrong token's answer waits. No I/O; any thread (one mutex).
#pragma once

#include <chrono>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <mutex>
#include <string>
#include <unordered_map>
#include <utility>

#include "irradcast/service/net_server.h"

namespace irradcast {

class PeerTable {
 public:
  using Clock = std::chrono::steady_clock;
  enum class Admission { Ok, Full, PeerLimit, Banned };

  // `options` must outlive the table (max_clients, max_clients_per_peer, the token limits).
  explicit PeerTable(const ServerOptions& options) : options_(options) {}

  // A new connection from `key`; counts it in when admitted. `sessions` tells how many sessions
  // the server has (it is asked with the table locked, after the peer's own checks).
  // trusted_proxy: the peer carries other clients' connections (--trusted-proxy): neither its
  // limit nor a ban applies to it, only the server's.
  Admission admit(const std::string& key, const std::function<std::size_t()>& sessions,
                  bool trusted_proxy = false);
  // A session admitted under `from` (a trusted proxy) turns out to be a client at `to`: counted
  // under `to` from now on when `to` is under its limit and not banned (else it stays `from`'s).
  // to_trusted: `to` is another trusted proxy (stacked proxies): no limit or ban of its own.
  Admission move(const std::string& from, const std::string& to, bool to_trusted = false);
  // What a refused connection is told (Error REFUSED, or the web port's HTTP reply).
  std::string refusal(Admission admission) const;
  // A session of `key` ended.
  void release(const std::string& key);
  // A wrong token from this peer: the delay before the answer, and whether the peer is now
  // refused (banned).
  std::pair<std::chrono::milliseconds, bool> token_failed(const std::string& key);
  // A right token: the peer's failures are forgiven.
  void token_passed(const std::string& key);

 private:
  struct Peer {
    std::uint32_t sessions = 0;
    std::uint32_t token_failures = 0;
    Clock::time_point banned_until{};
    Clock::time_point last_seen{};
  };

  Admission own_limits(const Peer& p, Clock::time_point now, bool trusted_proxy) const;

  const ServerOptions& options_;
  std::mutex mutex_;
  std::unordered_map<std::string, Peer> peers_;
};

}  // namespace irradcast
