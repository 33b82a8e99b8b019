// HOST:PORT and --connect's failover list (host_port.h).
#include "irradcast/client/host_port.h"

#include <cctype>
#include <stdexcept>

#include "irradcast/common/error.h"
#include "irradcast/common/log.h"

namespace irradcast {

namespace {

// "FLAG: " (nothing for an empty flag: CLI11 names the option itself).
std::string prefix(const std::string& flag) {
  return flag.empty() ? std::string() : flag + ": ";
}

}  // namespace

HostPort parse_host_port(const std::string& spec, const std::string& flag) {
  const auto colon = spec.rfind(':');
  if (colon == std::string::npos || colon == 0 || colon + 1 == spec.size())
    throw Error(prefix(flag) + log::quote(spec, 80) + " is not HOST:PORT");
  HostPort hp;
  hp.host = spec.substr(0, colon);
  // A name or an address: letters, digits, '.', '-', '_', and ':' '%' of IPv6 (a zone).
  for (const char c : hp.host)
    if (!std::isalnum(static_cast<unsigned char>(c)) && c != '.' && c != '-' && c != '_' &&
        c != ':' && c != '%')
      throw Error(prefix(flag) + log::quote(hp.host, 80) + " is not a host name or address");
  try {
    std::size_t used = 0;
    const int port = std::stoi(spec.substr(colon + 1), &used);
    if (used != spec.size() - colon - 1 || port < 1 || port > 65535)
      throw std::invalid_argument("port");
    hp.port = static_cast<std::uint16_t>(port);
  } catch (const std::exception&) {
    throw Error(prefix(flag) + log::quote(spec.substr(colon + 1), 40) + " is not a port number");
  }
  return hp;
}

std::vector<HostPort> parse_host_list(const std::string& spec, const std::string& flag) {
  if (spec.empty()) throw Error(prefix(flag) + "no address (HOST:PORT[,HOST:PORT...])");
  std::vector<HostPort> list;
  std::size_t begin = 0;
  for (;;) {
    const std::size_t comma = spec.find(',', begin);
    const std::string part =
        spec.substr(begin, comma == std::string::npos ? std::string::npos : comma - begin);
    if (list.size() == kMaxServerAddresses)
      throw Error(prefix(flag) + "more than " + std::to_string(kMaxServerAddresses) + " addresses");
    if (part.empty())
      throw Error(prefix(flag) + "address " + std::to_string(list.size() + 1) +
                  " is empty (a list is HOST:PORT,HOST:PORT,... without spaces)");
    list.push_back(parse_host_port(part, flag));
    if (comma == std::string::npos) return list;
    begin = comma + 1;
  }
}

std::vector<HostPort> servers_or(const std::vector<HostPort>& list, const std::string& host,
                                 std::uint16_t port) {
  if (!list.empty()) return list;
  return {HostPort{host, port}};
}

}  // namespace irradcast
