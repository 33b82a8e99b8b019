// The server behind a reverse proxy or load balancer (--trusted-proxy, issue 31 part 7): the
// per-address session limit and the ban after wrong control tokens apply to each client the proxy
// names (a PROXY protocol v2 header on either port, X-Forwarded-For or Forwarded on the web
// port), the proxy itself is not limited, and what a peer that is not trusted says is ignored.
// Every test talks to a real server over loopback; 127.0.0.1 is the proxy, 127.0.0.2 a client
// that connects directly.
#include <gtest/gtest.h>

#include <unistd.h>

#include <csignal>
#include <filesystem>
#include <fstream>
#include <memory>
#include <thread>
#include <vector>

#include "cli.h"
#include "irradcast/common/builtin.h"
#include "irradcast/common/scene_edit.h"
#include "irradcast/service/engine_host.h"
#include "irradcast/service/net_server.h"
#include "irradcast/wire/edit_message.h"
#include "irradcast/wire/loopback_tls.h"
#include "process.h"
#include "proxy_header.h"
#include "service_fixture.h"
#include "testdata.h"
#include "websocket_client.h"

namespace irradcast::test_trusted_proxy {

using namespace std::chrono_literals;
using test::proxy_v2;
using Raw = test::RawConnection;
using Headers = std::vector<std::pair<std::string, std::string>>;

namespace {

const std::string kToken = "proxy-test-token-0123456";

ServerOptions behind_proxy(std::uint32_t per_peer) {
  ServerOptions o = test::loopback(30000ms);
  o.http_port = 0;
  o.max_clients_per_peer = per_peer;
  o.trusted_proxies = {"127.0.0.1/32"};
  o.proxy_protocol = true;  // the protocol port: a TCP balancer; the web port: an HTTP proxy
  o.control_token = kToken;
  o.token_failure_delay = 20ms;
  o.max_token_failures = 2;
  o.ban_duration = 60000ms;
  return o;
}

wire::Envelope wrong_edit(const std::string& token) {
  return test::nudge_edit_frame(token, 7);
}

// One HTTP request to the web port with `headers`, from `from` (empty: 127.0.0.1), after
// `preamble`: the whole response.
std::string http_get(std::uint16_t port, const Headers& headers, const std::string& from = {},
                     const std::string& preamble = {}) {
  Raw c(port, nullptr, preamble, from);
  std::string request = "GET / HTTP/1.1\r\nHost: 127.0.0.1\r\nConnection: close\r\n";
  for (const auto& [name, value] : headers) request += name + ": " + value + "\r\n";
  c.write(request + "\r\n");
  std::string out;
  const auto deadline = std::chrono::steady_clock::now() + 5s;
  while (!c.eof && std::chrono::steady_clock::now() < deadline) {
    const auto [result, n] = test::read_some_before(c.io, c.stream, asio::buffer(c.buf), deadline,
                                                    [&] { c.stream.socket().cancel(); });
    out.append(c.buf.data(), n);
    if (result) c.eof = true;
  }
  return out;
}

std::string status_line(const std::string& response) {
  return response.substr(0, response.find("\r\n"));
}

bool refused_with(const std::optional<wire::Error>& e, const std::string& words) {
  return e && e->code() == wire::REFUSED && e->message().find(words) != std::string::npos;
}

}  // namespace

// The protocol port: two sessions per client address, however many the proxy carries.
TEST(TrustedProxy, ProxyHeadersNameTheClientsOnTheProtocolPort) {
  EngineHost host(make_cornell_box(), "cornell", test::quick_host());
  Server server(host, behind_proxy(2));
  server.start();
  std::vector<std::unique_ptr<Raw>> open;
  for (const char* client : {"203.0.113.5", "203.0.113.5", "203.0.113.6", "2001:db8::6"}) {
    open.push_back(std::make_unique<Raw>(server.port(), nullptr, proxy_v2(client, 40000)));
    ASSERT_TRUE(open.back()->join()) << client;
  }
  // The same /64 is the same client.
  open.push_back(std::make_unique<Raw>(server.port(), nullptr, proxy_v2("2001:db8::7", 1)));
  ASSERT_TRUE(open.back()->join());
  Raw third(server.port(), nullptr, proxy_v2("203.0.113.5", 40001));
  EXPECT_TRUE(refused_with(third.error_then_close(2000ms), "too many connections"));
  Raw third6(server.port(), nullptr, proxy_v2("2001:db8::8", 40001));
  EXPECT_TRUE(refused_with(third6.error_then_close(2000ms), "too many connections"));
  // The proxy's own connections (a health check: a LOCAL header) are not limited.
  for (int i = 0; i < 3; ++i) {
    open.push_back(std::make_unique<Raw>(server.port(), nullptr, test::proxy_v2_local()));
    ASSERT_TRUE(open.back()->join()) << i;
  }
  EXPECT_EQ(server.stats().peer_refused, 2u);
  // The header is required (--proxy-protocol): a trusted peer's connection without one is not
  // guessed at, it is closed.
  Raw headless(server.port());
  EXPECT_FALSE(headless.join());
  EXPECT_TRUE(headless.eof);
  // A client that connects directly is limited, and its PROXY header is not believed: its
  // bytes are a frame of 168 MB.
  Raw a(server.port(), nullptr, {}, "127.0.0.2"), b(server.port(), nullptr, {}, "127.0.0.2");
  ASSERT_TRUE(a.join());
  ASSERT_TRUE(b.join());
  Raw spoof(server.port(), nullptr, proxy_v2("198.51.100.1", 1), "127.0.0.2");
  EXPECT_TRUE(refused_with(spoof.error_then_close(2000ms), "too many connections"));
  b.stream.close();
  ASSERT_TRUE(test::eventually([&] { return server.stats().clients == open.size() + 1; }));
  Raw spoof2(server.port(), nullptr, proxy_v2("198.51.100.1", 1), "127.0.0.2");
  const auto e = spoof2.error_then_close(2000ms);
  ASSERT_TRUE(e.has_value());
  EXPECT_EQ(e->code(), wire::FRAME_TOO_LARGE) << e->message();
  server.stop();
}

// Wrong control tokens ban the client that sent them, on both ports, and never the proxy or the
// proxy's other clients.
TEST(TrustedProxy, WrongTokensBanTheClientNotTheProxy) {
  EngineHost host(make_cornell_box(), "cornell", test::quick_host());
  Server server(host, behind_proxy(8));
  server.start();
  {
    Raw guesser(server.port(), nullptr, proxy_v2("203.0.113.66", 5000));
    ASSERT_TRUE(guesser.join());
    guesser.send(wrong_edit("guess-one-guess-one"));
    guesser.send(wrong_edit("guess-two-guess-two"));
    EXPECT_TRUE(guesser.error_then_close(5000ms).has_value());
    EXPECT_TRUE(guesser.eof);
  }
  Raw again(server.port(), nullptr, proxy_v2("203.0.113.66", 5001));
  EXPECT_TRUE(refused_with(again.error_then_close(2000ms), "refused for a while"));
  const std::string web = http_get(server.http_port(), {{"X-Forwarded-For", "203.0.113.66"}});
  EXPECT_EQ(status_line(web), "HTTP/1.1 503 Service Unavailable") << web;
  EXPECT_NE(web.find("refused for a while"), std::string::npos) << web;
  EXPECT_EQ(server.stats().banned_refused, 2u);
  // Another client through the same proxy edits with the right token.
  Raw other(server.port(), nullptr, proxy_v2("203.0.113.67", 5002));
  ASSERT_TRUE(other.join());
  const std::optional<wire::Envelope> ack = other.edit(wrong_edit(kToken));
  ASSERT_TRUE(ack.has_value());
  EXPECT_TRUE(ack->has_scene_edit()) << ack->DebugString();
  // The proxy's own page request (no X-Forwarded-For) is served.
  EXPECT_EQ(status_line(http_get(server.http_port(), {})), "HTTP/1.1 200 OK");
  // A session that names no client may not present a token: its failures would fall on the
  // proxy's other clients.
  const std::uint64_t failures = server.stats().token_failures;
  Raw unnamed(server.port(), nullptr, test::proxy_v2_local());
  ASSERT_TRUE(unnamed.join());
  unnamed.send(wrong_edit("guess-three-guess-three"));
  std::optional<wire::Envelope> denied;
  while ((denied = unnamed.read(5000ms)) && !denied->has_error()) {
  }
  ASSERT_TRUE(denied.has_value());
  EXPECT_EQ(denied->error().code(), wire::PERMISSION_DENIED) << denied->DebugString();
  EXPECT_NE(denied->error().message().find("does not name its client"), std::string::npos);
  EXPECT_EQ(server.stats().token_failures, failures);
  server.stop();
}

// The web port: X-Forwarded-For read from the nearest hop; a client cannot name itself by
// writing the header, neither through the proxy (read from the right) nor directly (ignored).
TEST(TrustedProxy, ForwardedForNamesTheClientsOnTheWebPort) {
  EngineHost host(make_cornell_box(), "cornell", test::quick_host());
  ServerOptions o = behind_proxy(2);
  o.trusted_proxies.push_back("10.0.0.0/8");  // a second hop inside the operator's network
  Server server(host, o);
  server.start();
  const std::uint16_t port = server.http_port();
  std::vector<std::unique_ptr<test::WsConnection>> open;
  for (const char* xff :
       {"198.51.100.1, 203.0.113.9", "198.51.100.2, 203.0.113.9, 10.1.1.1", "203.0.113.10"}) {
    open.push_back(std::make_unique<test::WsConnection>(port, nullptr, "/ws",
                                                        Headers{{"X-Forwarded-For", xff}}));
    ASSERT_TRUE(open.back()->join()) << xff;
  }
  const std::string third = http_get(port, {{"X-Forwarded-For", "198.51.100.3, 203.0.113.9"}});
  EXPECT_EQ(status_line(third), "HTTP/1.1 503 Service Unavailable") << third;
  EXPECT_NE(third.find("too many connections from this address"), std::string::npos) << third;
  // The upgrade is refused alike.
  test::WsConnection refused(port, nullptr, "/ws", Headers{{"X-Forwarded-For", "203.0.113.9"}});
  EXPECT_FALSE(refused.opened());
  // A quote a client wrote before what its proxy appended changes nothing (X-Forwarded-For has
  // no quoting), on one line or as a second header line.
  const std::string quoted = http_get(port, {{"X-Forwarded-For", "\", 203.0.113.9"}});
  EXPECT_EQ(status_line(quoted), "HTTP/1.1 503 Service Unavailable") << quoted;
  const std::string two_lines =
      http_get(port, {{"X-Forwarded-For", "\""}, {"X-Forwarded-For", "203.0.113.9"}});
  EXPECT_EQ(status_line(two_lines), "HTTP/1.1 503 Service Unavailable") << two_lines;
  // A forwarded header that names no client is refused: nobody to count it under.
  const std::string unknown = http_get(port, {{"X-Forwarded-For", "203.0.113.9, unknown"}});
  EXPECT_EQ(status_line(unknown), "HTTP/1.1 400 Bad Request") << unknown;
  // Directly connected: the header is the client's own word, and ignored.
  test::WsConnection a(port, nullptr, "/ws", Headers{{"X-Forwarded-For", "192.0.2.1"}}, {},
                       "127.0.0.2");
  test::WsConnection b(port, nullptr, "/ws", Headers{{"X-Forwarded-For", "192.0.2.2"}}, {},
                       "127.0.0.2");
  ASSERT_TRUE(a.join());
  ASSERT_TRUE(b.join());
  const std::string spoof = http_get(port, {{"X-Forwarded-For", "192.0.2.3"}}, "127.0.0.2");
  EXPECT_EQ(status_line(spoof), "HTTP/1.1 503 Service Unavailable") << spoof;
  // The Forwarded header is not read when the proxies write X-Forwarded-For (a client could
  // write it): the request counts as the proxy's own.
  EXPECT_EQ(status_line(http_get(port, {{"Forwarded", "for=203.0.113.9"}})), "HTTP/1.1 200 OK");
  EXPECT_EQ(server.stats().peer_refused, 5u);
  server.stop();
}

// A TCP balancer (PROXY headers, --proxy-protocol web) in front of trusted HTTP proxies
// (X-Forwarded-For): each hop trusted, the client counted; the HTTP proxy itself is neither
// limited nor banned, whatever its unnamed requests do.
TEST(TrustedProxy, StackedBalancerAndProxies) {
  EngineHost host(make_cornell_box(), "cornell", test::quick_host());
  ServerOptions o = behind_proxy(1);
  o.trusted_proxies.push_back("10.0.0.0/8");
  o.web_proxy_protocol = true;
  Server server(host, o);
  server.start();
  const std::uint16_t port = server.http_port();
  const std::string via_proxy = proxy_v2("10.2.3.4", 1000);
  test::WsConnection a(port, nullptr, "/ws", Headers{{"X-Forwarded-For", "203.0.113.9"}},
                       via_proxy);
  ASSERT_TRUE(a.join());
  const std::string again = http_get(port, {{"X-Forwarded-For", "203.0.113.9"}}, {}, via_proxy);
  EXPECT_EQ(status_line(again), "HTTP/1.1 503 Service Unavailable") << again;
  // The balancer naming the client directly: that client, whatever it writes.
  const std::string direct =
      http_get(port, {{"X-Forwarded-For", "203.0.113.77"}}, {}, proxy_v2("203.0.113.9", 1000));
  EXPECT_EQ(status_line(direct), "HTTP/1.1 503 Service Unavailable") << direct;
  // The HTTP proxy's own connections (no X-Forwarded-For): no limit of 1 for it.
  std::vector<std::unique_ptr<test::WsConnection>> own;
  for (int i = 0; i < 3; ++i) {
    own.push_back(std::make_unique<test::WsConnection>(port, nullptr, "/ws", Headers{}, via_proxy));
    ASSERT_TRUE(own.back()->join()) << i;
  }
  // ... and their tokens are not taken, so they cannot get it banned.
  own.front()->send(wrong_edit("guess-four-guess-four"));
  std::optional<wire::Envelope> e;
  while ((e = own.front()->read(5000ms)) && !e->has_error()) {
  }
  ASSERT_TRUE(e.has_value());
  EXPECT_EQ(e->error().code(), wire::PERMISSION_DENIED);
  test::WsConnection b(port, nullptr, "/ws", Headers{{"X-Forwarded-For", "203.0.113.10"}},
                       via_proxy);
  EXPECT_TRUE(b.join());
  // Without the balancer's header the connection is closed unanswered.
  EXPECT_EQ(http_get(port, {{"X-Forwarded-For", "203.0.113.11"}}), "");
  EXPECT_EQ(server.stats().token_failures, 0u);
  server.stop();
}

TEST(TrustedProxy, ForwardedHeaderWhenTheProxiesWriteIt) {
  EngineHost host(make_cornell_box(), "cornell", test::quick_host());
  ServerOptions o = behind_proxy(1);
  o.forwarded_header = ForwardedHeader::Forwarded;
  Server server(host, o);
  server.start();
  const std::uint16_t port = server.http_port();
  test::WsConnection a(port, nullptr, "/ws",
                       Headers{{"Forwarded", "for=\"[2001:db8::1]:4711\";proto=https"}});
  ASSERT_TRUE(a.join());
  const std::string second =
      http_get(port, {{"Forwarded", "for=198.51.100.1, for=\"[2001:db8::2]\""}});
  EXPECT_EQ(status_line(second), "HTTP/1.1 503 Service Unavailable") << second;
  EXPECT_EQ(status_line(http_get(port, {{"X-Forwarded-For", "2001:db8::1"}})), "HTTP/1.1 200 OK");
  server.stop();
}

// With TLS the PROXY header comes before the handshake (HAProxy's send-proxy-v2 in front of a
// TLS server); a client refused behind it is told so over TLS.
TEST(TrustedProxy, ProxyHeaderBeforeTls) {
  const auto dir = std::filesystem::temp_directory_path() / "irradcast_proxy_tls";
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  const wire::LoopbackTlsFiles files = wire::make_loopback_tls_files(dir.string());
  EngineHost host(make_cornell_box(), "cornell", test::quick_host());
  ServerOptions o = behind_proxy(1);
  o.web_proxy_protocol = true;
  o.tls_cert = files.cert;
  o.tls_key = files.key;
  Server server(host, o);
  server.start();
  auto tls = wire::make_client_tls(files.ca);
  Raw first(server.port(), tls.get(), proxy_v2("203.0.113.5", 1));
  ASSERT_FALSE(first.connect_error) << first.connect_error.message();
  ASSERT_TRUE(first.join());
  Raw second(server.port(), tls.get(), proxy_v2("203.0.113.5", 2));
  ASSERT_FALSE(second.connect_error) << second.connect_error.message();
  EXPECT_TRUE(refused_with(second.error_then_close(2000ms), "too many connections"));
  Raw other(server.port(), tls.get(), proxy_v2("203.0.113.6", 3));
  EXPECT_TRUE(other.join());
  test::WsConnection wss(server.http_port(), tls.get(), "/ws", {}, proxy_v2("203.0.113.7", 4));
  EXPECT_TRUE(wss.join());
  server.stop();
  std::filesystem::remove_all(dir);
}

// A header that starts as a PROXY header and is not one closes the connection; the proxy's
// other connections go on.
TEST(TrustedProxy, ABadProxyHeaderClosesItsConnectionOnly) {
  EngineHost host(make_cornell_box(), "cornell", test::quick_host());
  Server server(host, behind_proxy(2));
  server.start();
  std::string bad = proxy_v2("203.0.113.5", 1);
  bad[12] = '\x11';  // version 1
  Raw r(server.port(), nullptr, bad);
  r.read(2000ms);
  EXPECT_TRUE(r.eof);
  Raw silent(server.port(), nullptr, proxy_v2("203.0.113.5", 1).substr(0, 14));
  Raw ok(server.port(), nullptr, proxy_v2("203.0.113.5", 2));
  EXPECT_TRUE(ok.join());
  EXPECT_TRUE(test::eventually([&] {
    return server.stats().sessions_closed[static_cast<std::size_t>(CloseReason::BadFrame)] == 1u;
  }));
  server.stop();
}

// The programs take the option and say which entry is wrong before they load anything.
TEST(TrustedProxy, TheProgramsNameABadNetwork) {
  for (const char* exe : {IRRADCAST_SERVER_EXE, IRRADCAST_GATEWAY_EXE}) {
    const test::CliResult r = test::run_cli(std::string("timeout 30 ") + exe,
                                            "--trusted-proxy 10.0.0.0/8,10.1.2.3/16 --port 0");
    EXPECT_NE(r.status, 0) << r.output;
    EXPECT_NE(r.output.find("'10.1.2.3/16': the address has bits set past the prefix length"),
              std::string::npos)
        << r.output;
    const test::CliResult alone = test::run_cli(
        std::string("timeout 30 ") + exe,
        std::string("--proxy-protocol both --port 0") +
            (exe == std::string(IRRADCAST_GATEWAY_EXE) ? " --nats nats://127.0.0.1:1" : ""));
    EXPECT_EQ(alone.status, 1) << alone.output;
    EXPECT_NE(alone.output.find("--proxy-protocol both needs --trusted-proxy"), std::string::npos)
        << alone.output;
  }
}

// HAProxy in front of both ports, as an operator would run it: TCP mode with send-proxy-v2 to
// the protocol port, HTTP mode with `option forwardfor` to the web port. Its clients connect from
// 127.0.0.2 to 127.0.0.5; the server trusts only 127.0.0.1, where HAProxy's own connections
// come from.
TEST(TrustedProxy, BehindARealHaproxy) {
  const char* haproxy = "/usr/sbin/haproxy";
  if (::access(haproxy, X_OK) != 0) {
    if (test::testdata_required()) FAIL() << "no haproxy (apt-get install haproxy)";
    GTEST_SKIP() << "no haproxy (apt-get install haproxy)";
  }
  EngineHost host(make_cornell_box(), "cornell", test::quick_host());
  Server server(host, behind_proxy(1));
  server.start();
  const auto dir =
      std::filesystem::temp_directory_path() / ("irradcast_haproxy_" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  const std::uint16_t tcp_port = test::free_port(), web_port = test::free_port();
  {
    std::ofstream cfg(dir / "haproxy.cfg");
    cfg << "defaults\n  timeout connect 5s\n  timeout client 30s\n  timeout server 30s\n"
        << "  timeout tunnel 30s\n"
        << "frontend protocol\n  mode tcp\n  bind 127.0.0.1:" << tcp_port << "\n"
        << "  default_backend irradcast_tcp\n"
        << "backend irradcast_tcp\n  mode tcp\n  server s1 127.0.0.1:" << server.port()
        << " send-proxy-v2\n"
        << "frontend web\n  mode http\n  bind 127.0.0.1:" << web_port << "\n"
        << "  option forwardfor\n  default_backend irradcast_web\n"
        << "backend irradcast_web\n  mode http\n  server s1 127.0.0.1:" << server.http_port()
        << "\n";
  }
  test::Process proxy(test::command(haproxy, "-db -f " + (dir / "haproxy.cfg").string()),
                      dir / "haproxy.log");
  ASSERT_TRUE(test::eventually([&] {
    asio::io_context io;
    asio::ip::tcp::socket s(io);
    std::error_code ec;
    s.connect({asio::ip::make_address("127.0.0.1"), web_port}, ec);
    return !ec;
  })) << proxy.output();

  Raw a(tcp_port, nullptr, {}, "127.0.0.2");
  ASSERT_TRUE(a.join()) << proxy.output();
  Raw a2(tcp_port, nullptr, {}, "127.0.0.2");
  EXPECT_TRUE(refused_with(a2.error_then_close(3000ms), "too many connections"));
  Raw b(tcp_port, nullptr, {}, "127.0.0.3");
  EXPECT_TRUE(b.join());

  test::WsConnection c(web_port, nullptr, "/ws", {}, {}, "127.0.0.4");
  ASSERT_TRUE(c.join()) << proxy.output();
  // A client's own X-Forwarded-For goes before the one HAProxy adds: not believed.
  const std::string c2 = http_get(web_port, {{"X-Forwarded-For", "198.51.100.9"}}, "127.0.0.4");
  EXPECT_EQ(status_line(c2), "HTTP/1.1 503 Service Unavailable") << c2;
  EXPECT_NE(c2.find("too many connections from this address"), std::string::npos) << c2;
  const std::string d = http_get(web_port, {}, "127.0.0.5");
  EXPECT_EQ(status_line(d), "HTTP/1.1 200 OK") << d;
  EXPECT_EQ(server.stats().peer_refused, 2u);
  proxy.signal(SIGTERM);
  proxy.wait_for(5000ms);
  server.stop();
  std::filesystem::remove_all(dir);
}

}  // namespace irradcast::test_trusted_proxy
