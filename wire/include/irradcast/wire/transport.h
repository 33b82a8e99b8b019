// The byte stream under the protocol: a TCP connection, with or without TLS on top (asio::ssl
// over OpenSSL). The server's sessions, the metrics endpoint and every client use it the same way,
// so TLS is a choice made once where the connection is made, not a second code path
// (docs/OPERATIONS.md, "TLS").
#pragma once

// A standard header before asio: asio's config decides between aligned_alloc and operator new
// from libstdc++'s _GLIBCXX_HAVE_ALIGNED_ALLOC, so every file must see it defined alike (else
// one file allocates handler memory with aligned_alloc and another frees it with delete).
#include <cstddef>

#include <asio.hpp>
#include <asio/ssl.hpp>

#include <atomic>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace irradcast::wire {

// A server's TLS: certificate chain and private key, PEM files. Throws irradcast::Error naming
// the file and OpenSSL's reason when one cannot be read or the key does not match the
// certificate, and naming the date when the certificate has expired or is not valid yet. TLS 1.2
// or newer.
std::shared_ptr<asio::ssl::context> make_server_tls(const std::string& cert_file,
                                                    const std::string& key_file);

// The certificate a server context presents: its subject, when it expires (UTC, "2026-12-04
// 15:10:00 UTC") and in how many days (negative: expired).
struct CertificateInfo {
  std::string subject;
  std::string not_after;
  double days_left = 0.0;
};
CertificateInfo certificate_info(asio::ssl::context& ctx);

// A server's TLS that can be reloaded (SIGHUP) while it serves: new connections get the context
// of the last successful load; connections made with an older one keep it (every context loaded
// is kept for the life of this object: a reload is an operator's act, a few kB each).
class ServerTls {
 public:
  static constexpr double kWarnDays = 14.0;  // expires sooner: a warning at load
  // Loads (make_server_tls) and logs the certificate's expiry (a warning within kWarnDays).
  ServerTls(std::string cert_file, std::string key_file, std::string component);
  asio::ssl::context* current() const { return current_.load(); }
  // Loads the files again. True: new connections get the new certificate (logged). False: the
  // files are bad (the reason logged as an error) and the current certificate stays.
  bool reload();

 private:
  void log_loaded(asio::ssl::context& ctx, const char* verb);
  std::string cert_file_, key_file_, component_;
  std::mutex mutex_;
  std::vector<std::shared_ptr<asio::ssl::context>> loaded_;  // the current one last
  std::atomic<asio::ssl::context*> current_{nullptr};
};

// A client's TLS: the server's certificate must chain to a CA in ca_file (PEM), or to the
// system's trusted CAs when ca_file is empty. Throws irradcast::Error if ca_file cannot be read.
std::shared_ptr<asio::ssl::context> make_client_tls(const std::string& ca_file);

// One connection: plain TCP, or TLS over TCP when made with a TLS context. The reads and writes
// have the shape of an Asio stream (async_read_some, async_write_some, read_some, write_some),
// so asio::async_write and asio::write work on it.
class Stream {
 public:
  using executor_type = asio::any_io_executor;
  using lowest_layer_type = asio::ip::tcp::socket;

  // tls == nullptr: plain TCP. The context must outlive the stream.
  Stream(const executor_type& ex, asio::ssl::context* tls)
      : socket_(ex),
        tls_(tls ? std::make_optional<asio::ssl::stream<asio::ip::tcp::socket&>>(socket_, *tls)
                 : std::nullopt) {}
  // An accepted socket.
  Stream(asio::ip::tcp::socket socket, asio::ssl::context* tls)
      : socket_(std::move(socket)),
        tls_(tls ? std::make_optional<asio::ssl::stream<asio::ip::tcp::socket&>>(socket_, *tls)
                 : std::nullopt) {}
  Stream(const Stream&) = delete;
  Stream& operator=(const Stream&) = delete;

  bool tls() const { return tls_.has_value(); }
  asio::ip::tcp::socket& socket() { return socket_; }
  lowest_layer_type& lowest_layer() { return socket_; }
  executor_type get_executor() { return socket_.get_executor(); }

  // A client names the server it expects (SNI, and the name its certificate must carry: a DNS
  // name, or an IP address for a certificate with an IP subjectAltName). No-op without TLS.
  void expect_server_name(const std::string& host);

  // Bytes read from the socket before the stream took over (behind a PROXY protocol header):
  // the TLS handshake reads them first, or without TLS the next read returns them.
  void unread(std::string bytes) { early_ = std::move(bytes); }

  // The TLS handshake; completes at once without TLS.
  template <class Handler>
  void async_handshake(asio::ssl::stream_base::handshake_type type, Handler&& handler) {
    if (tls_ && !early_.empty()) {
      // A client's first flight (its ClientHello) is all the handshake can have been sent
      // before the server answered it, so the handshake uses every early byte.
      auto ex = asio::get_associated_executor(handler, socket_.get_executor());
      tls_->async_handshake(
          type, asio::buffer(early_),
          asio::bind_executor(ex, [this, h = std::forward<Handler>(handler)](
                                      std::error_code ec, std::size_t used) mutable {
            early_.erase(0, used);
            if (!ec && !early_.empty()) ec = asio::error::invalid_argument;
            h(ec);
          }));
    } else if (tls_) {
      tls_->async_handshake(type, std::forward<Handler>(handler));
    } else {
      // On the handler's own executor (a session's strand), as the TLS handshake would be.
      auto ex = asio::get_associated_executor(handler, socket_.get_executor());
      asio::post(ex, [h = std::forward<Handler>(handler)]() mutable { h(std::error_code()); });
    }
  }
  void handshake(asio::ssl::stream_base::handshake_type type, std::error_code& ec) {
    if (tls_)
      tls_->handshake(type, ec);
    else
      ec.clear();
  }

  template <class Buffers, class Handler>
  void async_read_some(const Buffers& buffers, Handler&& handler) {
    if (!tls_ && !early_.empty()) {
      const std::size_t n = asio::buffer_copy(buffers, asio::buffer(early_));
      early_.erase(0, n);
      auto ex = asio::get_associated_executor(handler, socket_.get_executor());
      asio::post(ex,
                 [h = std::forward<Handler>(handler), n]() mutable { h(std::error_code(), n); });
    } else if (tls_)
      tls_->async_read_some(buffers, std::forward<Handler>(handler));
    else
      socket_.async_read_some(buffers, std::forward<Handler>(handler));
  }
  template <class Buffers, class Handler>
  void async_write_some(const Buffers& buffers, Handler&& handler) {
    if (tls_)
      tls_->async_write_some(buffers, std::forward<Handler>(handler));
    else
      socket_.async_write_some(buffers, std::forward<Handler>(handler));
  }
  template <class Buffers>
  std::size_t read_some(const Buffers& buffers, std::error_code& ec) {
    return tls_ ? tls_->read_some(buffers, ec) : socket_.read_some(buffers, ec);
  }
  template <class Buffers>
  std::size_t write_some(const Buffers& buffers, std::error_code& ec) {
    return tls_ ? tls_->write_some(buffers, ec) : socket_.write_some(buffers, ec);
  }

  // Closes the TCP connection (no TLS close_notify: every protocol message is framed, so a
  // truncation cannot be mistaken for a complete message).
  void close() {
    std::error_code ec;
    socket_.shutdown(asio::ip::tcp::socket::shutdown_both, ec);
    socket_.close(ec);
  }

 private:
  asio::ip::tcp::socket socket_;
  std::optional<asio::ssl::stream<asio::ip::tcp::socket&>> tls_;
  std::string early_;  // unread()
};

// One line for a TLS failure: OpenSSL's reason where there is one ("certificate verify failed",
// "wrong version number", ...), else the error's message.
std::string describe_tls_error(const std::error_code& ec);

}  // namespace irradcast::wire
