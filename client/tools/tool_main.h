// What the client tools (irradcast-view, irradcast-load, irradcast-edit) share: the flags every
// one of them has (--connect with its failover list, --tls, --tls-ca), the tile encoding flag,
// the start of a run (log level, server addresses) and main()'s command-line parsing and error
// reporting.
#pragma once

#include "irradcast/common/cli.h"

#include <functional>
#include <string>
#include <vector>

#include "irradcast.pb.h"
#include "irradcast/client/client_tls.h"
#include "irradcast/client/host_port.h"

namespace irradcast::tools {

// --connect HOST:PORT[,HOST:PORT...] (required; checked when parsed), --tls and --tls-ca.
void add_connect_flags(CLI::App& app, std::string& connect, ClientTls& tls);

// --tls-ca alone means TLS.
ClientTls tls_of(ClientTls tls);

// "rgb9e5" or "half" (--encoding); throws irradcast::Error for anything else.
wire::TileEncoding parse_encoding(const std::string& name);

// The start of a run: sets the log level (--log-level) and parses --connect's list.
std::vector<HostPort> start_run(const std::string& log_level, const std::string& connect);

// main(): parses the command line (a bad one: CLI11's message and exit code), calls `check`
// (an irradcast::Error from it is reported as a bad command line), then returns run()'s exit
// status. An irradcast::Error from run() prints "<tool>: error: <what>" and exits 1, any other
// exception "<tool>: internal error: <what>" and exits 2.
int parse_and_run(CLI::App& app, int argc, char** argv, const std::function<int()>& run,
                  const std::function<void()>& check = {});

}  // namespace irradcast::tools
