#include "irradcast/wire/blocking_channel.h"

namespace irradcast::wire {

void connect_stream(asio::io_context& io, Stream& stream, const std::string& host,
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
    what = stage == std::string("connect") ? "connect: " + ec.message() : describe_tls_error(ec);
    return;
  }
  std::error_code ignored;
  stream.socket().set_option(tcp::no_delay(true), ignored);
}

BlockingChannel::BlockingChannel(const std::string& host, std::uint16_t port,
                                 std::shared_ptr<asio::ssl::context> tls,
                                 std::chrono::milliseconds timeout)
    : tls_(std::move(tls)), stream_(io_.get_executor(), tls_.get()) {
  std::error_code ec;
  std::string what;
  connect_stream(io_, stream_, host, port, timeout, ec, what);
  if (ec && ec.category() == asio::error::get_ssl_category())
    throw irradcast::Error("cannot connect to " + host + ":" + std::to_string(port) + ": " + what);
  if (ec) throw ChannelLost(what);
}

BlockingChannel::~BlockingChannel() {
  close();
}

void BlockingChannel::send(const Envelope& e) {
  const std::string frame = encode_frame(e);
  std::error_code ec;
  asio::write(stream_, asio::buffer(frame), ec);
  if (ec) throw ChannelLost("write: " + describe_tls_error(ec));
  last_send_ = Clock::now();
}

bool BlockingChannel::read(Envelope& out, Clock::time_point deadline) {
  for (;;) {
    switch (decoder_.next(out)) {
      case DecodeStatus::Frame:
        return true;
      case DecodeStatus::TooLarge:
      case DecodeStatus::Malformed:
        throw irradcast::Error("the server sent a bad frame: " + decoder_.error());
      case DecodeStatus::NeedMore:
        break;
    }
    const auto now = Clock::now();
    if (now >= deadline) return false;
    std::error_code result = asio::error::would_block;
    std::size_t got = 0;
    stream_.async_read_some(asio::buffer(buffer_), [&](std::error_code ec, std::size_t n) {
      result = ec;
      got = n;
    });
    io_.restart();
    io_.run_for(deadline - now);
    bool timed_out = false;
    if (result == asio::error::would_block) {
      // Timed out: cancel the read and let its handler run before the buffer goes out of use
      // (it may still have read some bytes: they are kept).
      std::error_code ignored;
      stream_.socket().cancel(ignored);
      io_.restart();
      io_.run();
      timed_out = result == asio::error::would_block || result == asio::error::operation_aborted;
    }
    if (!timed_out && result)
      throw ChannelLost(result == asio::error::eof ? "the server closed the connection"
                                                   : "read: " + describe_tls_error(result));
    bytes_received_ += got;
    decoder_.feed(buffer_.data(), got);  // past the deadline: a frame now whole, or false
  }
}

void BlockingChannel::close() {
  stream_.close();
}

}  // namespace irradcast::wire
