// The texel G-buffer ("global G-buffer" of seed 001): per lightmap texel the surface point it
// stands for, as its triangle and barycentric coordinates (the world position and normals follow
// from the object's placement: TexelGBuffer::point), and its kind. The albedo is read where light
// leaves a surface, at hits, so no texel keeps one. Texels whose centre lies in a triangle
// sample that point; texels a triangle only partly covers sample the triangle's point closest to
// the texel centre (so bilinear lookups at chart borders read real surface values); the rest
// (gutters, unused space) are empty and filled by dilation of the lightmap values.
#pragma once

#include <cstdint>
#include <vector>

#include <glm/glm.hpp>

#include "irradcast/common/atlas.h"
#include "irradcast/common/world.h"

namespace irradcast {

// Empty: no surface. Covered / Conservative: see rasterize_gbuffer. Hidden: a surface point
// buried inside other geometry (see mark_hidden_texels) or cut out (a Mask material's alpha is
// below its cutoff, common/cutout.h: rays pass through it, no view shows it); it holds no
// estimate of its own and is filled from its visible neighbours like an empty texel.
enum class TexelKind : std::uint8_t { Empty = 0, Covered = 1, Conservative = 2, Hidden = 3 };
inline bool holds_estimate(TexelKind k) {
  return k == TexelKind::Covered || k == TexelKind::Conservative;
}

// A texel's surface point in world space.
struct TexelPoint {
  glm::vec3 position{0.0f};
  glm::vec3 normal{0.0f};      // unit shading normal
  glm::vec3 geo_normal{0.0f};  // unit geometric normal, on the shading normal's side
};

// One object's texels. 13 bytes a texel: the world position and normals (36 bytes) are worked out
// from the object where they are read, with the arithmetic that placed the sample.
struct TexelGBuffer {
  int width = 0;
  int height = 0;
  std::vector<glm::vec2> bary;         // the sample's barycentric (u, v) in its triangle
  std::vector<std::int32_t> triangle;  // -1 for empty texels
  std::vector<TexelKind> kind;

  std::size_t size() const { return kind.size(); }
  bool valid(std::size_t i) const { return holds_estimate(kind[i]); }
  std::size_t valid_count() const;
  // Texel i's point on `object` (the world object these texels were rasterized for, as placed
  // then); all zero for an Empty texel.
  TexelPoint point(const WorldObject& object, std::size_t i) const;
  glm::vec3 position(const WorldObject& object, std::size_t i) const;
};

// Per object: a texel whose centre lies in a triangle (inclusive; the lowest triangle index wins
// on shared edges) is Covered and samples that point; a texel a triangle's footprint overlaps
// (with positive area) but no triangle's interior contains the centre is Conservative and samples
// the closest point, in lightmap space, of the nearest such triangle; the texel holding a
// triangle's lightmap centroid is always valid (zero-area triangles get just that one). A texel
// whose sample point is cut out (cutout.h) is Hidden. Parallel over objects and bands of rows;
// deterministic.
std::vector<TexelGBuffer> rasterize_gbuffer(const World& world, const Atlas& atlas);
// Rasterizes again only the objects with which[o] != 0 (after a scene edit), in place.
void rasterize_gbuffer(const World& world, const Atlas& atlas, std::vector<TexelGBuffer>& gbuffers,
                       const std::vector<std::uint8_t>& which);

// Fills the empty texels of a lightmap from their valid neighbours, ring by ring (each pass
// averages the already-filled 8-neighbours), so bilinear lookups never read unfilled texels.
// `valid` marks the texels holding real values; `rings` bounds the number of passes (-1 = until
// every texel reachable is filled).
void dilate(std::vector<glm::vec3>& texels, int width, int height,
            const std::vector<TexelKind>& valid, int rings = -1);

}  // namespace irradcast
