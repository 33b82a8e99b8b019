// One client connection: TLS handshake, reads, writes, timers and the write-stall watch around
// the session's protocol.
#include "session.h"

#include "irradcast/common/log.h"
#include "irradcast/service/web_origin.h"
#include "web_site.h"

namespace irradcast {

using asio::ip::tcp;
using Clock = std::chrono::steady_clock;

namespace {

// "address:port" of the peer, for log lines.
std::string peer_name(tcp::socket& socket) {
  std::error_code ec;
  auto ep = socket.remote_endpoint(ec);
  return ec ? std::string("?") : ep.address().to_string() + ":" + std::to_string(ep.port());
}

}  // namespace

Session::Session(SessionServer& server, tcp::socket socket, std::string peer_key, std::uint64_t id,
                 bool web, bool proxied)
    : server_(server),
      strand_(socket.get_executor()),
      stream_(std::move(socket), server_.tls ? server_.tls->current() : nullptr),
      idle_timer_(strand_),
      rate_timer_(strand_),
      close_timer_(strand_),
      hello_timer_(strand_),
      penalty_timer_(strand_),
      stall_timer_(strand_),
      protocol_(server_.context, id, std::move(peer_key), peer_name(stream_.socket())),
      proxied_(proxied && server_.proxies) {
  const ServerOptions& o = server_.context.options;
  if (proxied_ && (web ? o.web_proxy_protocol : o.proxy_protocol))
    proxy_reader_ = std::make_unique<ProxyHeaderReader>();
  protocol_.set_unattributed(proxied_);  // until the proxy names the client
  channel_ = web ? make_web_channel() : wire::FrameChannel::plain();
}

// The web port: HTTP requests are answered from the page's files; each binary message of the
// WebSocket goes to the protocol as one frame, under the protocol's cap for the frames of this
// moment (Hello's before Welcome).
std::unique_ptr<wire::FrameChannel> Session::make_web_channel() {
  wire::WsServerConnection::Handlers h;
  h.ws_path = "/ws";
  h.http = serve_web;
  h.allow_origin = [this](const std::string& origin, const std::string& host) {
    return origin_allowed(origin, host, server_.context.options.allowed_origins);
  };
  h.request = [this](const std::function<std::string(const std::string&)>& header) {
    return screen_request(header);
  };
  return wire::FrameChannel::websocket(std::move(h), server_.context.hello_frame_cap);
}

void Session::on_channel_input() {
  using State = wire::FrameChannel::State;
  ServerCounters& counters = server_.context.counters;
  const State state = channel_->state();
  if (!channel_counted_ && channel_->upgraded()) {
    channel_counted_ = true;
    ++counters.websocket_sessions;
  }
  if (!channel_counted_ && (state == State::HttpAnswered || state == State::Refused)) {
    channel_counted_ = true;
    ++counters.http_requests;
  }
  if (state == State::TooLarge)
    protocol_.transport_failed(wire::FRAME_TOO_LARGE, channel_->state_message());
  if (state == State::BadMessage)
    protocol_.transport_failed(wire::BAD_FRAME, channel_->state_message());
}

bool Session::pump_channel() {
  if (channel_->output_size() > 0) {
    write(
        {SessionWrite::Kind::Control, std::make_shared<const std::string>(channel_->take_output())},
        true);
    return true;
  }
  if (channel_->finished()) {
    close(CloseReason::Disconnect);  // answered, refused or closed by the peer
    return true;
  }
  if (!channel_->carries_frames()) {
    // Still HTTP: a protocol failure (the hello timeout) has no WebSocket to go out on.
    if (protocol_.closing()) close(CloseReason::Disconnect);
    return true;
  }
  return false;
}

bool Session::read_paused() const {
  return protocol_.paused() || channel_->output_size() > kMaxChannelOutput;
}

void Session::start() {
  asio::post(strand_, [self = shared_from_this()] {
    self->arm_idle_timer();
    self->arm_hello_timer();
    if (self->proxy_reader_)
      self->read_proxy_header();
    else
      self->handshake();
  });
}

// The raw bytes of a trusted proxy's connection up to the end of its PROXY header
// (--proxy-protocol: required, within the hello timeout); what follows the header goes back to the
// stream.
void Session::read_proxy_header() {
  stream_.socket().async_read_some(
      asio::buffer(buffer_),
      asio::bind_executor(strand_, [self = shared_from_this()](std::error_code ec, std::size_t n) {
        if (self->protocol_.closed()) return;
        if (ec) {
          self->close(CloseReason::Disconnect);
          return;
        }
        self->server_.context.counters.bytes_received += n;
        ProxyHeaderReader& reader = *self->proxy_reader_;
        switch (reader.feed(self->buffer_.data(), n)) {
          case ProxyHeaderReader::State::More:
            self->read_proxy_header();
            return;
          case ProxyHeaderReader::State::Bad:
            self->protocol_.note(log::Level::Info, "closed: " + reader.error());
            self->close(CloseReason::BadFrame);
            return;
          case ProxyHeaderReader::State::Done:
            if (reader.source()) self->learn_client(*reader.source());
            break;
          case ProxyHeaderReader::State::None:
            self->protocol_.note(log::Level::Info,
                                 "closed: no PROXY protocol v2 header from a trusted proxy "
                                 "(--proxy-protocol)");
            self->close(CloseReason::BadFrame);
            return;
        }
        self->stream_.unread(reader.take_rest());
        self->proxy_reader_.reset();
        self->handshake();
      }));
}

void Session::learn_client(const asio::ip::address& client) {
  const bool trusted = server_.proxies->contains(client);
  refusal_ = protocol_.move_peer(
      peer_key_of(client), client.to_string() + " via " + peer_name(stream_.socket()), trusted);
  proxied_ = trusted;
  if (refusal_.empty()) protocol_.set_unattributed(trusted);
}

// The web port's requests: the client a trusted proxy names in its forwarded header, and the
// refusal of a client the server does not admit.
std::optional<wire::HttpReply> Session::screen_request(
    const std::function<std::string(const std::string&)>& header) {
  if (refusal_.empty() && proxied_) {
    const ForwardedHeader which = server_.context.options.forwarded_header;
    const char* name = which == ForwardedHeader::Forwarded ? "Forwarded" : "X-Forwarded-For";
    const ForwardedClient client = forwarded_client(header(name), which, *server_.proxies);
    if (client.kind == ForwardedClient::Kind::Client) learn_client(client.address);
    if (client.kind == ForwardedClient::Kind::Unknown) {
      // Nobody to count it under: not the proxy either (its other clients would share it).
      protocol_.note(log::Level::Info, std::string("refused: the ") + name +
                                           " header of a trusted proxy names no client address");
      return wire::HttpReply{400,
                             {{"Content-Type", "text/plain; charset=utf-8"}},
                             std::string("the ") + name +
                                 " header names no client address: this server counts every "
                                 "client by its address\n"};
    }
  }
  if (refusal_.empty()) return std::nullopt;
  protocol_.note(log::Level::Info, "refused: " + refusal_);
  return wire::HttpReply{503, {{"Content-Type", "text/plain; charset=utf-8"}}, refusal_ + "\n"};
}

void Session::handshake() {
  stream_.async_handshake(
      asio::ssl::stream_base::server,
      asio::bind_executor(strand_, [self = shared_from_this()](std::error_code ec) {
        if (self->protocol_.closed()) return;
        if (ec) {
          self->protocol_.note(log::Level::Info,
                               "TLS handshake failed: " + wire::describe_tls_error(ec));
          self->close(CloseReason::Tls);
          return;
        }
        // Refused behind a PROXY header: in a frame where frames go (the web port refuses the
        // HTTP request instead, screen_request).
        if (!self->refusal_.empty() && self->channel_->carries_frames()) {
          self->protocol_.note(log::Level::Info, "refused: " + self->refusal_);
          self->protocol_.refuse(self->refusal_);
          self->act();
          return;
        }
        self->read();
      }));
}

void Session::tiles_changed(std::shared_ptr<const std::vector<std::uint32_t>> tiles) {
  asio::post(strand_, [self = shared_from_this(), tiles] {
    if (self->protocol_.closed()) return;
    self->protocol_.tiles_changed(*tiles);
    self->pump();
  });
}

void Session::edit_applied(std::shared_ptr<const std::string> frame) {
  asio::post(strand_, [self = shared_from_this(), frame = std::move(frame)]() mutable {
    if (self->protocol_.closed()) return;
    self->protocol_.edit_applied(std::move(frame));
    self->pump();
  });
}

void Session::poses_changed() {
  asio::post(strand_, [self = shared_from_this()] {
    if (self->protocol_.closed()) return;
    self->protocol_.poses_changed();
    self->pump();
  });
}

void Session::presence_changed(std::shared_ptr<const AvatarSnapshot> avatars) {
  asio::post(strand_, [self = shared_from_this(), avatars = std::move(avatars)]() mutable {
    if (self->protocol_.closed()) return;
    self->protocol_.presence_changed(std::move(avatars));
    self->pump();
  });
}

void Session::shutdown() {
  asio::post(strand_, [self = shared_from_this()] {
    self->protocol_.shutdown();
    self->act();
  });
}

// No Hello (after the TLS handshake) within the hello timeout: close.
void Session::arm_hello_timer() {
  hello_timer_.expires_after(server_.context.options.hello_timeout);
  hello_timer_.async_wait([self = shared_from_this()](std::error_code ec) {
    if (ec) return;
    self->protocol_.hello_timed_out(self->handshaking());
    self->act();
  });
}

// Watches a write in flight: one that made no progress for the write stall timeout means a
// client that does not read, and it is closed as slow. Armed while writes are in flight.
void Session::arm_stall_timer() {
  const auto timeout = server_.context.options.write_stall_timeout;
  if (stall_armed_ || timeout.count() <= 0) return;
  stall_armed_ = true;
  stall_timer_.expires_after(timeout / 4);
  stall_timer_.async_wait([self = shared_from_this(), timeout](std::error_code ec) {
    self->stall_armed_ = false;
    if (ec || self->protocol_.closed() || !self->writing_) return;
    if (Clock::now() - self->write_progress_at_ >= timeout) {
      self->protocol_.note(log::Level::Info, "closed: slow client (no write progress for " +
                                                 std::to_string(timeout.count()) + " ms)");
      self->close(CloseReason::SlowClient);
      return;
    }
    self->arm_stall_timer();
  });
}

void Session::arm_idle_timer() {
  idle_timer_.expires_after(server_.context.options.idle_timeout);
  idle_timer_.async_wait([self = shared_from_this()](std::error_code ec) {
    if (ec) return;
    self->protocol_.idle_timed_out();
    self->act();
  });
}

void Session::read() {
  reading_started_ = true;
  if (protocol_.closed() || protocol_.closing() || read_pending_) return;
  read_pending_ = true;
  stream_.async_read_some(
      asio::buffer(buffer_),
      asio::bind_executor(strand_, [self = shared_from_this()](std::error_code ec, std::size_t n) {
        self->read_pending_ = false;
        self->on_read(ec, n);
      }));
}

void Session::on_read(std::error_code ec, std::size_t n) {
  if (protocol_.closed()) return;
  if (ec) {
    if (ec != asio::error::eof && ec != asio::error::operation_aborted)
      log::debug("server", "session " + std::to_string(protocol_.id()) + ": read: " + ec.message());
    close(CloseReason::Disconnect);
    return;
  }
  server_.context.counters.bytes_received += n;
  channel_->receive(buffer_.data(), n,
                    [this](const char* data, std::size_t k) { protocol_.receive(data, k); });
  on_channel_input();
  drain();
}

// Handles the frames received, then reads on; stops while a wrong token's answer is delayed or
// while the client's replies pile up (it reads on once they are written).
void Session::drain() {
  wire::Envelope env;
  while (protocol_.next_frame(env)) {
    arm_idle_timer();
    protocol_.handle(env);
    act();
  }
  act();
  if (protocol_.closed() || protocol_.closing()) return;
  if (!protocol_.account_partial(channel_->held_bytes())) {
    act();
    return;
  }
  if (!read_paused()) read();
}

void Session::act() {
  const SessionEvents ev = protocol_.take_events();
  if (ev.welcomed) {
    hello_timer_.cancel();
    channel_->set_max_frame(server_.context.options.max_frame);
  }
  if (ev.closing) {
    // The Error frame is written first; a client that does not read gets a grace period.
    close_timer_.expires_after(std::chrono::seconds(2));
    close_timer_.async_wait([self = shared_from_this()](std::error_code ec) {
      if (!ec) self->close(CloseReason::Disconnect);
    });
  }
  if (ev.penalty) {
    penalty_timer_.expires_after(*ev.penalty);
    penalty_timer_.async_wait([self = shared_from_this(), banned = ev.banned](std::error_code ec) {
      self->protocol_.penalty_ended();
      if (ec || self->protocol_.closed()) return;
      self->on_penalty_over(banned);
    });
  }
  if (ev.close) close(*ev.close);
  pump();
}

void Session::on_penalty_over(bool banned) {
  protocol_.answer_token_failure(banned);
  act();
  if (!banned) drain();
}

// Starts the next write if none is in flight.
void Session::pump() {
  if (protocol_.closed() || writing_) return;
  if (pump_channel()) return;
  SessionWrite w = protocol_.next_write(Clock::now());
  switch (w.kind) {
    case SessionWrite::Kind::None:
      return;
    case SessionWrite::Kind::Close:
      if (std::string bytes = channel_->closing_bytes(); !bytes.empty()) {  // a close frame first
        write({SessionWrite::Kind::Control, std::make_shared<const std::string>(std::move(bytes))},
              true);
        return;
      }
      close(CloseReason::Disconnect);
      return;
    case SessionWrite::Kind::Wait:
      if (rate_waiting_) return;
      rate_waiting_ = true;
      rate_timer_.expires_after(w.wait);
      rate_timer_.async_wait([self = shared_from_this()](std::error_code ec) {
        self->rate_waiting_ = false;
        if (!ec) self->pump();
      });
      return;
    default:
      write(std::move(w));
  }
}

// The frames the protocol has ready behind the first one (tiles, replies, edits, scene chunks),
// up to kMaxBatchBytes and as many as the channel takes in one write (the web port: one), go out
// in the same write: a burst of tiles costs one system call per batch rather than one per tile,
// on both ends. A Wait (the rate cap) or a Close ends the batch; the protocol hands it out again
// once the batch is written.
void Session::gather(std::vector<SessionWrite>& batch) {
  std::size_t bytes = batch.front().frame->size();
  const std::size_t most = std::min(kMaxBatchFrames, channel_->frames_per_write());
  while (bytes < kMaxBatchBytes && batch.size() < most) {
    SessionWrite w = protocol_.next_write(Clock::now());
    if (!w.frame) break;  // None, Wait or Close
    bytes += w.frame->size();
    batch.push_back(std::move(w));
  }
}

// raw: the channel's own bytes; otherwise protocol frames, in the channel's buffers.
void Session::write(SessionWrite w, bool raw) {
  writing_ = true;
  write_progress_at_ = Clock::now();
  write_progress_ = 0;
  arm_stall_timer();
  // The completion condition runs before each partial write: it notes progress for the stall
  // timer.
  auto progress = [self = this](const std::error_code& ec, std::size_t n) -> std::size_t {
    if (n > self->write_progress_) {
      self->write_progress_ = n;
      self->write_progress_at_ = Clock::now();
    }
    return asio::transfer_all()(ec, n);
  };
  std::vector<SessionWrite> batch;
  batch.push_back(std::move(w));
  std::vector<asio::const_buffer> buffers;
  if (raw) {
    buffers.push_back(asio::buffer(*batch.front().frame));
  } else {
    gather(batch);
    std::vector<std::string_view> frames;
    for (const SessionWrite& b : batch) frames.emplace_back(*b.frame);
    buffers = channel_->frame_buffers(frames);
  }
  asio::async_write(
      stream_, buffers, progress,
      asio::bind_executor(strand_, [self = shared_from_this(), batch = std::move(batch)](
                                       std::error_code ec, std::size_t n) {
        self->writing_ = false;
        if (ec) {
          self->close(CloseReason::Disconnect);
          return;
        }
        ServerCounters& counters = self->server_.context.counters;
        counters.bytes_sent += n;
        for (const SessionWrite& b : batch) {
          // A WebSocket write is one frame, with its header: n.
          const std::size_t size = batch.size() == 1 ? n : b.frame->size();
          if (b.kind == SessionWrite::Kind::Tile) {
            ++counters.tiles_sent;
            counters.tile_bytes_sent += size;
          }
          if (b.kind == SessionWrite::Kind::Scene) counters.scene_bytes_sent += size;
        }
        const bool was_paused = self->read_paused();
        self->pump();
        if (was_paused && !self->read_paused()) self->drain();  // replies written: read on
      }));
}

// Closes the connection. `reason` counts unless the protocol gave one before.
void Session::close(CloseReason reason) {
  if (protocol_.closed()) return;
  idle_timer_.cancel();
  rate_timer_.cancel();
  close_timer_.cancel();
  hello_timer_.cancel();
  penalty_timer_.cancel();
  stall_timer_.cancel();
  stream_.close();
  protocol_.close(reason);
  server_.remove(shared_from_this());
}

}  // namespace irradcast
