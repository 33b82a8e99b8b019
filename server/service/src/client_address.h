// Who a client is when it comes through a reverse proxy or load balancer (--trusted-proxy): the
// addresses the operator trusts to say so, the client address in an X-Forwarded-For or Forwarded
// header, and the PROXY protocol v2 header a TCP proxy puts before the client's bytes. What a peer
// that is not trusted says about its clients is never read. No I/O; any thread.
#pragma once

#include <asio/ip/address.hpp>

#include <array>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "irradcast/service/forwarded_header.h"

namespace irradcast {

// The address a peer is counted under (PeerTable): an IPv4 address (IPv4-mapped IPv6 included),
// or the /64 of an IPv6 address (one subscriber's network gets one).
std::string peer_key_of(const asio::ip::address& address);

// IPv4 and IPv6 networks (CIDR) the operator trusts to report their clients' addresses.
class TrustedProxies {
 public:
  TrustedProxies() = default;
  // "10.0.0.0/8", "192.168.1.7" (a /32), "fd00::/8", "::1": throws irradcast::Error naming the
  // entry that does not parse (or whose host bits are set).
  explicit TrustedProxies(const std::vector<std::string>& cidrs);
  bool empty() const { return nets_.empty(); }
  // An IPv4-mapped IPv6 address matches the IPv4 networks.
  bool contains(const asio::ip::address& address) const;

 private:
  struct Net {
    std::array<std::uint8_t, 16> bytes{};  // IPv4 as IPv4-mapped IPv6
    unsigned prefix = 0;                   // of the 128 bits
  };
  std::vector<Net> nets_;
};

// An address as proxies write it: "192.0.2.7", "192.0.2.7:4711", "2001:db8::1",
// "[2001:db8::1]:4711", optionally in double quotes (Forwarded). Nothing else ("unknown",
// "_hidden", a name): nullopt.
std::optional<asio::ip::address> parse_forwarded_address(std::string_view text);

// The client behind a trusted peer, from the header its proxy sets (every instance of the header,
// joined by ", "): the hops are read from the right (the nearest) and trusted proxies skipped; the
// first one that is not trusted is the client. The hops are split from the right, so nothing a
// client wrote (an unbalanced quote included) changes what its proxy appended: X-Forwarded-For at
// every comma (it has no quoting), Forwarded at each comma outside a quoted string.
struct ForwardedClient {
  enum class Kind {
    None,     // no header, or every hop is a trusted proxy: the connection is the proxy's own
    Client,   // `address`
    Unknown,  // the nearest untrusted hop is not an address ("unknown", "_hidden", garbage)
  };
  Kind kind = Kind::None;
  asio::ip::address address;
};
ForwardedClient forwarded_client(std::string_view header_value, ForwardedHeader header,
                                 const TrustedProxies& trusted);

// The PROXY protocol version 2 header (haproxy.org's proxy-protocol.txt, section 2.2) at the start
// of a connection from a trusted peer. Fed the bytes as they are read; the header is recognised by
// its 12-byte signature, whose first bytes no TLS record, HTTP request or frame of ours starts
// with (its length would be 168 MB), so a trusted peer may also connect without one.
class ProxyHeaderReader {
 public:
  enum class State {
    More,  // the signature so far: feed more
    None,  // no PROXY header: every byte fed is the connection's (rest())
    Done,  // a header was read: source() and the bytes after it (rest())
    Bad,   // a signature with a header that is not valid (error())
  };
  // Largest header accepted: the addresses and TLVs a proxy adds (TLS details, a unique id).
  static constexpr std::size_t kMaxHeaderBytes = 16 + 2048;

  State feed(const char* data, std::size_t n);
  State state() const { return state_; }
  // Done: the client's address; nullopt for a LOCAL command (the proxy's own health check) or a
  // connection over UNIX sockets or of an unspecified family (the peer stays the proxy).
  const std::optional<asio::ip::address>& source() const { return source_; }
  std::string take_rest() { return std::move(rest_); }
  const std::string& error() const { return error_; }

 private:
  State parse();
  State state_ = State::More;
  std::string bytes_;
  std::string rest_;
  std::optional<asio::ip::address> source_;
  std::string error_;
};

}  // namespace irradcast
