#include "irradcast/service/tile_store.h"

#include <tbb/parallel_for.h>

#include <cmath>

#include "irradcast/common/error.h"

namespace irradcast {

TileStore::TileStore(const std::vector<std::pair<int, int>>& sizes, TileStoreOptions options)
    : options_(options), sizes_(sizes) {
  if (options_.tile_size < 1 || options_.tile_size > 4096)
    throw Error("tile size must be in 1..4096, not " + std::to_string(options_.tile_size));
  if (!(options_.change_threshold >= 0.0f)) throw Error("tile change threshold must be >= 0");
  if (!(options_.refresh_ratio >= 1.0f))
    throw Error("tile refresh ratio must be >= 1, not " + std::to_string(options_.refresh_ratio));
  if (!(options_.significance >= 0.0f)) throw Error("tile significance must be >= 0");
  for (std::uint32_t m = 0; m < sizes_.size(); ++m) {
    first_tile_.push_back(static_cast<std::uint32_t>(tiles_.size()));
    const auto [w, h] = sizes_[m];
    const int nx = wire::tiles_along(w, options_.tile_size);
    const int ny = wire::tiles_along(h, options_.tile_size);
    for (int ty = 0; ty < ny; ++ty)
      for (int tx = 0; tx < nx; ++tx)
        tiles_.push_back({m, static_cast<std::uint32_t>(tx), static_cast<std::uint32_t>(ty),
                          wire::tile_rect(w, h, options_.tile_size, tx, ty)});
    published_.emplace_back(w, h);
  }
  first_tile_.push_back(static_cast<std::uint32_t>(tiles_.size()));
  state_.resize(tiles_.size());
}

int TileStore::tiles_x(std::uint32_t lightmap) const {
  return wire::tiles_along(sizes_.at(lightmap).first, options_.tile_size);
}

int TileStore::tiles_y(std::uint32_t lightmap) const {
  return wire::tiles_along(sizes_.at(lightmap).second, options_.tile_size);
}

std::int64_t TileStore::index(std::uint32_t lightmap, std::uint32_t tx, std::uint32_t ty) const {
  if (lightmap >= sizes_.size()) return -1;
  const auto nx = static_cast<std::uint32_t>(tiles_x(lightmap));
  const auto ny = static_cast<std::uint32_t>(tiles_y(lightmap));
  if (tx >= nx || ty >= ny) return -1;
  return first_tile_[lightmap] + ty * nx + tx;
}

std::pair<std::uint32_t, std::uint32_t> TileStore::tiles_of(std::uint32_t lightmap) const {
  return {first_tile_.at(lightmap), first_tile_.at(lightmap + 1)};
}

namespace {

double luminance(glm::vec3 v) {
  return 0.2126 * v.x + 0.7152 * v.y + 0.0722 * v.z;
}

// h in [0, 1) per tile, evenly spread (golden-ratio sequence).
double tile_jitter(std::size_t i) {
  const double x = static_cast<double>(i) * 0.6180339887498949;
  return x - std::floor(x);
}

}  // namespace

bool TileStore::changed_enough(std::size_t i, const std::vector<Lightmap>& maps, float floor,
                               const Noise* noise) const {
  const Tile& t = tiles_[i];
  const State& s = state_[i];
  if (s.version == 0) return true;
  // Below the threshold nothing is worth sending, noise or not.
  if (!wire::tile_changed(maps[t.lightmap], published_[t.lightmap], t.rect,
                          options_.change_threshold, floor))
    return false;
  if (!noise || !noise->standard_error || noise->standard_error->size() != maps.size() ||
      s.samples == 0 || noise->samples <= s.samples)
    return true;
  // Enough new samples: the client's copy is noticeably noisier than ours.
  const double growth = static_cast<double>(noise->samples) / static_cast<double>(s.samples);
  const double ratio = std::pow(static_cast<double>(options_.refresh_ratio), 1.0 + tile_jitter(i));
  if (growth >= ratio) return true;
  // Otherwise only a change beyond the noise. For nested running means the change since the
  // version with n0 samples has a variance of se(n)^2 (n / n0 - 1), with se(n) the standard
  // error now; RMS over the tile, in luminance.
  const Lightmap& now = maps[t.lightmap];
  const Lightmap& sent = published_[t.lightmap];
  const Lightmap& se = (*noise->standard_error)[t.lightmap];
  if (se.width != now.width || se.height != now.height) return true;
  double change2 = 0.0, noise2 = 0.0;
  for (int y = t.rect.y0; y < t.rect.y0 + t.rect.h; ++y)
    for (int x = t.rect.x0; x < t.rect.x0 + t.rect.w; ++x) {
      const std::size_t k = static_cast<std::size_t>(y) * now.width + x;
      const double d = luminance(now.texels[k]) - luminance(sent.texels[k]);
      change2 += d * d;
      noise2 += static_cast<double>(se.texels[k].x) * se.texels[k].x;
    }
  const double expected2 = noise2 * (growth - 1.0);
  const double z = options_.significance;
  return change2 > z * z * expected2;
}

std::vector<std::uint32_t> TileStore::publish(const std::vector<Lightmap>& maps,
                                              std::uint64_t time_us, const Noise* noise) {
  if (maps.size() != sizes_.size())
    throw Error("tile store: " + std::to_string(maps.size()) + " lightmaps published, expected " +
                std::to_string(sizes_.size()));
  for (std::size_t m = 0; m < maps.size(); ++m)
    if (maps[m].width != sizes_[m].first || maps[m].height != sizes_[m].second)
      throw Error("tile store: lightmap " + std::to_string(m) + " changed size");
  std::vector<float> floors(maps.size());
  for (std::size_t m = 0; m < maps.size(); ++m)
    floors[m] = wire::change_floor(maps[m], options_.floor_fraction);

  // Decide and encode outside the lock (only this thread writes published_ and state_).
  std::vector<std::uint8_t> changed(tiles_.size(), 0);
  std::vector<std::shared_ptr<const std::string>> encoded(tiles_.size());
  tbb::parallel_for(std::size_t(0), tiles_.size(), [&](std::size_t i) {
    const Tile& t = tiles_[i];
    if (!changed_enough(i, maps, floors[t.lightmap], noise)) return;
    changed[i] = 1;
    encoded[i] = std::make_shared<const std::string>(
        wire::encode_tile(maps[t.lightmap], t.rect, wire::TILE_RGB9E5_ZSTD));
  });
  std::vector<std::uint32_t> out;
  std::unique_lock lock(mutex_);
  for (std::size_t i = 0; i < tiles_.size(); ++i) {
    if (!changed[i]) continue;
    const Tile& t = tiles_[i];
    Lightmap& dst = published_[t.lightmap];
    const Lightmap& src = maps[t.lightmap];
    for (int y = t.rect.y0; y < t.rect.y0 + t.rect.h; ++y)
      for (int x = t.rect.x0; x < t.rect.x0 + t.rect.w; ++x) {
        const std::size_t k = static_cast<std::size_t>(y) * dst.width + x;
        dst.texels[k] = src.texels[k];
      }
    State& s = state_[i];
    if (s.rgb9e5) payload_bytes_ -= s.rgb9e5->size();
    payload_bytes_ += encoded[i]->size();
    ++s.version;
    s.time_us = time_us;
    s.samples = noise ? noise->samples : 0;
    s.rgb9e5 = std::move(encoded[i]);
    {
      std::lock_guard half_lock(half_mutex_);
      s.half.reset();
    }
    out.push_back(static_cast<std::uint32_t>(i));
  }
  ++publishes_;
  return out;
}

bool TileStore::install(std::uint32_t index, std::uint64_t version, std::uint64_t time_us,
                        std::shared_ptr<const std::string> rgb9e5, bool force) {
  if (index >= tiles_.size())
    throw Error("tile store: there is no tile " + std::to_string(index) + " (the store has " +
                std::to_string(tiles_.size()) + ")");
  if (version == 0 || !rgb9e5) throw Error("tile store: version 0 or no payload installed");
  if (!force && version <= this->version(index)) return false;
  const Tile& t = tiles_[index];
  Lightmap decoded(t.rect.w, t.rect.h);
  wire::decode_tile(*rgb9e5, wire::TILE_RGB9E5_ZSTD, {0, 0, t.rect.w, t.rect.h}, decoded);
  std::unique_lock lock(mutex_);
  Lightmap& dst = published_[t.lightmap];
  for (int y = 0; y < t.rect.h; ++y)
    for (int x = 0; x < t.rect.w; ++x)
      dst.texels[static_cast<std::size_t>(t.rect.y0 + y) * dst.width + t.rect.x0 + x] =
          decoded.texels[static_cast<std::size_t>(y) * t.rect.w + x];
  State& s = state_[index];
  if (s.rgb9e5) payload_bytes_ -= s.rgb9e5->size();
  payload_bytes_ += rgb9e5->size();
  s.version = version;
  s.time_us = time_us;
  s.rgb9e5 = std::move(rgb9e5);
  {
    std::lock_guard half_lock(half_mutex_);
    s.half.reset();
  }
  if (publishes_ == 0) publishes_ = 1;  // bytes_per_texel counts from here
  return true;
}

std::uint64_t TileStore::version(std::uint32_t index) const {
  std::shared_lock lock(mutex_);
  return state_.at(index).version;
}

TileStore::Snapshot TileStore::snapshot(std::uint32_t index, wire::TileEncoding encoding) const {
  std::shared_lock lock(mutex_);
  const State& s = state_.at(index);
  Snapshot snap{s.version, s.time_us, nullptr};
  if (s.version == 0) return snap;
  if (encoding == wire::TILE_RGB9E5_ZSTD) {
    snap.payload = s.rgb9e5;
  } else if (encoding == wire::TILE_HALF_ZSTD) {
    std::lock_guard half_lock(half_mutex_);
    if (!s.half) {
      const Tile& t = tiles_[index];
      s.half = std::make_shared<const std::string>(
          wire::encode_tile(published_[t.lightmap], t.rect, wire::TILE_HALF_ZSTD));
    }
    snap.payload = s.half;
  } else {
    throw Error("tile store: encoding " + std::to_string(static_cast<int>(encoding)) +
                " is not served");
  }
  return snap;
}

std::vector<Lightmap> TileStore::published() const {
  std::shared_lock lock(mutex_);
  return published_;
}

std::uint64_t TileStore::publishes() const {
  std::shared_lock lock(mutex_);
  return publishes_;
}

double TileStore::bytes_per_texel() const {
  std::shared_lock lock(mutex_);
  if (publishes_ == 0) return 0.0;
  std::uint64_t texels = 0;
  for (const auto& [w, h] : sizes_) texels += static_cast<std::uint64_t>(w) * h;
  return texels ? static_cast<double>(payload_bytes_) / static_cast<double>(texels) : 0.0;
}

}  // namespace irradcast
