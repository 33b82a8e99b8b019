#include "irradcast/client/client_tls.h"

namespace irradcast {

std::shared_ptr<asio::ssl::context> make_tls_context(const ClientTls& tls) {
  if (!tls.enabled) {
    return nullptr;
  }
  return wire::make_client_tls(tls.ca_file);
}

void connect_stream(asio::io_context& io, wire::Stream& stream, const std::string& host,
                    std::uint16_t port, std::chrono::milliseconds timeout, std::error_code& ec,
                    std::string& what) {
  using asio::ip::tcp;
  ec.clear();
  what.clear();
  tcp::resolver resolver(io);
  const auto endpoints = resolver.resolve(host, std::to_string(port), ec);
  if (ec) {
    what = "resolve: " + ec.message();
    return;
  }
  stream.expect_server_name(host);
  bool done = false;
  const char* stage = "connect";
  asio::async_connect(stream.socket(), endpoints, [&](std::error_code cec, const tcp::endpoint&) {
    if (cec || !stream.tls()) {
      ec = cec;
      done = true;
      return;
    }
    stage = "TLS handshake";
    stream.async_handshake(asio::ssl::stream_base::client, [&](std::error_code hec) {
      ec = hec;
      done = true;
    });
  });
  io.restart();
  io.run_for(timeout);
  if (!done) {
    // Timed out: cancel, and let the handlers run before the locals they use go away.
    std::error_code ignored;
    stream.socket().cancel(ignored);
    stream.socket().close(ignored);
    io.restart();
    io.run();
    ec = asio::error::timed_out;
    what = std::string(stage) + ": no answer within " + std::to_string(timeout.count()) + " ms";
    return;
  }
  io.restart();
  if (ec) {
    what =
        stage == std::string("connect") ? "connect: " + ec.message() : wire::describe_tls_error(ec);
    return;
  }
  std::error_code ignored;
  stream.socket().set_option(tcp::no_delay(true), ignored);
}

}  // namespace irradcast
