// Lightmap tiles and their wire encodings (TileUpdate.payload). A lightmap of width x height
// texels is cut into tiles of tile_size x tile_size texels (edge tiles smaller); tile (tx, ty)
// has index ty * tiles_x + tx. docs/PROTOCOL.md ("Tile encodings") specifies the byte layout.
//
//   TILE_RGB9E5_ZSTD        GL_EXT_texture_shared_exponent texels (32 bits), spatially predicted.
//   TILE_HALF_ZSTD          IEEE binary16 per channel (48 bits), spatially predicted.
//   TILE_RGB9E5_DELTA_ZSTD  RGB9E5 predicted from the client's copy of an earlier version.
// Residuals against the prediction are decorrelated across channels, stored as byte planes and
// compressed with zstd (level 3, with the frame checksum). Texel values are first sanitised: NaN
// and negatives become 0, values above the format's maximum (65408 for RGB9E5, 65504 for half)
// are clamped to it.
#pragma once

#include <cstdint>
#include <string>

#include <glm/glm.hpp>

#include "irradcast.pb.h"
#include "irradcast/common/lightmap.h"

namespace irradcast::wire {

struct TileRect {
  int x0, y0, w, h;
};

int tiles_along(int extent, int tile_size);
// Throws irradcast::Error if the tile is outside the lightmap or tile_size < 1.
TileRect tile_rect(int width, int height, int tile_size, int tx, int ty);

constexpr int kZstdLevel = 3;

// Encodes the texels of one tile (RGB9E5 or HALF; DELTA needs encode_tile_delta). Throws
// irradcast::Error on bad arguments (rect outside the map, map size inconsistent, unknown
// encoding).
std::string encode_tile(const Lightmap& map, const TileRect& r, TileEncoding enc);

// TILE_RGB9E5_DELTA_ZSTD: the tile of `now` relative to `base`, which must hold exactly what the
// client holds at r (the decoded texels of the base version, e.g. kept with quantize_tile()).
std::string encode_tile_delta(const Lightmap& now, const Lightmap& base, const TileRect& r);

// Decodes into map's texels at r (map must be large enough). For DELTA, map's texels at r must
// hold the base version; they are replaced by the new version. Throws irradcast::Error on a
// corrupt or short payload, a size mismatch or a rect outside the map; never reads or writes out
// of bounds, and leaves the map unchanged when it throws.
void decode_tile(const std::string& payload, TileEncoding enc, const TileRect& r, Lightmap& map);

// Replaces map's texels at r by what a client decodes from encode_tile(map, r, enc) (DELTA
// quantises like RGB9E5). The server keeps such a copy per sent tile for deltas.
void quantize_tile(Lightmap& map, const TileRect& r, TileEncoding enc);

// The per-texel formats, exposed for tests and tools.
std::uint32_t pack_rgb9e5(glm::vec3 v);
glm::vec3 unpack_rgb9e5(std::uint32_t packed);
glm::vec3 quantize_half(glm::vec3 v);
constexpr float kRgb9e5Max = 65408.0f;
constexpr float kHalfMax = 65504.0f;

// Error bounds, for a sanitised texel v with largest component m, decoded as d:
//   RGB9E5: |d_c - v_c| <= rgb9e5_max_relative_error() * m + tile_absolute_error_floor()
//   HALF:   |d_c - v_c| <= half_max_relative_error() * v_c + tile_absolute_error_floor()
float rgb9e5_max_relative_error();  // 1 / 511.5 (2^-9, a little more when the exponent rounds up)
float half_max_relative_error();    // 2^-11
float tile_absolute_error_floor();  // 2^-25 (the smallest steps of both formats, halved)

// Decides whether a tile changed enough to send a new version: true if the RMS over the tile's
// texels and channels of (now - sent) exceeds threshold * (the tile's mean sent value + floor).
// An RMS, not a maximum: a progressive engine changes every texel a little after every update.
// Values are sanitised as the encoder does first. Throws irradcast::Error if the maps differ in
// size or r is outside them.
bool tile_changed(const Lightmap& now, const Lightmap& sent, const TileRect& r, float threshold,
                  float floor);
// A floor for tile_changed(): `fraction` of the mean luminance of the map (0 for an empty map).
float change_floor(const Lightmap& map, float fraction = 1e-3f);

}  // namespace irradcast::wire
