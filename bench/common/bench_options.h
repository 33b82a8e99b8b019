// The options the benches share, spelled and explained as the tools spell them (irradcast-bake and
// irradcast-server: server/tools/engine_options.h). One place, so that a density is always
// --texels-per-scene (texels across the scene's largest extent) and a metric one always
// --texels-per-metre.
#pragma once

#include "irradcast/common/cli.h"

#include <string>

namespace irradcast::bench {

// The atlas density: lightmap texels across the scene's largest extent.
inline CLI::Option* add_texels_per_scene(CLI::App& app, float& texels,
                                         const std::string& more = "") {
  return app.add_option("--texels-per-scene", texels,
                        "lightmap texels across the scene's largest extent (the atlas density, as "
                        "irradcast-bake's and irradcast-server's)" +
                            (more.empty() ? std::string() : "; " + more));
}

// A density in lightmap texels per metre (the same for every scene size).
inline CLI::Option* add_texels_per_metre(CLI::App& app, float& texels, const std::string& what) {
  return app.add_option("--texels-per-metre", texels, "lightmap texels per metre " + what);
}

// Worker threads of the engine and the benches' loops.
inline CLI::Option* add_threads(CLI::App& app, int& threads) {
  return app.add_option("--threads", threads, "worker threads (0 = all cores)");
}

}  // namespace irradcast::bench
