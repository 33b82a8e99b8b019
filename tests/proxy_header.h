// A PROXY protocol v2 header as HAProxy's send-proxy-v2 writes it (TCP over IPv4 or IPv6), for
// tests of the server behind a trusted proxy.
#pragma once

#include <asio/ip/address.hpp>

#include <cstdint>
#include <string>

namespace irradcast::test {

// The header of a proxied connection from `source`:`port` to the proxy's address, with `tlvs`
// (type-length-value records) after the addresses.
inline std::string proxy_v2(const std::string& source, std::uint16_t port,
                            const std::string& tlvs = {}) {
  const asio::ip::address a = asio::ip::make_address(source);
  std::string addresses;
  if (a.is_v4()) {
    const auto b = a.to_v4().to_bytes();
    addresses.assign(b.begin(), b.end());
    addresses += std::string("\x7f\x00\x00\x01", 4);  // destination 127.0.0.1
  } else {
    const auto b = a.to_v6().to_bytes();
    addresses.assign(b.begin(), b.end());
    addresses.append(15, '\0');  // destination ::1
    addresses += '\x01';
  }
  addresses += static_cast<char>(port >> 8);
  addresses += static_cast<char>(port & 0xff);
  addresses += std::string("\x1c\x52", 2);  // destination port 7250
  const std::size_t length = addresses.size() + tlvs.size();
  std::string h("\r\n\r\n\0\r\nQUIT\n", 12);
  h += '\x21';                       // version 2, PROXY
  h += a.is_v4() ? '\x11' : '\x21';  // TCP over IPv4 or IPv6
  h += static_cast<char>(length >> 8);
  h += static_cast<char>(length & 0xff);
  return h + addresses + tlvs;
}

// A LOCAL header: the proxy's own connection (a health check), no client.
inline std::string proxy_v2_local() {
  std::string h("\r\n\r\n\0\r\nQUIT\n", 12);
  return h + std::string("\x20\x00\x00\x00", 4);
}

}  // namespace irradcast::test
