#include "irradcast/metrics_endpoint.h"

#include <asio.hpp>

#include <algorithm>
#include <array>
#include <atomic>
#include <cstring>
#include <optional>
#include <set>
#include <string_view>
#include <thread>

#include "irradcast/error.h"
#include "irradcast/log.h"

namespace irradcast {

using asio::ip::tcp;

namespace {

// How long a connection may stay open after its response, for the client to close first (so that
// closing with unread request bytes does not reset the connection before the client read the
// response).
constexpr std::chrono::milliseconds kLinger{1000};

class Connection;

bool is_tchar(unsigned char c) {
  return (c >= '0' && c <= '9') || (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') ||
         (c != 0 && std::strchr("!#$%&'*+-.^_`|~", c) != nullptr);
}
bool is_ctl(unsigned char c) {
  return (c < 0x20 && c != '\t') || c == 0x7f;
}

enum class Parse { NeedMore, Bad, Done };

struct Request {
  std::string method;
  std::string target;
};

// The request line: METHOD SP target SP HTTP/1.x, target in origin form.
bool parse_request_line(std::string_view line, Request& req) {
  const std::size_t a = line.find(' ');
  if (a == std::string_view::npos || a == 0) return false;
  const std::size_t b = line.find(' ', a + 1);
  if (b == std::string_view::npos || b == a + 1) return false;
  const std::string_view method = line.substr(0, a), target = line.substr(a + 1, b - a - 1),
                         version = line.substr(b + 1);
  for (unsigned char c : method)
    if (!is_tchar(c)) return false;
  if (target.front() != '/') return false;
  for (unsigned char c : target)
    if (c <= 0x20 || c >= 0x7f) return false;
  if (version.size() != 8 || version.substr(0, 7) != "HTTP/1." || version[7] < '0' ||
      version[7] > '9')
    return false;
  req.method = method;
  req.target = target;
  return true;
}

// Parses the head (request line and headers, lines ending in CRLF or LF) from the bytes received
// so far. Bad as soon as the bytes cannot be the start of a valid request, or when the head does
// not end within `max` bytes.
Parse parse_request(std::string_view data, std::size_t max, Request& req) {
  const std::string_view head = data.substr(0, max);
  bool have_request_line = false;
  std::size_t pos = 0;
  for (;;) {
    const std::size_t nl = head.find('\n', pos);
    const bool complete = nl != std::string_view::npos;
    std::string_view line = head.substr(pos, complete ? nl - pos : std::string_view::npos);
    if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
    for (unsigned char c : line)
      if (is_ctl(c)) return Parse::Bad;
    if (!complete) {
      // A partial line: the method so far must be a token.
      if (!have_request_line)
        for (unsigned char c : line.substr(0, line.find(' ')))
          if (!is_tchar(c)) return Parse::Bad;
      return data.size() >= max ? Parse::Bad : Parse::NeedMore;
    }
    pos = nl + 1;
    if (!have_request_line) {
      if (line.empty()) continue;  // empty lines before the request line are ignored (RFC 9112)
      if (!parse_request_line(line, req)) return Parse::Bad;
      have_request_line = true;
      continue;
    }
    if (line.empty()) return Parse::Done;
    // A header: a token, a colon, a value (obsolete line folding is refused).
    const std::size_t colon = line.find(':');
    if (colon == std::string_view::npos || colon == 0) return Parse::Bad;
    for (unsigned char c : line.substr(0, colon))
      if (!is_tchar(c)) return Parse::Bad;
  }
}

std::string response(int status, std::string_view reason, std::string_view content_type,
                     std::string_view body, bool head_only, std::string_view extra_headers = {}) {
  std::string r = "HTTP/1.1 " + std::to_string(status) + " ";
  r += reason;
  r += "\r\nContent-Type: ";
  r += content_type;
  r += "\r\nContent-Length: " + std::to_string(body.size());
  r += "\r\nCache-Control: no-store\r\nConnection: close\r\n";
  r += extra_headers;
  r += "\r\n";
  if (!head_only) r += body;
  return r;
}

}  // namespace

struct MetricsEndpoint::Impl {
  Impl(BodyFunction b, MetricsEndpointOptions o)
      : body(std::move(b)), options(std::move(o)), acceptor(io) {}

  BodyFunction body;
  MetricsEndpointOptions options;
  asio::io_context io;
  tcp::acceptor acceptor;
  std::optional<asio::executor_work_guard<asio::io_context::executor_type>> work;
  std::thread thread;
  bool stopping = false;  // I/O thread only
  std::atomic<bool> stopped{false};
  std::set<std::shared_ptr<Connection>> open;  // I/O thread only
  std::atomic<std::uint64_t> connections{0}, refused{0}, ok{0}, bad{0}, timeouts{0};

  void accept();
};

namespace {

// One HTTP exchange. Everything runs on the endpoint's single I/O thread.
class Connection : public std::enable_shared_from_this<Connection> {
 public:
  Connection(MetricsEndpoint::Impl* ep, tcp::socket socket)
      : ep_(ep), socket_(std::move(socket)), timer_(ep->io) {}

  void start() {
    timer_.expires_after(ep_->options.timeout);
    timer_.async_wait([self = shared_from_this()](std::error_code ec) {
      if (ec || self->closed_) return;
      if (!self->responded_) ++self->ep_->timeouts;
      self->close();
    });
    read();
  }

  void close() {
    if (closed_) return;
    closed_ = true;
    std::error_code ec;
    timer_.cancel();
    socket_.shutdown(tcp::socket::shutdown_both, ec);
    socket_.close(ec);
    ep_->open.erase(shared_from_this());
  }

 private:
  void read() {
    socket_.async_read_some(
        asio::buffer(buffer_),
        [self = shared_from_this()](std::error_code ec, std::size_t n) { self->on_read(ec, n); });
  }

  void on_read(std::error_code ec, std::size_t n) {
    if (closed_) return;
    if (ec) {
      close();  // the client went away before finishing its request
      return;
    }
    request_.append(buffer_.data(), n);
    Request req;
    switch (parse_request(request_, ep_->options.max_request_bytes, req)) {
      case Parse::NeedMore:
        read();
        return;
      case Parse::Bad:
        respond(400, "Bad Request", "bad request\n", false);
        return;
      case Parse::Done:
        break;
    }
    const std::string path = req.target.substr(0, req.target.find('?'));
    const bool head = req.method == "HEAD";
    if (path != "/metrics") {
      respond(404, "Not Found", "not found: this endpoint serves /metrics\n", head);
    } else if (req.method != "GET" && !head) {
      respond(405, "Method Not Allowed", "method not allowed: use GET\n", false,
              "Allow: GET, HEAD\r\n");
    } else {
      std::string body;
      try {
        body = ep_->body();
      } catch (const std::exception& e) {
        log::error("metrics", std::string("collecting the metrics failed: ") + e.what());
        respond(500, "Internal Server Error", "internal error\n", head);
        return;
      }
      ++ep_->ok;
      send(response(200, "OK", "text/plain; version=0.0.4; charset=utf-8", body, head));
    }
  }

  void respond(int status, std::string_view reason, std::string_view body, bool head,
               std::string_view extra_headers = {}) {
    ++ep_->bad;
    send(response(status, reason, "text/plain; charset=utf-8", body, head, extra_headers));
  }

  // Writes the response, then half-closes and waits (briefly) for the client to close.
  void send(std::string bytes) {
    responded_ = true;
    auto data = std::make_shared<std::string>(std::move(bytes));
    asio::async_write(
        socket_, asio::buffer(*data),
        [self = shared_from_this(), data](std::error_code ec, std::size_t) {
          if (self->closed_) return;
          if (ec) {
            self->close();
            return;
          }
          std::error_code ignored;
          self->socket_.shutdown(tcp::socket::shutdown_send, ignored);
          // Re-arming cancels the wait of start(); the deadline only shortens.
          self->timer_.expires_at(
              std::min(self->timer_.expiry(), asio::steady_timer::clock_type::now() + kLinger));
          self->timer_.async_wait([self](std::error_code e) {
            if (!e) self->close();
          });
          self->drain();
        });
  }

  // Discards what the client still sends (the rest of a request we did not read) until it
  // closes.
  void drain() {
    socket_.async_read_some(asio::buffer(buffer_),
                            [self = shared_from_this()](std::error_code ec, std::size_t) {
                              if (self->closed_) return;
                              if (ec)
                                self->close();
                              else
                                self->drain();
                            });
  }

  MetricsEndpoint::Impl* ep_;
  tcp::socket socket_;
  asio::steady_timer timer_;
  std::array<char, 4096> buffer_{};
  std::string request_;
  bool responded_ = false, closed_ = false;
};

}  // namespace

void MetricsEndpoint::Impl::accept() {
  acceptor.async_accept([this](std::error_code ec, tcp::socket socket) {
    if (stopping) return;
    if (!ec) {
      ++connections;
      if (open.size() >= options.max_connections) {
        ++refused;
        std::error_code ignored;
        socket.close(ignored);
      } else {
        auto c = std::make_shared<Connection>(this, std::move(socket));
        open.insert(c);
        c->start();
      }
    } else if (ec != asio::error::operation_aborted) {
      log::warn("metrics", "accept: " + ec.message());
    }
    accept();
  });
}

MetricsEndpoint::MetricsEndpoint(BodyFunction body, MetricsEndpointOptions options)
    : impl_(std::make_unique<Impl>(std::move(body), std::move(options))) {
  if (!impl_->body) throw Error("metrics endpoint: no body function");
  if (impl_->options.max_request_bytes < 16)
    throw Error("metrics endpoint: max_request_bytes below 16");
  if (impl_->options.max_connections < 1) throw Error("metrics endpoint: max_connections is 0");
}

MetricsEndpoint::~MetricsEndpoint() {
  stop();
}

void MetricsEndpoint::start() {
  Impl& im = *impl_;
  if (im.thread.joinable() || im.stopped) throw Error("metrics endpoint: started twice");
  std::error_code ec;
  const asio::ip::address address = asio::ip::make_address(im.options.bind, ec);
  if (ec) throw Error("--metrics-bind: '" + im.options.bind + "' is not an IP address");
  const tcp::endpoint endpoint(address, im.options.port);
  im.acceptor.open(endpoint.protocol(), ec);
  if (!ec) im.acceptor.set_option(tcp::acceptor::reuse_address(true), ec);
  if (!ec) im.acceptor.bind(endpoint, ec);
  if (!ec) im.acceptor.listen(asio::socket_base::max_listen_connections, ec);
  if (ec)
    throw Error("metrics: cannot listen on " + im.options.bind + ":" +
                std::to_string(im.options.port) + ": " + ec.message());
  im.work.emplace(asio::make_work_guard(im.io));
  im.accept();
  im.thread = std::thread([&im] {
    for (;;) {
      try {
        im.io.run();
        break;
      } catch (const std::exception& e) {
        log::error("metrics", std::string("handler failed: ") + e.what());
      }
    }
  });
  log::info("metrics", "metrics on " + url());
}

void MetricsEndpoint::stop() {
  Impl& im = *impl_;
  if (im.stopped.exchange(true)) return;
  if (!im.thread.joinable()) return;
  asio::post(im.io, [&im] {
    im.stopping = true;
    std::error_code ec;
    im.acceptor.close(ec);
    // close() erases from the set: iterate over a copy.
    const auto open = im.open;
    for (const auto& c : open) c->close();
  });
  im.work.reset();
  im.thread.join();
}

std::uint16_t MetricsEndpoint::port() const {
  std::error_code ec;
  const auto ep = impl_->acceptor.local_endpoint(ec);
  return ec ? impl_->options.port : ep.port();
}

std::string MetricsEndpoint::url() const {
  const std::string& bind = impl_->options.bind;
  const std::string host = bind.find(':') != std::string::npos ? "[" + bind + "]" : bind;
  return "http://" + host + ":" + std::to_string(port()) + "/metrics";
}

MetricsEndpointStats MetricsEndpoint::stats() const {
  const Impl& im = *impl_;
  MetricsEndpointStats s;
  s.connections = im.connections.load();
  s.refused = im.refused.load();
  s.ok = im.ok.load();
  s.bad = im.bad.load();
  s.timeouts = im.timeouts.load();
  return s;
}

}  // namespace irradcast
