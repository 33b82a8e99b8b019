// HTTP and WebSocket on one connection without I/O: websocketpp's server and client roles over
// its iostream transport, whose "writes" land in a string the caller takes. Built as C++17
// (websocketpp 0.8.2 is not C++20-clean); see websocket.h.
#include "irradcast/wire/websocket.h"

#include <websocketpp/client.hpp>
#include <websocketpp/config/core.hpp>
#include <websocketpp/config/core_client.hpp>
#include <websocketpp/frame.hpp>
#include <websocketpp/server.hpp>

#include <algorithm>

namespace irradcast::wire {

namespace {

namespace ws = websocketpp;

// A protocol error ends the connection at once (no close handshake from the library): the
// caller still sends its own Error message and close frame (WsServerConnection::End).
struct ServerConfig : ws::config::core {
  typedef ServerConfig type;
  static const bool drop_on_protocol_error = true;
  static const bool silent_close = true;  // close reasons do not echo the peer's text
};
using ServerEndpoint = ws::server<ServerConfig>;
using ClientEndpoint = ws::client<ws::config::core_client>;

template <class Endpoint>
void quiet(Endpoint& ep) {
  ep.clear_access_channels(ws::log::alevel::all);
  ep.clear_error_channels(ws::log::elevel::all);
}

// Routes the library's writes into `out`.
template <class Con>
void capture_output(const Con& con, std::string& out) {
  con->set_write_handler([&out](ws::connection_hdl, const char* d, std::size_t n) {
    out.append(d, n);
    return std::error_code();
  });
  con->set_vector_write_handler(
      [&out](ws::connection_hdl, const std::vector<ws::transport::buffer>& bufs) {
        for (const auto& b : bufs) out.append(b.buf, b.len);
        return std::error_code();
      });
}

// Hands bytes to the connection until it takes no more (it stops reading once terminated).
template <class Con>
void feed(const Con& con, const char* data, std::size_t n) {
  while (n > 0) {
    const std::size_t k = con->read_some(data, n);
    if (k == 0) return;
    data += k;
    n -= k;
  }
}

std::string header_of(ws::frame::opcode::value op, std::size_t size) {
  const ws::frame::basic_header h(op, size, true, false);
  const ws::frame::extended_header e(size);
  return ws::frame::prepare_header(h, e);
}

std::string frame_of(ws::frame::opcode::value op, std::string_view payload) {
  std::string out = header_of(op, payload.size());
  out.append(payload.data(), payload.size());
  return out;
}

}  // namespace

// ---- server ----

// Follows the frames a client sends, header by header (RFC 6455 5.2), to tell how many payload
// bytes of an unfinished data message the library holds; it does not check them (the library
// does, and ends the connection on a bad one).
class MessageTracker {
 public:
  // Every byte the peer sends: first its HTTP request (up to the blank line that ends it), then
  // frames.
  void feed(const char* data, std::size_t n) {
    std::size_t i = 0;
    while (!frames_ && i < n) {  // the upgrade request ends at the first blank line
      tail_ = (tail_ << 8) | static_cast<unsigned char>(data[i++]);
      if ((tail_ & 0xffffffffu) == 0x0d0a0d0au) frames_ = true;
    }
    while (i < n) {
      if (payload_left_ > 0) {
        const std::size_t take =
            static_cast<std::size_t>(std::min<std::uint64_t>(payload_left_, n - i));
        if (data_frame_) held_ += take;
        payload_left_ -= take;
        i += take;
        if (payload_left_ == 0) end_frame();
        continue;
      }
      head_[head_size_++] = static_cast<unsigned char>(data[i++]);
      if (head_size_ < 2) continue;
      const unsigned len7 = head_[1] & 0x7f;
      const std::size_t need = 2 +
                               (len7 == 126   ? 2
                                : len7 == 127 ? 8
                                              : 0) +
                               ((head_[1] & 0x80) ? 4 : 0);
      if (head_size_ < need) continue;
      std::uint64_t len = len7;
      if (len7 >= 126) {
        len = 0;
        for (std::size_t k = 2; k < (len7 == 126 ? 4u : 10u); ++k) len = (len << 8) | head_[k];
      }
      fin_ = (head_[0] & 0x80) != 0;
      data_frame_ = (head_[0] & 0x0f) < 0x8;
      head_size_ = 0;
      payload_left_ = len;
      if (len == 0) end_frame();
    }
  }
  std::size_t held() const { return held_; }

 private:
  void end_frame() {
    if (data_frame_ && fin_) held_ = 0;  // the message is complete: delivered and released
  }
  bool frames_ = false;
  std::uint32_t tail_ = 0;
  unsigned char head_[14] = {};
  std::size_t head_size_ = 0;
  std::uint64_t payload_left_ = 0;
  bool fin_ = false, data_frame_ = false;
  std::size_t held_ = 0;
};

struct WsServerConnection::Impl {
  MessageTracker tracker;
  Handlers handlers;
  ServerEndpoint endpoint;
  ServerEndpoint::connection_ptr con;
  std::string out;
  bool open = false, http = false, shut = false;
  End end = End::None;
  std::string end_message;
  std::string refused_origin;  // the Origin of an upgrade refused by allow_origin
  std::string refused;         // the reason of a request refused by the request handler

  // The request handler's answer (Handlers::request), nullopt to go on.
  std::optional<HttpReply> screen() {
    if (!handlers.request) return std::nullopt;
    return handlers.request(
        [this](const std::string& name) { return con->get_request_header(name); });
  }
  void set_reply(const HttpReply& reply) {
    con->set_status(static_cast<ws::http::status_code::value>(reply.status));
    for (const auto& [name, value] : reply.headers) con->replace_header(name, value);
    con->set_body(reply.body);
  }

  void finish(End e, std::string why) {
    if (end != End::None) return;
    end = e;
    end_message = std::move(why);
  }
  void on_http();
  bool on_validate();
  void on_message(ServerEndpoint::message_ptr msg);
  void on_close();
};

void WsServerConnection::Impl::on_http() {
  http = true;
  const std::string& method = con->get_request().get_method();
  const std::string& target = con->get_resource();
  HttpReply reply;
  if (auto refusal = screen()) {
    reply = std::move(*refusal);
  } else if (target == handlers.ws_path && method == "GET") {
    reply.status = 426;
    reply.headers = {{"Content-Type", "text/plain; charset=utf-8"},
                     {"Upgrade", "websocket"},
                     {"Connection", "Upgrade"}};
    reply.body =
        "this is the WebSocket of the irradcast protocol: connect with a WebSocket client\n";
  } else {
    reply = handlers.http(method, target);
  }
  set_reply(reply);
}

bool WsServerConnection::Impl::on_validate() {
  if (con->get_resource() != handlers.ws_path) {
    con->set_status(ws::http::status_code::not_found);
    return false;
  }
  // RFC 6455 only (websocketpp also speaks the drafts, whose framing has no message cap), and no
  // body after the request: the message tracker follows frames from the blank line on.
  const std::string length = con->get_request_header("Content-Length");
  if (con->get_request_header("Sec-WebSocket-Version") != "13" ||
      !con->get_request_header("Transfer-Encoding").empty() || (!length.empty() && length != "0")) {
    con->set_status(ws::http::status_code::bad_request);
    con->set_body("a WebSocket upgrade needs Sec-WebSocket-Version: 13 and no body\n");
    return false;
  }
  if (auto refusal = screen()) {
    refused = refusal->body.substr(0, 200);
    while (!refused.empty() && refused.back() == '\n') refused.pop_back();
    set_reply(*refusal);
    return false;
  }
  const std::string origin = con->get_request_header("Origin");
  if (origin.empty() || !handlers.allow_origin ||
      handlers.allow_origin(origin, con->get_request_header("Host")))
    return true;
  // A page of another site in a visitor's browser: it must not read this server's scene.
  refused_origin = origin.substr(0, 200);
  con->set_status(ws::http::status_code::forbidden);
  con->set_body("a WebSocket from a page of another origin is not allowed here\n");
  return false;
}

void WsServerConnection::Impl::on_message(ServerEndpoint::message_ptr msg) {
  if (end != End::None) return;
  if (msg->get_opcode() != ws::frame::opcode::binary) {
    finish(End::BadMessage,
           "a WebSocket text message: every message is one binary protobuf Envelope");
    return;
  }
  handlers.binary(std::move(msg->get_raw_payload()));
}

void WsServerConnection::Impl::on_close() {
  const std::error_code ec = con->get_ec();
  if (!ec) {
    finish(End::Closed, "the peer closed the WebSocket");
  } else if (ec == ws::processor::error::message_too_big) {
    finish(End::TooLarge, "a WebSocket message above the cap of " +
                              std::to_string(con->get_max_message_size()) + " bytes");
  } else {
    finish(End::BadMessage, "a malformed WebSocket frame: " + ec.message());
  }
}

WsServerConnection::WsServerConnection(Handlers handlers, std::size_t max_message)
    : impl_(std::make_unique<Impl>()) {
  Impl& im = *impl_;
  im.handlers = std::move(handlers);
  quiet(im.endpoint);
  im.endpoint.set_user_agent("irradcast");
  im.endpoint.set_max_message_size(max_message);
  im.endpoint.set_http_handler([&im](ws::connection_hdl) { im.on_http(); });
  im.endpoint.set_validate_handler([&im](ws::connection_hdl) { return im.on_validate(); });
  im.endpoint.set_open_handler([&im](ws::connection_hdl) { im.open = true; });
  im.endpoint.set_message_handler(
      [&im](ws::connection_hdl, ServerEndpoint::message_ptr m) { im.on_message(std::move(m)); });
  im.endpoint.set_close_handler([&im](ws::connection_hdl) { im.on_close(); });
  im.endpoint.set_fail_handler([&im](ws::connection_hdl) {
    if (!im.refused.empty())
      im.finish(End::Handshake, "a WebSocket upgrade refused: " + im.refused);
    else if (!im.refused_origin.empty())
      im.finish(End::Handshake, "a WebSocket upgrade from the page origin '" + im.refused_origin +
                                    "', not this server's (--allowed-origin)");
    else
      im.finish(End::Handshake,
                "not a valid HTTP request or WebSocket upgrade: " + im.con->get_ec().message());
  });
  im.con = im.endpoint.get_connection();
  capture_output(im.con, im.out);
  // The library shuts the transport down before it calls the close or fail handler, which say
  // why; receive() settles an end that no handler named.
  im.con->set_shutdown_handler([&im](ws::connection_hdl) {
    im.shut = true;
    if (im.http) im.finish(End::HttpDone, "HTTP request answered");
    return std::error_code();
  });
  im.con->start();
}

// A connection waiting for bytes holds its own read handler, which holds the connection: ending
// the read (a transport error) breaks that cycle, else every connection would leak. Its handlers
// run now, while the Impl they refer to is still whole.
template <class Con>
void release(const Con& con) {
  con->fatal_error();
}

WsServerConnection::~WsServerConnection() {
  release(impl_->con);
}

void WsServerConnection::receive(const char* data, std::size_t n) {
  if (impl_->end != End::None) return;
  impl_->tracker.feed(data, n);
  feed(impl_->con, data, n);
  if (impl_->shut) impl_->finish(End::Closed, "the connection ended");
}

void WsServerConnection::set_max_message(std::size_t bytes) {
  impl_->con->set_max_message_size(bytes);
}

std::size_t WsServerConnection::partial_message_bytes() const {
  return impl_->end == End::None ? impl_->tracker.held() : 0;
}

bool WsServerConnection::is_open() const {
  return impl_->open && impl_->end == End::None;
}
bool WsServerConnection::upgraded() const {
  return impl_->open;
}
WsServerConnection::End WsServerConnection::end() const {
  return impl_->end;
}
const std::string& WsServerConnection::end_message() const {
  return impl_->end_message;
}

WsCloseCode WsServerConnection::close_code() const {
  switch (impl_->end) {
    case End::TooLarge:
      return WsCloseCode::TooBig;
    case End::BadMessage:
      return WsCloseCode::ProtocolError;
    default:
      return WsCloseCode::Normal;
  }
}

bool WsServerConnection::has_output() const {
  return !impl_->out.empty();
}
std::size_t WsServerConnection::output_size() const {
  return impl_->out.size();
}
std::string WsServerConnection::take_output() {
  return std::exchange(impl_->out, std::string());
}

std::string WsServerConnection::binary_frame(std::string_view payload) {
  return frame_of(ws::frame::opcode::binary, payload);
}

std::string WsServerConnection::binary_frame_header(std::size_t payload_size) {
  return header_of(ws::frame::opcode::binary, payload_size);
}

std::string WsServerConnection::close_frame(WsCloseCode code, std::string_view reason) {
  std::string payload(2, '\0');
  payload[0] = static_cast<char>(static_cast<std::uint16_t>(code) >> 8);
  payload[1] = static_cast<char>(static_cast<std::uint16_t>(code) & 0xff);
  payload.append(reason.substr(0, std::min<std::size_t>(reason.size(), 123)));
  return frame_of(ws::frame::opcode::close, payload);
}

// ---- client ----

struct WsClientConnection::Impl {
  ClientEndpoint endpoint;
  ClientEndpoint::connection_ptr con;
  std::string out, error;
  bool open = false, closed = false;
  std::vector<std::pair<bool, std::string>> messages;
};

WsClientConnection::WsClientConnection(
    const std::string& host, const std::string& target, std::size_t max_message,
    const std::vector<std::pair<std::string, std::string>>& headers)
    : impl_(std::make_unique<Impl>()) {
  Impl& im = *impl_;
  quiet(im.endpoint);
  im.endpoint.set_max_message_size(max_message);
  im.endpoint.set_open_handler([&im](ws::connection_hdl) { im.open = true; });
  im.endpoint.set_message_handler([&im](ws::connection_hdl, ClientEndpoint::message_ptr m) {
    im.messages.emplace_back(m->get_opcode() == ws::frame::opcode::binary,
                             std::move(m->get_raw_payload()));
  });
  im.endpoint.set_close_handler([&im](ws::connection_hdl) {
    im.closed = true;
    if (im.con->get_ec()) im.error = im.con->get_ec().message();
  });
  im.endpoint.set_fail_handler([&im](ws::connection_hdl) {
    im.closed = true;
    im.error = "handshake failed: " + im.con->get_ec().message();
  });
  std::error_code ec;
  im.con = im.endpoint.get_connection("ws://" + host + target, ec);
  if (ec) throw std::runtime_error("WebSocket client: " + ec.message());
  for (const auto& [name, value] : headers) im.con->append_header(name, value);
  capture_output(im.con, im.out);
  im.con->set_shutdown_handler([&im](ws::connection_hdl) {
    im.closed = true;
    return std::error_code();
  });
  im.endpoint.connect(im.con);
}

WsClientConnection::~WsClientConnection() {
  release(impl_->con);
}

void WsClientConnection::receive(const char* data, std::size_t n) {
  if (!impl_->closed) feed(impl_->con, data, n);
}
bool WsClientConnection::is_open() const {
  return impl_->open && !impl_->closed;
}
bool WsClientConnection::closed() const {
  return impl_->closed;
}
std::uint16_t WsClientConnection::remote_close_code() const {
  return impl_->con->get_remote_close_code();
}
const std::string& WsClientConnection::error() const {
  return impl_->error;
}
std::vector<std::pair<bool, std::string>> WsClientConnection::take_messages() {
  return std::exchange(impl_->messages, {});
}

void WsClientConnection::send(std::string_view payload, bool binary) {
  impl_->con->send(payload.data(), payload.size(),
                   binary ? ws::frame::opcode::binary : ws::frame::opcode::text);
}

void WsClientConnection::close(WsCloseCode code, const std::string& reason) {
  std::error_code ec;
  impl_->con->close(static_cast<ws::close::status::value>(code), reason, ec);
}

bool WsClientConnection::has_output() const {
  return !impl_->out.empty();
}
std::string WsClientConnection::take_output() {
  return std::exchange(impl_->out, std::string());
}

}  // namespace irradcast::wire
