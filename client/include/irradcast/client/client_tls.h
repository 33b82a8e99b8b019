// How a client reaches the server: plain TCP, or TLS with the server's certificate checked
// against a CA and the host name given in --connect (docs/OPERATIONS.md, "TLS"). Shared by
// irradcast-view, irradcast-load and irradcast-edit.
#pragma once

#include <memory>
#include <string>

#include "irradcast/wire/transport.h"

namespace irradcast {

struct ClientTls {
  bool enabled = false;  // --tls
  std::string ca_file;   // --tls-ca: PEM; empty: the system's trusted CAs
};

// The TLS context of these settings, or null for plain TCP. Throws irradcast::Error for a CA
// file that cannot be read.
std::shared_ptr<asio::ssl::context> make_tls_context(const ClientTls& tls);

}  // namespace irradcast
