// The NATS options irradcast-server (--nats: the origin) and irradcast-gateway share: the URL, and
// who they are to NATS and over what (docs/DISTRIBUTION.md#security). One declared set, added to
// both programs' command lines.
#pragma once

#include "irradcast/common/cli.h"

#include <string>

#include "irradcast/service/nats_credentials.h"

namespace irradcast::tools {

struct NatsOptions {
  std::string url;
  NatsCredentials credentials;

  // Adds --nats (with `url_help`) and the credential and TLS flags.
  void add_to(CLI::App& app, const std::string& url_help) {
    app.add_option("--nats", url, url_help)->default_str("none");
    app.add_option("--nats-user", credentials.user,
                   "the NATS user to connect as (with --nats-password-file)");
    app.add_option("--nats-password-file", credentials.password_file,
                   "the NATS user's password: this file's first line");
    app.add_option("--nats-creds", credentials.creds_file,
                   "a NATS credentials file (user JWT and NKey seed) to connect with");
    app.add_option("--nats-nkey", credentials.nkey_file,
                   "a file holding a NATS user NKey seed (SU...) to connect with");
    app.add_option("--nats-tls-ca", credentials.tls_ca,
                   "trust these CA certificates (PEM) for NATS; implies TLS");
    app.add_option("--nats-tls-cert", credentials.tls_cert,
                   "a client certificate (PEM) for NATS (with --nats-tls-key); implies TLS");
    app.add_option("--nats-tls-key", credentials.tls_key, "the client certificate's key (PEM)");
  }
};

}  // namespace irradcast::tools
