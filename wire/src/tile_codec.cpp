#include "irradcast/wire/tile_codec.h"

#include <zstd.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <memory>
#include <vector>

#include <glm/gtc/packing.hpp>

#include "irradcast/common/error.h"

namespace irradcast::wire {
namespace {

// NaN and negatives -> 0, values above `max` (including +inf) -> max.
float sanitize(float v, float max) {
  return v > 0.0f ? (v < max ? v : max) : 0.0f;
}

void check_map(const Lightmap& map, const char* what) {
  if (map.width < 0 || map.height < 0 ||
      map.texels.size() !=
          static_cast<std::size_t>(map.width) * static_cast<std::size_t>(map.height))
    throw irradcast::Error(std::string("tile codec: the ") + what + " lightmap's texels (" +
                           std::to_string(map.texels.size()) + ") do not match its size " +
                           std::to_string(map.width) + " x " + std::to_string(map.height));
}

void check_rect(const Lightmap& map, const TileRect& r, const char* what) {
  check_map(map, what);
  if (r.w <= 0 || r.h <= 0 || r.x0 < 0 || r.y0 < 0 || r.x0 > map.width - r.w ||
      r.y0 > map.height - r.h)
    throw irradcast::Error("tile codec: tile (" + std::to_string(r.x0) + ", " +
                           std::to_string(r.y0) + ") " + std::to_string(r.w) + " x " +
                           std::to_string(r.h) + " is not inside the " + what + " lightmap of " +
                           std::to_string(map.width) + " x " + std::to_string(map.height));
}

std::size_t texel_index(const Lightmap& map, const TileRect& r, int i, int j) {
  return static_cast<std::size_t>(r.y0 + j) * static_cast<std::size_t>(map.width) +
         static_cast<std::size_t>(r.x0 + i);
}

// Leading one-byte planes of the raw layout (RGB9E5: the exponent plane); throws on an unknown
// encoding.
int lead_planes(TileEncoding enc) {
  switch (enc) {
    case TILE_RGB9E5_ZSTD:
    case TILE_RGB9E5_DELTA_ZSTD:
      return 1;
    case TILE_HALF_ZSTD:
      return 0;
    default:
      throw irradcast::Error("tile codec: unknown tile encoding " +
                             std::to_string(static_cast<int>(enc)));
  }
}

struct CCtxFree {
  void operator()(ZSTD_CCtx* c) const { ZSTD_freeCCtx(c); }
};
struct DCtxFree {
  void operator()(ZSTD_DCtx* c) const { ZSTD_freeDCtx(c); }
};

std::string compress(const std::vector<std::uint8_t>& raw) {
  // One context per thread, configured once: level 3, content size and checksum in the frame
  // header (4 bytes that let the decoder reject a damaged payload instead of decoding garbage).
  thread_local std::unique_ptr<ZSTD_CCtx, CCtxFree> ctx = [] {
    std::unique_ptr<ZSTD_CCtx, CCtxFree> c(ZSTD_createCCtx());
    if (c) {
      ZSTD_CCtx_setParameter(c.get(), ZSTD_c_compressionLevel, kZstdLevel);
      ZSTD_CCtx_setParameter(c.get(), ZSTD_c_checksumFlag, 1);
    }
    return c;
  }();
  if (!ctx) throw irradcast::Error("tile codec: out of memory (zstd)");
  std::string out(ZSTD_compressBound(raw.size()), '\0');
  const std::size_t n = ZSTD_compress2(ctx.get(), out.data(), out.size(), raw.data(), raw.size());
  if (ZSTD_isError(n))
    throw irradcast::Error(std::string("tile codec: zstd: ") + ZSTD_getErrorName(n));
  out.resize(n);
  out.shrink_to_fit();  // the store keeps it: without the bound's room (about 4 bytes a texel)
  return out;
}

// Decompresses exactly `expected` bytes; anything else is a corrupt payload.
std::vector<std::uint8_t> decompress(const std::string& payload, std::size_t expected) {
  thread_local std::unique_ptr<ZSTD_DCtx, DCtxFree> ctx(ZSTD_createDCtx());
  if (!ctx) throw irradcast::Error("tile codec: out of memory (zstd)");
  const unsigned long long declared = ZSTD_getFrameContentSize(payload.data(), payload.size());
  if (declared == ZSTD_CONTENTSIZE_ERROR)
    throw irradcast::Error("tile payload is corrupt: not a zstd frame (" +
                           std::to_string(payload.size()) + " bytes)");
  if (declared != ZSTD_CONTENTSIZE_UNKNOWN && declared != expected)
    throw irradcast::Error("tile payload holds " + std::to_string(declared) + " bytes, expected " +
                           std::to_string(expected) + " for the tile's size");
  std::vector<std::uint8_t> raw(expected);
  const std::size_t n =
      ZSTD_decompressDCtx(ctx.get(), raw.data(), raw.size(), payload.data(), payload.size());
  if (ZSTD_isError(n))
    throw irradcast::Error(std::string("tile payload is corrupt: zstd: ") + ZSTD_getErrorName(n));
  if (n != expected)
    throw irradcast::Error("tile payload holds " + std::to_string(n) + " bytes, expected " +
                           std::to_string(expected) + " for the tile's size");
  return raw;
}

std::uint16_t pack_half(float v) {
  return glm::packHalf1x16(sanitize(v, kHalfMax));
}

// --- Residual coding (docs/PROTOCOL.md, "Tile encodings") --------------------------------------
// Texels are coded in row-major order as residuals against a prediction that the decoder can
// form from what it already has: the texels to the left and above (spatial), or the client's copy
// of the base version (delta). The residuals of the three channels are decorrelated (R-G, G, B-G:
// lightmaps are mostly grey-ish, so the channels' noise is correlated), zigzag-mapped to 16 bits
// and stored as byte planes (all low bytes, then all high bytes), which zstd compresses well.

std::uint16_t zigzag(int d) {
  const int v = static_cast<std::int16_t>(static_cast<std::uint16_t>(d & 0xFFFF));
  return static_cast<std::uint16_t>(((v * 2) ^ (v >> 15)) & 0xFFFF);
}
int unzigzag(std::uint16_t z) {
  return static_cast<int>(z >> 1) ^ -static_cast<int>(z & 1);
}

// The residual planes of one tile: `lead` planes of one byte, then 3 channels x 2 byte planes.
class Planes {
 public:
  Planes(std::size_t n, int lead) : n_(n), lead_(lead), raw_(n * (lead + 6)) {}
  Planes(std::size_t n, int lead, std::vector<std::uint8_t> raw)
      : n_(n), lead_(lead), raw_(std::move(raw)) {}
  static std::size_t size(std::size_t n, int lead) {
    return n * static_cast<std::size_t>(lead + 6);
  }

  void put_lead(std::size_t i, int v) { raw_[i] = static_cast<std::uint8_t>(v & 0xFF); }
  int lead(std::size_t i) const { return raw_[i]; }
  // Channel residuals r (mod 2^16) stored as zigzag(R-G), zigzag(G), zigzag(B-G).
  void put_residuals(std::size_t i, const int r[3]) {
    const std::uint16_t z[3] = {zigzag(r[0] - r[1]), zigzag(r[1]), zigzag(r[2] - r[1])};
    for (int c = 0; c < 3; ++c) {
      raw_[plane(2 * c) + i] = static_cast<std::uint8_t>(z[c] & 0xFF);
      raw_[plane(2 * c + 1) + i] = static_cast<std::uint8_t>(z[c] >> 8);
    }
  }
  void residuals(std::size_t i, int r[3]) const {
    int d[3];
    for (int c = 0; c < 3; ++c)
      d[c] = unzigzag(
          static_cast<std::uint16_t>(raw_[plane(2 * c) + i] | (raw_[plane(2 * c + 1) + i] << 8)));
    r[1] = d[1];
    r[0] = d[0] + d[1];
    r[2] = d[2] + d[1];
  }
  const std::vector<std::uint8_t>& raw() const { return raw_; }

 private:
  std::size_t plane(int k) const { return static_cast<std::size_t>(lead_ + k) * n_; }
  std::size_t n_;
  int lead_;
  std::vector<std::uint8_t> raw_;
};

// RGB9E5 words: 5-bit exponent e, 9-bit mantissas m[3]; value_c = m_c * 2^(e - 24).
int exponent(std::uint32_t w) {
  return static_cast<int>(w >> 27);
}
int mantissa(std::uint32_t w, int c) {
  return static_cast<int>((w >> (9 * c)) & 511u);
}
// Mantissa m at exponent `from` expressed at exponent `to` (rounded, clamped to 9 bits).
int rescale(int m, int from, int to) {
  if (from >= to) {
    const int s = from - to;
    return m == 0 ? 0 : s >= 9 ? 511 : std::min(m << s, 511);
  }
  const int s = to - from;
  return s > 9 ? 0 : (m + (1 << (s - 1))) >> s;
}

// Up to two already-known words the current texel is predicted from.
struct Rgb9e5Prediction {
  std::uint32_t ref[2] = {0, 0};
  int count = 0;
  int exponent() const {
    if (count == 0) return 0;
    if (count == 1) return wire::exponent(ref[0]);
    return (wire::exponent(ref[0]) + wire::exponent(ref[1]) + 1) >> 1;
  }
  int mantissa(int c, int e) const {
    if (count == 0) return 0;
    const int a = rescale(wire::mantissa(ref[0], c), wire::exponent(ref[0]), e);
    if (count == 1) return a;
    return (a + rescale(wire::mantissa(ref[1], c), wire::exponent(ref[1]), e) + 1) >> 1;
  }
};

void put_rgb9e5(Planes& p, std::size_t i, std::uint32_t w, const Rgb9e5Prediction& pred) {
  const int e = exponent(w);
  p.put_lead(i, e - pred.exponent());
  int r[3];
  for (int c = 0; c < 3; ++c) r[c] = mantissa(w, c) - pred.mantissa(c, e);
  p.put_residuals(i, r);
}

std::uint32_t get_rgb9e5(const Planes& p, std::size_t i, const Rgb9e5Prediction& pred) {
  const int e = (pred.exponent() + p.lead(i)) & 0xFF;
  if (e > 31) throw irradcast::Error("tile payload is corrupt: exponent out of range");
  int r[3];
  p.residuals(i, r);
  std::uint32_t w = static_cast<std::uint32_t>(e) << 27;
  for (int c = 0; c < 3; ++c) {
    const int m = (pred.mantissa(c, e) + r[c]) & 0xFFFF;
    if (m > 511) throw irradcast::Error("tile payload is corrupt: mantissa out of range");
    w |= static_cast<std::uint32_t>(m) << (9 * c);
  }
  return w;
}

// Spatial neighbours of texel (x, y) of a w-wide tile: left, then above.
template <typename Get>
Rgb9e5Prediction spatial_rgb9e5(int x, int y, int w, std::size_t i, Get&& word) {
  Rgb9e5Prediction p;
  if (x > 0) p.ref[p.count++] = word(i - 1);
  if (y > 0) p.ref[p.count++] = word(i - static_cast<std::size_t>(w));
  return p;
}

// Half floats: prediction = left, above, or their rounded mean, per channel (bit patterns as
// integers, which for non-negative halves is monotonic, roughly logarithmic).
void predict_half(const std::vector<std::uint16_t>& h, int x, int y, int w, std::size_t i,
                  int p[3]) {
  for (int c = 0; c < 3; ++c) {
    const std::size_t k = 3 * i + static_cast<std::size_t>(c);
    const std::size_t up = 3 * static_cast<std::size_t>(w);
    if (x > 0 && y > 0)
      p[c] = (h[k - 3] + h[k - up] + 1) >> 1;
    else if (x > 0)
      p[c] = h[k - 3];
    else if (y > 0)
      p[c] = h[k - up];
    else
      p[c] = 0;
  }
}

}  // namespace

int tiles_along(int extent, int tile_size) {
  if (tile_size < 1)
    throw irradcast::Error("tile size must be at least 1 (got " + std::to_string(tile_size) + ")");
  if (extent <= 0) return 0;
  return (extent - 1) / tile_size + 1;
}

TileRect tile_rect(int width, int height, int tile_size, int tx, int ty) {
  const int nx = tiles_along(width, tile_size), ny = tiles_along(height, tile_size);
  if (tx < 0 || ty < 0 || tx >= nx || ty >= ny)
    throw irradcast::Error("tile (" + std::to_string(tx) + ", " + std::to_string(ty) +
                           ") does not exist in a " + std::to_string(width) + " x " +
                           std::to_string(height) + " lightmap with " + std::to_string(nx) + " x " +
                           std::to_string(ny) + " tiles of " + std::to_string(tile_size));
  const int x0 = tx * tile_size, y0 = ty * tile_size;
  return TileRect{x0, y0, std::min(tile_size, width - x0), std::min(tile_size, height - y0)};
}

std::uint32_t pack_rgb9e5(glm::vec3 v) {
  // GL_EXT_texture_shared_exponent, "Encoding": N = 9 mantissa bits, B = 15 exponent bias.
  constexpr int kN = 9, kB = 15;
  const double rc = sanitize(v.x, kRgb9e5Max), gc = sanitize(v.y, kRgb9e5Max),
               bc = sanitize(v.z, kRgb9e5Max);
  const double maxrgb = std::max(rc, std::max(gc, bc));
  int floor_log2 = -kB - 1;
  if (maxrgb > 0.0) {
    int e = 0;
    std::frexp(maxrgb, &e);  // maxrgb = m * 2^e, m in [0.5, 1)
    floor_log2 = std::max(floor_log2, e - 1);
  }
  int exp_shared = floor_log2 + 1 + kB;
  double step = std::ldexp(1.0, exp_shared - kB - kN);
  if (std::floor(maxrgb / step + 0.5) >= double(1 << kN)) {
    ++exp_shared;
    step *= 2.0;
  }
  auto mant = [&](double c) {
    return std::min<std::uint32_t>(static_cast<std::uint32_t>(std::floor(c / step + 0.5)), 511u);
  };
  return mant(rc) | (mant(gc) << 9) | (mant(bc) << 18) |
         (static_cast<std::uint32_t>(exp_shared) << 27);
}

glm::vec3 unpack_rgb9e5(std::uint32_t p) {
  // 2^(e - 15 - 9) built from its bits (e - 24 + 127 is always a normal exponent): this is on
  // every client's hot path, and ldexp is a library call.
  const float scale = std::bit_cast<float>(((p >> 27) + 103u) << 23);
  return glm::vec3(static_cast<float>(p & 511u) * scale,
                   static_cast<float>((p >> 9) & 511u) * scale,
                   static_cast<float>((p >> 18) & 511u) * scale);
}

glm::vec3 quantize_half(glm::vec3 v) {
  return glm::vec3(glm::unpackHalf1x16(pack_half(v.x)), glm::unpackHalf1x16(pack_half(v.y)),
                   glm::unpackHalf1x16(pack_half(v.z)));
}

float rgb9e5_max_relative_error() {
  return 1.0f / 511.5f;
}
float half_max_relative_error() {
  return std::ldexp(1.0f, -11);
}
float tile_absolute_error_floor() {
  return std::ldexp(1.0f, -25);
}

std::string encode_tile(const Lightmap& map, const TileRect& r, TileEncoding enc) {
  check_rect(map, r, "source");
  if (enc == TILE_RGB9E5_DELTA_ZSTD)
    throw irradcast::Error("tile codec: a delta needs a base; use encode_tile_delta()");
  const int lead = lead_planes(enc);
  const std::size_t n = static_cast<std::size_t>(r.w) * static_cast<std::size_t>(r.h);
  Planes planes(n, lead);
  if (enc == TILE_RGB9E5_ZSTD) {
    std::vector<std::uint32_t> words(n);
    std::size_t i = 0;
    for (int y = 0; y < r.h; ++y)
      for (int x = 0; x < r.w; ++x, ++i)
        words[i] = pack_rgb9e5(map.texels[texel_index(map, r, x, y)]);
    i = 0;
    for (int y = 0; y < r.h; ++y)
      for (int x = 0; x < r.w; ++x, ++i)
        put_rgb9e5(planes, i, words[i],
                   spatial_rgb9e5(x, y, r.w, i, [&](std::size_t k) { return words[k]; }));
  } else {
    std::vector<std::uint16_t> h(3 * n);
    std::size_t i = 0;
    for (int y = 0; y < r.h; ++y)
      for (int x = 0; x < r.w; ++x, ++i) {
        const glm::vec3& v = map.texels[texel_index(map, r, x, y)];
        for (int c = 0; c < 3; ++c) h[3 * i + c] = pack_half(v[c]);
      }
    i = 0;
    for (int y = 0; y < r.h; ++y)
      for (int x = 0; x < r.w; ++x, ++i) {
        int p[3], res[3];
        predict_half(h, x, y, r.w, i, p);
        for (int c = 0; c < 3; ++c) res[c] = h[3 * i + c] - p[c];
        planes.put_residuals(i, res);
      }
  }
  return compress(planes.raw());
}

std::string encode_tile_delta(const Lightmap& now, const Lightmap& base, const TileRect& r) {
  check_rect(now, r, "source");
  check_rect(base, r, "base");
  const std::size_t n = static_cast<std::size_t>(r.w) * static_cast<std::size_t>(r.h);
  Planes planes(n, lead_planes(TILE_RGB9E5_DELTA_ZSTD));
  std::size_t i = 0;
  for (int y = 0; y < r.h; ++y)
    for (int x = 0; x < r.w; ++x, ++i) {
      Rgb9e5Prediction pred;
      pred.ref[pred.count++] = pack_rgb9e5(base.texels[texel_index(base, r, x, y)]);
      put_rgb9e5(planes, i, pack_rgb9e5(now.texels[texel_index(now, r, x, y)]), pred);
    }
  return compress(planes.raw());
}

void decode_tile(const std::string& payload, TileEncoding enc, const TileRect& r, Lightmap& map) {
  check_rect(map, r, "destination");
  const int lead = lead_planes(enc);
  const std::size_t n = static_cast<std::size_t>(r.w) * static_cast<std::size_t>(r.h);
  const Planes planes(n, lead, decompress(payload, Planes::size(n, lead)));
  std::vector<glm::vec3> out(n);
  if (enc == TILE_HALF_ZSTD) {
    std::vector<std::uint16_t> h(3 * n);
    std::size_t i = 0;
    for (int y = 0; y < r.h; ++y)
      for (int x = 0; x < r.w; ++x, ++i) {
        int p[3], res[3];
        predict_half(h, x, y, r.w, i, p);
        planes.residuals(i, res);
        for (int c = 0; c < 3; ++c) {
          const int v = (p[c] + res[c]) & 0xFFFF;
          // Sanitised halves are finite and non-negative: anything else is damage.
          if (v > 0x7BFF)
            throw irradcast::Error("tile payload is corrupt: half value out of range");
          h[3 * i + c] = static_cast<std::uint16_t>(v);
          out[i][c] = glm::unpackHalf1x16(static_cast<std::uint16_t>(v));
        }
      }
  } else {
    std::vector<std::uint32_t> words(n);
    std::size_t i = 0;
    for (int y = 0; y < r.h; ++y)
      for (int x = 0; x < r.w; ++x, ++i) {
        Rgb9e5Prediction pred;
        if (enc == TILE_RGB9E5_DELTA_ZSTD)
          pred.ref[pred.count++] = pack_rgb9e5(map.texels[texel_index(map, r, x, y)]);
        else
          pred = spatial_rgb9e5(x, y, r.w, i, [&](std::size_t k) { return words[k]; });
        words[i] = get_rgb9e5(planes, i, pred);
        out[i] = unpack_rgb9e5(words[i]);
      }
  }
  std::size_t i = 0;
  for (int y = 0; y < r.h; ++y)
    for (int x = 0; x < r.w; ++x, ++i) map.texels[texel_index(map, r, x, y)] = out[i];
}

void quantize_tile(Lightmap& map, const TileRect& r, TileEncoding enc) {
  check_rect(map, r, "source");
  lead_planes(enc);  // rejects unknown encodings
  for (int y = 0; y < r.h; ++y)
    for (int x = 0; x < r.w; ++x) {
      glm::vec3& v = map.texels[texel_index(map, r, x, y)];
      v = enc == TILE_HALF_ZSTD ? quantize_half(v) : unpack_rgb9e5(pack_rgb9e5(v));
    }
}

bool tile_changed(const Lightmap& now, const Lightmap& sent, const TileRect& r, float threshold,
                  float floor) {
  check_rect(now, r, "current");
  check_rect(sent, r, "sent");
  if (now.width != sent.width || now.height != sent.height)
    throw irradcast::Error("tile_changed: the lightmaps differ in size (" +
                           std::to_string(now.width) + " x " + std::to_string(now.height) +
                           " and " + std::to_string(sent.width) + " x " +
                           std::to_string(sent.height) + ")");
  constexpr float kMax = 3.0e38f;
  const double f = sanitize(floor, kMax);
  const double t = sanitize(threshold, kMax);
  // RMS of the texel changes against the tile's mean level: a progressive engine nudges every
  // texel after every update (Monte Carlo noise shrinking as 1/n), and the largest single change
  // in a tile stays above any useful threshold long after the tile as a whole has settled.
  double diff2 = 0.0, level = 0.0;
  for (int y = 0; y < r.h; ++y)
    for (int x = 0; x < r.w; ++x) {
      const std::size_t k = texel_index(now, r, x, y);
      const glm::vec3 a = now.texels[k], b = sent.texels[k];
      for (int c = 0; c < 3; ++c) {
        const double ac = sanitize(a[c], kMax), bc = sanitize(b[c], kMax);
        diff2 += (ac - bc) * (ac - bc) / 3.0;
        level += bc / 3.0;
      }
    }
  const double n = static_cast<double>(r.w) * static_cast<double>(r.h);
  return n > 0.0 && std::sqrt(diff2 / n) > t * (level / n + f);
}

float change_floor(const Lightmap& map, float fraction) {
  check_map(map, "source");
  if (map.texels.empty()) return 0.0f;
  double sum = 0.0;
  for (const glm::vec3& v : map.texels)
    sum += 0.2126 * sanitize(v.x, kRgb9e5Max) + 0.7152 * sanitize(v.y, kRgb9e5Max) +
           0.0722 * sanitize(v.z, kRgb9e5Max);
  return fraction * static_cast<float>(sum / static_cast<double>(map.texels.size()));
}

}  // namespace irradcast::wire
