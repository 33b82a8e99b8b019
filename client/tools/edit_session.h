// irradcast-edit's session with the server (edit_main.cpp, edit_stream.cpp): its options, one
// connection to a server of --connect (pings answered, Error frames thrown), and the session that
// moves to the next server of the list when a connection is lost.
#pragma once

#include <algorithm>
#include <chrono>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "irradcast/client/backoff.h"
#include "irradcast/client/client_tls.h"
#include "irradcast/client/host_port.h"
#include "irradcast/common/error.h"
#include "irradcast/common/log.h"
#include "irradcast/wire/blocking_channel.h"
#include "irradcast/wire/frame.h"
#include "tool_main.h"

namespace irradcast::edit_tool {

using Clock = std::chrono::steady_clock;

struct Options {
  std::string connect;
  irradcast::ClientTls tls;
  std::string token;
  std::string token_file;
  std::string json;
  std::string script;
  std::vector<std::string> move, rotate, scale, show, hide, light_color, light_intensity, albedo,
      emission;
  std::string export_path;  // --export FILE.glb|.gltf
  bool stream = false;      // --stream [FILE]: one edit per line, sent as streamed poses
  std::string stream_path;  // empty: stdin
  bool no_wait = false;
  int timeout_ms = 10000;
  std::string name = "irradcast-edit";
  std::string log_level = "warn";
};

// The connection is gone (refused, reset, closed): another server of the list may do.
using Lost = irradcast::wire::ChannelLost;

// The server answered with an Error frame.
struct Refused : irradcast::Error {
  Refused(irradcast::wire::ErrorCode c, const std::string& message, std::uint64_t request = 0)
      : irradcast::Error(message), code(c), request_id(request) {}
  irradcast::wire::ErrorCode code;
  std::uint64_t request_id;  // the request it answers (0: none)
};

// The server's connection (wire::BlockingChannel) as irradcast-edit reads it: pings answered,
// Error frames thrown.
class Connection {
 public:
  Connection(const irradcast::HostPort& hp, std::chrono::milliseconds timeout,
             const irradcast::ClientTls& tls)
      : channel_(hp.host, hp.port, irradcast::make_tls_context(tls), timeout), timeout_(timeout) {}

  void send(const irradcast::wire::Envelope& e) { channel_.send(e); }

  // The next frame before `deadline` (nullopt on timeout). An Error frame throws Refused, or Lost
  // for one after which the server closes (shutting down, full, idle): another server may do.
  std::optional<irradcast::wire::Envelope> read(Clock::time_point deadline) {
    irradcast::wire::Envelope e;
    while (channel_.read(e, deadline)) {
      if (e.has_error() && irradcast::server_error_is_transient(e.error().code()))
        throw Lost("the server says: " + e.error().message());
      if (e.has_error())
        throw Refused(e.error().code(), e.error().message(), e.error().request_id());
      if (!e.has_ping()) return e;
      irradcast::wire::Envelope pong;
      pong.mutable_pong()->set_nonce(e.ping().nonce());
      pong.mutable_pong()->set_time_us(e.ping().time_us());
      send(pong);
    }
    return std::nullopt;
  }

  // The next frame within the timeout; throws when none comes.
  irradcast::wire::Envelope expect(const std::string& what) {
    auto e = read(Clock::now() + timeout_);
    if (!e)
      throw irradcast::Error("no " + what + " from the server within " +
                             std::to_string(timeout_.count()) + " ms");
    return *e;
  }

  // Waits `ms`, reading (and dropping) frames and pinging so the server's idle timer is happy.
  void wait(double ms, std::chrono::milliseconds ping_every) {
    const auto until =
        Clock::now() + std::chrono::microseconds(static_cast<std::int64_t>(ms * 1e3));
    while (Clock::now() < until) {
      if (Clock::now() - last_send() >= ping_every) {
        irradcast::wire::Envelope p;
        p.mutable_ping()->set_nonce(1);
        send(p);
      }
      read(std::min(until, last_send() + ping_every));
    }
  }

  void close() {
    try {
      send(irradcast::wire::make_bye("edits sent"));
    } catch (const irradcast::Error&) {
    }
    channel_.close();
  }

  std::chrono::milliseconds ping_every{10000};  // a third of the server's idle timeout
  Clock::time_point last_send() const { return channel_.last_send(); }

 private:
  irradcast::wire::BlockingChannel channel_;
  std::chrono::milliseconds timeout_{10000};
};

// A session on one server of the --connect list: Hello, Welcome, and on a lost connection the
// next server.
class Session {
 public:
  Session(const Options& o, std::vector<irradcast::HostPort> servers)
      : o_(o), servers_(std::move(servers)) {
    connect();
  }
  Connection& connection() { return *c_; }
  const irradcast::HostPort& server() const { return servers_[current_]; }

  // The first server that answers, trying each once from the one after the current (the
  // first: from the start of the list). An Error frame that ends the session (server full,
  // shutting down) counts as no answer; every failure is in the error.
  void connect() {
    using namespace irradcast;
    std::string failures;
    for (std::size_t i = 0; i < servers_.size(); ++i) {
      if (c_ || i > 0) current_ = (current_ + 1) % servers_.size();
      c_.reset();
      try {
        c_ = std::make_unique<Connection>(server(), std::chrono::milliseconds(o_.timeout_ms),
                                          tools::tls_of(o_.tls));
        hello();
        return;
      } catch (const Lost& e) {
        failures += "; " + server().text() + ": " + e.what();
      }
    }
    c_.reset();
    throw Error("no server of --connect answered" + failures);
  }

 private:
  void hello() {
    using namespace irradcast;
    wire::Envelope hello;
    hello.mutable_hello()->set_protocol_version(wire::kProtocolVersion);
    hello.mutable_hello()->set_client_name(o_.name);
    c_->send(hello);
    wire::Envelope w = c_->expect("welcome");
    if (!w.has_welcome())
      throw Error(std::string("expected welcome, got ") + wire::message_name(w));
    if (w.welcome().idle_timeout_ms() > 0)
      c_->ping_every =
          std::min(c_->ping_every, std::chrono::milliseconds(w.welcome().idle_timeout_ms() / 3));
    if (servers_.size() > 1) log::info("edit", "connected to " + server().text());
  }

  const Options& o_;
  std::vector<irradcast::HostPort> servers_;
  std::size_t current_ = 0;
  std::unique_ptr<Connection> c_;
};

// --stream [FILE]: sends the lines of FILE (stdin when empty) as streamed poses (edit_stream.cpp).
int run_stream(const Options& o, const std::string& token);

}  // namespace irradcast::edit_tool
