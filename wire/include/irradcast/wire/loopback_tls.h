// Certificates for TLS on loopback, made at run time (OpenSSL, EC P-256) for the tests and the
// benches that run a TLS server and its clients on one machine: a certificate authority, a server
// certificate for 127.0.0.1 and localhost signed by it, its key, and a second CA that signed
// nothing the server has (a client that trusts only it must fail the handshake). Never for a
// deployment: a server's certificate comes from its operator (--tls-cert, docs/OPERATIONS.md).
#pragma once

#include <string>

namespace irradcast::wire {

// PEM files in one folder: ca.pem (the CA a client trusts), cert.pem and key.pem (the server's),
// other_ca.pem (the CA that signed nothing the server has).
struct LoopbackTlsFiles {
  std::string ca, cert, key, other_ca;
};

// Writes the files into dir (which must exist): the server certificate has serial number
// `serial` and is valid from `from_s` to `until_s` seconds from now (30 days by default).
// Throws std::runtime_error where OpenSSL fails or a file cannot be written.
LoopbackTlsFiles make_loopback_tls_files(const std::string& dir, long serial = 2,
                                         long from_s = -3600, long until_s = 3600L * 24 * 30);

}  // namespace irradcast::wire
