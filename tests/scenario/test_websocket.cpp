// The web port end to end over loopback: the viewer page's files over HTTP, and the protocol over
// a WebSocket (websocketpp's client role) against the same session as on TCP: the same tiles,
// the same Error for bad input, the same per-client limits, TLS.
#include <gtest/gtest.h>

#include <filesystem>
#include <thread>

#include "irradcast/client/client_session.h"
#include "irradcast/common/builtin.h"
#include "irradcast/common/error.h"
#include "irradcast/service/engine_host.h"
#include "irradcast/service/net_server.h"
#include "irradcast/service/web_origin.h"
#include "irradcast/web/assets.h"
#include "irradcast/wire/loopback_tls.h"
#include "service_fixture.h"
#include "websocket_client.h"

namespace irradcast::test_websocket {

using namespace std::chrono_literals;
using test::WsConnection;

namespace {

ServerOptions web_loopback(std::chrono::milliseconds idle = 5000ms) {
  ServerOptions o = test::loopback(idle);
  o.http_port = 0;
  return o;
}

// Drives a ClientSession over a connection (WsConnection or RawConnection) until every tile
// arrived at the version the tile store holds; false if the connection ended first.
template <class Connection>
bool download_everything(Connection& c, ClientSession& s, const TileStore& store) {
  c.send(s.hello());
  auto current = [&] {
    if (!s.tiles().all_received()) return false;
    for (std::uint32_t i = 0; i < store.tile_count(); ++i)
      if (s.tiles().versions()[i] != store.version(i)) return false;
    return true;
  };
  while (!current()) {
    const auto e = c.read(5000ms);
    if (!e) return false;
    const ClientStep step = s.on_frame(*e);
    for (const auto& m : step.send) c.send(m);
    if (step.event == ClientStep::Event::NeedScene) c.send(s.download());
  }
  return true;
}

std::string status_line(const std::string& response) {
  return response.substr(0, response.find("\r\n"));
}
std::string body_of(const std::string& response) {
  const auto p = response.find("\r\n\r\n");
  return p == std::string::npos ? "" : response.substr(p + 4);
}
std::string get(std::uint16_t port, const std::string& target) {
  return test::http_exchange(port, "GET " + target + " HTTP/1.1\r\nHost: x\r\n\r\n");
}

// A hand-made client frame: FIN + opcode byte, masked with a zero key.
std::string masked_frame(unsigned char first, const std::string& payload) {
  std::string f(1, static_cast<char>(first));
  f += static_cast<char>(0x80 | payload.size());  // payloads below 126 bytes
  f += std::string(4, '\0');
  return f + payload;
}

}  // namespace

TEST(WebSocket, ARoundTripGivesTheSameTilesAsTcp) {
  EngineHost host(make_cornell_box(), "cornell", test::quick_host(2));
  Server server(host, web_loopback());
  server.start();
  host.start();
  host.wait_for_updates(2);
  ASSERT_TRUE(test::eventually([&] { return host.stats().idle; }));

  WsConnection ws(server.http_port());
  ASSERT_TRUE(ws.opened());
  ClientSession over_ws({}), over_tcp({});
  ASSERT_TRUE(download_everything(ws, over_ws, host.tiles()));
  test::RawConnection tcp(server.port());
  ASSERT_TRUE(download_everything(tcp, over_tcp, host.tiles()));

  EXPECT_EQ(over_ws.scene_hash(), over_tcp.scene_hash());
  EXPECT_EQ(over_ws.tiles().versions(), over_tcp.tiles().versions());
  const auto& a = over_ws.tiles().lightmaps();
  const auto& b = over_tcp.tiles().lightmaps();
  ASSERT_EQ(a.size(), b.size());
  double lit = 0.0;
  for (std::size_t m = 0; m < a.size(); ++m) {
    ASSERT_EQ(a[m].texels.size(), b[m].texels.size());
    for (std::size_t t = 0; t < a[m].texels.size(); ++t) {
      ASSERT_EQ(a[m].texels[t], b[m].texels[t]) << "lightmap " << m << " texel " << t;
      lit += a[m].texels[t].x;
    }
  }
  EXPECT_GT(lit, 0.0);
  // A ping over the WebSocket gets its pong.
  ws.send(ClientSession::ping(7, 1));
  std::optional<wire::Envelope> pong;
  while ((pong = ws.read()) && !pong->has_pong()) {
  }
  ASSERT_TRUE(pong);
  EXPECT_EQ(pong->pong().nonce(), 7u);
  const ServerStats ss = server.stats();
  EXPECT_EQ(ss.websocket_sessions, 1u);
  EXPECT_EQ(ss.http_requests, 0u);
  server.stop();
  host.stop();
}

TEST(WebSocket, ServesThePageAndNothingElse) {
  EngineHost host(make_cornell_box(), "cornell", test::quick_host(1));
  Server server(host, web_loopback());
  server.start();
  const std::uint16_t port = server.http_port();
  ASSERT_NE(port, 0);
  ASSERT_NE(web::find_asset("/index.html"), nullptr);
  ASSERT_NE(web::find_asset("/viewer.js"), nullptr);

  const std::string page = get(port, "/");
  EXPECT_EQ(status_line(page), "HTTP/1.1 200 OK");
  EXPECT_NE(page.find("Content-Type: text/html; charset=utf-8\r\n"), std::string::npos);
  EXPECT_NE(page.find("X-Content-Type-Options: nosniff\r\n"), std::string::npos);
  EXPECT_NE(page.find("Content-Security-Policy: default-src 'self'"), std::string::npos);
  EXPECT_NE(page.find("Cache-Control: no-cache\r\n"), std::string::npos);
  EXPECT_EQ(body_of(page), web::find_asset("/index.html")->body);
  // The page's URL parameters do not change what is served.
  EXPECT_EQ(body_of(get(port, "/?camera=eye=0,0,1:target=0,0,0&ui=0")), body_of(page));
  const std::string js = get(port, "/viewer.js");
  EXPECT_EQ(status_line(js), "HTTP/1.1 200 OK");
  EXPECT_NE(js.find("Content-Type: text/javascript; charset=utf-8\r\n"), std::string::npos);
  EXPECT_EQ(body_of(js), web::find_asset("/viewer.js")->body);

  // Only the table's names: no path ever reaches the file system.
  for (const char* target : {"/nope", "/../web/index.html", "/%2e%2e/etc/passwd", "/index.html/",
                             "//index.html", "http://x/index.html", "/web/index.html"})
    EXPECT_EQ(status_line(get(port, target)), "HTTP/1.1 404 Not Found") << target;
  EXPECT_EQ(status_line(test::http_exchange(port, "POST / HTTP/1.1\r\nHost: x\r\n\r\n")),
            "HTTP/1.1 405 Method Not Allowed");
  // /ws without an upgrade; an upgrade elsewhere.
  EXPECT_EQ(status_line(get(port, "/ws")), "HTTP/1.1 426 Upgrade Required");
  WsConnection elsewhere(port, nullptr, "/index.html");
  EXPECT_FALSE(elsewhere.opened());
  // Not HTTP, a huge header: a 4xx reply and a close, no crash.
  EXPECT_EQ(status_line(test::http_exchange(port, "GARBAGE\r\n\r\n")).substr(0, 12),
            "HTTP/1.1 400");
  const std::string huge =
      "GET / HTTP/1.1\r\nHost: x\r\nX-Big: " + std::string(64 << 10, 'a') + "\r\n\r\n";
  EXPECT_EQ(status_line(test::http_exchange(port, huge)).substr(0, 12), "HTTP/1.1 431");

  // The server still serves a viewer.
  WsConnection ws(port);
  ASSERT_TRUE(ws.opened());
  EXPECT_TRUE(ws.join());
  // (The refused connections' sessions end just after their replies.)
  EXPECT_TRUE(test::eventually([&] { return server.stats().clients == 1; }));
  const ServerStats ss = server.stats();
  EXPECT_EQ(ss.http_requests, 15u);
  EXPECT_EQ(ss.websocket_sessions, 1u);
  EXPECT_EQ(ss.clients, 1u);
  server.stop();
}

// Each kind of bad input, once over TCP and once over the WebSocket: the same Error code, then a
// close (a WebSocket close frame with the matching code).
TEST(WebSocket, BadInputGetsTheSameErrorsAsTcp) {
  EngineHost host(make_cornell_box(), "cornell", test::quick_host(1));
  ServerOptions so = web_loopback();
  so.max_frame = 256u << 10;
  Server server(host, so);
  server.start();
  wire::Envelope ping;
  ping.mutable_ping()->set_nonce(1);
  const std::string garbage("\xff\xff\xff\xff", 4);
  const std::string big(1u << 20, 'x');
  struct Case {
    const char* name;
    bool hello_first;
    std::function<void(test::RawConnection&)> tcp;
    std::function<void(WsConnection&)> ws;
    wire::ErrorCode code;
    std::uint16_t close_code;
  };
  const std::vector<Case> cases = {
      {"not an Envelope", false, [&](auto& c) { c.write(std::string("\4\0\0\0", 4) + garbage); },
       [&](auto& c) { c.send_message(garbage); }, wire::BAD_FRAME, 1000},
      {"a frame other than Hello first", false, [&](auto& c) { c.send(ping); },
       [&](auto& c) { c.send(ping); }, wire::UNEXPECTED_MESSAGE, 1000},
      {"oversized before Hello", false,
       [&](auto& c) { c.write(std::string("\0\0\x10\0", 4) + big); },
       [&](auto& c) { c.send_message(big); }, wire::FRAME_TOO_LARGE, 1009},
      {"oversized after Hello", true, [&](auto& c) { c.write(std::string("\0\0\x10\0", 4) + big); },
       [&](auto& c) { c.send_message(big); }, wire::FRAME_TOO_LARGE, 1009},
      {"a text message", true, [&](auto& c) { c.write(std::string("\4\0\0\0", 4) + garbage); },
       [&](auto& c) { c.send_message("hello", false); }, wire::BAD_FRAME, 1002},
      {"an unmasked frame", true, [&](auto& c) { c.write(std::string("\4\0\0\0", 4) + garbage); },
       [&](auto& c) {
         c.write_raw(
             std::string("\x82\x03"
                         "abc",
                         5));
       },
       wire::BAD_FRAME, 1002},
      {"a reserved opcode", true, [&](auto& c) { c.write(std::string("\4\0\0\0", 4) + garbage); },
       [&](auto& c) { c.write_raw(masked_frame(0x83, "abc")); }, wire::BAD_FRAME, 1002},
      {"reserved bits", true, [&](auto& c) { c.write(std::string("\4\0\0\0", 4) + garbage); },
       [&](auto& c) { c.write_raw(masked_frame(0xC2, "abc")); }, wire::BAD_FRAME, 1002},
  };
  for (const Case& k : cases) {
    SCOPED_TRACE(k.name);
    test::RawConnection tcp(server.port());
    if (k.hello_first) {
      ASSERT_TRUE(tcp.join());
    }
    k.tcp(tcp);
    const auto tcp_error = tcp.error_then_close();
    ASSERT_TRUE(tcp_error);
    EXPECT_TRUE(tcp.eof);

    WsConnection ws(server.http_port());
    ASSERT_TRUE(ws.opened());
    if (k.hello_first) {
      ASSERT_TRUE(ws.join());
    }
    k.ws(ws);
    const auto ws_error = ws.error_then_close();
    ASSERT_TRUE(ws_error);
    EXPECT_TRUE(ws.raw.eof);
    EXPECT_EQ(ws_error->code(), k.code) << ws_error->message();
    EXPECT_EQ(tcp_error->code(), k.code) << tcp_error->message();
    EXPECT_EQ(ws.ws.remote_close_code(), k.close_code);
  }
  // The server goes on.
  WsConnection ws(server.http_port());
  EXPECT_TRUE(ws.join());
  EXPECT_TRUE(test::eventually([&] { return server.stats().clients == 1; }));
  const ServerStats ss = server.stats();
  EXPECT_EQ(ss.sessions_closed[static_cast<std::size_t>(CloseReason::BadFrame)], 10u);
  EXPECT_EQ(ss.sessions_closed[static_cast<std::size_t>(CloseReason::FrameTooLarge)], 4u);
  EXPECT_EQ(ss.websocket_sessions, cases.size() + 1);
  server.stop();
}

TEST(WebSocket, PerClientLimitsAndTimeoutsHoldAsOnTcp) {
  EngineHost host(make_cornell_box(), "cornell", test::quick_host(1));
  ServerOptions so = web_loopback(1500ms);
  so.max_clients_per_peer = 2;
  so.hello_timeout = 700ms;
  Server server(host, so);
  server.start();
  {
    WsConnection a(server.http_port()), b(server.http_port());
    ASSERT_TRUE(a.join());
    ASSERT_TRUE(b.join());
    // The third connection from this address: an HTTP refusal, like the TCP port's Error.
    const std::string third = get(server.http_port(), "/");
    EXPECT_EQ(status_line(third), "HTTP/1.1 503 Service Unavailable");
    EXPECT_NE(body_of(third).find("too many connections from this address"), std::string::npos);
    // Idle: the same Error as on TCP, then a close.
    const auto idle = a.error_then_close(5000ms);
    ASSERT_TRUE(idle);
    EXPECT_EQ(idle->code(), wire::IDLE_TIMEOUT);
    b.error_then_close(5000ms);
  }
  ASSERT_TRUE(test::eventually([&] { return server.stats().clients == 0; }));
  // No Hello in time: the same Error as on TCP once upgraded; a bare close before.
  test::RawConnection tcp(server.port());
  WsConnection ws(server.http_port());
  ASSERT_TRUE(ws.opened());
  const auto tcp_error = tcp.error_then_close(5000ms);
  const auto ws_error = ws.error_then_close(5000ms);
  ASSERT_TRUE(tcp_error);
  ASSERT_TRUE(ws_error);
  EXPECT_EQ(ws_error->code(), tcp_error->code());
  test::RawConnection silent(server.http_port());  // (two per peer: after the others)
  silent.error_then_close(5000ms);
  EXPECT_TRUE(silent.eof) << "a connection that never sends a request is closed";
  ASSERT_TRUE(test::eventually([&] { return server.stats().clients == 0; }));
  const ServerStats ss = server.stats();
  EXPECT_EQ(ss.sessions_closed[static_cast<std::size_t>(CloseReason::IdleTimeout)], 2u);
  EXPECT_EQ(ss.sessions_closed[static_cast<std::size_t>(CloseReason::HelloTimeout)], 3u);
  EXPECT_EQ(ss.peer_refused, 1u);
  server.stop();
}

TEST(WebSocket, TheWebPortUsesTheServersTls) {
  const std::filesystem::path dir =
      std::filesystem::path(testing::TempDir()) / "irradcast_websocket_tls";
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  const wire::LoopbackTlsFiles files = wire::make_loopback_tls_files(dir.string());
  EngineHost host(make_cornell_box(), "cornell", test::quick_host(1));
  ServerOptions so = web_loopback();
  so.tls_cert = files.cert;
  so.tls_key = files.key;
  Server server(host, so);
  server.start();
  auto tls = wire::make_client_tls(files.ca);
  const std::string page =
      test::http_exchange(server.http_port(), "GET / HTTP/1.1\r\nHost: x\r\n\r\n", tls.get());
  EXPECT_EQ(status_line(page), "HTTP/1.1 200 OK");
  EXPECT_EQ(body_of(page), web::find_asset("/index.html")->body);
  WsConnection wss(server.http_port(), tls.get());
  ASSERT_TRUE(wss.opened());
  EXPECT_TRUE(wss.join());
  // Plain HTTP on the TLS port gets no page.
  const std::string plain = get(server.http_port(), "/");
  EXPECT_EQ(plain.find("200 OK"), std::string::npos);
  server.stop();
}

// RFC 6455 lets any hop split a message into fragments: they are joined into one frame (within
// the same cap), so a proxy that re-fragments does not break the protocol. Then the server stops.
TEST(WebSocket, AFragmentedMessageIsOneFrameAndShutdownIsAnnounced) {
  EngineHost host(make_cornell_box(), "cornell", test::quick_host(1));
  Server server(host, web_loopback());
  server.start();
  WsConnection ws(server.http_port());
  ASSERT_TRUE(ws.opened());
  const std::string hello = test::hello_frame("fragments").SerializeAsString();
  ASSERT_GT(hello.size(), 4u);
  ws.write_raw(masked_frame(0x02, hello.substr(0, 3)) +  // binary, not final
               masked_frame(0x89, "ping") +              // a control frame in between
               masked_frame(0x80, hello.substr(3)));     // continuation, final
  std::optional<wire::Envelope> e = ws.read();
  ASSERT_TRUE(e);
  ASSERT_TRUE(e->has_welcome()) << wire::message_name(*e);
  // Shutdown reaches a WebSocket client as on TCP.
  std::thread stopper([&] { server.stop(); });
  const auto error = ws.error_then_close();
  stopper.join();
  ASSERT_TRUE(error);
  EXPECT_EQ(error->code(), wire::SERVER_SHUTDOWN);
  EXPECT_EQ(ws.ws.remote_close_code(), 1000);
}

namespace {
// A WebSocket upgrade of /ws with these extra header lines; the reply's status line.
std::string upgrade_status(std::uint16_t port, const std::string& host, const std::string& extra) {
  const std::string request = "GET /ws HTTP/1.1\r\nHost: " + host +
                              "\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
                              "Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\n"
                              "Sec-WebSocket-Version: 13\r\n" +
                              extra + "\r\n";
  return status_line(test::http_exchange(port, request, nullptr, true));
}
}  // namespace

// Cross-site WebSocket hijacking: a page of another site, in the browser of someone who can
// reach the server, must not open /ws (and download the scene through them). Pages of the
// server's own host, clients that send no Origin (not browsers), and origins given with
// --allowed-origin may.
TEST(WebSocket, OnlyPagesOfTheServersOwnOriginOrAllowedOnesOpenTheWebSocket) {
  EngineHost host(make_cornell_box(), "cornell", test::quick_host(1));
  ServerOptions o = web_loopback();
  o.allowed_origins = {"https://viewer.example.org"};
  Server server(host, o);
  server.start();
  const std::uint16_t port = server.http_port();
  const std::string self = "127.0.0.1:" + std::to_string(port);
  const std::string switching = "HTTP/1.1 101 Switching Protocols";
  const std::string forbidden = "HTTP/1.1 403 Forbidden";
  EXPECT_EQ(upgrade_status(port, self, ""), switching);
  EXPECT_EQ(upgrade_status(port, self, "Origin: http://" + self + "\r\n"), switching);
  EXPECT_EQ(upgrade_status(port, self, "Origin: HTTPS://" + self + "/\r\n"), switching);
  EXPECT_EQ(upgrade_status(port, self, "Origin: https://viewer.example.org\r\n"), switching);
  for (const char* origin : {"http://evil.example", "http://127.0.0.1:1", "null",
                             "https://viewer.example.org.evil", "http://viewer.example.org"})
    EXPECT_EQ(upgrade_status(port, self, std::string("Origin: ") + origin + "\r\n"), forbidden)
        << origin;
  // RFC 6455 only, and nothing after the request's blank line.
  const std::string key = "Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\n";
  const std::string head = "GET /ws HTTP/1.1\r\nHost: " + self +
                           "\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n" + key;
  // (Without a version websocketpp refuses by itself, with a 4xx or 5xx of its choosing.)
  const std::string draft = status_line(test::http_exchange(port, head + "\r\n", nullptr, true));
  EXPECT_TRUE(draft.rfind("HTTP/1.1 4", 0) == 0 || draft.rfind("HTTP/1.1 5", 0) == 0) << draft;
  EXPECT_EQ(status_line(test::http_exchange(
                port, head + "Sec-WebSocket-Version: 13\r\nContent-Length: 10\r\n\r\n0123456789",
                nullptr, true)),
            "HTTP/1.1 400 Bad Request");
  // Pages on the default ports.
  EXPECT_TRUE(origin_allowed("http://example.com", "example.com:80", {}));
  EXPECT_TRUE(origin_allowed("https://example.com:443", "example.com", {}));
  EXPECT_FALSE(origin_allowed("https://example.com:8443", "example.com", {}));
  EXPECT_FALSE(origin_allowed("http://example.com", "", {}));
  EXPECT_TRUE(origin_allowed("null", "x", {"null"}));
  // --allowed-origin values are checked.
  for (const char* bad : {"evil.example", "ftp://x", "http://", "http://a/path", "http://u@h"})
    EXPECT_THROW(check_origin(bad), Error) << bad;
  EXPECT_NO_THROW(check_origin("https://viewer.example.org:8443"));
  const ServerStats ss = server.stats();
  EXPECT_EQ(ss.websocket_sessions, 4u);
  server.stop();
}

namespace {
// A masked client frame (mask 0) of `payload_bytes` announced, with `sent` of them: `first` is
// FIN and the opcode.
std::string big_frame(unsigned char first, std::uint64_t announced, std::size_t sent) {
  std::string f(1, static_cast<char>(first));
  f += static_cast<char>(0x80 | 127);
  for (int i = 7; i >= 0; --i) f += static_cast<char>((announced >> (8 * i)) & 0xff);
  f += std::string(4, '\0');
  return f + std::string(sent, 'p');
}
}  // namespace

// Unfinished WebSocket messages count in the server's budget of incomplete frames, as TCP frames
// do (the WebSocket library buffers them itself): one large frame half sent, or a message
// fragmented into complete frames without FIN; 6 sessions each holding 512 KiB under a 1 MiB
// budget: most are closed with FRAME_TOO_LARGE, and the total held stays bounded.
TEST(WebSocket, UnfinishedMessagesCountInTheBudgetOfIncompleteFrames) {
  for (const bool fragmented : {false, true}) {
    EngineHost host(make_cornell_box(), "cornell", test::quick_host(1));
    ServerOptions o = web_loopback();
    o.max_partial_bytes = 1u << 20;
    Server server(host, o);
    server.start();
    std::vector<std::unique_ptr<WsConnection>> clients;
    for (int i = 0; i < 6; ++i) {
      clients.push_back(std::make_unique<WsConnection>(server.http_port()));
      ASSERT_TRUE(clients.back()->opened());
      ASSERT_TRUE(clients.back()->join());
      if (fragmented)
        for (int k = 0; k < 4; ++k)  // binary, then continuations, none final
          clients.back()->write_raw(big_frame(k == 0 ? 0x02 : 0x00, 128u << 10, 128u << 10));
      else
        clients.back()->write_raw(big_frame(0x82, 4u << 20, 512u << 10));
    }
    int refused = 0;
    for (auto& c : clients) {
      auto e = c->read(1500ms);
      if (e && e->has_error()) {
        EXPECT_EQ(e->error().code(), wire::FRAME_TOO_LARGE);
        ++refused;
      }
    }
    EXPECT_GE(refused, 4) << (fragmented ? "fragmented" : "one frame");
    EXPECT_LE(server.stats().partial_bytes, (1u << 20) + (512u << 10));
    clients.clear();
    server.stop();
    EXPECT_EQ(server.stats().partial_bytes, 0u);
  }
}

}  // namespace irradcast::test_websocket
