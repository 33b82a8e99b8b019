// Who a client is behind a proxy (client_address.h): trusted networks, X-Forwarded-For and
// Forwarded headers read from the nearest hop, the PROXY protocol v2 header; and the peer table
// moving a proxy's session to its client's address (peer_table.h).
#include <gtest/gtest.h>

#include <string>

#include "client_address.h"
#include "irradcast/common/error.h"
#include "irradcast/service/net_server.h"
#include "peer_table.h"
#include "proxy_header.h"

namespace irradcast::test_client_address {

namespace {

asio::ip::address ip(const std::string& s) {
  return asio::ip::make_address(s);
}

std::string client_of(const std::string& header, ForwardedHeader which,
                      const TrustedProxies& trusted) {
  const ForwardedClient c = forwarded_client(header, which, trusted);
  return c.kind == ForwardedClient::Kind::Client    ? c.address.to_string()
         : c.kind == ForwardedClient::Kind::Unknown ? "unknown"
                                                    : "none";
}

}  // namespace

TEST(TrustedProxies, NetworksOfBothFamilies) {
  const TrustedProxies t({"10.0.0.0/8", "192.0.2.7", " fd00::/8 ", "::1"});
  EXPECT_TRUE(t.contains(ip("10.1.2.3")));
  EXPECT_TRUE(t.contains(ip("::ffff:10.1.2.3")));  // IPv4-mapped
  EXPECT_FALSE(t.contains(ip("11.0.0.1")));
  EXPECT_TRUE(t.contains(ip("192.0.2.7")));
  EXPECT_FALSE(t.contains(ip("192.0.2.8")));
  EXPECT_TRUE(t.contains(ip("fd12:3456::1")));
  EXPECT_FALSE(t.contains(ip("fe80::1")));
  EXPECT_TRUE(t.contains(ip("::1")));
  EXPECT_FALSE(t.contains(ip("127.0.0.1")));
  EXPECT_TRUE(TrustedProxies().empty());
  const TrustedProxies v4_all({"0.0.0.0/0"});
  EXPECT_TRUE(v4_all.contains(ip("203.0.113.9")));
  EXPECT_FALSE(v4_all.contains(ip("2001:db8::1")));
  const TrustedProxies odd({"172.16.0.0/12"});
  EXPECT_TRUE(odd.contains(ip("172.31.255.255")));
  EXPECT_FALSE(odd.contains(ip("172.32.0.0")));
}

TEST(TrustedProxies, BadEntriesAreErrorsNamingThem) {
  for (const char* bad : {"10.0.0.1/8", "10.0.0.0/33", "10.0.0.0/", "10.0.0.0/-1", "::/129",
                          "proxy.example", "10.0.0.0/8x", "fd00::1/8"}) {
    try {
      TrustedProxies t({"192.0.2.1", bad});
      ADD_FAILURE() << bad << " was taken";
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find(std::string("'") + bad + "'"), std::string::npos)
          << e.what();
    }
  }
  EXPECT_THROW(check_trusted_proxies({"10.0.0.0/8", "nonsense"}), Error);
  EXPECT_NO_THROW(check_trusted_proxies({"10.0.0.0/8", "2001:db8::/32"}));
}

TEST(ForwardedAddress, TheFormsProxiesWrite) {
  const auto text = [](const char* s) {
    const auto a = parse_forwarded_address(s);
    return a ? a->to_string() : std::string("none");
  };
  EXPECT_EQ(text("192.0.2.7"), "192.0.2.7");
  EXPECT_EQ(text(" 192.0.2.7:4711 "), "192.0.2.7");
  EXPECT_EQ(text("2001:db8::1"), "2001:db8::1");
  EXPECT_EQ(text("[2001:db8::1]:4711"), "2001:db8::1");
  EXPECT_EQ(text("\"[2001:db8:cafe::17]:4711\""), "2001:db8:cafe::17");
  EXPECT_EQ(text("\"192.0.2.43:47011\""), "192.0.2.43");
  for (const char* bad : {"", "unknown", "_hidden", "host.example", "192.0.2.7:port", "[192.0.2.7]",
                          "[2001:db8::1", "[2001:db8::1]x", "1.2.3.4.5", "\"\""})
    EXPECT_EQ(text(bad), "none") << bad;
}

// Read from the right: what a client wrote on the left never counts once an untrusted hop is
// reached.
TEST(ForwardedClient, XForwardedForFromTheNearestHop) {
  const TrustedProxies t({"10.0.0.0/8"});
  const auto xff = ForwardedHeader::XForwardedFor;
  EXPECT_EQ(client_of("203.0.113.5", xff, t), "203.0.113.5");
  EXPECT_EQ(client_of("1.1.1.1, 203.0.113.5, 10.0.0.2", xff, t), "203.0.113.5");
  EXPECT_EQ(client_of("garbage, 203.0.113.5", xff, t), "203.0.113.5");
  EXPECT_EQ(client_of("203.0.113.5,10.9.9.9", xff, t), "203.0.113.5");
  EXPECT_EQ(client_of("2001:db8::5, 10.0.0.2", xff, t), "2001:db8::5");
  EXPECT_EQ(client_of("203.0.113.5, unknown", xff, t), "unknown");
  EXPECT_EQ(client_of("10.0.0.3, 10.0.0.2", xff, t), "none");  // every hop trusted
  EXPECT_EQ(client_of("", xff, t), "none");
  EXPECT_EQ(client_of("  ", xff, t), "none");
  EXPECT_EQ(client_of("203.0.113.5, ", xff, t), "unknown");  // an empty nearest hop
  // X-Forwarded-For has no quoting: a quote a client wrote swallows nothing its proxy appended
  // (on the same line, or as a second header joined by ", ").
  EXPECT_EQ(client_of("\", 203.0.113.9", xff, t), "203.0.113.9");
  EXPECT_EQ(client_of("\"1.1.1.1, 203.0.113.9, 10.0.0.2", xff, t), "203.0.113.9");
}

TEST(ForwardedClient, ForwardedHeaderOfRfc7239) {
  const TrustedProxies t({"10.0.0.0/8"});
  const auto fwd = ForwardedHeader::Forwarded;
  EXPECT_EQ(client_of("for=192.0.2.60;proto=http;by=203.0.113.43", fwd, t), "192.0.2.60");
  EXPECT_EQ(client_of("for=192.0.2.60, For=\"[2001:db8:cafe::17]:4711\"", fwd, t),
            "2001:db8:cafe::17");
  EXPECT_EQ(client_of("for=198.51.100.1;proto=https, for=10.0.0.2", fwd, t), "198.51.100.1");
  EXPECT_EQ(client_of("for=\"a,b\", for=198.51.100.1", fwd, t), "198.51.100.1");
  EXPECT_EQ(client_of("for=_hidden", fwd, t), "unknown");
  EXPECT_EQ(client_of("for=198.51.100.1, proto=https", fwd, t), "unknown");  // a hop, no for=
  // An X-Forwarded-For value is not a Forwarded header.
  EXPECT_EQ(client_of("198.51.100.1", fwd, t), "unknown");
  // A client's unbalanced quote is to the left of what its proxy appended: the split from the
  // right never reaches it.
  EXPECT_EQ(client_of("for=\", for=203.0.113.9", fwd, t), "203.0.113.9");
  EXPECT_EQ(client_of("for=\"[::1, for=203.0.113.9;proto=https, for=10.0.0.2", fwd, t),
            "203.0.113.9");
}

TEST(ProxyHeader, Ipv4AndIpv6SourcesByteByByte) {
  for (const std::string& source : {std::string("203.0.113.5"), std::string("2001:db8::77")}) {
    const std::string header = test::proxy_v2(source, 4711, "\x01\x00\x02hi");  // one TLV
    const std::string bytes = header + "after";
    ProxyHeaderReader r;
    for (std::size_t i = 0; i < bytes.size(); ++i) {
      const auto state = r.feed(&bytes[i], 1);
      if (i + 1 < header.size()) {
        ASSERT_EQ(state, ProxyHeaderReader::State::More) << i;
      }
    }
    ASSERT_EQ(r.state(), ProxyHeaderReader::State::Done) << r.error();
    ASSERT_TRUE(r.source().has_value());
    EXPECT_EQ(r.source()->to_string(), source);
    // Fed one byte at a time, the bytes after the header came after Done: not kept.
    ProxyHeaderReader whole;
    ASSERT_EQ(whole.feed(bytes.data(), bytes.size()), ProxyHeaderReader::State::Done);
    EXPECT_EQ(whole.take_rest(), "after");
  }
}

TEST(ProxyHeader, LocalCommandAndUnspecifiedFamilyKeepTheProxy) {
  std::string local = test::proxy_v2("203.0.113.5", 1);
  local[12] = '\x20';  // LOCAL: the proxy's own health check
  ProxyHeaderReader r;
  ASSERT_EQ(r.feed(local.data(), local.size()), ProxyHeaderReader::State::Done) << r.error();
  EXPECT_FALSE(r.source().has_value());
  std::string unspec = local.substr(0, 16);
  unspec[13] = '\x00';
  unspec[14] = unspec[15] = '\x00';
  ProxyHeaderReader u;
  ASSERT_EQ(u.feed(unspec.data(), unspec.size()), ProxyHeaderReader::State::Done) << u.error();
  EXPECT_FALSE(u.source().has_value());
}

// A trusted peer may connect without a header: its first bytes are its own.
TEST(ProxyHeader, OtherFirstBytesAreNotAHeader) {
  const std::string tls_hello("\x16\x03\x01\x02\x00\x01", 6);
  for (const std::string& first :
       {std::string("GET / HTTP/1.1\r\n"), tls_hello, std::string("\r\n\r\nX", 5),
        std::string("\x0c\x00\x00\x00", 4)}) {
    ProxyHeaderReader r;
    ASSERT_EQ(r.feed(first.data(), first.size()), ProxyHeaderReader::State::None);
    EXPECT_EQ(r.take_rest(), first);
  }
}

TEST(ProxyHeader, BadHeadersAreRefusedWithAReason) {
  const std::string good = test::proxy_v2("203.0.113.5", 1);
  const auto bad = [&](std::size_t at, char value, const char* expect) {
    std::string h = good;
    h[at] = value;
    ProxyHeaderReader r;
    EXPECT_EQ(r.feed(h.data(), h.size()), ProxyHeaderReader::State::Bad) << expect;
    EXPECT_NE(r.error().find(expect), std::string::npos) << r.error();
  };
  bad(12, '\x11', "version 1");
  bad(12, '\x22', "unknown command");
  bad(13, '\x41', "address family");
  bad(13, '\x13', "address family");
  bad(14, '\x40', "at most");  // 16 KiB of header
  std::string shortened = good.substr(0, 16) + std::string(8, '\0');
  shortened[15] = 8;  // TCP over IPv4 needs 12 bytes of addresses
  ProxyHeaderReader r;
  EXPECT_EQ(r.feed(shortened.data(), shortened.size()), ProxyHeaderReader::State::Bad);
  EXPECT_NE(r.error().find("cut short"), std::string::npos) << r.error();
}

TEST(PeerTable, AProxysSessionsMoveToTheirClients) {
  ServerOptions o;
  o.max_clients_per_peer = 2;
  o.max_token_failures = 2;
  PeerTable table(o);
  const auto none = [] { return std::size_t{0}; };
  for (int i = 0; i < 5; ++i)  // a trusted proxy has no limit of its own
    ASSERT_EQ(table.admit("10.0.0.1", none, true), PeerTable::Admission::Ok);
  EXPECT_EQ(table.admit("10.0.0.1", none), PeerTable::Admission::PeerLimit);  // were it not
  EXPECT_EQ(table.move("10.0.0.1", "203.0.113.5"), PeerTable::Admission::Ok);
  EXPECT_EQ(table.move("10.0.0.1", "203.0.113.5"), PeerTable::Admission::Ok);
  EXPECT_EQ(table.move("10.0.0.1", "203.0.113.5"), PeerTable::Admission::PeerLimit);
  EXPECT_EQ(table.admit("203.0.113.5", none), PeerTable::Admission::PeerLimit);
  table.release("203.0.113.5");
  EXPECT_EQ(table.move("10.0.0.1", "203.0.113.5"), PeerTable::Admission::Ok);
  table.token_failed("203.0.113.6");
  EXPECT_TRUE(table.token_failed("203.0.113.6").second);  // banned
  EXPECT_EQ(table.move("10.0.0.1", "203.0.113.6"), PeerTable::Admission::Banned);
  EXPECT_NE(table.refusal(PeerTable::Admission::Banned).find("refused for a while"),
            std::string::npos);
  // The proxy's own address is never banned for its clients' tokens.
  EXPECT_EQ(table.admit("10.0.0.1", none, true), PeerTable::Admission::Ok);
  // Another trusted proxy (stacked behind a balancer) has no limit or ban of its own.
  table.token_failed("10.0.0.9");
  table.token_failed("10.0.0.9");
  for (int i = 0; i < 3; ++i)
    EXPECT_EQ(table.move("10.0.0.1", "10.0.0.9", true), PeerTable::Admission::Ok);
  EXPECT_EQ(table.move("10.0.0.1", "10.0.0.9"), PeerTable::Admission::Banned);
}

}  // namespace irradcast::test_client_address
