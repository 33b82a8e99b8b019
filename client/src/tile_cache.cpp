#include "irradcast/client/tile_cache.h"

#include <algorithm>
#include <string>

#include "irradcast/common/error.h"
#include "irradcast/wire/tile_codec.h"

namespace irradcast {

void TileCache::configure(const wire::Welcome& w, const Atlas& atlas, std::size_t added) {
  if (added > atlas.objects.size() ||
      static_cast<std::size_t>(w.lightmaps_size()) != atlas.objects.size() - added)
    throw Error("the server announces " + std::to_string(w.lightmaps_size()) +
                " lightmaps, the scene package has " +
                std::to_string(atlas.objects.size() - std::min(added, atlas.objects.size())));
  for (std::size_t m = atlas.objects.size() - added; m < atlas.objects.size(); ++m)
    if (atlas.objects[m].width != 0 || atlas.objects[m].height != 0)
      throw Error("an object the client added has a lightmap layout");
  if (w.tile_size() == 0) throw Error("the server announces a tile size of 0");
  const int ts = static_cast<int>(w.tile_size());
  std::vector<wire::LightmapInfo> infos(w.lightmaps().begin(), w.lightmaps().end());
  std::vector<std::uint32_t> first;
  std::vector<Lightmap> maps;
  std::uint32_t total = 0;
  for (std::size_t m = 0; m < infos.size(); ++m) {
    const wire::LightmapInfo& li = infos[m];
    const ObjectLightmap& o = atlas.objects[m];
    if (static_cast<int>(li.width()) != o.width || static_cast<int>(li.height()) != o.height ||
        static_cast<int>(li.tiles_x()) != wire::tiles_along(o.width, ts) ||
        static_cast<int>(li.tiles_y()) != wire::tiles_along(o.height, ts))
      throw Error("lightmap " + std::to_string(m) +
                  ": the server's layout does not match the scene");
    first.push_back(total);
    total += li.tiles_x() * li.tiles_y();
    if (shared_texels_ == SharedTexels::Copy) maps.emplace_back(o.width, o.height);
  }
  first.push_back(total);
  if (shared_texels_ == SharedTexels::Copy) maps.resize(atlas.objects.size());  // added: empty
  tile_size_ = w.tile_size();
  infos_ = std::move(infos);
  first_tile_ = std::move(first);
  lightmaps_ = std::move(maps);
  versions_.assign(total, 0);
  held_.assign(shared_texels_ == SharedTexels::Reference ? total : 0, nullptr);
  received_ = 0;
}

void TileCache::share_decodes(std::shared_ptr<TileDecodeCache> shared, SharedTexels texels) {
  if (configured()) throw Error("share_decodes() after configure()");
  if (texels == SharedTexels::Reference && !shared)
    throw Error("a tile cache that holds references needs a shared decode cache");
  shared_ = std::move(shared);
  shared_texels_ = texels;
}

const std::vector<Lightmap>& TileCache::lightmaps() const {
  if (shared_texels_ == SharedTexels::Reference)
    throw Error("this tile cache holds references to shared decodes, not lightmaps");
  return lightmaps_;
}

std::uint32_t TileCache::tile_index(std::uint32_t lightmap, std::uint32_t tx,
                                    std::uint32_t ty) const {
  return first_tile_[lightmap] + ty * infos_[lightmap].tiles_x() + tx;
}

std::vector<glm::vec3> TileCache::tile_texels(std::uint32_t lightmap, std::uint32_t tx,
                                              std::uint32_t ty) const {
  if (version(lightmap, tx, ty) == 0) return {};
  const std::uint32_t index = tile_index(lightmap, tx, ty);
  if (shared_texels_ == SharedTexels::Reference) return held_[index]->texels;
  const wire::LightmapInfo& li = infos_[lightmap];
  const wire::TileRect r =
      wire::tile_rect(static_cast<int>(li.width()), static_cast<int>(li.height()),
                      static_cast<int>(tile_size_), static_cast<int>(tx), static_cast<int>(ty));
  const Lightmap& map = lightmaps_[lightmap];
  std::vector<glm::vec3> out(static_cast<std::size_t>(r.w) * static_cast<std::size_t>(r.h));
  for (int y = 0; y < r.h; ++y)
    std::copy_n(map.texels.begin() + static_cast<std::ptrdiff_t>(r.y0 + y) * map.width + r.x0, r.w,
                out.begin() + static_cast<std::ptrdiff_t>(y) * r.w);
  return out;
}

bool TileCache::apply(const wire::TileUpdate& t) {
  if (!configured()) throw Error("a tile arrived before the scene");
  if (t.lightmap() >= infos_.size())
    throw Error("tile for unknown lightmap " + std::to_string(t.lightmap()));
  const wire::LightmapInfo& li = infos_[t.lightmap()];
  if (t.tile_x() >= li.tiles_x() || t.tile_y() >= li.tiles_y())
    throw Error("tile " + std::to_string(t.tile_x()) + "," + std::to_string(t.tile_y()) +
                " is outside lightmap " + std::to_string(t.lightmap()));
  const wire::TileRect r = wire::tile_rect(
      static_cast<int>(li.width()), static_cast<int>(li.height()), static_cast<int>(tile_size_),
      static_cast<int>(t.tile_x()), static_cast<int>(t.tile_y()));
  if (static_cast<int>(t.width()) != r.w || static_cast<int>(t.height()) != r.h)
    throw Error("tile size does not match the layout");
  const std::uint32_t index = tile_index(t.lightmap(), t.tile_x(), t.tile_y());
  if (t.version() <= versions_[index]) return false;  // stale (this server never sends one)
  decode(t, r, index);
  if (versions_[index] == 0) ++received_;
  versions_[index] = t.version();
  return true;
}

// Decodes into the tile's lightmap, or takes what the shared cache decoded from the same
// bytes (a copy, or a reference). A payload that does not decode throws here, and is never
// stored.
void TileCache::decode(const wire::TileUpdate& t, const wire::TileRect& r, std::uint32_t index) {
  if (!shared_ || t.encoding() == wire::TILE_RGB9E5_DELTA_ZSTD) {
    if (shared_texels_ == SharedTexels::Reference)
      throw Error("a delta tile needs the client's own texels (this cache holds references)");
    wire::decode_tile(t.payload(), t.encoding(), r, lightmaps_[t.lightmap()]);
    return;
  }
  const TileDecodeCache::Key key{t.lightmap(), t.tile_x(), t.tile_y(),
                                 static_cast<int>(t.encoding())};
  std::shared_ptr<const TileDecodeCache::Decoded> found =
      shared_->find(key, t.version(), t.payload());
  if (!found) {
    // Decode into a map of the tile's own size, then share it.
    Lightmap own(r.w, r.h);
    wire::decode_tile(t.payload(), t.encoding(), wire::TileRect{0, 0, r.w, r.h}, own);
    auto decoded = std::make_shared<TileDecodeCache::Decoded>();
    decoded->version = t.version();
    decoded->payload = t.payload();
    decoded->texels = std::move(own.texels);
    found = decoded;
    shared_->store(key, std::move(decoded));
  }
  if (shared_texels_ == SharedTexels::Reference) {
    held_[index] = std::move(found);
    return;
  }
  Lightmap& map = lightmaps_[t.lightmap()];
  for (int y = 0; y < r.h; ++y)
    std::copy_n(found->texels.begin() + static_cast<std::ptrdiff_t>(y) * r.w, r.w,
                map.texels.begin() + static_cast<std::ptrdiff_t>(r.y0 + y) * map.width + r.x0);
}

std::shared_ptr<const TileDecodeCache::Decoded> TileDecodeCache::find(
    const Key& key, std::uint64_t version, const std::string& payload) const {
  std::shared_ptr<const Decoded> e;
  {
    std::lock_guard lock(mutex_);
    const auto it = entries_.find(key);
    if (it == entries_.end()) return nullptr;
    e = it->second;
  }
  // Immutable once stored: compared outside the lock.
  if (e->version != version || e->payload != payload) return nullptr;
  std::lock_guard lock(mutex_);
  ++hits_;
  return e;
}

void TileDecodeCache::store(const Key& key, std::shared_ptr<const Decoded> decoded) {
  std::lock_guard lock(mutex_);
  std::shared_ptr<const Decoded>& e = entries_[key];
  if (e && e->version > decoded->version) return;  // a newer one is held (users not in step)
  e = std::move(decoded);
}

std::uint64_t TileDecodeCache::hits() const {
  std::lock_guard lock(mutex_);
  return hits_;
}

void TileCache::forget_versions() {
  std::fill(versions_.begin(), versions_.end(), 0);
  received_ = 0;
}

void TileCache::add_known(wire::Hello& h) const {
  for (std::uint32_t m = 0; m < infos_.size(); ++m)
    for (std::uint32_t ty = 0; ty < infos_[m].tiles_y(); ++ty)
      for (std::uint32_t tx = 0; tx < infos_[m].tiles_x(); ++tx) {
        const std::uint64_t v = versions_[first_tile_[m] + ty * infos_[m].tiles_x() + tx];
        if (v == 0) continue;
        wire::TileVersion* k = h.add_known();
        k->set_lightmap(m);
        k->set_tile_x(tx);
        k->set_tile_y(ty);
        k->set_version(v);
      }
}

std::uint64_t TileCache::version(std::uint32_t lightmap, std::uint32_t tx, std::uint32_t ty) const {
  if (lightmap >= infos_.size() || tx >= infos_[lightmap].tiles_x() ||
      ty >= infos_[lightmap].tiles_y())
    return 0;
  return versions_[tile_index(lightmap, tx, ty)];
}

}  // namespace irradcast
