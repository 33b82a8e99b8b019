// A client's copy of the server's lightmaps: the tile layout the server announced in Welcome,
// checked against the scene package's atlas, one decoded Lightmap per object, and the version
// of every tile it holds. Shared by the viewer (ViewClient) and the simulated users of
// irradcast-load, so both apply TileUpdates, and reject bad ones, the same way.
#pragma once

#include <cstdint>
#include <vector>

#include "irradcast.pb.h"
#include "irradcast/common/atlas.h"
#include "irradcast/common/lightmap.h"

namespace irradcast {

class TileCache {
 public:
  // Takes the layout of `welcome`; throws irradcast::Error when it does not match the atlas.
  // Versions start at 0 (nothing held) and the lightmaps black.
  void configure(const wire::Welcome& welcome, const Atlas& atlas);
  bool configured() const { return !first_tile_.empty(); }

  // Decodes the tile into its lightmap. Returns false for a version older than the one held
  // (nothing changes); throws irradcast::Error for a tile outside the layout or a bad payload.
  bool apply(const wire::TileUpdate& t);

  // Forget every version (a new lineage of versions: anything the server sends is news); the
  // texels stay as they are until replaced.
  void forget_versions();
  // The versions held, as Hello.known entries (tiles never received are left out).
  void add_known(wire::Hello& hello) const;

  std::uint64_t version(std::uint32_t lightmap, std::uint32_t tx, std::uint32_t ty) const;
  const std::vector<std::uint64_t>& versions() const { return versions_; }
  bool all_received() const { return received_ == versions_.size() && !versions_.empty(); }
  std::size_t tiles_received() const { return received_; }
  std::size_t tile_count() const { return versions_.size(); }
  const std::vector<Lightmap>& lightmaps() const { return lightmaps_; }

 private:
  std::uint32_t tile_size_ = 0;
  std::vector<wire::LightmapInfo> infos_;
  std::vector<std::uint32_t> first_tile_;
  std::vector<Lightmap> lightmaps_;
  std::vector<std::uint64_t> versions_;
  std::size_t received_ = 0;  // tiles with a version > 0
};

}  // namespace irradcast
