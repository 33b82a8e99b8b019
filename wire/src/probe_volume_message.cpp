// The irradiance volume's ProbeVolume message: binary16 numbers under zstd.
#include "irradcast/wire/probe_volume_message.h"

#include <zstd.h>

#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

#include <glm/gtc/packing.hpp>

#include "irradcast/common/error.h"

namespace irradcast::wire {

namespace {

constexpr int kZstdLevel = 3;
constexpr std::size_t kLayoutBytesPerProbe =
    3 * 2 + 1 + std::size_t{IrradianceVolume::kDepthTexels} * 2 * 2;
constexpr std::size_t kShBytesPerProbe = kShCoefficients * 3 * 2;

void put_half(std::string& out, float x) {
  const float c = std::isfinite(x) ? std::clamp(x, -65504.0f, 65504.0f) : 0.0f;
  const std::uint16_t h = glm::packHalf1x16(c);
  out.push_back(static_cast<char>(h & 0xff));
  out.push_back(static_cast<char>(h >> 8));
}

float get_half(const std::string& in, std::size_t& at) {
  const auto lo = static_cast<unsigned char>(in[at]), hi = static_cast<unsigned char>(in[at + 1]);
  at += 2;
  const auto h = static_cast<std::uint16_t>(lo | (hi << 8));
  if ((h & 0x7c00) == 0x7c00)  // infinity or NaN: a peer's data, not ours
    throw irradcast::Error("probe volume: a value that is not finite");
  return glm::unpackHalf1x16(h);
}

std::string compress(const std::string& raw) {
  std::string z(ZSTD_compressBound(raw.size()), '\0');
  const std::size_t n = ZSTD_compress(z.data(), z.size(), raw.data(), raw.size(), kZstdLevel);
  if (ZSTD_isError(n))
    throw irradcast::Error(std::string("probe volume: zstd: ") + ZSTD_getErrorName(n));
  z.resize(n);
  z.shrink_to_fit();  // kept by the host until the next refine: without the bound's room
  return z;
}

std::string decompress(const std::string& z, std::size_t expected, const char* what) {
  const unsigned long long size = ZSTD_getFrameContentSize(z.data(), z.size());
  if (size != expected)
    throw irradcast::Error(std::string("probe volume: the ") + what + " is not zstd of " +
                           std::to_string(expected) + " bytes");
  std::string raw(expected, '\0');
  const std::size_t n = ZSTD_decompress(raw.data(), raw.size(), z.data(), z.size());
  if (ZSTD_isError(n) || n != expected)
    throw irradcast::Error(std::string("probe volume: the ") + what + " is corrupt");
  return raw;
}

std::string encode_sh(const std::vector<ShIrradiance>& sh) {
  std::string raw;
  raw.reserve(sh.size() * kShBytesPerProbe);
  for (const ShIrradiance& e : sh)
    for (const glm::vec3& c : e)
      for (int a = 0; a < 3; ++a) put_half(raw, c[a]);
  return compress(raw);
}

// Empty z: all zero, where `may_be_empty`.
std::vector<ShIrradiance> decode_sh(const std::string& z, std::size_t probes, const char* what,
                                    bool may_be_empty) {
  std::vector<ShIrradiance> out(probes);
  if (z.empty() && may_be_empty) return out;
  const std::string raw = decompress(z, probes * kShBytesPerProbe, what);
  std::size_t at = 0;
  for (ShIrradiance& e : out)
    for (glm::vec3& c : e)
      for (int a = 0; a < 3; ++a) c[a] = get_half(raw, at);
  return out;
}

}  // namespace

std::string encode_probe_layout(const IrradianceVolume& v) {
  const std::size_t n = v.probe_count();
  std::string raw;
  raw.reserve(n * kLayoutBytesPerProbe);
  for (std::size_t i = 0; i < n; ++i) {
    for (int a = 0; a < 3; ++a) put_half(raw, v.offsets[i][a]);
    raw.push_back(v.active[i] ? 1 : 0);
  }
  // As fractions of the farthest distance recorded: binary16 keeps its precision at any
  // scene scale (a mean square in metres would clip past 256 m).
  const float far = v.grid.max_distance();
  for (const glm::vec2& d : v.depth) {
    put_half(raw, d.x / far);
    put_half(raw, d.y / (far * far));
  }
  return compress(raw);
}

ProbeVolume probe_volume_to_proto(const IrradianceVolume& v, std::uint64_t epoch,
                                  std::uint64_t version, bool with_layout) {
  return probe_volume_to_proto(v, epoch, version,
                               with_layout ? encode_probe_layout(v) : std::string());
}

ProbeVolume probe_volume_to_proto(const IrradianceVolume& v, std::uint64_t epoch,
                                  std::uint64_t version, const std::string& layout) {
  ProbeVolume m;
  m.set_epoch(epoch);
  m.set_version(version);
  for (int a = 0; a < 3; ++a) {
    m.add_origin(v.grid.origin[a]);
    m.add_counts(static_cast<std::uint32_t>(v.grid.counts[a]));
  }
  m.set_spacing(v.grid.spacing);
  m.set_layout(layout);
  m.set_sh(encode_sh(v.sh));
  const bool any_emitted = std::any_of(v.emitted.begin(), v.emitted.end(), [](const auto& e) {
    return std::any_of(e.begin(), e.end(), [](glm::vec3 c) { return c != glm::vec3(0.0f); });
  });
  if (any_emitted) m.set_emitted(encode_sh(v.emitted));
  return m;
}

bool apply_probe_volume(const ProbeVolume& m, ReceivedVolume& into) {
  const bool layout = !m.layout().empty();
  if (!layout && m.epoch() != into.epoch) return false;  // its layout has not come
  if (m.origin_size() != 3 || m.counts_size() != 3)
    throw irradcast::Error("probe volume: the grid needs 3 origin coordinates and 3 counts");
  VolumeGrid g;
  std::size_t probes = 1;
  for (int a = 0; a < 3; ++a) {
    g.origin[a] = m.origin(a);
    const std::uint32_t c = m.counts(a);
    if (c == 0 || c > kMaxWireProbes)
      throw irradcast::Error("probe volume: a count of " + std::to_string(c));
    g.counts[a] = static_cast<int>(c);
    probes *= c;
    if (probes > kMaxWireProbes)
      throw irradcast::Error("probe volume: more than " + std::to_string(kMaxWireProbes) +
                             " probes");
  }
  g.spacing = m.spacing();
  if (!(g.spacing >= 1e-6f) || !std::isfinite(g.spacing) || !std::isfinite(g.origin.x) ||
      !std::isfinite(g.origin.y) || !std::isfinite(g.origin.z))
    throw irradcast::Error(
        "probe volume: a spacing or origin that is not finite (or a spacing under 1e-6)");
  // Every probe position (and a look-up's arithmetic around it) stays finite.
  for (int a = 0; a < 3; ++a)
    if (std::fabs(g.origin[a]) + float(g.counts[a] + 2) * g.spacing > 1e18f)
      throw irradcast::Error("probe volume: the grid reaches past 1e18 from the origin");
  if (!layout && g.probe_count() != into.volume.probe_count())
    throw irradcast::Error("probe volume: the grid differs from its epoch's layout");
  std::vector<ShIrradiance> coefficients = decode_sh(m.sh(), probes, "SH data", false);
  std::vector<ShIrradiance> emitted = decode_sh(m.emitted(), probes, "emitters' SH data", true);
  IrradianceVolume next;
  if (layout) {
    const std::string raw = decompress(m.layout(), probes * kLayoutBytesPerProbe, "layout");
    next.reset(g);
    std::size_t at = 0;
    for (std::size_t i = 0; i < probes; ++i) {
      for (int a = 0; a < 3; ++a) next.offsets[i][a] = get_half(raw, at);
      next.active[i] = raw[at++] != 0 ? 1 : 0;
    }
    const float far = g.max_distance();
    for (glm::vec2& d : next.depth) {
      d.x = get_half(raw, at);
      d.y = get_half(raw, at);
      if (d.x < 0.0f || d.y < 0.0f) throw irradcast::Error("probe volume: a negative distance");
      d *= glm::vec2(far, far * far);
    }
  }
  if (layout) into.volume = std::move(next);
  into.volume.sh = std::move(coefficients);
  into.volume.emitted = std::move(emitted);
  into.epoch = m.epoch();
  into.version = m.version();
  into.has_sh = true;
  return true;
}

}  // namespace irradcast::wire
