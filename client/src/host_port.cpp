#include "irradcast/client/host_port.h"

#include <stdexcept>

#include "irradcast/common/error.h"

namespace irradcast {

HostPort parse_host_port(const std::string& spec, const std::string& flag) {
  const auto colon = spec.rfind(':');
  if (colon == std::string::npos || colon == 0 || colon + 1 == spec.size())
    throw Error(flag + " must be HOST:PORT, not '" + spec + "'");
  HostPort hp;
  hp.host = spec.substr(0, colon);
  try {
    std::size_t used = 0;
    const int port = std::stoi(spec.substr(colon + 1), &used);
    if (used != spec.size() - colon - 1 || port < 1 || port > 65535)
      throw std::invalid_argument("port");
    hp.port = static_cast<std::uint16_t>(port);
  } catch (const std::exception&) {
    throw Error(flag + ": '" + spec.substr(colon + 1) + "' is not a port number");
  }
  return hp;
}

}  // namespace irradcast
