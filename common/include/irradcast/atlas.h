// Lightmap atlas: one lightmap per object. Each object's triangles get lightmap coordinates in
// texel units (texel (i, j) covers [i, i+1) x [j, j+1), its centre is (i + 0.5, j + 0.5)), either
// from the file's TEXCOORD_1 or from generated charts packed with gutters.
#pragma once

#include <cstdint>
#include <vector>

#include <glm/glm.hpp>

#include "irradcast/world.h"

namespace irradcast {

struct AtlasOptions {
  // Texel density: texels per unit length, relative to the scene size (texels across the
  // scene's largest extent).
  float texels_per_scene = 256.0f;
  int max_lightmap_size = 1024;  // per-object cap on width and height; density drops to fit
  int gutter = 2;                // empty texels kept around every chart, each side
  float chart_max_angle_deg = 45.0f;  // normal deviation allowed inside a chart
  bool use_file_uv1 = true;           // use TEXCOORD_1 when the mesh has it and it is usable
};

struct ObjectLightmap {
  int width = 0;
  int height = 0;
  // Lightmap coordinates (texel units) of each triangle corner: 3 per triangle. Corners are
  // per triangle, not per vertex, because chart borders split vertices.
  std::vector<glm::vec2> corner_uv;
  int chart_count = 0;
  bool from_file_uv1 = false;
  float texels_per_unit = 0.0f;  // world-space density actually used

  glm::vec2 uv(std::uint32_t t, float u, float v) const {
    return (1.0f - u - v) * corner_uv[3 * t] + u * corner_uv[3 * t + 1] + v * corner_uv[3 * t + 2];
  }
};

struct Atlas {
  std::vector<ObjectLightmap> objects;  // one per World::objects entry
  std::size_t texel_count() const;      // sum of width * height
};

Atlas build_atlas(const World& world, const AtlasOptions& options = {});

}  // namespace irradcast
