// The tile store: the server's published irradiance, cut into tiles with versions. The engine
// thread publishes its lightmaps after every update; a tile gets a new version only when it
// changed beyond a threshold since its last version, and its payload is encoded once for all
// clients. Sessions read snapshots (version, time stamp, payload) concurrently.
#pragma once

#include <cstdint>
#include <memory>
#include <mutex>
#include <shared_mutex>
#include <string>
#include <vector>

#include "irradcast/common/lightmap.h"
#include "irradcast/wire/tile_codec.h"

namespace irradcast {

struct TileStoreOptions {
  int tile_size = 32;              // texels per tile edge
  float change_threshold = 0.01f;  // RMS change / mean level that earns a tile a new version
  float floor_fraction = 1e-3f;    // of the map's mean luminance, below which changes are noise
  // With noise information (see TileStore::Noise): a tile whose change is within Monte Carlo
  // noise gets a new version only once its sample count grew by a factor R^(1+h), h in [0, 1)
  // spread over the tiles (so versions do not come in bursts); a change beyond `significance`
  // times the expected noise of the change (a real change, e.g. a scene edit) at once.
  float refresh_ratio = 2.0f;
  float significance = 2.0f;
};

class TileStore {
 public:
  struct Tile {
    std::uint32_t lightmap = 0;
    std::uint32_t tx = 0, ty = 0;
    wire::TileRect rect{0, 0, 0, 0};
  };
  struct Snapshot {
    std::uint64_t version = 0;  // 0: not published yet
    std::uint64_t time_us = 0;  // when the engine computed this version (system clock)
    std::shared_ptr<const std::string> payload;
  };

  // One lightmap per (width, height). Throws irradcast::Error on a bad tile size.
  TileStore(const std::vector<std::pair<int, int>>& sizes, TileStoreOptions options = {});

  // What the engine knows of its own noise: the samples per texel so far and the standard error
  // of each texel's mean (Engine::standard_error(); null before the engine has one, e.g. after
  // its first update: the versions then record their samples, and any change counts).
  struct Noise {
    std::uint64_t samples = 0;
    const std::vector<Lightmap>* standard_error = nullptr;
  };

  // Engine thread: gives every tile that changed beyond the threshold (all of them the first
  // time) a new version and encodes it; with `noise`, changes within the noise wait for the
  // refresh ratio (see TileStoreOptions). Returns the global indices of those tiles.
  std::vector<std::uint32_t> publish(const std::vector<Lightmap>& maps, std::uint64_t time_us,
                                     const Noise* noise = nullptr);

  // A gateway's store (nats_gateway.h): installs a version that another tile store published,
  // from its RGB9E5 payload, when it is newer than the version held (or always, with `force`:
  // the origin started a new lineage). The payload is decoded (the half-float encoding is made
  // from the decoded texels). Throws irradcast::Error on a bad index or a payload that does not
  // decode to the tile (nothing changes). Returns whether it was installed. One thread.
  bool install(std::uint32_t index, std::uint64_t version, std::uint64_t time_us,
               std::shared_ptr<const std::string> rgb9e5, bool force = false);

  std::size_t tile_count() const { return tiles_.size(); }
  const Tile& tile(std::uint32_t index) const { return tiles_[index]; }
  std::size_t lightmap_count() const { return sizes_.size(); }
  std::pair<int, int> lightmap_size(std::uint32_t lightmap) const { return sizes_[lightmap]; }
  int tiles_x(std::uint32_t lightmap) const;
  int tiles_y(std::uint32_t lightmap) const;
  // Global index of tile (tx, ty) of a lightmap; -1 when out of range.
  std::int64_t index(std::uint32_t lightmap, std::uint32_t tx, std::uint32_t ty) const;
  // Global indices [first, last) of a lightmap's tiles.
  std::pair<std::uint32_t, std::uint32_t> tiles_of(std::uint32_t lightmap) const;
  const TileStoreOptions& options() const { return options_; }

  std::uint64_t version(std::uint32_t index) const;
  // The newest version of a tile in an encoding (RGB9E5 or HALF; others throw irradcast::Error).
  Snapshot snapshot(std::uint32_t index, wire::TileEncoding encoding) const;
  // The published values (what the newest versions hold, before encoding).
  std::vector<Lightmap> published() const;
  std::uint64_t publishes() const;
  // Mean encoded bytes per texel of the newest RGB9E5 versions (0 before the first publish).
  double bytes_per_texel() const;

 private:
  struct State {
    std::uint64_t version = 0;
    std::uint64_t time_us = 0;
    std::uint64_t samples = 0;  // the engine's samples per texel at this version (0: unknown)
    std::shared_ptr<const std::string> rgb9e5;
    mutable std::shared_ptr<const std::string> half;  // encoded on first request
  };
  bool changed_enough(std::size_t i, const std::vector<Lightmap>& maps, float floor,
                      const Noise* noise) const;

  TileStoreOptions options_;
  std::vector<std::pair<int, int>> sizes_;
  std::vector<std::uint32_t> first_tile_;  // per lightmap, plus the total at the end
  std::vector<Tile> tiles_;
  mutable std::shared_mutex mutex_;
  mutable std::mutex half_mutex_;
  std::vector<State> state_;
  std::vector<Lightmap> published_;
  std::uint64_t publishes_ = 0;
  std::uint64_t payload_bytes_ = 0;  // sum of the newest RGB9E5 payload sizes
};

}  // namespace irradcast
