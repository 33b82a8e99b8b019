// "HOST:PORT" from the command line (the last colon splits, so "::1:7450" works too), and the
// failover list "HOST:PORT[,HOST:PORT...]" of --connect: the servers (origins or gateways of the
// same scene) a client tries in turn when a connection is refused or lost.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace irradcast {

struct HostPort {
  std::string host;
  std::uint16_t port = 0;
  std::string text() const { return host + ":" + std::to_string(port); }
};

// The most addresses a --connect list may name.
inline constexpr std::size_t kMaxServerAddresses = 16;

// Throws irradcast::Error (its message starts "FLAG: " unless `flag` is empty) when the spec is not
// HOST:PORT with a port in 1..65535.
HostPort parse_host_port(const std::string& spec, const std::string& flag = "--connect");

// A comma-separated list of HOST:PORT (1..kMaxServerAddresses of them, each as parse_host_port
// wants). Throws irradcast::Error naming `flag` for an empty list or part, a bad address, or too
// many; `flag` as in parse_host_port.
std::vector<HostPort> parse_host_list(const std::string& spec,
                                      const std::string& flag = "--connect");

// `list` when it names any address, else the one address {host, port} (the options' default).
std::vector<HostPort> servers_or(const std::vector<HostPort>& list, const std::string& host,
                                 std::uint16_t port);

}  // namespace irradcast
