// The sky on the wire (docs/PROTOCOL.md, "The sky"): irradcast::Sky to and from the SceneSky
// message of the scene package, and a sky map to and from the SkyMap message that the package and
// a sky edit's broadcast carry. Viewers use the sky only as the background of rays that miss, so
// a map travels at most kMaxViewerSkyWidth x kMaxViewerSkyHeight (a larger one is
// box-downsampled) as zstd-compressed RGB9E5 texels (the tile codec's format): 2 MiB before zstd
// at most, instead of the 96 MiB of a 4096 x 2048 float map.
#pragma once

#include "irradcast.pb.h"
#include "irradcast/common/image.h"
#include "irradcast/common/sky.h"

namespace irradcast::wire {

inline constexpr int kMaxViewerSkyWidth = 1024;
inline constexpr int kMaxViewerSkyHeight = 512;

// `map` box-downsampled to at most kMaxViewerSkyWidth x kMaxViewerSkyHeight (each side on its
// own; a map within the limits is returned as it is). Every source texel goes to exactly one
// target texel, which is the mean of its source texels.
ImageRGB viewer_sky_map(const ImageRGB& map);

// Encodes viewer_sky_map(map) (RGB9E5: values above 65408 are clamped, negatives and NaN become 0).
void sky_map_to_proto(const ImageRGB& map, SkyMap* out);
// Decodes a SkyMap from a peer. Throws irradcast::Error naming `what` on a size of 0 or above the
// viewer limits, or data that is not zstd of exactly width x height x 4 bytes.
ImageRGB sky_map_from_proto(const SkyMap& m, const std::string& what);

// Whether `sky` is the default (no sky: colour 0, strength 1, no map, no source); such a sky is
// not written to the package at all.
bool is_default_sky(const Sky& sky);
// The sky with its map as viewers get it (viewer_sky_map).
void sky_to_proto(const Sky& sky, SceneSky* out);
// Decodes and validates (validate_sky). Throws irradcast::Error naming `what`.
Sky sky_from_proto(const SceneSky& m, const std::string& what);

}  // namespace irradcast::wire
