// The client tools' shared flags and main() (tool_main.h).
#include "tool_main.h"

#include <cstdio>
#include <exception>

#include "irradcast/common/error.h"
#include "irradcast/common/log.h"

namespace irradcast::tools {

void add_connect_flags(CLI::App& app, std::string& connect, ClientTls& tls) {
  app.add_option("--connect", connect,
                 "server address HOST:PORT, or a failover list HOST:PORT,HOST:PORT,... (at most " +
                     std::to_string(kMaxServerAddresses) +
                     ": servers of the same scene, origins or gateways); a refused or lost "
                     "connection moves on to the next, resuming with the tiles held")
      ->required()
      ->check([](const std::string& spec) {
        try {
          parse_host_list(spec, "");  // CLI11 names the option
          return std::string();
        } catch (const Error& e) {
          return std::string(e.what());
        }
      });
  app.add_flag("--tls", tls.enabled,
               "connect with TLS (a server started with --tls-cert); the server's certificate "
               "must name the --connect host and chain to a trusted CA");
  app.add_option("--tls-ca", tls.ca_file,
                 "PEM file of the CA that signed the server's certificate (implies --tls; "
                 "default: the system's trusted CAs)")
      ->default_str("system");
}

ClientTls tls_of(ClientTls tls) {
  if (!tls.ca_file.empty()) tls.enabled = true;
  return tls;
}

wire::TileEncoding parse_encoding(const std::string& name) {
  if (name == "rgb9e5") return wire::TILE_RGB9E5_ZSTD;
  if (name == "half") return wire::TILE_HALF_ZSTD;
  throw Error("--encoding must be rgb9e5 or half, not '" + name + "'");
}

std::vector<HostPort> start_run(const std::string& log_level, const std::string& connect) {
  log::set_level(log::parse_level(log_level));
  return parse_host_list(connect);
}

int parse_and_run(CLI::App& app, int argc, char** argv, const std::function<int()>& run,
                  const std::function<void()>& check) {
  try {
    app.parse(argc, argv);
    if (check) {
      try {
        check();
      } catch (const Error& e) {
        throw CLI::ValidationError(e.what());
      }
    }
  } catch (const CLI::ParseError& e) {
    return app.exit(e);
  }
  const std::string tool = app.get_name();
  try {
    return run();
  } catch (const Error& e) {
    std::fprintf(stderr, "%s: error: %s\n", tool.c_str(), e.what());
    return 1;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "%s: internal error: %s\n", tool.c_str(), e.what());
    return 2;
  }
}

}  // namespace irradcast::tools
