// The messages a session builds from the server's state (session_protocol.h decides when): the
// Welcome, the parts of a Stats reply, a TileUpdate; and the close reason an Error code means.
#pragma once

#include <cstdint>

#include "irradcast/service/engine_host.h"
#include "irradcast/service/net_server.h"
#include "irradcast/service/tile_store.h"
#include "irradcast/wire/frame.h"

namespace irradcast {

// The reason a session ends after sending an Error frame with this code.
CloseReason reason_of(wire::ErrorCode code);

// The Welcome that answers a Hello: the session, the scene package, the lightmaps and tiles, the
// server's limits.
wire::Envelope welcome_message(const EngineHost& host, const ServerOptions& options,
                               std::uint64_t session, const wire::ScenePackage& package);
// The engine's and the server's parts of a Stats reply.
void add_engine_stats(const EngineHostStats& es, wire::Stats* s);
void add_server_stats(const ServerStats& ss, wire::Stats* s);
// The TileUpdate that carries a snapshot of `tile`.
wire::Envelope tile_update_message(const TileStore::Tile& tile, const TileStore::Snapshot& snap,
                                   wire::TileEncoding encoding);

}  // namespace irradcast
