// The whole service over TLS with a certificate made at test time: the server's protocol port
// and metrics endpoint, irradcast-view, irradcast-load and irradcast-edit as a user runs them.
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <openssl/ssl.h>
#include <openssl/x509.h>
#include <asio.hpp>

#include <filesystem>
#include <fstream>
#include <thread>

#include "cli.h"
#include "irradcast/common/builtin.h"
#include "irradcast/common/image.h"
#include "irradcast/common/log.h"
#include "irradcast/common/progress.h"
#include "irradcast/service/engine_host.h"
#include "irradcast/service/metrics_endpoint.h"
#include "irradcast/service/metrics_text.h"
#include "irradcast/service/net_server.h"
#include "irradcast/wire/loopback_tls.h"
#include "irradcast/wire/transport.h"
#include "process.h"
#include "service_fixture.h"

namespace irradcast::test_tls_service {

using namespace std::chrono_literals;
namespace fs = std::filesystem;

namespace {

const std::string kToken = "tls-test-token-0123456789";

// GET /metrics over TLS; the response (head and body), or "" on failure (and why in `error`).
std::string https_get(std::uint16_t port, const std::string& ca, std::string& error) {
  asio::io_context io;
  auto ctx = wire::make_client_tls(ca);
  wire::Stream s(io.get_executor(), ctx.get());
  std::error_code ec;
  s.socket().connect({asio::ip::make_address("127.0.0.1"), port}, ec);
  if (!ec) {
    s.expect_server_name("127.0.0.1");
    s.handshake(asio::ssl::stream_base::client, ec);
  }
  if (!ec)
    asio::write(s, asio::buffer(std::string("GET /metrics HTTP/1.1\r\nHost: x\r\n\r\n")), ec);
  if (ec) {
    error = wire::describe_tls_error(ec);
    return "";
  }
  std::string out;
  std::array<char, 8192> buf{};
  for (;;) {
    const std::size_t n = s.read_some(asio::buffer(buf), ec);
    out.append(buf.data(), n);
    if (ec) break;
  }
  return out;
}

}  // namespace

TEST(Tls, TheWholeServiceOverTls) {
  const fs::path dir = fs::path(testing::TempDir()) / "irradcast_tls_service";
  fs::remove_all(dir);
  fs::create_directories(dir);
  const wire::LoopbackTlsFiles files = wire::make_loopback_tls_files(dir.string());

  EngineHost host(make_cornell_box(), "cornell", test::quick_host(4));
  ServerOptions so = test::loopback();
  so.control_token = kToken;
  so.tls_cert = files.cert;
  so.tls_key = files.key;
  Server server(host, so);
  server.start();
  MetricsEndpointOptions mo;
  mo.bind = "127.0.0.1";
  mo.port = 0;
  mo.tls_cert = files.cert;
  mo.tls_key = files.key;
  MetricsEndpoint metrics([&] { return format_metrics(collect_metrics(server, host)); }, mo);
  metrics.start();
  host.start();
  EXPECT_EQ(metrics.url().rfind("https://", 0), 0u) << metrics.url();

  const std::string connect = "--connect 127.0.0.1:" + std::to_string(server.port());
  const std::string tls = " --tls --tls-ca " + files.ca;

  // A viewer converges and writes its image.
  const fs::path image = dir / "view.png";
  test::CliResult v =
      test::run_cli(IRRADCAST_VIEW_EXE,
                    connect + tls + " --out " + image.string() +
                        " --until-converged --timeout 60 --width 64 --height 48 --cache-dir " +
                        (dir / "cache").string());
  EXPECT_EQ(v.status, 0) << v.output;
  EXPECT_TRUE(fs::exists(image));

  // An edit is applied.
  test::CliResult e = test::run_cli(IRRADCAST_EDIT_EXE,
                                    connect + tls + " --token " + kToken + " --hide short_block");
  EXPECT_EQ(e.status, 0) << e.output;
  EXPECT_NE(e.output.find("revision 1 applied"), std::string::npos) << e.output;

  // Simulated users, all connected, none failed.
  const fs::path report = dir / "load.json";
  test::CliResult l = test::run_cli(
      IRRADCAST_LOAD_EXE, connect + tls + " --users 4 --duration 2 --json " + report.string());
  EXPECT_EQ(l.status, 0) << l.output;
  if (fs::exists(report)) {
    std::ifstream f(report);
    const nlohmann::json rep = nlohmann::json::parse(f);
    EXPECT_EQ(rep["users"]["connected"], 4) << rep.dump();
    EXPECT_EQ(rep["users"]["failed"], 0) << rep.dump();
  }

  // Metrics over HTTPS.
  std::string error;
  const std::string scrape = https_get(metrics.port(), files.ca, error);
  EXPECT_EQ(scrape.rfind("HTTP/1.1 200", 0), 0u) << error << scrape.substr(0, 200);
  EXPECT_NE(scrape.find("irradcast_clients"), std::string::npos);

  // A client that does not trust the CA, or speaks plain TCP, is turned away with a clear error.
  test::CliResult bad =
      test::run_cli(IRRADCAST_EDIT_EXE, connect + " --tls --tls-ca " + files.other_ca +
                                            " --token " + kToken + " --hide short_block");
  EXPECT_EQ(bad.status, 1) << bad.output;
  EXPECT_NE(bad.output.find("certificate verify failed"), std::string::npos) << bad.output;
  test::CliResult plain = test::run_cli(
      IRRADCAST_EDIT_EXE, connect + " --timeout-ms 2000 --token " + kToken + " --hide short_block");
  EXPECT_NE(plain.status, 0) << plain.output;
  EXPECT_EQ(host.revision(), 1u);

  metrics.stop();
  server.stop();
  host.stop();

  // irradcast-server names a key file it cannot use.
  test::CliResult s = test::run_cli(
      std::string("timeout 30 ") + IRRADCAST_SERVER_EXE,
      "--port 0 --tls-cert " + files.cert + " --tls-key " + (dir / "missing.pem").string());
  EXPECT_EQ(s.status, 1) << s.output;
  EXPECT_NE(s.output.find("missing.pem"), std::string::npos) << s.output;
}

namespace {

// The serial number of the certificate the server on `port` presents (0 on failure).
long peer_serial(std::uint16_t port, const std::string& ca) {
  asio::io_context io;
  auto ctx = wire::make_client_tls(ca);
  asio::ssl::stream<asio::ip::tcp::socket> s(io, *ctx);
  std::error_code ec;
  s.lowest_layer().connect({asio::ip::make_address("127.0.0.1"), port}, ec);
  if (!ec) s.handshake(asio::ssl::stream_base::client, ec);
  if (ec) {
    ADD_FAILURE() << "TLS to port " << port << ": " << wire::describe_tls_error(ec);
    return 0;
  }
  X509* x = SSL_get_peer_certificate(s.native_handle());
  const long serial = x ? ASN1_INTEGER_get(X509_get_serialNumber(x)) : 0;
  X509_free(x);
  s.shutdown(ec);
  return serial;
}

void copy_over(const std::string& from, const std::string& to) {
  fs::copy_file(from, to, fs::copy_options::overwrite_existing);
}

}  // namespace

// Certificates run out: one that has expired, or is not valid yet, is refused at start with the
// date; SIGHUP (Server::reload_tls) gives new connections the new certificate while open ones
// keep theirs, and a bad file keeps the current certificate.
TEST(Tls, ExpiredCertificatesAreRefusedAndAReloadReachesNewConnectionsOnly) {
  Progress::set_enabled(false);
  const fs::path dir = fs::path(::testing::TempDir()) / "tls_reload";
  fs::remove_all(dir);
  for (const char* d : {"a", "b", "old", "young"}) fs::create_directories(dir / d);
  const wire::LoopbackTlsFiles a = wire::make_loopback_tls_files((dir / "a").string(), 2);
  const wire::LoopbackTlsFiles b = wire::make_loopback_tls_files((dir / "b").string(), 9);
  const wire::LoopbackTlsFiles old =
      wire::make_loopback_tls_files((dir / "old").string(), 3, -7200, -60);
  const wire::LoopbackTlsFiles young =
      wire::make_loopback_tls_files((dir / "young").string(), 4, 3600, 7200);
  EngineHost host(make_cornell_box(), "cornell", test::quick_host(1));
  auto options = [&](const wire::LoopbackTlsFiles& f) {
    ServerOptions o = test::loopback();
    o.tls_cert = f.cert;
    o.tls_key = f.key;
    return o;
  };
  try {
    Server s(host, options(old));
    ADD_FAILURE() << "an expired certificate was accepted";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("expired on"), std::string::npos) << e.what();
  }
  try {
    Server s(host, options(young));
    ADD_FAILURE() << "a certificate not valid yet was accepted";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("not valid before"), std::string::npos) << e.what();
  }

  const wire::LoopbackTlsFiles live{"", (dir / "cert.pem").string(), (dir / "key.pem").string(),
                                    ""};
  copy_over(a.cert, live.cert);
  copy_over(a.key, live.key);
  // (Each certificate is checked against its own CA: the two test CAs share a name.)
  Server server(host, options(live));
  server.start();
  EXPECT_EQ(peer_serial(server.port(), a.ca), 2);
  auto client_tls = wire::make_client_tls(a.ca);
  test::RawConnection open(server.port(), client_tls.get());
  ASSERT_TRUE(open.join("kept"));

  copy_over(b.cert, live.cert);
  copy_over(b.key, live.key);
  EXPECT_TRUE(server.reload_tls());
  EXPECT_EQ(peer_serial(server.port(), b.ca), 9);
  // The connection made before the reload goes on.
  wire::Envelope ping;
  ping.mutable_ping()->set_nonce(77);
  open.send(ping);
  bool pong = false;
  while (auto e = open.read(5000ms))
    if (e->has_pong()) {
      pong = e->pong().nonce() == 77;
      break;
    }
  EXPECT_TRUE(pong);

  std::ofstream(live.cert) << "not a certificate\n";
  EXPECT_FALSE(server.reload_tls());
  EXPECT_EQ(peer_serial(server.port(), b.ca), 9);
  server.stop();
}

// irradcast-server: SIGHUP reloads (a log line, the process goes on), and a certificate that
// expires within 14 days is a warning with its date at start.
TEST(Tls, SighupReloadsTheCertificateOfARunningServer) {
  const fs::path dir = fs::path(::testing::TempDir()) / "tls_sighup";
  fs::remove_all(dir);
  fs::create_directories(dir);
  const wire::LoopbackTlsFiles f = wire::make_loopback_tls_files(dir.string(), 5, -3600, 3 * 86400);
  test::Process server(test::command(IRRADCAST_SERVER_EXE,
                                     "--scene cornell --bind 127.0.0.1 --port 0 --threads 1 "
                                     "--texels-per-scene 32 --max-updates 1 --io-threads 1 "
                                     "--tls-cert " +
                                         f.cert + " --tls-key " + f.key),
                       dir / "server.log");
  ASSERT_TRUE(
      test::eventually([&] { return server.output().find("listening") != std::string::npos; }, 30s))
      << server.output();
  EXPECT_NE(server.output().find("expires in under 14 days"), std::string::npos) << server.output();
  server.signal(SIGHUP);
  EXPECT_TRUE(test::eventually([&] {
    return server.output().find("TLS: reloaded the certificate") != std::string::npos;
  })) << server.output();
  EXPECT_TRUE(server.running());
  server.signal(SIGINT);
  EXPECT_TRUE(server.wait_for(10s));
}

}  // namespace irradcast::test_tls_service
