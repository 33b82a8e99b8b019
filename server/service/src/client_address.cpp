// Trusted proxies, forwarded-for headers and the PROXY protocol v2 header.
#include "client_address.h"

#include <algorithm>
#include <cctype>
#include <cstring>

#include "irradcast/common/error.h"

namespace irradcast {

namespace {

using Bytes = std::array<std::uint8_t, 16>;

// IPv4 as IPv4-mapped IPv6, so one comparison serves both.
Bytes mapped_bytes(const asio::ip::address& a) {
  if (a.is_v6()) return a.to_v6().to_bytes();
  Bytes b{};
  b[10] = b[11] = 0xff;
  const auto v4 = a.to_v4().to_bytes();
  std::copy(v4.begin(), v4.end(), b.begin() + 12);
  return b;
}

bool same_prefix(const Bytes& a, const Bytes& b, unsigned prefix) {
  const unsigned whole = prefix / 8, bits = prefix % 8;
  if (std::memcmp(a.data(), b.data(), whole) != 0) return false;
  if (bits == 0) return true;
  const auto mask = static_cast<std::uint8_t>(0xff << (8 - bits));
  return (a[whole] & mask) == (b[whole] & mask);
}

std::string_view trim(std::string_view s) {
  while (!s.empty() && (s.front() == ' ' || s.front() == '\t')) s.remove_prefix(1);
  while (!s.empty() && (s.back() == ' ' || s.back() == '\t')) s.remove_suffix(1);
  return s;
}

std::optional<asio::ip::address> parse_address(std::string_view text) {
  std::error_code ec;
  const asio::ip::address a = asio::ip::make_address(std::string(text), ec);
  if (ec) return std::nullopt;
  return a;
}

bool all_digits(std::string_view s) {
  return !s.empty() && s.size() <= 5 &&
         std::all_of(s.begin(), s.end(), [](char c) { return c >= '0' && c <= '9'; });
}

// The `for=` parameter of a Forwarded element (RFC 7239), or "" (a hop that names no address).
std::string_view for_parameter(std::string_view element) {
  std::string_view found;
  while (!element.empty()) {
    const std::size_t semicolon = element.find(';');
    const std::string_view pair = trim(element.substr(0, semicolon));
    element =
        semicolon == std::string_view::npos ? std::string_view() : element.substr(semicolon + 1);
    if (pair.size() > 4 && std::tolower(static_cast<unsigned char>(pair[0])) == 'f' &&
        std::tolower(static_cast<unsigned char>(pair[1])) == 'o' &&
        std::tolower(static_cast<unsigned char>(pair[2])) == 'r' && pair[3] == '=')
      found = pair.substr(4);
  }
  return found;
}

// The hops of a header, nearest first, split from the right: X-Forwarded-For at every comma,
// Forwarded at the commas outside quoted strings (the quotes counted from the right, so that an
// unbalanced quote a client wrote on the left cannot swallow the elements its proxies appended).
std::vector<std::string_view> hops_of(std::string_view value, ForwardedHeader header) {
  std::vector<std::string_view> hops;
  std::size_t end = value.size();
  bool quoted = false;
  for (std::size_t i = value.size(); i-- > 0;) {
    if (header == ForwardedHeader::Forwarded && value[i] == '"') quoted = !quoted;
    if (value[i] != ',' || quoted) continue;
    hops.push_back(trim(value.substr(i + 1, end - i - 1)));
    end = i;
  }
  hops.push_back(trim(value.substr(0, end)));
  if (header == ForwardedHeader::Forwarded)
    for (std::string_view& h : hops) h = for_parameter(h);
  return hops;
}

}  // namespace

std::string peer_key_of(const asio::ip::address& address) {
  asio::ip::address a = address;
  if (a.is_v6() && a.to_v6().is_v4_mapped())
    a = asio::ip::make_address_v4(asio::ip::v4_mapped, a.to_v6());
  if (a.is_v4()) return a.to_string();
  asio::ip::address_v6::bytes_type b = a.to_v6().to_bytes();
  std::fill(b.begin() + 8, b.end(), 0);
  return asio::ip::address_v6(b).to_string() + "/64";
}

TrustedProxies::TrustedProxies(const std::vector<std::string>& cidrs) {
  for (const std::string& entry : cidrs) {
    const std::string text(trim(entry));
    if (text.empty()) continue;
    const std::size_t slash = text.find('/');
    const auto address = parse_address(std::string_view(text).substr(0, slash));
    if (!address)
      throw Error("--trusted-proxy '" + entry +
                  "': not an IPv4 or IPv6 address or network (like 10.0.0.0/8 or fd00::/8)");
    const unsigned width = address->is_v4() ? 32 : 128;
    unsigned prefix = width;
    if (slash != std::string::npos) {
      const std::string_view bits = std::string_view(text).substr(slash + 1);
      if (!all_digits(bits) || std::stoul(std::string(bits)) > width)
        throw Error("--trusted-proxy '" + entry + "': the prefix length must be 0 to " +
                    std::to_string(width));
      prefix = static_cast<unsigned>(std::stoul(std::string(bits)));
    }
    Net net{mapped_bytes(*address), prefix + (address->is_v4() ? 96 : 0)};
    Bytes masked = net.bytes;
    for (unsigned bit = net.prefix; bit < 128; ++bit)
      masked[bit / 8] &= static_cast<std::uint8_t>(~(0x80 >> (bit % 8)));
    if (masked != net.bytes)
      throw Error("--trusted-proxy '" + entry +
                  "': the address has bits set past the prefix length (a network is written "
                  "with its first address)");
    nets_.push_back(net);
  }
}

bool TrustedProxies::contains(const asio::ip::address& address) const {
  const Bytes b = mapped_bytes(address);
  return std::any_of(nets_.begin(), nets_.end(),
                     [&](const Net& n) { return same_prefix(b, n.bytes, n.prefix); });
}

std::optional<asio::ip::address> parse_forwarded_address(std::string_view text) {
  text = trim(text);
  if (text.size() >= 2 && text.front() == '"' && text.back() == '"')
    text = text.substr(1, text.size() - 2);
  if (text.empty() || text.size() > 64) return std::nullopt;
  if (text.front() == '[') {  // [v6] or [v6]:port
    const std::size_t close = text.find(']');
    if (close == std::string_view::npos) return std::nullopt;
    const std::string_view after = text.substr(close + 1);
    if (!after.empty() && (after.front() != ':' || !all_digits(after.substr(1))))
      return std::nullopt;
    const auto a = parse_address(text.substr(1, close - 1));
    return a && a->is_v6() ? a : std::nullopt;
  }
  const std::size_t colon = text.find(':');
  if (colon != std::string_view::npos && text.find(':', colon + 1) == std::string_view::npos) {
    // v4:port
    if (!all_digits(text.substr(colon + 1))) return std::nullopt;
    const auto a = parse_address(text.substr(0, colon));
    return a && a->is_v4() ? a : std::nullopt;
  }
  return parse_address(text);
}

ForwardedClient forwarded_client(std::string_view header_value, ForwardedHeader header,
                                 const TrustedProxies& trusted) {
  ForwardedClient out;
  if (trim(header_value).empty()) return out;
  for (const std::string_view hop : hops_of(header_value, header)) {
    const auto a = parse_forwarded_address(hop);
    if (!a) {
      out.kind = ForwardedClient::Kind::Unknown;
      return out;
    }
    if (!trusted.contains(*a)) {
      out.kind = ForwardedClient::Kind::Client;
      out.address = *a;
      return out;
    }
  }
  return out;
}

ProxyHeaderReader::State ProxyHeaderReader::feed(const char* data, std::size_t n) {
  if (state_ != State::More) return state_;
  bytes_.append(data, n);
  state_ = parse();
  return state_;
}

ProxyHeaderReader::State ProxyHeaderReader::parse() {
  static constexpr char kSignature[12] = {'\r', '\n', '\r', '\n', '\0', '\r',
                                          '\n', 'Q',  'U',  'I',  'T',  '\n'};
  const std::size_t have = std::min(bytes_.size(), sizeof kSignature);
  if (std::memcmp(bytes_.data(), kSignature, have) != 0) {
    rest_ = std::move(bytes_);
    return State::None;
  }
  if (bytes_.size() < 16) return State::More;
  const auto byte = [&](std::size_t i) { return static_cast<std::uint8_t>(bytes_[i]); };
  const unsigned version = byte(12) >> 4, command = byte(12) & 0x0f;
  const std::size_t length = (std::size_t(byte(14)) << 8) | byte(15);
  if (version != 2) {
    error_ = "a PROXY protocol header of version " + std::to_string(version) + " (only 2 is read)";
    return State::Bad;
  }
  if (command > 1) {
    error_ = "a PROXY protocol header with the unknown command " + std::to_string(command);
    return State::Bad;
  }
  if (16 + length > kMaxHeaderBytes) {
    error_ = "a PROXY protocol header of " + std::to_string(16 + length) + " bytes (at most " +
             std::to_string(kMaxHeaderBytes) + ")";
    return State::Bad;
  }
  if (bytes_.size() < 16 + length) return State::More;
  const unsigned family = byte(13) >> 4, transport = byte(13) & 0x0f;
  if (family > 3 || transport > 2 || (family != 0) != (transport != 0)) {
    error_ = "a PROXY protocol header with the unknown address family " + std::to_string(byte(13));
    return State::Bad;
  }
  const std::size_t need = family == 1 ? 12 : family == 2 ? 36 : family == 3 ? 216 : 0;
  if (length < need) {
    error_ = "a PROXY protocol header whose addresses are cut short (" + std::to_string(length) +
             " bytes, " + std::to_string(need) + " needed)";
    return State::Bad;
  }
  if (command == 1 && family == 1) {
    asio::ip::address_v4::bytes_type b;
    std::memcpy(b.data(), bytes_.data() + 16, 4);
    source_ = asio::ip::address_v4(b);
  } else if (command == 1 && family == 2) {
    asio::ip::address_v6::bytes_type b;
    std::memcpy(b.data(), bytes_.data() + 16, 16);
    source_ = asio::ip::address_v6(b);
  }
  rest_ = bytes_.substr(16 + length);
  bytes_.clear();
  return State::Done;
}

}  // namespace irradcast
