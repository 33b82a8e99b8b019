#include "irradcast/service/metrics_endpoint.h"

#include <sys/resource.h>

#include <asio.hpp>

#include <algorithm>
#include <array>
#include <atomic>
#include <cstring>
#include <list>
#include <optional>
#include <string_view>
#include <thread>

#include "irradcast/common/error.h"
#include "irradcast/common/log.h"
#include "irradcast/wire/transport.h"
#include "listener.h"
#include "run_io.h"

namespace irradcast {

using asio::ip::tcp;
using Clock = std::chrono::steady_clock;

namespace {

// How long a connection may stay open after its response, for the client to close first (so that
// closing with unread request bytes does not reset the connection before the client read the
// response).
constexpr std::chrono::milliseconds kLinger{1000};

class Connection;

// Where a connection is in its exchange; the endpoint keeps one list per phase, oldest first,
// and drops from them in the order Lingering, Reading, Writing when it needs room.
enum Phase : std::size_t { kReading = 0, kWriting = 1, kLingering = 2, kPhases = 3 };
using ConnectionList = std::list<std::shared_ptr<Connection>>;

bool is_tchar(unsigned char c) {
  return (c >= '0' && c <= '9') || (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') ||
         (c != 0 && std::strchr("!#$%&'*+-.^_`|~", c) != nullptr);
}
bool is_ctl(unsigned char c) {
  return (c < 0x20 && c != '\t') || c == 0x7f;
}

// NeedMore: the head is incomplete; Bad: the bytes cannot start a valid request (400);
// LineTooLong: the request line passes the byte cap (414); HeadTooLarge: the headers do (431).
enum class Parse { NeedMore, Bad, LineTooLong, HeadTooLarge, Done };

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

// The request head (request line and headers, lines ending in CRLF or LF), fed as it arrives.
// Every byte is looked at once, so a client that trickles its request costs no more than one
// that sends it at once. Bad as soon as the bytes cannot be the start of a valid request.
class HeadParser {
 public:
  explicit HeadParser(std::size_t max_bytes) : max_(max_bytes) {}

  // Bytes after the end of the head (a body, a pipelined request) are not looked at.
  Parse feed(std::string_view bytes) {
    for (const char ch : bytes) {
      const auto c = static_cast<unsigned char>(ch);
      if (++bytes_ > max_) return have_request_line_ ? Parse::HeadTooLarge : Parse::LineTooLong;
      if (c == '\n') {
        const Parse p = end_line();
        if (p != Parse::NeedMore) return p;
        continue;
      }
      if (cr_ || is_ctl(c)) {  // a CR is only allowed right before the LF
        if (c != '\r' || cr_) return Parse::Bad;
        cr_ = true;
        continue;
      }
      if (!have_request_line_ && !method_done_) {  // the method so far must be a token
        if (c == ' ')
          method_done_ = true;
        else if (!is_tchar(c))
          return Parse::Bad;
      }
      line_ += ch;
    }
    return Parse::NeedMore;
  }
  const Request& request() const { return request_; }

 private:
  Parse end_line() {
    const std::string line = std::move(line_);
    line_.clear();
    cr_ = false;
    method_done_ = false;
    if (!have_request_line_) {
      if (line.empty()) return Parse::NeedMore;  // empty lines before it are ignored (RFC 9112)
      if (!parse_request_line(line, request_)) return Parse::Bad;
      have_request_line_ = true;
      return Parse::NeedMore;
    }
    if (line.empty()) return Parse::Done;
    // A header: a token, a colon, a value (obsolete line folding is refused).
    const std::size_t colon = line.find(':');
    if (colon == std::string::npos || colon == 0) return Parse::Bad;
    for (unsigned char c : std::string_view(line).substr(0, colon))
      if (!is_tchar(c)) return Parse::Bad;
    return Parse::NeedMore;
  }

  std::size_t max_;
  std::size_t bytes_ = 0;
  std::string line_;  // the current line, without its CR
  bool cr_ = false, method_done_ = false, have_request_line_ = false;
  Request request_;
};

std::string response_head(int status, std::string_view reason, std::string_view content_type,
                          std::size_t content_length, std::string_view extra_headers = {}) {
  std::string r = "HTTP/1.1 " + std::to_string(status) + " ";
  r += reason;
  r += "\r\nContent-Type: ";
  r += content_type;
  r += "\r\nContent-Length: " + std::to_string(content_length);
  r += "\r\nCache-Control: no-store\r\nConnection: close\r\n";
  r += extra_headers;
  r += "\r\n";
  return r;
}

}  // namespace

struct MetricsEndpoint::Impl {
  Impl(BodyFunction b, MetricsEndpointOptions o)
      : body(std::move(b)),
        options(std::move(o)),
        io(1),
        listener(io, {"metrics", "--metrics-bind", options.listen_backlog, false, {}}),
        max_open(options.max_connections) {
    if (options.tls_cert.empty() != options.tls_key.empty())
      throw Error("metrics: TLS needs both a certificate and a key");
    if (!options.tls_cert.empty())
      tls = std::make_unique<wire::ServerTls>(options.tls_cert, options.tls_key, "metrics");
  }

  BodyFunction body;
  MetricsEndpointOptions options;
  std::unique_ptr<wire::ServerTls> tls;  // null: plain HTTP
  asio::io_context io;
  Listener listener;
  std::optional<asio::executor_work_guard<asio::io_context::executor_type>> work;
  std::thread thread;
  std::uint32_t max_open;  // options.max_connections, lowered by the descriptor limit
  std::atomic<std::uint32_t> max_open_applied{0};
  std::atomic<bool> stopped{false};

  // I/O thread only.
  bool stopping = false;
  std::array<ConnectionList, kPhases> open;  // by phase, oldest first
  std::shared_ptr<const std::string> cached;
  Clock::time_point cached_at;

  std::atomic<std::uint64_t> connections{0}, open_now{0}, dropped{0}, ok{0}, bad{0}, timeouts{0},
      collections{0};

  void on_accept(tcp::socket socket);
  // Closes one connection to make room for a new one.
  void drop_one();
  // The body function's text, reused while younger than cache_for. Throws what the body throws.
  std::shared_ptr<const std::string> metrics_text();
};

namespace {

// One HTTP exchange. Everything runs on the endpoint's single I/O thread.
class Connection : public std::enable_shared_from_this<Connection> {
 public:
  // The stream the exchange runs on, plain TCP or TLS (wire::Stream). Only the functions under
  // "Stream I/O" touch it.
  using Stream = wire::Stream;

  Connection(MetricsEndpoint::Impl* ep, tcp::socket socket)
      : ep_(ep),
        stream_(std::move(socket), ep->tls ? ep->tls->current() : nullptr),
        timer_(ep->io),
        parser_(ep->options.max_request_bytes),
        accepted_(Clock::now()) {}

  // Takes its place (the newest) in the endpoint's list of connections being read.
  void start() {
    ConnectionList& list = ep_->open[kReading];
    list.push_back(shared_from_this());
    where_ = std::prev(list.end());
    ++ep_->open_now;
    const MetricsEndpointOptions& o = ep_->options;
    arm(accepted_ + std::min(o.header_timeout, o.timeout));
    // The TLS handshake (none for plain HTTP) runs under the header deadline.
    stream_.async_handshake(asio::ssl::stream_base::server,
                            [self = shared_from_this()](std::error_code ec) {
                              if (self->closed_) return;
                              if (ec) {
                                ++self->ep_->bad;
                                self->close();
                                return;
                              }
                              self->read();
                            });
  }

  void close() {
    if (closed_) return;
    const auto self = shared_from_this();  // the list below may hold the last reference
    closed_ = true;
    timer_.cancel();
    close_stream();
    ep_->open[phase_].erase(where_);
    --ep_->open_now;
  }

 private:
  // ---- Stream I/O

  template <class Handler>
  void read_some(Handler handler) {
    stream_.async_read_some(asio::buffer(buffer_), std::move(handler));
  }
  template <class Handler>
  void write_response(Handler handler) {
    std::array<asio::const_buffer, 2> buffers = {asio::buffer(head_), asio::const_buffer()};
    if (body_) buffers[1] = asio::buffer(*body_);
    asio::async_write(stream_, buffers, std::move(handler));
  }
  // After the response: tells the client there is nothing more (it reads EOF).
  // Over TLS the TCP half-close carries no close_notify: the response's Content-Length says
  // where it ends.
  void finish_sending() {
    std::error_code ignored;
    stream_.socket().shutdown(tcp::socket::shutdown_send, ignored);
  }
  void close_stream() { stream_.close(); }

  // ---- The exchange

  void move_to(Phase phase) {
    ConnectionList& to = ep_->open[phase];
    to.splice(to.end(), ep_->open[phase_], where_);  // where_ stays valid
    phase_ = phase;
  }

  // One deadline at a time: re-arming replaces the previous one.
  void arm(Clock::time_point at) {
    timer_.expires_at(at);
    timer_.async_wait([self = shared_from_this()](std::error_code ec) {
      if (ec || self->closed_) return;
      if (self->timer_.expiry() > Clock::now()) return;  // re-armed after this wait completed
      if (self->phase_ != kLingering) ++self->ep_->timeouts;
      self->close();
    });
  }

  void read() {
    read_some(
        [self = shared_from_this()](std::error_code ec, std::size_t n) { self->on_read(ec, n); });
  }

  void on_read(std::error_code ec, std::size_t n) {
    if (closed_) return;
    if (ec) {
      close();  // the client went away before finishing its request
      return;
    }
    switch (parser_.feed(std::string_view(buffer_.data(), n))) {
      case Parse::NeedMore:
        read();
        return;
      case Parse::Bad:
        respond_error(400, "Bad Request", "bad request\n", false);
        return;
      case Parse::LineTooLong:
        respond_error(414, "URI Too Long", "request line too long\n", false);
        return;
      case Parse::HeadTooLarge:
        respond_error(431, "Request Header Fields Too Large", "request headers too large\n", false);
        return;
      case Parse::Done:
        break;
    }
    const Request& req = parser_.request();
    const std::string path = req.target.substr(0, req.target.find('?'));
    const bool head = req.method == "HEAD";
    if (path != "/metrics") {
      respond_error(404, "Not Found", "not found: this endpoint serves /metrics\n", head);
    } else if (req.method != "GET" && !head) {
      respond_error(405, "Method Not Allowed", "method not allowed: use GET\n", false,
                    "Allow: GET, HEAD\r\n");
    } else {
      std::shared_ptr<const std::string> text;
      try {
        text = ep_->metrics_text();
      } catch (const std::exception& e) {
        log::error("metrics", std::string("collecting the metrics failed: ") + e.what());
        respond_error(500, "Internal Server Error", "internal error\n", head);
        return;
      }
      ++ep_->ok;
      std::string response =
          response_head(200, "OK", "text/plain; version=0.0.4; charset=utf-8", text->size());
      send(std::move(response), head ? nullptr : std::move(text));
    }
  }

  void respond_error(int status, std::string_view reason, std::string_view body, bool head,
                     std::string_view extra_headers = {}) {
    ++ep_->bad;
    send(response_head(status, reason, "text/plain; charset=utf-8", body.size(), extra_headers),
         head ? nullptr : std::make_shared<const std::string>(body));
  }

  // Writes the response, then half-closes and waits (briefly) for the client to close.
  void send(std::string head, std::shared_ptr<const std::string> body) {
    head_ = std::move(head);
    body_ = std::move(body);
    move_to(kWriting);
    arm(accepted_ + ep_->options.timeout);  // the header deadline no longer applies
    write_response([self = shared_from_this()](std::error_code ec, std::size_t) {
      if (self->closed_) return;
      if (ec) {
        self->close();
        return;
      }
      self->body_.reset();
      self->move_to(kLingering);
      self->finish_sending();
      self->arm(std::min(self->accepted_ + self->ep_->options.timeout, Clock::now() + kLinger));
      self->drain();
    });
  }

  // Discards what the client still sends (the rest of a request we did not read) until it
  // closes.
  void drain() {
    read_some([self = shared_from_this()](std::error_code ec, std::size_t) {
      if (self->closed_) return;
      if (ec)
        self->close();
      else
        self->drain();
    });
  }

  MetricsEndpoint::Impl* ep_;
  Stream stream_;
  asio::steady_timer timer_;
  HeadParser parser_;
  Clock::time_point accepted_;
  Phase phase_ = kReading;
  ConnectionList::iterator where_;  // in ep_->open[phase_]
  std::array<char, 2048> buffer_{};
  std::string head_;                         // the response's status line and headers
  std::shared_ptr<const std::string> body_;  // its body (the cached metrics text, shared)
  bool closed_ = false;
};

}  // namespace

void MetricsEndpoint::Impl::on_accept(tcp::socket socket) {
  if (stopping) return;
  ++connections;
  if (open_now.load() >= max_open) drop_one();
  std::make_shared<Connection>(this, std::move(socket))->start();
}

void MetricsEndpoint::Impl::drop_one() {
  for (const Phase phase : {kLingering, kReading, kWriting}) {
    if (open[phase].empty()) continue;
    const std::shared_ptr<Connection> oldest = open[phase].front();
    ++dropped;
    oldest->close();
    return;
  }
}

std::shared_ptr<const std::string> MetricsEndpoint::Impl::metrics_text() {
  const auto now = Clock::now();
  if (cached && now - cached_at < options.cache_for) return cached;
  ++collections;
  cached = std::make_shared<const std::string>(body());
  cached_at = now;
  return cached;
}

MetricsEndpoint::MetricsEndpoint(BodyFunction body, MetricsEndpointOptions options)
    : impl_(std::make_unique<Impl>(std::move(body), std::move(options))) {
  const MetricsEndpointOptions& o = impl_->options;
  if (!impl_->body) throw Error("metrics endpoint: no body function");
  if (o.max_request_bytes < 16) throw Error("metrics endpoint: max_request_bytes below 16");
  if (o.max_connections < 1) throw Error("metrics endpoint: max_connections is 0");
  if (o.header_timeout.count() <= 0 || o.timeout.count() <= 0)
    throw Error("metrics endpoint: a timeout is not positive");
  if (o.listen_backlog < 1) throw Error("metrics endpoint: listen_backlog below 1");
  if (o.cache_for.count() < 0) throw Error("metrics endpoint: cache_for is negative");
}

MetricsEndpoint::~MetricsEndpoint() {
  stop();
}

void MetricsEndpoint::start() {
  Impl& im = *impl_;
  if (im.thread.joinable() || im.stopped) throw Error("metrics endpoint: started twice");
  im.listener.listen(im.options.bind, im.options.port);
  // The endpoint takes at most a quarter of the process's descriptors: the rest are the game
  // server's.
  rlimit limit{};
  if (getrlimit(RLIMIT_NOFILE, &limit) == 0 && limit.rlim_cur != RLIM_INFINITY) {
    const rlim_t quarter = std::max<rlim_t>(1, limit.rlim_cur / 4);
    if (quarter < im.max_open) {
      log::info("metrics", "at most " + std::to_string(quarter) + " connections (of " +
                               std::to_string(im.options.max_connections) +
                               " asked): a quarter of the descriptor limit (ulimit -n " +
                               std::to_string(limit.rlim_cur) + ")");
      im.max_open = static_cast<std::uint32_t>(quarter);
    }
  }
  im.max_open_applied = im.max_open;
  im.work.emplace(asio::make_work_guard(im.io));
  im.listener.start([&im](tcp::socket socket) { im.on_accept(std::move(socket)); });
  im.thread = std::thread([&im] { run_io(im.io, "metrics", "handler"); });
  log::info("metrics", "metrics on " + url());
}

void MetricsEndpoint::stop() {
  Impl& im = *impl_;
  if (im.stopped.exchange(true)) return;
  if (!im.thread.joinable()) return;
  asio::post(im.io, [&im] {
    im.stopping = true;
    im.listener.close();
    // close() erases from the lists: iterate over copies.
    for (const ConnectionList& list : im.open) {
      const ConnectionList copy = list;
      for (const auto& c : copy) c->close();
    }
  });
  im.work.reset();
  im.thread.join();
}

std::uint16_t MetricsEndpoint::port() const {
  return impl_->listener.port();
}

bool MetricsEndpoint::reload_tls() {
  return impl_->tls && impl_->tls->reload();
}

std::string MetricsEndpoint::url() const {
  const std::string& bind = impl_->options.bind;
  const std::string host = bind.find(':') != std::string::npos ? "[" + bind + "]" : bind;
  return (impl_->tls ? "https://" : "http://") + host + ":" + std::to_string(port()) + "/metrics";
}

std::uint32_t MetricsEndpoint::max_connections() const {
  const std::uint32_t applied = impl_->max_open_applied.load();
  return applied > 0 ? applied : impl_->options.max_connections;
}

MetricsEndpointStats MetricsEndpoint::stats() const {
  const Impl& im = *impl_;
  MetricsEndpointStats s;
  s.connections = im.connections.load();
  s.open = im.open_now.load();
  s.dropped = im.dropped.load();
  s.ok = im.ok.load();
  s.bad = im.bad.load();
  s.timeouts = im.timeouts.load();
  s.collections = im.collections.load();
  return s;
}

}  // namespace irradcast
