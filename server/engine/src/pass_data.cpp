// The engine's shared pass data (pass_data.h): the grid of radiance cells (cell lookup, cell
// centres), a texel's probe weights, and where a scene change happened.
#include <algorithm>
#include <cmath>
#include <limits>

#include "irradcast/engine/pass_data.h"

#include "irradcast/common/error.h"

namespace irradcast {

int ProbeGrid::cell_index(glm::vec3 p) const {
  glm::ivec3 c = glm::clamp(glm::ivec3(glm::floor((p - origin) / cell)), glm::ivec3(0), dims - 1);
  return (c.z * dims.y + c.y) * dims.x + c.x;
}

glm::vec3 ProbeGrid::centre(std::size_t i) const {
  const glm::ivec3 c(static_cast<int>(i % dims.x), static_cast<int>((i / dims.x) % dims.y),
                     static_cast<int>(i / (static_cast<std::size_t>(dims.x) * dims.y)));
  return origin + (glm::vec3(c) + 0.5f) * cell;
}

namespace {

// Cubes of `cap` metres over a box of extents `e` (largest `extent`), grown by 1 % steps until
// at most 256 lie along the largest extent and ProbeGrid::kMaxCappedCells in all.
float capped_cell(glm::vec3 e, float extent, float cap) {
  float cell = std::max(cap, extent / 256.0f);
  auto count = [&](float c) {
    double n = 1.0;
    for (int a = 0; a < 3; ++a) n *= std::max(1.0f, std::ceil(e[a] / c - 1e-4f));
    return n;
  };
  while (count(cell) > static_cast<double>(ProbeGrid::kMaxCappedCells)) cell *= 1.01f;
  return cell;
}

}  // namespace

namespace {

// The grid's cube edge and its cells along the largest extent.
struct Edge {
  float cell;
  int per_axis;
};

Edge edge_of(const Bounds& b, const EngineParams& params) {
  const float extent = std::max(b.max_extent(), 1e-6f);
  // A fraction: ceil(1 / cell_size) cubes across the largest extent (seed 001 grids the
  // normalised cube). Metres: cubes of that edge, as many as cover the largest extent.
  // A capped fraction whose cap binds is metres, grown where it must to keep the grid's limits.
  Length size = params.cell_size;
  if (size.has_cap() && size.value * extent > size.cap)
    size = Length::in_metres(capped_cell(b.extent(), extent, size.cap));
  const float across =
      size.metres ? std::ceil(extent / size.value - 1e-4f) : std::ceil(1.0f / size.value);
  if (!(across <= 256.0f))
    throw Error("cell_size " + param_text(size) + " gives " + param_text(across) +
                " cells along the scene's largest extent of " + param_text(extent) +
                " m (at most 256)");
  const int per_axis = std::max(1, static_cast<int>(across));
  // (A cube larger than the scene is one cell over it: its probe stays inside the bounds.)
  return {size.metres ? std::min(size.value, extent) : extent / static_cast<float>(per_axis),
          per_axis};
}

}  // namespace

float ProbeGrid::cell_edge(const Bounds& b, const EngineParams& params) {
  return edge_of(b, params).cell;
}

ProbeGrid ProbeGrid::cells_of(const Bounds& b, const EngineParams& params) {
  ProbeGrid g;
  const auto [cell, per_axis] = edge_of(b, params);
  // Axes shorter than the largest get fewer cells (cells outside the bounds would hold nothing).
  g.cell = cell;
  g.origin = b.lo;
  glm::vec3 e = b.extent();
  for (int a = 0; a < 3; ++a)
    g.dims[a] = std::clamp(static_cast<int>(std::ceil(e[a] / g.cell - 1e-4f)), 1, per_axis);
  g.resolution = params.probe_resolution;
  const std::size_t count = static_cast<std::size_t>(g.dims.x) * g.dims.y * g.dims.z;
  g.position.resize(count);
  g.usable.assign(count, 1);
  for (int z = 0; z < g.dims.z; ++z)
    for (int y = 0; y < g.dims.y; ++y)
      for (int x = 0; x < g.dims.x; ++x)
        g.position[(z * g.dims.y + y) * g.dims.x + x] =
            g.origin + (glm::vec3(x, y, z) + 0.5f) * g.cell;
  return g;
}

ProbeBlock::ProbeBlock(const ProbeGrid& grid, glm::vec3 p) {
  const glm::vec3 f = (p - grid.origin) / grid.cell - 0.5f;
  base = glm::ivec3(glm::floor(f));
  frac = f - glm::vec3(base);
}

float ProbeBlock::trilinear(int c) const {
  const glm::ivec3 o(c & 1, (c >> 1) & 1, (c >> 2) & 1);
  const glm::vec3 tw = glm::mix(1.0f - frac, frac, glm::vec3(o));
  return glm::max(tw.x, 0.0f) * glm::max(tw.y, 0.0f) * glm::max(tw.z, 0.0f);
}

ProbeWeights probe_weights(const ProbeGrid& grid, glm::vec3 p, std::uint8_t mask) {
  const ProbeBlock block(grid, p);
  ProbeWeights w;
  w.base = (block.base.z * grid.dims.y + block.base.y) * grid.dims.x + block.base.x;
  float sum = 0.0f;
  for (int c = 0; c < 8; ++c) {
    if (!(mask >> c & 1u)) continue;
    const float weight = std::max(block.trilinear(c), 1e-4f);
    w.add(c, weight);
    sum += weight;
  }
  for (int k = 0; k < w.count(); ++k) w.weight[k] /= sum;
  return w;
}

float SceneChange::distance(glm::vec3 p) const {
  float nearest = std::numeric_limits<float>::infinity();
  for (const Bounds& b : regions) {
    const glm::vec3 d = glm::max(glm::max(b.lo - p, p - b.hi), glm::vec3(0.0f));
    nearest = std::min(nearest, glm::length(d));
  }
  return nearest;
}

}  // namespace irradcast
