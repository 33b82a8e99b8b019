// --tls and --tls-ca, the same in every client tool.
#pragma once

#include <CLI/CLI.hpp>

#include "irradcast/client/client_tls.h"

namespace irradcast::tools {

inline void add_tls_flags(CLI::App& app, ClientTls& tls) {
  app.add_flag("--tls", tls.enabled,
               "connect with TLS (a server started with --tls-cert); the server's certificate "
               "must name the --connect host and chain to a trusted CA");
  app.add_option("--tls-ca", tls.ca_file,
                 "PEM file of the CA that signed the server's certificate (implies --tls; "
                 "default: the system's trusted CAs)")
      ->default_str("system");
}

// --tls-ca alone means TLS.
inline ClientTls tls_of(ClientTls tls) {
  if (!tls.ca_file.empty()) tls.enabled = true;
  return tls;
}

}  // namespace irradcast::tools
