// libFuzzer target for the tile decoder (TileUpdate payloads come from the network): arbitrary
// payloads, encodings and tile sizes must either decode to finite, non-negative texels inside the
// tile or throw irradcast::Error, leaving the lightmap untouched. Half of the inputs are wrapped
// in a valid zstd frame first, so that the residual decoding behind zstd's checksum gets fuzzed
// too, not only the container.
#include <fuzzer/FuzzedDataProvider.h>
#include <zstd.h>

#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <string>
#include <utility>

#include "irradcast/common/error.h"
#include "irradcast/wire/tile_codec.h"

using namespace irradcast;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  FuzzedDataProvider in(data, size);
  const int w = in.ConsumeIntegralInRange<int>(1, 40), h = in.ConsumeIntegralInRange<int>(1, 40);
  const wire::TileRect r{
      in.ConsumeIntegralInRange<int>(-2, 10), in.ConsumeIntegralInRange<int>(-2, 10),
      in.ConsumeIntegralInRange<int>(-1, 40), in.ConsumeIntegralInRange<int>(-1, 40)};
  const auto enc = static_cast<wire::TileEncoding>(in.ConsumeIntegralInRange<int>(0, 3));
  const bool wrap = in.ConsumeBool();
  std::string payload = in.ConsumeRemainingBytesAsString();
  if (wrap) {
    std::string z(ZSTD_compressBound(payload.size()), '\0');
    ZSTD_CCtx* ctx = ZSTD_createCCtx();
    ZSTD_CCtx_setParameter(ctx, ZSTD_c_checksumFlag, 1);
    const std::size_t n = ZSTD_compress2(ctx, z.data(), z.size(), payload.data(), payload.size());
    ZSTD_freeCCtx(ctx);
    if (ZSTD_isError(n)) std::abort();
    z.resize(n);
    payload = std::move(z);
  }
  Lightmap map(w, h, glm::vec3(0.25f, 1.0f, 4.0f));
  const Lightmap before = map;
  try {
    wire::decode_tile(payload, enc, r, map);
  } catch (const irradcast::Error&) {
    if (map.texels != before.texels) std::abort();
    return 0;
  }
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const glm::vec3 v = map.texels[static_cast<std::size_t>(y) * w + x];
      const bool inside = x >= r.x0 && x < r.x0 + r.w && y >= r.y0 && y < r.y0 + r.h;
      if (!inside && v != before.texels[static_cast<std::size_t>(y) * w + x]) std::abort();
      for (int c = 0; c < 3; ++c)
        if (!std::isfinite(v[c]) || v[c] < 0.0f) std::abort();
    }
  return 0;
}
