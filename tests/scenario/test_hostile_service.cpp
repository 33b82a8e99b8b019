// The server against hostile clients and an operator's faults (issue 16): frames before Hello,
// silent connections, incomplete frames, bursts of edits, forged log lines, control tokens,
// sessions per address, clients that never read, running out of file descriptors, and TLS.
// Every test talks to a real server over loopback.
#include <gtest/gtest.h>

#include <asio.hpp>

#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <csignal>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <thread>

#include "cli.h"
#include "irradcast/common/builtin.h"
#include "irradcast/common/error.h"
#include "irradcast/common/log.h"
#include "irradcast/common/progress.h"
#include "irradcast/common/sanitizer.h"
#include "irradcast/common/scene_edit.h"
#include "irradcast/service/engine_host.h"
#include "irradcast/service/net_server.h"
#include "irradcast/wire/edit_message.h"
#include "irradcast/wire/frame.h"
#include "irradcast/wire/loopback_tls.h"
#include "irradcast/wire/transport.h"
#include "service_fixture.h"

namespace irradcast::test_hostile_service {

using asio::ip::tcp;
using namespace std::chrono_literals;
using Clock = std::chrono::steady_clock;

namespace {

const std::string kToken = "hostile-test-token-0123";

using test::quick_host;

ServerOptions loopback() {
  return test::loopback(30000ms);  // longer than any test: what closes a session is the feature
}

using Raw = test::RawConnection;

wire::Envelope hello(const std::string& name = "raw") {
  return test::hello_frame(name);
}

wire::Envelope edit_frame(const std::string& token, std::uint64_t request_id) {
  return test::nudge_edit_frame(token, request_id);
}

// Sessions closed for a reason; waits up to a second for it to reach `at_least` (the server
// counts a close just after the client sees it).
std::uint64_t closed(const Server& s, CloseReason r, std::uint64_t at_least = 1) {
  const auto deadline = Clock::now() + 1s;
  std::uint64_t n = 0;
  while ((n = s.stats().sessions_closed[static_cast<std::size_t>(r)]) < at_least &&
         Clock::now() < deadline)
    std::this_thread::sleep_for(10ms);
  return n;
}

}  // namespace

// Before Hello a frame may only be a few KiB: a 16 MiB announcement is refused at once instead of
// being buffered until the idle timeout.
TEST(HostileService, FramesBeforeHelloAreCapped) {
  EngineHost host(make_cornell_box(), "cornell", quick_host());
  Server server(host, loopback());
  server.start();
  Raw r(server.port());
  const std::uint32_t announced = (16u << 20) - 16;
  std::string header(4, '\0');
  for (int i = 0; i < 4; ++i) header[i] = static_cast<char>((announced >> (8 * i)) & 0xff);
  r.write(header + std::string(8192, 'x'));
  auto err = r.error_then_close(3000ms);
  ASSERT_TRUE(err.has_value()) << "no error within 3 s: the frame is being buffered";
  EXPECT_EQ(err->code(), wire::FRAME_TOO_LARGE);
  EXPECT_TRUE(r.eof);
  // After Hello the full cap applies: a client may send larger frames.
  Raw ok(server.port());
  ASSERT_TRUE(ok.join());
  wire::Envelope big;
  big.mutable_ping()->set_nonce(1);
  big.mutable_bye()->set_reason(std::string(20000, 'b'));  // the last oneof wins: a 20 KB Bye
  ok.send(big);
  EXPECT_FALSE(ok.error_then_close(3000ms).has_value());
  server.stop();
}

// A connection that sends nothing, or no Hello, is closed after the hello timeout.
TEST(HostileService, ConnectionsWithoutHelloAreClosed) {
  EngineHost host(make_cornell_box(), "cornell", quick_host());
  ServerOptions o = loopback();
  o.hello_timeout = 300ms;
  Server server(host, o);
  server.start();
  Raw silent(server.port());
  Raw partial(server.port());
  partial.write(std::string("\x10\x00\x00\x00", 4) + "abc");  // half a frame, then nothing
  for (Raw* r : {&silent, &partial}) {
    auto err = r->error_then_close(4000ms);
    EXPECT_TRUE(r->eof) << "still open after 4 s";
    ASSERT_TRUE(err.has_value());
    EXPECT_NE(err->message().find("no hello within 300 ms"), std::string::npos) << err->message();
  }
  EXPECT_EQ(closed(server, CloseReason::HelloTimeout, 2), 2u);
  // A client that says Hello in time is not affected.
  Raw ok(server.port());
  ASSERT_TRUE(ok.join());
  std::this_thread::sleep_for(600ms);
  wire::Envelope ping;
  ping.mutable_ping()->set_nonce(7);
  ok.send(ping);
  auto pong = ok.read();
  ASSERT_TRUE(pong && pong->has_pong());
  server.stop();
}

// Incomplete frames of all sessions together stay under max_partial_bytes (plus 64 KiB a
// session): the sessions that hold large incomplete frames past it are closed.
TEST(HostileService, IncompleteFramesAreBoundedTogether) {
  EngineHost host(make_cornell_box(), "cornell", quick_host());
  ServerOptions o = loopback();
  o.max_partial_bytes = 1u << 20;
  Server server(host, o);
  server.start();
  std::vector<std::unique_ptr<Raw>> clients;
  const std::uint32_t announced = 4u << 20;
  std::string header(4, '\0');
  for (int i = 0; i < 4; ++i) header[i] = static_cast<char>((announced >> (8 * i)) & 0xff);
  int refused = 0;
  for (int i = 0; i < 6; ++i) {
    clients.push_back(std::make_unique<Raw>(server.port()));
    ASSERT_TRUE(clients.back()->join());
    clients.back()->write(header + std::string(512u << 10, 'p'));
  }
  for (auto& c : clients) {
    auto e = c->read(1500ms);
    if (e && e->has_error()) {
      EXPECT_EQ(e->error().code(), wire::FRAME_TOO_LARGE);
      ++refused;
    }
  }
  EXPECT_GE(refused, 4) << "6 x 512 KiB held under a 1 MiB cap";
  EXPECT_LE(server.stats().partial_bytes, (1u << 20) + (512u << 10));
  server.stop();
  EXPECT_EQ(server.stats().partial_bytes, 0u);
}

// Another client's burst of edits (more than the 256 queued replies that drop a slow client)
// does not drop the viewers: the broadcasts wait in their own bounded queue, and the editor,
// whose acknowledgements pile up, is simply read more slowly.
TEST(HostileService, AnEditBurstDropsNobody) {
  EngineHost host(make_cornell_box(), "cornell", quick_host(0));
  ServerOptions o = loopback();
  o.control_token = kToken;
  Server server(host, o);
  server.start();
  host.start();
  std::vector<std::unique_ptr<Raw>> viewers;
  for (int i = 0; i < 3; ++i) {
    viewers.push_back(std::make_unique<Raw>(server.port()));
    ASSERT_TRUE(viewers.back()->join("viewer"));
  }
  Raw editor(server.port());
  ASSERT_TRUE(editor.join("editor"));
  const int kEdits = 400;
  std::string burst;
  for (int i = 1; i <= kEdits; ++i) burst += wire::encode_frame(edit_frame(kToken, i));
  std::thread writer([&] { editor.write(burst); });
  int acks = 0;
  while (acks < kEdits) {
    auto e = editor.read(10000ms);
    if (!e) break;
    ASSERT_FALSE(e->has_error()) << e->error().message();
    if (e->has_scene_edit() && !e->scene_edit().applied()) ++acks;
  }
  writer.join();
  EXPECT_EQ(acks, kEdits);
  // Every viewer reaches the last revision (a broadcast of it, possibly after a gap).
  for (auto& v : viewers) {
    std::uint64_t last = 0;
    const auto deadline = Clock::now() + 30s;
    while (last < kEdits && Clock::now() < deadline) {
      auto e = v->read(2000ms);
      if (!e) continue;
      ASSERT_FALSE(e->has_error()) << e->error().message();
      if (e->has_scene_edit()) last = std::max<std::uint64_t>(last, e->scene_edit().revision());
    }
    EXPECT_EQ(last, static_cast<std::uint64_t>(kEdits));
    EXPECT_FALSE(v->eof);
  }
  EXPECT_EQ(closed(server, CloseReason::SlowClient, 0), 0u);
  EXPECT_EQ(server.stats().clients, 4u);
  server.stop();
  host.stop();
}

// Text from a client cannot forge log lines, and one client cannot flood the log.
TEST(HostileService, ClientTextIsEscapedAndRateLimitedInTheLog) {
  EngineHost host(make_cornell_box(), "cornell", quick_host());
  ServerOptions o = loopback();
  Server server(host, o);
  server.start();
  log::set_level(log::Level::Info);
  testing::internal::CaptureStderr();
  {
    Raw r(server.port());
    ASSERT_TRUE(r.join("evil\n2026-01-01T00:00:00.000Z ERROR server FORGED-NAME"));
    wire::Envelope err =
        wire::make_error(wire::INTERNAL, "x\nFORGED-ERROR " + std::string(1 << 20, 'e'));
    for (int i = 0; i < 25; ++i) r.send(err);
    wire::Envelope ping;
    ping.mutable_ping()->set_nonce(1);
    r.send(ping);
    auto pong = r.read();
    ASSERT_TRUE(pong && pong->has_pong());
  }
  std::this_thread::sleep_for(100ms);
  server.stop();
  const std::string out = testing::internal::GetCapturedStderr();
  log::set_level(log::Level::Warn);
  EXPECT_LT(out.size(), 16000u) << "25 x 1 MiB of error text reached the log";
  std::istringstream lines(out);
  std::string line;
  int lines_from_session = 0;
  while (std::getline(lines, line)) {
    // A forged line would start with the forged text; escaped, it stays inside the real line.
    EXPECT_NE(line.rfind("FORGED", 0), 0u) << line;
    EXPECT_NE(line.rfind("2026-01-01T00:00:00.000Z", 0), 0u) << line;
    if (line.find("session ") != std::string::npos) ++lines_from_session;
  }
  EXPECT_NE(out.find("\\n2026-01-01T00:00:00.000Z ERROR server FORGED-NAME"), std::string::npos)
      << out;
  EXPECT_LE(lines_from_session, 24);
  EXPECT_GT(server.stats().log_lines_suppressed, 0u);
}

TEST(HostileService, ShortControlTokensAreRefused) {
  EngineHost host(make_cornell_box(), "cornell", quick_host());
  ServerOptions o = loopback();
  o.control_token = "x";
  EXPECT_THROW(Server(host, o), Error);
  o.control_token = std::string(kMinTokenLength - 1, 'y');
  EXPECT_THROW(Server(host, o), Error);
  o.control_token = std::string(kMinTokenLength, 'y');
  EXPECT_NO_THROW(Server(host, o));
  const test::CliResult r = test::run_cli(std::string("timeout 30 ") + IRRADCAST_SERVER_EXE,
                                          "--port 0 --control-token abc");
  EXPECT_EQ(r.status, 1) << r.output;
  EXPECT_NE(r.output.find("at least 16"), std::string::npos) << r.output;
}

// Wrong tokens: each answer comes later than the one before, and after max_token_failures the
// connection is closed and the address refused for the ban duration.
TEST(HostileService, WrongTokensAreDelayedThenTheAddressIsRefused) {
  EngineHost host(make_cornell_box(), "cornell", quick_host());
  ServerOptions o = loopback();
  o.control_token = kToken;
  o.token_failure_delay = 100ms;
  o.max_token_failures = 3;
  o.ban_duration = 1500ms;
  Server server(host, o);
  server.start();
  {
    Raw r(server.port());
    ASSERT_TRUE(r.join());
    const auto began = Clock::now();
    std::string guesses;
    for (int i = 0; i < 50; ++i)
      guesses += wire::encode_frame(edit_frame("guess-" + std::to_string(i), i));
    r.write(guesses);
    int denied = 0;
    std::optional<wire::Error> last;
    while (auto e = r.read(3000ms)) {
      if (e->has_error()) {
        ++denied;
        last = e->error();
      }
    }
    EXPECT_TRUE(r.eof);
    EXPECT_EQ(denied, 3) << "50 guesses in one write";
    ASSERT_TRUE(last.has_value());
    EXPECT_NE(last->message().find("refused for"), std::string::npos) << last->message();
    EXPECT_GE(Clock::now() - began, 100ms + 200ms + 400ms);  // the delays, doubling
  }
  EXPECT_EQ(server.stats().token_failures, 3u);
  EXPECT_EQ(closed(server, CloseReason::TokenFailures), 1u);
  {  // Refused while banned, even with the right token.
    Raw r(server.port());
    auto err = r.error_then_close(2000ms);
    ASSERT_TRUE(err.has_value());
    EXPECT_NE(err->message().find("refused"), std::string::npos) << err->message();
    EXPECT_EQ(server.stats().banned_refused, 1u);
  }
  std::this_thread::sleep_for(1600ms);
  {  // The ban ends; the right token works.
    Raw r(server.port());
    ASSERT_TRUE(r.join());
    r.send(edit_frame(kToken, 99));
    auto ack = r.read();
    ASSERT_TRUE(ack.has_value());
    EXPECT_TRUE(ack->has_scene_edit()) << ack->DebugString();
  }
  server.stop();
}

TEST(HostileService, SessionsPerAddressAreLimited) {
  EngineHost host(make_cornell_box(), "cornell", quick_host());
  ServerOptions o = loopback();
  o.max_clients_per_peer = 3;
  Server server(host, o);
  server.start();
  std::vector<std::unique_ptr<Raw>> ok;
  for (int i = 0; i < 3; ++i) {
    ok.push_back(std::make_unique<Raw>(server.port()));
    ASSERT_TRUE(ok.back()->join());
  }
  {
    Raw fourth(server.port());
    auto err = fourth.error_then_close(2000ms);
    ASSERT_TRUE(err.has_value());
    EXPECT_EQ(err->code(), wire::REFUSED) << err->message();
    EXPECT_NE(err->message().find("too many connections from this address (3; the server's "
                                  "--max-clients-per-peer)"),
              std::string::npos)
        << err->message();
    EXPECT_TRUE(fourth.eof);
  }
  EXPECT_EQ(server.stats().peer_refused, 1u);
  ok.pop_back();  // one leaves: another may come
  std::this_thread::sleep_for(200ms);
  Raw again(server.port());
  EXPECT_TRUE(again.join());
  server.stop();
}

// A client that subscribes and never reads is closed as slow once its writes make no progress
// for the stall timeout, long before the idle timeout.
TEST(HostileService, ClientsThatNeverReadAreClosed) {
  EngineHost host(make_cornell_box(), "cornell", quick_host(0));
  ServerOptions o = loopback();
  o.write_stall_timeout = 800ms;
  o.socket_send_buffer = 16384;
  o.scene_chunk_bytes = 4096;
  Server server(host, o);
  server.start();
  host.start();
  asio::io_context io;
  tcp::socket s(io);
  s.open(tcp::v4());
  s.set_option(asio::socket_base::receive_buffer_size(4096));
  s.connect(tcp::endpoint(asio::ip::make_address("127.0.0.1"), server.port()));
  wire::Envelope sub;
  sub.mutable_subscribe()->set_all(true);
  wire::Envelope req;
  req.mutable_scene_request()->set_offset(0);
  asio::write(s, asio::buffer(wire::encode_frame(hello("sleeper")) + wire::encode_frame(req) +
                              wire::encode_frame(sub)));
  const auto deadline = Clock::now() + 8s;
  while (closed(server, CloseReason::SlowClient, 0) == 0 && Clock::now() < deadline)
    std::this_thread::sleep_for(50ms);
  EXPECT_EQ(closed(server, CloseReason::SlowClient), 1u) << "not closed within 8 s";
  for (int i = 0; i < 100 && server.stats().clients > 0; ++i) std::this_thread::sleep_for(10ms);
  EXPECT_EQ(server.stats().clients, 0u);
  server.stop();
  host.stop();
}

// Out of file descriptors the accept loop pauses (one warning, not a spin), and accepts again
// once descriptors are free. The server runs as its own process with a limit of 64 files.
TEST(HostileService, AcceptPausesWhenOutOfDescriptors) {
#if IRRADCAST_ASAN
  // UBSan's vptr check needs a pipe to test memory: in a process out of descriptors it reports
  // every virtual call. The normal build runs this test.
  GTEST_SKIP() << "a sanitized server cannot run out of file descriptors";
#endif
  const std::string dir = testing::TempDir() + "/hostile_fd";
  std::filesystem::create_directories(dir);
  const std::string log = dir + "/server.log";
  const pid_t pid = fork();
  ASSERT_GE(pid, 0);
  if (pid == 0) {
    rlimit r{64, 64};
    setrlimit(RLIMIT_NOFILE, &r);
    const int fd = ::open(log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    dup2(fd, 1);
    dup2(fd, 2);
    execl(IRRADCAST_SERVER_EXE, IRRADCAST_SERVER_EXE, "--bind", "127.0.0.1", "--port", "0",
          "--max-updates", "1", "--status-every", "1", "--threads", "1", "--max-clients-per-peer",
          "0", static_cast<char*>(nullptr));
    _exit(127);
  }
  auto read_log = [&] {
    std::ifstream f(log);
    return std::string(std::istreambuf_iterator<char>(f), {});
  };
  std::uint16_t port = 0;
  for (int i = 0; i < 300 && port == 0; ++i) {
    std::this_thread::sleep_for(100ms);
    const std::string text = read_log();
    const std::size_t at = text.find("listening on 127.0.0.1:");
    if (at != std::string::npos) port = static_cast<std::uint16_t>(std::stoi(text.substr(at + 23)));
  }
  ASSERT_NE(port, 0) << read_log();
  // The engine's one update done first: out of descriptors, a sanitizer runtime cannot check
  // memory (it needs a pipe) and reports the engine's virtual calls falsely.
  for (int i = 0; i < 600 && read_log().find("(final)") == std::string::npos; ++i)
    std::this_thread::sleep_for(100ms);
  {
    std::vector<std::unique_ptr<Raw>> flood;
    for (int i = 0; i < 100; ++i) flood.push_back(std::make_unique<Raw>(port));
    std::this_thread::sleep_for(1500ms);
    const std::string text = read_log();
    std::size_t warnings = 0;
    for (std::size_t at = text.find("accept:"); at != std::string::npos;
         at = text.find("accept:", at + 1))
      ++warnings;
    EXPECT_GE(warnings, 1u) << "the server never ran out of descriptors: the test is void";
    EXPECT_LE(warnings, 2u) << text.substr(0, 2000);
  }
  // The flood is gone: a new client is served.
  std::this_thread::sleep_for(1500ms);
  Raw late(port);
  EXPECT_TRUE(late.join()) << read_log().substr(0, 4000);
  kill(pid, SIGTERM);
  int status = 0;
  waitpid(pid, &status, 0);
  EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << read_log().substr(0, 4000);
}

// The protocol over TLS: a client that trusts the CA gets its Welcome; one that trusts another
// CA, or speaks plain TCP, gets nowhere.
TEST(HostileService, TlsOnTheProtocolPort) {
  const std::string dir = testing::TempDir() + "/hostile_tls";
  std::filesystem::create_directories(dir);
  const wire::LoopbackTlsFiles files = wire::make_loopback_tls_files(dir);
  EngineHost host(make_cornell_box(), "cornell", quick_host());
  ServerOptions o = loopback();
  o.tls_cert = files.cert;
  o.tls_key = files.key;
  o.hello_timeout = 1000ms;
  Server server(host, o);
  server.start();
  {
    auto ctx = wire::make_client_tls(files.ca);
    Raw r(server.port(), ctx.get());
    ASSERT_FALSE(r.connect_error) << wire::describe_tls_error(r.connect_error);
    EXPECT_TRUE(r.join());
  }
  {
    auto ctx = wire::make_client_tls(files.other_ca);
    Raw r(server.port(), ctx.get());
    ASSERT_TRUE(r.connect_error);
    EXPECT_NE(wire::describe_tls_error(r.connect_error).find("certificate verify failed"),
              std::string::npos)
        << wire::describe_tls_error(r.connect_error);
  }
  {
    Raw plain(server.port());
    plain.send(hello());
    EXPECT_FALSE(plain.read(2000ms).has_value());
  }
  // Bad files are refused with the file named.
  o.tls_key = dir + "/no_such_key.pem";
  try {
    Server bad(host, o);
    ADD_FAILURE() << "a missing key was accepted";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("no_such_key.pem"), std::string::npos) << e.what();
  }
  o.tls_key = files.ca;  // not a key
  EXPECT_THROW(Server(host, o), Error);
  server.stop();
  EXPECT_GE(closed(server, CloseReason::Tls), 1u);
}

}  // namespace irradcast::test_hostile_service
