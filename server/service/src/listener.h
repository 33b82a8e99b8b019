// One listening port and its accept loop: the protocol port, the web port and the metrics
// endpoint all accept through it, with one policy for failed accepts. Out of descriptors (or
// kernel memory), the pending connection stays in the kernel's queue, so accepting again at once
// would spin: accepting pauses, 10 ms doubling to 1 s, with a warning when the episode starts
// and a line when a connection is accepted again. Any other failed accept is logged and accepting
// goes on. All these lines come at most once per 10 s (saying how many were left out). Each port
// backs off on its own (the server's two ports run out of the same descriptors, and each finds it
// out with its next accept). The acceptor and its timer live on a strand of their own, so close()
// from any thread never meets a handler of theirs.
#pragma once

// A standard header before asio (see session.h).
#include <cstddef>

#include <asio.hpp>

#include <atomic>
#include <chrono>
#include <cstdint>
#include <functional>
#include <string>

namespace irradcast {

class Listener {
 public:
  struct Options {
    std::string component;  // the log lines' component ("server", "metrics")
    std::string bind_flag;  // the option that named the address, for its error ("--bind")
    int backlog = asio::socket_base::max_listen_connections;
    // Each accepted socket on its own strand of the io_context (the server's sessions, which run
    // on many I/O threads); else on the io_context itself (one thread).
    bool strand_per_socket = false;
    // Appended to the warning that accepting pauses (e.g. how many sessions are open).
    std::function<std::string()> describe;
  };
  using OnSocket = std::function<void(asio::ip::tcp::socket)>;

  Listener(asio::io_context& io, Options options);

  // Binds `bind`:`port` and listens. Throws irradcast::Error saying which address and why.
  void listen(const std::string& bind, std::uint16_t port);
  // Accepts until close(): each connection to on_socket, each failed accept to on_error (may be
  // empty), on the io_context's threads.
  void start(OnSocket on_socket, std::function<void()> on_error = {});
  // Stops accepting, from any thread (the acceptor closes on its strand). Idempotent.
  void close();
  // The port listen() bound (0 before).
  std::uint16_t port() const { return bound_port_; }

 private:
  void accept();
  void on_accept(std::error_code ec, asio::ip::tcp::socket socket);
  void on_error(const std::error_code& ec);
  // A warning, unless one was logged less than 10 s ago (then counted, and said with the next).
  void warn(const std::string& line);

  asio::io_context& io_;
  Options options_;
  asio::strand<asio::io_context::executor_type> strand_;
  asio::ip::tcp::acceptor acceptor_;
  asio::steady_timer pause_;
  OnSocket on_socket_;
  std::function<void()> on_error_;
  std::atomic<std::uint16_t> bound_port_{0};
  std::atomic<bool> closed_{false};       // close() may run on another I/O thread than a handler
  std::chrono::milliseconds backoff_{0};  // the pause now; 0: accepting
  std::chrono::steady_clock::time_point last_warning_{};
  std::uint64_t unlogged_ = 0;  // failed accepts not logged since the last line
};

}  // namespace irradcast
