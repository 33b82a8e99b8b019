// The whole service over TLS with a certificate made at test time: the server's protocol port
// and metrics endpoint, irradcast-view, irradcast-load and irradcast-edit as a user runs them.
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

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
#include "irradcast/wire/transport.h"
#include "service_fixture.h"
#include "tls_cert.h"

using namespace irradcast;
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
  const test::TlsFiles files = test::make_tls_files(dir.string());

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
