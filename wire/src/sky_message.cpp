// The sky on the wire (sky_message.h): downsampling for viewers, RGB9E5 + zstd maps, SceneSky.
#include "irradcast/wire/sky_message.h"

#include <zstd.h>

#include <algorithm>
#include <cstdint>
#include <string>
#include <vector>

#include "irradcast/common/error.h"
#include "irradcast/wire/tile_codec.h"

namespace irradcast::wire {

ImageRGB viewer_sky_map(const ImageRGB& map) {
  const int w = std::min(map.width, kMaxViewerSkyWidth);
  const int h = std::min(map.height, kMaxViewerSkyHeight);
  if (w == map.width && h == map.height) return map;
  if (w <= 0 || h <= 0 ||
      map.pixels.size() !=
          static_cast<std::size_t>(map.width) * static_cast<std::size_t>(map.height))
    throw irradcast::Error("sky map: " + std::to_string(map.width) + " x " +
                           std::to_string(map.height) + " with " +
                           std::to_string(map.pixels.size()) + " pixels");
  // Source texel x goes to target texel x * w / map.width (a partition of the source); sums in
  // double, so a 4096-wide row of bright texels keeps its precision.
  std::vector<glm::dvec3> sum(static_cast<std::size_t>(w) * static_cast<std::size_t>(h));
  std::vector<std::uint32_t> count(sum.size(), 0);
  for (int y = 0; y < map.height; ++y) {
    const std::size_t ty = static_cast<std::size_t>(static_cast<std::int64_t>(y) * h / map.height);
    for (int x = 0; x < map.width; ++x) {
      const std::size_t tx = static_cast<std::size_t>(static_cast<std::int64_t>(x) * w / map.width);
      sum[ty * static_cast<std::size_t>(w) + tx] += glm::dvec3(map.at(x, y));
      ++count[ty * static_cast<std::size_t>(w) + tx];
    }
  }
  ImageRGB out(w, h);
  for (std::size_t i = 0; i < sum.size(); ++i)
    out.pixels[i] = glm::vec3(sum[i] / static_cast<double>(std::max<std::uint32_t>(count[i], 1)));
  return out;
}

void sky_map_to_proto(const ImageRGB& map, SkyMap* out) {
  const ImageRGB small = viewer_sky_map(map);
  std::string raw(small.pixels.size() * 4, '\0');
  for (std::size_t i = 0; i < small.pixels.size(); ++i) {
    const std::uint32_t v = pack_rgb9e5(small.pixels[i]);
    for (int b = 0; b < 4; ++b)
      raw[4 * i + static_cast<std::size_t>(b)] = static_cast<char>(v >> (8 * b));
  }
  std::string z(ZSTD_compressBound(raw.size()), '\0');
  const std::size_t n = ZSTD_compress(z.data(), z.size(), raw.data(), raw.size(), kZstdLevel);
  if (ZSTD_isError(n))
    throw irradcast::Error(std::string("sky map: zstd: ") + ZSTD_getErrorName(n));
  z.resize(n);
  out->set_width(static_cast<std::uint32_t>(small.width));
  out->set_height(static_cast<std::uint32_t>(small.height));
  out->set_data(std::move(z));
}

ImageRGB sky_map_from_proto(const SkyMap& m, const std::string& what) {
  if (m.width() == 0 || m.height() == 0 ||
      m.width() > static_cast<std::uint32_t>(kMaxViewerSkyWidth) ||
      m.height() > static_cast<std::uint32_t>(kMaxViewerSkyHeight))
    throw irradcast::Error(what + ": the sky map is " + std::to_string(m.width()) + " x " +
                           std::to_string(m.height()) + " (1 x 1 to " +
                           std::to_string(kMaxViewerSkyWidth) + " x " +
                           std::to_string(kMaxViewerSkyHeight) + " expected)");
  const std::size_t texels = static_cast<std::size_t>(m.width()) * m.height();
  const unsigned long long size = ZSTD_getFrameContentSize(m.data().data(), m.data().size());
  if (size != texels * 4)
    throw irradcast::Error(what + ": the sky map's data is not zstd of " +
                           std::to_string(texels * 4) + " bytes (" + std::to_string(m.width()) +
                           " x " + std::to_string(m.height()) + " RGB9E5 texels)");
  std::string raw(texels * 4, '\0');
  const std::size_t n = ZSTD_decompress(raw.data(), raw.size(), m.data().data(), m.data().size());
  if (ZSTD_isError(n) || n != raw.size())
    throw irradcast::Error(what + ": the sky map's data is corrupt (zstd: " +
                           (ZSTD_isError(n) ? ZSTD_getErrorName(n) : "short") + ")");
  ImageRGB map(static_cast<int>(m.width()), static_cast<int>(m.height()));
  for (std::size_t i = 0; i < texels; ++i) {
    std::uint32_t v = 0;
    for (int b = 0; b < 4; ++b)
      v |= static_cast<std::uint32_t>(
               static_cast<unsigned char>(raw[4 * i + static_cast<std::size_t>(b)]))
           << (8 * b);
    map.pixels[i] = unpack_rgb9e5(v);
  }
  return map;
}

bool is_default_sky(const Sky& sky) {
  return sky.color == glm::vec3(0.0f) && sky.strength == 1.0f && sky.map.width == 0 &&
         sky.map.height == 0 && sky.map.pixels.empty() && sky.source.empty();
}

void sky_to_proto(const Sky& sky, SceneSky* out) {
  out->mutable_color()->set_x(sky.color.x);
  out->mutable_color()->set_y(sky.color.y);
  out->mutable_color()->set_z(sky.color.z);
  out->set_strength(sky.strength);
  out->set_source(sky.source);
  if (sky.map.width > 0 || sky.map.height > 0 || !sky.map.pixels.empty())
    sky_map_to_proto(sky.map, out->mutable_map());
}

Sky sky_from_proto(const SceneSky& m, const std::string& what) {
  Sky sky;
  sky.color = glm::vec3(m.color().x(), m.color().y(), m.color().z());
  sky.strength = m.strength();
  sky.source = m.source();
  if (m.has_map()) sky.map = sky_map_from_proto(m.map(), what);
  validate_sky(sky, what);
  return sky;
}

}  // namespace irradcast::wire
