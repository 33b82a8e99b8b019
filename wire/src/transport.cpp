#include "irradcast/wire/transport.h"

#include <openssl/err.h>
#include <openssl/ssl.h>

#include <ctime>
#include <fstream>

#include "irradcast/common/error.h"
#include "irradcast/common/log.h"

namespace irradcast::wire {

namespace {

// OpenSSL's reason for the last failure, for an error message.
std::string openssl_reason(const std::error_code& ec) {
  const unsigned long e = ERR_peek_last_error();
  if (e != 0) {
    const char* reason = ERR_reason_error_string(e);
    ERR_clear_error();
    if (reason) return reason;
  }
  return ec.message();
}

void require_readable(const std::string& file, const char* what) {
  if (file.empty()) throw irradcast::Error(std::string(what) + ": no file given");
  std::ifstream f(file);
  if (!f) throw irradcast::Error(std::string(what) + ": cannot read '" + file + "'");
}

// "2026-12-04 15:10:00 UTC" for an ASN.1 time.
std::string utc_text(const ASN1_TIME* t) {
  std::tm tm{};
  if (!t || ASN1_TIME_to_tm(t, &tm) != 1) return "an unreadable date";
  char out[32];
  std::strftime(out, sizeof out, "%Y-%m-%d %H:%M:%S UTC", &tm);
  return out;
}

// Seconds from now to `t` (negative: in the past).
double seconds_to(const ASN1_TIME* t) {
  int days = 0, secs = 0;
  if (!t || ASN1_TIME_diff(&days, &secs, nullptr, t) != 1) return 0.0;
  return days * 86400.0 + secs;
}

}  // namespace

std::shared_ptr<asio::ssl::context> make_server_tls(const std::string& cert_file,
                                                    const std::string& key_file) {
  require_readable(cert_file, "--tls-cert");
  require_readable(key_file, "--tls-key");
  auto ctx = std::make_shared<asio::ssl::context>(asio::ssl::context::tls_server);
  ctx->set_options(asio::ssl::context::default_workarounds | asio::ssl::context::no_sslv2 |
                   asio::ssl::context::no_sslv3 | asio::ssl::context::no_tlsv1 |
                   asio::ssl::context::no_tlsv1_1 | asio::ssl::context::single_dh_use);
  std::error_code ec;
  ctx->use_certificate_chain_file(cert_file, ec);
  if (ec)
    throw irradcast::Error("--tls-cert: '" + cert_file + "' is not a PEM certificate chain (" +
                openssl_reason(ec) + ")");
  ctx->use_private_key_file(key_file, asio::ssl::context::pem, ec);
  if (ec)
    throw irradcast::Error("--tls-key: '" + key_file + "' is not a PEM private key (" + openssl_reason(ec) +
                ")");
  if (SSL_CTX_check_private_key(ctx->native_handle()) != 1)
    throw irradcast::Error("--tls-key: '" + key_file + "' does not match the certificate in '" + cert_file +
                "'");
  const X509* x = SSL_CTX_get0_certificate(ctx->native_handle());
  if (x && seconds_to(X509_get0_notAfter(x)) <= 0.0)
    throw irradcast::Error("--tls-cert: the certificate in '" + cert_file + "' expired on " +
                utc_text(X509_get0_notAfter(x)) + ": renew it");
  if (x && seconds_to(X509_get0_notBefore(x)) > 0.0)
    throw irradcast::Error("--tls-cert: the certificate in '" + cert_file + "' is not valid before " +
                utc_text(X509_get0_notBefore(x)) + " (is this machine's clock right?)");
  return ctx;
}

CertificateInfo certificate_info(asio::ssl::context& ctx) {
  CertificateInfo info;
  const X509* x = SSL_CTX_get0_certificate(ctx.native_handle());
  if (!x) return info;
  char subject[256] = {};
  X509_NAME_oneline(X509_get_subject_name(x), subject, sizeof subject);
  info.subject = subject;
  info.not_after = utc_text(X509_get0_notAfter(x));
  info.days_left = seconds_to(X509_get0_notAfter(x)) / 86400.0;
  return info;
}

ServerTls::ServerTls(std::string cert_file, std::string key_file, std::string component)
    : cert_file_(std::move(cert_file)),
      key_file_(std::move(key_file)),
      component_(std::move(component)) {
  loaded_.push_back(make_server_tls(cert_file_, key_file_));
  current_ = loaded_.back().get();
  log_loaded(*loaded_.back(), "using");
}

bool ServerTls::reload() {
  std::shared_ptr<asio::ssl::context> next;
  try {
    next = make_server_tls(cert_file_, key_file_);
  } catch (const irradcast::Error& e) {
    log::error(component_,
               std::string("TLS reload refused, keeping the current certificate: ") + e.what());
    return false;
  }
  std::lock_guard lock(mutex_);
  loaded_.push_back(next);
  current_ = next.get();
  log_loaded(*next, "reloaded");
  return true;
}

void ServerTls::log_loaded(asio::ssl::context& ctx, const char* verb) {
  const CertificateInfo info = certificate_info(ctx);
  const std::string line = std::string("TLS: ") + verb + " the certificate " + info.subject +
                           " of '" + cert_file_ + "', valid until " + info.not_after + " (" +
                           std::to_string(static_cast<long>(info.days_left)) + " days)";
  if (info.days_left < kWarnDays)
    log::warn(component_, line + ": it expires in under " +
                              std::to_string(static_cast<int>(kWarnDays)) + " days, renew it");
  else
    log::info(component_, line);
}

std::shared_ptr<asio::ssl::context> make_client_tls(const std::string& ca_file) {
  auto ctx = std::make_shared<asio::ssl::context>(asio::ssl::context::tls_client);
  ctx->set_options(asio::ssl::context::default_workarounds | asio::ssl::context::no_sslv2 |
                   asio::ssl::context::no_sslv3 | asio::ssl::context::no_tlsv1 |
                   asio::ssl::context::no_tlsv1_1);
  std::error_code ec;
  if (ca_file.empty()) {
    ctx->set_default_verify_paths(ec);
    if (ec) throw irradcast::Error("TLS: cannot load the system's trusted CAs (" + openssl_reason(ec) + ")");
  } else {
    require_readable(ca_file, "--tls-ca");
    ctx->load_verify_file(ca_file, ec);
    if (ec)
      throw irradcast::Error("--tls-ca: '" + ca_file + "' is not a PEM certificate (" + openssl_reason(ec) +
                  ")");
  }
  ctx->set_verify_mode(asio::ssl::verify_peer);
  return ctx;
}

void Stream::expect_server_name(const std::string& host) {
  if (!tls_) return;
  // SNI takes DNS names only; an IP address is checked against the certificate all the same.
  asio::error_code not_ip;
  (void)asio::ip::make_address(host, not_ip);
  if (not_ip) SSL_set_tlsext_host_name(tls_->native_handle(), host.c_str());
  tls_->set_verify_mode(asio::ssl::verify_peer);
  tls_->set_verify_callback(asio::ssl::host_name_verification(host));
}

std::string describe_tls_error(const std::error_code& ec) {
  if (ec.category() == asio::error::get_ssl_category()) {
    const unsigned long e = static_cast<unsigned long>(ec.value());
    const char* reason = ERR_reason_error_string(e);
    if (reason) return std::string("TLS: ") + reason;
    return "TLS: " + ec.message();
  }
  if (ec == asio::ssl::error::stream_truncated) return "TLS: the peer closed the connection";
  return ec.message();
}

}  // namespace irradcast::wire
