// The accept loop of every port (listener.h).
#include "listener.h"

#include <algorithm>

#include "irradcast/common/error.h"
#include "irradcast/common/log.h"

namespace irradcast {

using asio::ip::tcp;
using Clock = std::chrono::steady_clock;

namespace {

constexpr std::chrono::milliseconds kFirstPause{10}, kLongestPause{1000};
constexpr std::chrono::seconds kWarnEvery{10};

bool out_of_descriptors(const std::error_code& ec) {
  return ec == asio::error::no_descriptors || ec == std::errc::too_many_files_open_in_system ||
         ec == asio::error::no_buffer_space || ec == asio::error::no_memory;
}

}  // namespace

Listener::Listener(asio::io_context& io, Options options)
    : io_(io),
      options_(std::move(options)),
      strand_(asio::make_strand(io)),
      acceptor_(strand_),
      pause_(strand_) {}

void Listener::listen(const std::string& bind, std::uint16_t port) {
  std::error_code ec;
  const asio::ip::address address = asio::ip::make_address(bind, ec);
  if (ec) throw Error(options_.bind_flag + ": '" + bind + "' is not an IP address");
  const tcp::endpoint endpoint(address, port);
  acceptor_.open(endpoint.protocol(), ec);
  if (!ec) acceptor_.set_option(tcp::acceptor::reuse_address(true), ec);
  if (!ec) acceptor_.bind(endpoint, ec);
  if (!ec) acceptor_.listen(options_.backlog, ec);
  if (ec)
    throw Error(options_.component + ": cannot listen on " + bind + ":" + std::to_string(port) +
                ": " + ec.message());
  bound_port_ = acceptor_.local_endpoint(ec).port();
}

void Listener::start(OnSocket on_socket, std::function<void()> on_error) {
  on_socket_ = std::move(on_socket);
  on_error_ = std::move(on_error);
  accept();
}

void Listener::close() {
  if (closed_.exchange(true)) return;
  asio::dispatch(strand_, [this] {
    std::error_code ignored;
    acceptor_.close(ignored);
    pause_.cancel();
  });
}

void Listener::accept() {
  auto handler = [this](std::error_code ec, tcp::socket socket) {
    on_accept(ec, std::move(socket));
  };
  if (options_.strand_per_socket)
    acceptor_.async_accept(asio::make_strand(io_), std::move(handler));
  else
    acceptor_.async_accept(io_, std::move(handler));
}

void Listener::on_accept(std::error_code ec, tcp::socket socket) {
  if (closed_ || ec == asio::error::operation_aborted) return;
  if (ec) {
    on_error(ec);
    return;
  }
  if (backoff_.count() > 0) {
    warn("accepting connections again");
    backoff_ = std::chrono::milliseconds(0);
  }
  on_socket_(std::move(socket));
  accept();
}

void Listener::on_error(const std::error_code& ec) {
  if (on_error_) on_error_();
  if (!out_of_descriptors(ec)) {
    warn("accept: " + ec.message());
    accept();
    return;
  }
  if (backoff_.count() == 0)
    warn("accept: " + ec.message() +
         (options_.describe ? " (" + options_.describe() + ")" : std::string()) +
         "; pausing accepts until descriptors are free");
  backoff_ = std::clamp(backoff_ * 2, kFirstPause, kLongestPause);
  pause_.expires_after(backoff_);
  pause_.async_wait([this](std::error_code tec) {
    if (!tec && !closed_) accept();
  });
}

void Listener::warn(const std::string& line) {
  const auto now = Clock::now();
  if (now - last_warning_ < kWarnEvery) {
    ++unlogged_;
    return;
  }
  log::warn(options_.component, unlogged_ > 0 ? line + " (" + std::to_string(unlogged_) +
                                                    " more such lines left out since the last)"
                                              : line);
  last_warning_ = now;
  unlogged_ = 0;
}

}  // namespace irradcast
