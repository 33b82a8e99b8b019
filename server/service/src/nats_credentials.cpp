#include "irradcast/service/nats_credentials.h"

#include <openssl/evp.h>

#include <array>
#include <cstdint>
#include <fstream>
#include <vector>

#include "irradcast/common/error.h"

namespace irradcast {
namespace {

constexpr char kBase32[] = "ABCDEFGHIJKLMNOPQRSTUVWXYZ234567";
constexpr std::uint8_t kPrefixSeed = 18 << 3;  // 'S'
constexpr std::uint8_t kPrefixUser = 20 << 3;  // 'U'

void readable(const std::string& path, const char* flag) {
  if (path.empty()) return;
  std::ifstream f(path);
  if (!f) throw Error(std::string(flag) + ": cannot read '" + path + "'");
}

std::uint16_t crc16(const std::uint8_t* data, std::size_t n) {  // XMODEM, as NKeys use
  std::uint16_t crc = 0;
  for (std::size_t i = 0; i < n; ++i) {
    crc = static_cast<std::uint16_t>(crc ^ (data[i] << 8));
    for (int b = 0; b < 8; ++b)
      crc = static_cast<std::uint16_t>((crc & 0x8000) ? (crc << 1) ^ 0x1021 : crc << 1);
  }
  return crc;
}

std::vector<std::uint8_t> base32_decode(const std::string& text) {
  std::vector<std::uint8_t> out;
  std::uint32_t buffer = 0;
  int bits = 0;
  for (char c : text) {
    int v = -1;
    for (int i = 0; i < 32; ++i)
      if (kBase32[i] == c) v = i;
    if (v < 0) throw Error("not base32");
    buffer = (buffer << 5) | static_cast<std::uint32_t>(v);
    bits += 5;
    if (bits >= 8) {
      bits -= 8;
      out.push_back(static_cast<std::uint8_t>(buffer >> bits));
    }
  }
  return out;
}

std::string base32_encode(const std::vector<std::uint8_t>& data) {
  std::string out;
  std::uint32_t buffer = 0;
  int bits = 0;
  for (std::uint8_t b : data) {
    buffer = (buffer << 8) | b;
    bits += 8;
    while (bits >= 5) {
      bits -= 5;
      out += kBase32[(buffer >> bits) & 31];
    }
  }
  if (bits > 0) out += kBase32[(buffer << (5 - bits)) & 31];
  return out;
}

}  // namespace

bool NatsCredentials::tls(const std::string& url) const {
  return url.rfind("tls://", 0) == 0 || !tls_ca.empty() || !tls_cert.empty() || !tls_key.empty();
}

void NatsCredentials::validate() const {
  if (user.empty() != password_file.empty())
    throw Error("--nats-user and --nats-password-file go together");
  const int kinds =
      (user.empty() ? 0 : 1) + (creds_file.empty() ? 0 : 1) + (nkey_file.empty() ? 0 : 1);
  if (kinds > 1)
    throw Error(
        "give one of --nats-user (with --nats-password-file), --nats-creds and --nats-nkey");
  if (tls_cert.empty() != tls_key.empty())
    throw Error("--nats-tls-cert and --nats-tls-key go together");
  readable(password_file, "--nats-password-file");
  readable(creds_file, "--nats-creds");
  readable(nkey_file, "--nats-nkey");
  readable(tls_ca, "--nats-tls-ca");
  readable(tls_cert, "--nats-tls-cert");
  readable(tls_key, "--nats-tls-key");
}

std::string NatsCredentials::describe(const std::string& url) const {
  std::string d = !user.empty()         ? "user " + user
                  : !creds_file.empty() ? "credentials file " + creds_file
                  : !nkey_file.empty()  ? "NKey seed file " + nkey_file
                                        : "no credentials";
  if (url.find('@') != std::string::npos && user.empty() && creds_file.empty() && nkey_file.empty())
    d = "user info in the URL";
  if (tls(url)) d += ", TLS required";
  return d;
}

std::string redact_nats_url(const std::string& url) {
  std::string out;
  std::size_t start = 0;
  while (start <= url.size()) {
    std::size_t end = url.find(',', start);
    if (end == std::string::npos) end = url.size();
    std::string part = url.substr(start, end - start);
    const std::size_t scheme = part.find("://");
    const std::size_t from = scheme == std::string::npos ? 0 : scheme + 3;
    const std::size_t at = part.rfind('@');
    if (at != std::string::npos && at >= from)
      part = part.substr(0, from) + "***" + part.substr(at);
    out += part;
    if (end == url.size()) break;
    out += ',';
    start = end + 1;
  }
  return out;
}

std::string nkey_public_key(const std::string& seed_text) {
  std::vector<std::uint8_t> raw;
  try {
    raw = base32_decode(seed_text);
  } catch (const Error&) {
    throw Error("--nats-nkey: the seed is not base32");
  }
  if (raw.size() != 36) throw Error("--nats-nkey: the seed has the wrong length");
  const std::uint16_t crc = static_cast<std::uint16_t>(raw[34] | (raw[35] << 8));
  if (crc16(raw.data(), 34) != crc) throw Error("--nats-nkey: the seed's checksum does not match");
  const std::uint8_t prefix =
      static_cast<std::uint8_t>(((raw[0] & 7) << 5) | ((raw[1] & 0xF8) >> 3));
  if ((raw[0] & 0xF8) != kPrefixSeed || prefix != kPrefixUser)
    throw Error("--nats-nkey: not a user NKey seed (it must start with SU)");
  EVP_PKEY* key = EVP_PKEY_new_raw_private_key(EVP_PKEY_ED25519, nullptr, raw.data() + 2, 32);
  if (!key) throw Error("--nats-nkey: the seed is not an Ed25519 key");
  std::array<std::uint8_t, 32> pub{};
  std::size_t len = pub.size();
  const bool ok = EVP_PKEY_get_raw_public_key(key, pub.data(), &len) == 1 && len == pub.size();
  EVP_PKEY_free(key);
  if (!ok) throw Error("--nats-nkey: cannot derive the public key");
  std::vector<std::uint8_t> out = {kPrefixUser};
  out.insert(out.end(), pub.begin(), pub.end());
  const std::uint16_t c = crc16(out.data(), out.size());
  out.push_back(static_cast<std::uint8_t>(c & 0xFF));
  out.push_back(static_cast<std::uint8_t>(c >> 8));
  return base32_encode(out);
}

}  // namespace irradcast
