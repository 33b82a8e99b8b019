// A client's copy of the server's lightmaps: the tile layout the server announced in Welcome,
// checked against the scene package's atlas, one decoded Lightmap per object, and the version
// of every tile it holds. Shared by the viewer (ViewClient) and the simulated users of
// irradcast-load, so both apply TileUpdates, and reject bad ones, the same way.
// TileDecodeCache: the decoded texels of byte-identical payloads, shared by many TileCaches of
// one process (irradcast-load's users: one decode per tile version, not one per user).
#pragma once

#include <cstdint>
#include <memory>
#include <mutex>
#include <string>
#include <unordered_map>
#include <vector>

#include "irradcast.pb.h"
#include "irradcast/common/atlas.h"
#include "irradcast/common/lightmap.h"
#include "irradcast/wire/tile_codec.h"

namespace irradcast {

// The newest decoded version of each tile (RGB9E5 and half; a delta depends on the client's
// base and is never shared), keyed by tile and checked against the whole payload: a TileCache
// that finds the same bytes takes the texels instead of decoding them. Bounded by one entry
// per tile and encoding of the scene. Any thread (one mutex around the map; an entry is
// immutable once stored, so a TileCache may keep a reference to it).
class TileDecodeCache {
 public:
  struct Key {
    std::uint32_t lightmap = 0, tx = 0, ty = 0;
    int encoding = 0;
    bool operator==(const Key&) const = default;
  };
  struct Decoded {
    std::uint64_t version = 0;
    std::string payload;
    std::vector<glm::vec3> texels;  // w x h, row by row
  };
  // The decode of `payload` if these bytes were decoded before (null otherwise).
  std::shared_ptr<const Decoded> find(const Key& key, std::uint64_t version,
                                      const std::string& payload) const;
  void store(const Key& key, std::shared_ptr<const Decoded> decoded);
  std::uint64_t hits() const;

 private:
  struct KeyHash {
    std::size_t operator()(const Key& k) const {
      return ((static_cast<std::size_t>(k.lightmap) * 1000003u + k.tx) * 1000003u + k.ty) * 4u +
             static_cast<std::size_t>(k.encoding);
    }
  };
  mutable std::mutex mutex_;
  std::unordered_map<Key, std::shared_ptr<const Decoded>, KeyHash> entries_;
  mutable std::uint64_t hits_ = 0;
};

// How a TileCache that shares decodes holds the texels it applies.
enum class SharedTexels {
  Copy,       // copied into its own lightmaps (a viewer, a user that composes frames)
  Reference,  // a reference to the shared decode, no lightmaps (irradcast-load's thin users:
              // N users' copies of the same texels would measure this machine's memory
              // bandwidth, not the server; every tile is still parsed, checked and compared)
};

class TileCache {
 public:
  // Decode through `shared` (null: every tile decoded here). Before configure().
  void share_decodes(std::shared_ptr<TileDecodeCache> shared,
                     SharedTexels texels = SharedTexels::Copy);

  // Takes the layout of `welcome`; throws irradcast::Error when it does not match the atlas.
  // Versions start at 0 (nothing held) and the lightmaps black.
  // `added`: objects the client added to the scene after the package's (avatars, avatars.h), at
  // the end of the atlas with empty layouts; their lightmaps stay empty.
  void configure(const wire::Welcome& welcome, const Atlas& atlas, std::size_t added = 0);
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
  // The decoded lightmaps; throws irradcast::Error for a cache that holds references only
  // (SharedTexels::Reference).
  const std::vector<Lightmap>& lightmaps() const;
  // The texels of one tile held (w x h of its rectangle, row by row), whichever way they are
  // held; empty for a tile never received.
  std::vector<glm::vec3> tile_texels(std::uint32_t lightmap, std::uint32_t tx,
                                     std::uint32_t ty) const;

 private:
  std::uint32_t tile_size_ = 0;
  std::vector<wire::LightmapInfo> infos_;
  std::vector<std::uint32_t> first_tile_;
  std::vector<Lightmap> lightmaps_;
  std::vector<std::uint64_t> versions_;
  std::size_t received_ = 0;  // tiles with a version > 0
  std::shared_ptr<TileDecodeCache> shared_;
  SharedTexels shared_texels_ = SharedTexels::Copy;
  std::vector<std::shared_ptr<const TileDecodeCache::Decoded>> held_;  // Reference: per tile
  std::uint32_t tile_index(std::uint32_t lightmap, std::uint32_t tx, std::uint32_t ty) const;
  void decode(const wire::TileUpdate& t, const wire::TileRect& r, std::uint32_t index);
};

}  // namespace irradcast
