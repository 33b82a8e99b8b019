// The irradiance volume on the wire (docs/PROTOCOL.md "ProbeVolume"): irradcast::IrradianceVolume
// to and from the ProbeVolume message, its numbers as binary16 (values beyond +-65504 are clamped)
// and zstd. The layout (probe offsets, on/off, distance moments) travels with a new epoch, the SH
// coefficients with every version.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>

#include "irradcast.pb.h"
#include "irradcast/common/irradiance_volume.h"

namespace irradcast::wire {

// The most probes a volume on the wire may have (the server's cap; a client refuses more).
inline constexpr std::size_t kMaxWireProbes = std::size_t{1} << 16;

// `with_layout`: the grid's layout too (a client's first volume of this epoch).
ProbeVolume probe_volume_to_proto(const IrradianceVolume& v, std::uint64_t epoch,
                                  std::uint64_t version, bool with_layout);
// The same with the layout given as encode_probe_layout(v) made it (empty: none), for a sender
// that encodes it once per epoch rather than once per version.
ProbeVolume probe_volume_to_proto(const IrradianceVolume& v, std::uint64_t epoch,
                                  std::uint64_t version, const std::string& layout);
// ProbeVolume.layout of v: its probes' offsets, on/off flags and distance moments.
std::string encode_probe_layout(const IrradianceVolume& v);

// A volume a client holds from the messages so far.
struct ReceivedVolume {
  std::uint64_t epoch = 0;  // 0: none
  std::uint64_t version = 0;
  bool has_sh = false;  // irradiance received for this epoch
  IrradianceVolume volume;
  // The volume to light with: null before one with irradiance has come.
  const IrradianceVolume* lit() const { return epoch != 0 && has_sh ? &volume : nullptr; }
};
// Applies a message from the server. Throws irradcast::Error with a clear message on a grid that
// is not valid (a count of 0, over kMaxWireProbes, a spacing or origin that is not finite) or
// data that is not zstd of the exact size; `into` is then unchanged. A message of another epoch
// without a layout is ignored (false).
bool apply_probe_volume(const ProbeVolume& m, ReceivedVolume& into);

}  // namespace irradcast::wire
