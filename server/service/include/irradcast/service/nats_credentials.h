// How the origin and the gateways prove who they are to NATS, and how they reach it privately
// (docs/DISTRIBUTION.md#security): NATS's own mechanisms, not a scheme of ours. One of a user and
// password (the password read from a file), a credentials file (JWT and NKey seed, as `nsc`
// writes it) or an NKey seed file; and TLS, required whenever the URL is tls:// or a TLS file is
// given (a server that does not negotiate TLS is refused, never used in clear). User info in a URL
// (nats://user:pass@host) works too but is never logged: redact_nats_url.
#pragma once

#include <string>

namespace irradcast {

struct NatsCredentials {
  std::string user;           // --nats-user, with password_file
  std::string password_file;  // --nats-password-file: the first line is the password
  std::string creds_file;     // --nats-creds: a .creds file (user JWT + NKey seed)
  std::string nkey_file;      // --nats-nkey: a file holding a user NKey seed ("SU...")
  std::string tls_ca;         // --nats-tls-ca: trust these CA certificates (PEM)
  std::string tls_cert;       // --nats-tls-cert, --nats-tls-key: a client certificate
  std::string tls_key;

  // Whether the connection must be TLS for `url` (tls://, or any TLS file given).
  bool tls(const std::string& url) const;
  // Throws irradcast::Error on a combination that cannot work: a user without a password file
  // or the reverse, more than one of user / creds / nkey, a certificate without its key or the
  // reverse, or a file that cannot be read.
  void validate() const;
  // "user irradcast-origin", "credentials file F", "NKey seed file F" or "no credentials", and
  // ", TLS" when TLS is required: for the log line of the connection (no secrets).
  std::string describe(const std::string& url) const;
};

// `url` with the user info of every server in it (comma-separated list) replaced by "***":
// "nats://user:secret@host:4222" -> "nats://***@host:4222".
std::string redact_nats_url(const std::string& url);

// The public key ("U...") of a user NKey seed ("SU..."), both in NATS's base32 form. Throws
// irradcast::Error on a seed that is not a valid user seed (bad base32, prefix or checksum).
std::string nkey_public_key(const std::string& seed);

}  // namespace irradcast
