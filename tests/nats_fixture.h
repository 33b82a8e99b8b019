// What the NATS tests share: a nats-server with JetStream started on a random loopback port with
// its storage in a temporary folder (stopped, and restarted on the same port and storage, by the
// test), an in-process origin (EngineHost + NatsOrigin + Server) and gateways (NatsGateway +
// Server). Without nats-server the tests skip, or fail under IRRADCAST_TESTDATA_REQUIRED=1.
#pragma once

#include <arpa/inet.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <signal.h>
#include <sys/socket.h>
#include <sys/time.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <memory>
#include <sstream>
#include <string>

#include "irradcast/client/view_client.h"
#include "irradcast/common/builtin.h"
#include "irradcast/common/camera.h"
#include "irradcast/service/engine_host.h"
#include "irradcast/service/nats_gateway.h"
#include "irradcast/service/nats_origin.h"
#include "irradcast/service/net_server.h"
#include "process.h"
#include "service_fixture.h"
#include "testdata.h"

namespace irradcast::test {

inline std::string nats_server_exe() {
  for (const char* p :
       {"/usr/sbin/nats-server", "/usr/bin/nats-server", "/usr/local/bin/nats-server"})
    if (::access(p, X_OK) == 0) return p;
  return "";
}

#define IRRADCAST_NEED_NATS()                                                                    \
  do {                                                                                           \
    if (::irradcast::test::nats_server_exe().empty()) {                                          \
      if (::irradcast::test::testdata_required())                                                \
        FAIL() << "no nats-server (apt-get install nats-server; IRRADCAST_TESTDATA_REQUIRED=1)"; \
      GTEST_SKIP() << "no nats-server (apt-get install nats-server)";                            \
    }                                                                                            \
  } while (0)

inline std::uint16_t free_loopback_port() {
  asio::io_context io;
  asio::ip::tcp::acceptor a(io, asio::ip::tcp::endpoint(asio::ip::make_address("127.0.0.1"), 0));
  return a.local_endpoint().port();
}

// nats-server -js on 127.0.0.1, storage in its own temporary folder.
class NatsProcess {
 public:
  // With `config`: nats-server -c config, its port, storage and monitoring port replaced by
  // the test's (the config's users and permissions kept).
  explicit NatsProcess(std::string config = "")
      : config_(std::move(config)), dir_(std::filesystem::temp_directory_path() / unique_name()) {
    std::filesystem::create_directories(dir_ / "ports");
    // nats-server binds ports it picks itself and names them in its ports file: a port picked
    // here and released could be taken by another test's server under ctest -j before ours
    // bound it (our clients would then talk to that server).
    EXPECT_TRUE(launch()) << output();
  }
  ~NatsProcess() {
    process_.reset();
    std::error_code ec;
    std::filesystem::remove_all(dir_, ec);
    std::filesystem::remove(dir_.string() + ".conf", ec);
    std::filesystem::remove(dir_.string() + ".log", ec);
  }
  std::string url() const { return "nats://127.0.0.1:" + std::to_string(port_); }
  std::uint16_t port() const { return port_; }
  std::string output() const { return process_ ? process_->output() : ""; }
  // Starts it again on the same port and storage (after stop()).
  void start() { EXPECT_TRUE(launch()) << output(); }
  // Starts it (on ports of its choosing the first time, on the same client port after stop());
  // true once its port answers with a NATS INFO line.
  bool launch() {
    const std::filesystem::path ports = dir_ / "ports";
    for (const auto& e : std::filesystem::directory_iterator(ports))
      std::filesystem::remove(e.path());
    const std::string port = port_ ? std::to_string(port_) : "-1";
    std::vector<std::string> args{nats_server_exe(), "-a", "127.0.0.1", "-p", port};
    for (const std::string& a : {std::string("--ports_file_dir"), ports.string()})
      args.push_back(a);
    if (config_.empty()) {
      for (const char* a : {"-js", "-sd"}) args.push_back(a);
      args.push_back(dir_.string());
    } else {
      // The configuration with its JetStream store in the test's folder (nats-server refuses
      // -sd beside a store_dir of the file).
      std::ifstream in(config_);
      std::stringstream text;
      text << in.rdbuf();
      std::string conf = text.str();
      const std::string from = "store_dir: \"/data\"";
      const std::size_t at = conf.find(from);
      EXPECT_NE(at, std::string::npos) << config_ << " has no " << from;
      if (at != std::string::npos)
        conf.replace(at, from.size(), "store_dir: \"" + dir_.string() + "\"");
      const std::string copy = dir_.string() + ".conf";
      std::ofstream(copy) << conf;
      for (const char* a : {"-c", copy.c_str(), "-m", "-1"}) args.push_back(a);
    }
    process_ = std::make_unique<Process>(args, dir_.string() + ".log");
    if (!eventually([&] { return read_ports_file(); }, std::chrono::seconds(10))) return false;
    return eventually([&] { return speaks_nats(); }, std::chrono::seconds(10));
  }
  void stop() {
    process_->signal(SIGTERM);
    EXPECT_TRUE(process_->wait_for(std::chrono::seconds(10)));
    process_.reset();
  }

 private:
  static std::string unique_name() {
    static std::atomic<int> count{0};
    return "irradcast_nats_" + std::to_string(::getpid()) + "_" + std::to_string(++count);
  }
  // The client port from the ports file nats-server writes once it listens
  // ({"nats":["nats://127.0.0.1:PORT"],...}).
  bool read_ports_file() {
    for (const auto& e : std::filesystem::directory_iterator(dir_ / "ports")) {
      std::ifstream in(e.path());
      std::stringstream text;
      text << in.rdbuf();
      const std::string key = "nats://127.0.0.1:";
      const std::size_t at = text.str().find(key);
      if (at == std::string::npos) continue;  // written, not yet whole
      const int port = std::atoi(text.str().c_str() + at + key.size());
      if (port <= 0 || port > 65535) continue;
      port_ = static_cast<std::uint16_t>(port);
      return true;
    }
    return false;
  }
  // Our port accepts and greets with "INFO " (a NATS server's first line), within a second.
  bool speaks_nats() const {
    const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
    if (fd < 0) return false;
    timeval tv{1, 0};
    ::setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof tv);
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_port = htons(port_);
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    char head[5] = {};
    std::size_t got = 0;
    if (::connect(fd, reinterpret_cast<const sockaddr*>(&a), sizeof a) == 0)
      while (got < sizeof head) {
        const ssize_t n = ::recv(fd, head + got, sizeof head - got, 0);
        if (n <= 0) break;
        got += static_cast<std::size_t>(n);
      }
    ::close(fd);
    return got == sizeof head && std::string(head, sizeof head) == "INFO ";
  }
  std::string config_;
  std::uint16_t port_ = 0;
  std::filesystem::path dir_;
  std::unique_ptr<Process> process_;
};

// irradcast-server --nats in the process: cornell, small, final after `updates` updates.
struct NatsOriginNode {
  // presence: --presence, avatar sets every 50 ms; a gateway's avatars (and cameras) are kept a
  // minute after its last request (they go sooner only when it says goodbye).
  NatsOriginNode(const std::string& url, std::uint32_t updates, const std::string& token = "",
                 const NatsCredentials& credentials = {}, Scene scene = make_cornell_box(),
                 bool presence = false)
      : host(std::move(scene), "cornell", small_host(updates)),
        origin(host,
               [&] {
                 NatsOriginOptions o;
                 o.url = url;
                 o.credentials = credentials;
                 o.accept_edits = !token.empty();
                 o.presence = presence;
                 o.presence_every = std::chrono::milliseconds(50);
                 o.presence_expiry = std::chrono::minutes(1);
                 if (presence) o.camera_expiry = std::chrono::minutes(1);
                 return o;
               }()),
        server(origin, [&] {
          ServerOptions o = loopback();
          o.control_token = token;
          o.io_threads = 1;
          o.presence = presence;
          o.presence_hz = 20.0;
          o.presence_height = 0.14f;
          return o;
        }()) {
    server.start();
    host.start();
  }
  ~NatsOriginNode() {
    server.stop();
    host.stop();
  }
  // The engine is final and everything it made is in JetStream.
  bool settle() {
    host.wait_for_updates(~std::uint64_t{0});
    return origin.flush(std::chrono::seconds(10));
  }
  EngineHost host;
  NatsOrigin origin;
  Server server;
};

// irradcast-gateway in the process.
struct NatsGatewayNode {
  // presence: --presence, its avatars sent at most every 50 ms.
  explicit NatsGatewayNode(const std::string& url, const std::string& token = "",
                           const NatsCredentials& credentials = {}, bool presence = false)
      : gateway([&] {
          NatsGatewayOptions o{url, "cornell", credentials};
          o.presence = presence;
          o.presence_every = std::chrono::milliseconds(50);
          return o;
        }()) {
    EXPECT_TRUE(gateway.wait_ready(std::chrono::seconds(10))) << "no scene from NATS";
    ServerOptions o = loopback();
    o.control_token = token;
    o.io_threads = 1;
    o.presence = presence;
    o.presence_hz = 20.0;
    o.presence_height = 1.7f;  // the origin's (0.14) replaces it
    server = std::make_unique<Server>(gateway, o);
    server->start();
  }
  ~NatsGatewayNode() { server->stop(); }
  NatsGateway gateway;
  std::unique_ptr<Server> server;
};

// Polls viewer `v` until it holds every tile at the versions `want` has (the tile store it must
// match); false after the limit.
inline bool converge(ViewClient& v, const TileStore& want,
                     std::chrono::milliseconds limit = std::chrono::milliseconds(15000)) {
  auto matches = [&] {
    for (std::uint32_t i = 0; i < want.tile_count(); ++i) {
      const TileStore::Tile& t = want.tile(i);
      if (v.tile_version(t.lightmap, t.tx, t.ty) != want.version(i)) return false;
    }
    return true;
  };
  const auto deadline = std::chrono::steady_clock::now() + limit;
  while (!matches() && std::chrono::steady_clock::now() < deadline)
    v.poll(std::chrono::milliseconds(20));
  return matches();
}

// Two tile stores hold the same versions of every tile.
inline bool same_versions(const TileStore& a, const TileStore& b) {
  if (a.tile_count() != b.tile_count()) return false;
  for (std::uint32_t i = 0; i < a.tile_count(); ++i)
    if (a.version(i) != b.version(i)) return false;
  return true;
}

// A small view of what viewer `v` holds, from the scene's default camera.
inline ImageRGB view_of(const ViewClient& v) {
  return v.compose(default_camera(v.scene(), v.world()), 48, 36);
}

inline void expect_same_image(const ImageRGB& a, const ImageRGB& b, const char* what) {
  ASSERT_EQ(a.width, b.width);
  ASSERT_EQ(a.height, b.height);
  std::size_t differ = 0;
  for (std::size_t i = 0; i < a.pixels.size(); ++i) differ += a.pixels[i] != b.pixels[i];
  EXPECT_EQ(differ, 0u) << what << ": pixels differ from the origin viewer's";
}

}  // namespace irradcast::test
