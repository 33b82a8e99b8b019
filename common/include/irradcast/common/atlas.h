// Lightmap atlas: one lightmap per object. Each object's triangles get lightmap coordinates in
// texel units (texel (i, j) covers [i, i+1) x [j, j+1), its centre is (i + 0.5, j + 0.5); row j
// is the j-th row of the image, so a file's TEXCOORD_1 maps as uv1 * (width, height) with glTF's
// top-left origin), either from the file's TEXCOORD_1 or from generated charts packed with
// gutters.
//
// File TEXCOORD_1 is used when every coordinate lies in [0,1] and, rasterised at the lightmap's
// resolution (at least 128), at most 1% of the covered texel centres are claimed by two triangles
// that share no corner (and at most 1% of the triangles collapse to zero UV area); otherwise a
// warning is logged and charts are generated. Its lightmap is square, sized for the density.
//
// Generated charts: vertices are welded by position; triangles grow into charts over shared
// edges, best-aligned first, while every normal stays strictly within chart_max_angle_deg of the
// chart's area-weighted mean normal; each chart is projected onto that plane and rotated to its
// minimum-area bounding rectangle; charts whose projection overlaps itself (2D triangle overlap)
// are split until none does. Charts are shelf-packed (tallest first, landscape orientation),
// centred in cells of at least 1x1 texel, with `gutter` empty texels between any two charts and
// along the lightmap border. When the object exceeds max_lightmap_size its density is reduced
// (bisection) until it fits; only if its charts cannot fit even at one texel each is the cap
// exceeded (with a warning). Objects without triangles get a 0x0 lightmap. Cost O(n log n) in the
// triangle count, parallel over objects and charts.
#pragma once

#include <cstdint>
#include <vector>

#include <glm/glm.hpp>

#include "irradcast/common/world.h"

namespace irradcast {

struct AtlasOptions {
  // Texel density: texels per unit length, relative to the scene size (texels across the
  // scene's largest extent).
  float texels_per_scene = 256.0f;
  int max_lightmap_size = 1024;       // per-object cap on width and height; density drops to fit
  int gutter = 2;                     // empty texels kept around every chart, each side
  float chart_max_angle_deg = 45.0f;  // normal deviation allowed inside a chart
  bool use_file_uv1 = true;           // use TEXCOORD_1 when the mesh has it and it is usable
};

struct ObjectLightmap {
  int width = 0;
  int height = 0;
  // Lightmap coordinates (texel units) of each triangle corner: 3 per triangle. Corners are
  // per triangle, not per vertex, because chart borders split vertices.
  std::vector<glm::vec2> corner_uv;
  // Chart of each triangle (0 .. chart_count-1). For file UV1: its UV island (connected through
  // shared vertices).
  std::vector<std::uint32_t> triangle_chart;
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

// The density (texels per world unit) that AtlasOptions asks for before any per-object cap.
float atlas_base_density(const World& world, const AtlasOptions& options);

Atlas build_atlas(const World& world, const AtlasOptions& options = {});

}  // namespace irradcast
