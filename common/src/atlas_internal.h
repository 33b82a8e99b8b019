// Lightmap atlas internals shared by its files: 2D geometry helpers (atlas_geometry.cpp), chart
// generation (atlas_charts.cpp), chart packing into a generated lightmap (atlas_pack.cpp) and the
// file TEXCOORD_1 path (atlas_file_uv1.cpp). build_atlas() is in atlas.cpp.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include <glm/glm.hpp>

#include "irradcast/common/atlas.h"
#include "irradcast/common/world.h"

namespace irradcast::atlas_detail {

constexpr std::uint32_t kNone = ~0u;

// ------------------------------------------------------------------------------------------------
// Small 2D geometry helpers (double precision on float inputs).

inline double cross2(glm::dvec2 a, glm::dvec2 b) {
  return a.x * b.y - a.y * b.x;
}

// Strict 2D triangle-triangle interior overlap by separating axes (see atlas_geometry.cpp).
bool triangles_overlap(const glm::vec2* a, const glm::vec2* b, double abs_tol);

// Orthonormal tangent frame of a unit normal (Duff et al. 2017).
void tangent_frame(glm::vec3 n, glm::vec3& t, glm::vec3& b);

// Convex hull, counter-clockwise.
std::vector<glm::vec2> convex_hull(const std::vector<glm::vec2>& pts);

// Angle that, applied as a rotation, gives the hull's minimum-area bounding rectangle.
float min_area_rect_angle(const std::vector<glm::vec2>& hull);

// ------------------------------------------------------------------------------------------------
// Generated charts.

struct Chart {
  glm::vec2 extent{0.0f};  // world units, after rotation, corners start at (0, 0)
};

// Charts of an object: grown, projected, folds split (bisection in breadth-first order, then
// connected components) until no chart overlaps itself.
struct ChartSet {
  std::vector<Chart> charts;
  std::vector<std::uint32_t> tri_chart;
  std::vector<glm::vec2> uv;  // world units within the chart, 3 per triangle
};

ChartSet make_charts(const WorldObject& wo, const AtlasOptions& options);

// Object oi's lightmap from generated charts, packed at base_density or less to fit the cap.
void build_generated(const World& world, std::size_t oi, const AtlasOptions& options,
                     float base_density, ObjectLightmap& lm);

// Object oi's lightmap from its file TEXCOORD_1; false (with a warning) if that is unusable.
bool build_from_file_uv1(const World& world, std::size_t oi, const AtlasOptions& options,
                         float base_density, ObjectLightmap& lm);

}  // namespace irradcast::atlas_detail
