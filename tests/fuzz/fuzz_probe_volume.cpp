// libFuzzer target for the probe volume a client receives (wire/probe_volume_message.h): a
// ProbeVolume built from the fuzzer's bytes (the grid's numbers as given, the layout and SH
// payloads either raw bytes or zstd of bytes of the exact size, so that both the checks and the
// decoding past them are reached), applied with a layout and then without. Properties beyond "no
// crash, no leak, no UB": a refused message leaves the volume held unchanged, and every volume
// accepted gives finite, non-negative irradiance at any finite point and normal.
// Run: deploy/fuzz.sh (or build-fuzz/tests/fuzz/fuzz_probe_volume -max_total_time=30).
#include <fuzzer/FuzzedDataProvider.h>
#include <zstd.h>

#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <string>

#include "irradcast/common/error.h"
#include "irradcast/wire/probe_volume_message.h"

using namespace irradcast;

namespace {

void check(bool ok) {
  if (!ok) std::abort();
}

std::string zstd_of(const std::string& raw) {
  std::string z(ZSTD_compressBound(raw.size()), '\0');
  z.resize(ZSTD_compress(z.data(), z.size(), raw.data(), raw.size(), 1));
  return z;
}

// A payload: raw fuzz bytes, or zstd of `size` bytes drawn from the fuzzer (zero-padded).
std::string payload(FuzzedDataProvider& in, std::size_t size) {
  if (in.ConsumeBool())
    return in.ConsumeBytesAsString(in.ConsumeIntegralInRange<std::size_t>(0, 256));
  std::string raw = in.ConsumeBytesAsString(std::min<std::size_t>(size, in.remaining_bytes()));
  raw.resize(size, '\0');
  return zstd_of(raw);
}

wire::ProbeVolume message(FuzzedDataProvider& in, bool with_layout) {
  wire::ProbeVolume m;
  m.set_epoch(in.ConsumeIntegralInRange<std::uint64_t>(0, 3));
  m.set_version(in.ConsumeIntegral<std::uint64_t>());
  std::size_t probes = 1;
  for (int a = 0; a < 3; ++a) {
    m.add_origin(in.ConsumeBool() ? in.ConsumeFloatingPoint<float>()
                                  : in.ConsumeFloatingPointInRange<float>(-10.0f, 10.0f));
    const std::uint32_t c = in.ConsumeBool() ? in.ConsumeIntegral<std::uint32_t>()
                                             : in.ConsumeIntegralInRange<std::uint32_t>(1, 4);
    m.add_counts(c);
    probes *= std::min<std::uint32_t>(c, 8);  // payloads sized for at most 512 probes: fast
  }
  m.set_spacing(in.ConsumeBool() ? in.ConsumeFloatingPoint<float>()
                                 : in.ConsumeFloatingPointInRange<float>(0.01f, 4.0f));
  if (with_layout) m.set_layout(payload(in, probes * (7 + IrradianceVolume::kDepthTexels * 4)));
  m.set_sh(payload(in, probes * 27 * 2));
  return m;
}

void apply_and_check(const wire::ProbeVolume& m, wire::ReceivedVolume& held,
                     FuzzedDataProvider& in) {
  const std::uint64_t epoch = held.epoch, version = held.version;
  const std::size_t probes = held.volume.probe_count();
  try {
    wire::apply_probe_volume(m, held);
  } catch (const Error&) {
    check(held.epoch == epoch && held.version == version && held.volume.probe_count() == probes);
    return;
  }
  if (!held.lit()) return;
  for (int k = 0; k < 4; ++k) {
    const glm::vec3 p(in.ConsumeFloatingPointInRange<float>(-20.0f, 20.0f),
                      in.ConsumeFloatingPointInRange<float>(-20.0f, 20.0f),
                      in.ConsumeFloatingPointInRange<float>(-20.0f, 20.0f));
    glm::vec3 n(in.ConsumeFloatingPointInRange<float>(-1.0f, 1.0f),
                in.ConsumeFloatingPointInRange<float>(-1.0f, 1.0f), 1.0f);
    n = glm::normalize(n);
    const glm::vec3 e = held.volume.irradiance(p, n);
    for (int a = 0; a < 3; ++a) check(std::isfinite(e[a]) && e[a] >= 0.0f);
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  FuzzedDataProvider in(data, size);
  wire::ReceivedVolume held;
  const wire::ProbeVolume first = message(in, true);
  apply_and_check(first, held, in);
  const wire::ProbeVolume later = message(in, in.ConsumeBool());
  apply_and_check(later, held, in);
  return 0;
}
