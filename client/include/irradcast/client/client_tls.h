// How a client reaches the server: plain TCP, or TLS with the server's certificate checked
// against a CA and the host name given in --connect (docs/OPERATIONS.md, "TLS"). Shared by
// irradcast-view, irradcast-load and irradcast-edit.
#pragma once

#include <chrono>
#include <memory>
#include <string>
#include <system_error>

#include "irradcast/wire/transport.h"

namespace irradcast {

struct ClientTls {
  bool enabled = false;  // --tls
  std::string ca_file;   // --tls-ca: PEM; empty: the system's trusted CAs
};

// The TLS context of these settings, or null for plain TCP. Throws irradcast::Error for a CA
// file that cannot be read.
std::shared_ptr<asio::ssl::context> make_tls_context(const ClientTls& tls);

// Resolves host, connects `stream` (made on io) and, with TLS, completes the handshake, all
// within `timeout` (a server that accepts but never answers the handshake cannot hang the
// client). On failure: ec, and `what` says it in one line ("connect: Connection refused",
// "TLS: certificate verify failed", ...).
void connect_stream(asio::io_context& io, wire::Stream& stream, const std::string& host,
                    std::uint16_t port, std::chrono::milliseconds timeout, std::error_code& ec,
                    std::string& what);

}  // namespace irradcast
