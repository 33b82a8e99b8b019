// "HOST:PORT" from the command line (the last colon splits, so "::1:7450" works too).
#pragma once

#include <cstdint>
#include <string>

namespace irradcast {

struct HostPort {
  std::string host;
  std::uint16_t port = 0;
};

// Throws irradcast::Error naming `flag` when the spec is not HOST:PORT with a port in 1..65535.
HostPort parse_host_port(const std::string& spec, const std::string& flag = "--connect");

}  // namespace irradcast
