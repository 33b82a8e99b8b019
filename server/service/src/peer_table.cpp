// The server's table of peer addresses: admission, per-peer limits, wrong tokens and bans.
#include "peer_table.h"

#include <algorithm>

#include "irradcast/common/log.h"

namespace irradcast {

// A peer's own limits: its ban and its session count (a trusted proxy has neither).
PeerTable::Admission PeerTable::own_limits(const Peer& p, Clock::time_point now,
                                           bool trusted_proxy) const {
  if (trusted_proxy) return Admission::Ok;
  if (p.banned_until > now) return Admission::Banned;
  if (options_.max_clients_per_peer > 0 && p.sessions >= options_.max_clients_per_peer)
    return Admission::PeerLimit;
  return Admission::Ok;
}

PeerTable::Admission PeerTable::admit(const std::string& key,
                                      const std::function<std::size_t()>& sessions,
                                      bool trusted_proxy) {
  const auto now = Clock::now();
  std::lock_guard lock(mutex_);
  // Forget peers with no session, no recent failure and no ban (bounded by the sessions and
  // the addresses that failed within the ban duration).
  if (peers_.size() > 4 * static_cast<std::size_t>(options_.max_clients) + 1024)
    std::erase_if(peers_, [&](const auto& kv) {
      return kv.second.sessions == 0 && kv.second.banned_until <= now &&
             now - kv.second.last_seen > options_.ban_duration;
    });
  Peer& p = peers_[key];
  p.last_seen = now;
  if (const Admission own = own_limits(p, now, trusted_proxy); own != Admission::Ok) return own;
  if (sessions() >= options_.max_clients) return Admission::Full;
  ++p.sessions;
  return Admission::Ok;
}

PeerTable::Admission PeerTable::move(const std::string& from, const std::string& to,
                                     bool to_trusted) {
  if (from == to) return Admission::Ok;
  const auto now = Clock::now();
  std::lock_guard lock(mutex_);
  Peer& p = peers_[to];
  p.last_seen = now;
  if (const Admission own = own_limits(p, now, to_trusted); own != Admission::Ok) return own;
  ++p.sessions;
  auto it = peers_.find(from);
  if (it != peers_.end() && it->second.sessions > 0) {
    --it->second.sessions;
    it->second.last_seen = now;
  }
  return Admission::Ok;
}

std::string PeerTable::refusal(Admission admission) const {
  switch (admission) {
    case Admission::Ok:
      return "";
    case Admission::Full:
      return "the server is full";
    case Admission::PeerLimit:
      return "too many connections from this address (" +
             std::to_string(options_.max_clients_per_peer) +
             "; the server's --max-clients-per-peer)";
    case Admission::Banned:
      return "this address is refused for a while (wrong control tokens)";
  }
  return "";
}

void PeerTable::release(const std::string& key) {
  std::lock_guard lock(mutex_);
  auto it = peers_.find(key);
  if (it == peers_.end() || it->second.sessions == 0) return;
  --it->second.sessions;
  it->second.last_seen = Clock::now();
}

std::pair<std::chrono::milliseconds, bool> PeerTable::token_failed(const std::string& key) {
  const auto now = Clock::now();
  std::lock_guard lock(mutex_);
  Peer& p = peers_[key];
  // Failures older than the ban duration are forgiven.
  if (now - p.last_seen > options_.ban_duration) p.token_failures = 0;
  p.last_seen = now;
  ++p.token_failures;
  const std::uint32_t doublings = std::min<std::uint32_t>(p.token_failures - 1, 5);
  const auto delay = options_.token_failure_delay * (1 << doublings);
  if (p.token_failures >= options_.max_token_failures) {
    p.banned_until = now + options_.ban_duration;
    p.token_failures = 0;
    log::warn("server", "peer " + key + ": " + std::to_string(options_.max_token_failures) +
                            " wrong control tokens; refused for " +
                            std::to_string(options_.ban_duration.count() / 1000) + " s");
    return {delay, true};
  }
  return {delay, false};
}

void PeerTable::token_passed(const std::string& key) {
  std::lock_guard lock(mutex_);
  auto it = peers_.find(key);
  if (it != peers_.end()) it->second.token_failures = 0;
}

}  // namespace irradcast
