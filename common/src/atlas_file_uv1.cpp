// Lightmap atlas: the file's TEXCOORD_1 as lightmap coordinates, used when every coordinate lies
// in [0,1], few triangles collapse and, rasterised at the lightmap's resolution, few texels are
// claimed twice; its charts are the UV islands.
#include <algorithm>
#include <cmath>
#include <numeric>
#include <string>
#include <vector>

#include "atlas_internal.h"
#include "irradcast/common/log.h"

namespace irradcast::atlas_detail {
namespace {

// Union-find islands over shared vertex indices.
int uv_islands(const std::vector<glm::uvec3>& tris, std::size_t vertex_count,
               std::vector<std::uint32_t>& tri_chart) {
  std::vector<std::uint32_t> parent(vertex_count);
  std::iota(parent.begin(), parent.end(), 0u);
  auto find = [&](std::uint32_t x) {
    while (parent[x] != x) x = parent[x] = parent[parent[x]];
    return x;
  };
  for (const glm::uvec3& t : tris) {
    std::uint32_t a = find(t.x), b = find(t.y), d = find(t.z);
    parent[b] = a;
    parent[find(d)] = a;
  }
  std::vector<std::uint32_t> id(vertex_count, kNone);
  std::uint32_t next = 0;
  tri_chart.resize(tris.size());
  for (std::size_t t = 0; t < tris.size(); ++t) {
    std::uint32_t r = find(tris[t].x);
    if (id[r] == kNone) id[r] = next++;
    tri_chart[t] = id[r];
  }
  return static_cast<int>(next);
}

// Why the file's TEXCOORD_1 cannot be used, or an empty string if it can.
std::string check_file_uv1(const WorldObject& wo, int res) {
  const Mesh& mesh = *wo.source;
  const auto& uv = mesh.uv1;
  if (uv.size() != mesh.positions.size()) return "TEXCOORD_1 has the wrong vertex count";
  for (const glm::vec2& q : uv)
    if (!(q.x >= -1e-4f && q.x <= 1.0001f && q.y >= -1e-4f && q.y <= 1.0001f))
      return "TEXCOORD_1 lies outside [0,1]";
  const auto& tris = mesh.triangles;
  // Triangles with area in the world but none in UV space.
  std::size_t flat = 0;
  for (std::size_t t = 0; t < tris.size(); ++t) {
    glm::dvec2 a(uv[tris[t].x]), b(uv[tris[t].y]), c(uv[tris[t].z]);
    double uv_area = std::abs(cross2(b - a, c - a));
    if (uv_area <= 1e-14 && wo.area(static_cast<std::uint32_t>(t)) > 0.0f) ++flat;
  }
  if (static_cast<double>(flat) > 0.01 * static_cast<double>(tris.size()) + 0.5)
    return "TEXCOORD_1 collapses " + std::to_string(flat) + " triangles to zero area";
  // Rasterise texel centres; a texel claimed by two triangles that share no corner (the same
  // vertex, or one at the same position with the same UV) is an overlap.
  std::vector<std::int32_t> owner(static_cast<std::size_t>(res) * res, -1);
  std::vector<std::uint8_t> conflict(owner.size(), 0);
  const auto& pos = mesh.positions;
  auto adjacent = [&](std::size_t s, std::size_t t) {
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) {
        std::uint32_t a = tris[s][i], b = tris[t][j];
        if (a == b || (uv[a] == uv[b] && pos[a] == pos[b])) return true;
      }
    return false;
  };
  for (std::size_t t = 0; t < tris.size(); ++t) {
    glm::dvec2 c0 = glm::dvec2(uv[tris[t].x]) * static_cast<double>(res);
    glm::dvec2 c1 = glm::dvec2(uv[tris[t].y]) * static_cast<double>(res);
    glm::dvec2 c2 = glm::dvec2(uv[tris[t].z]) * static_cast<double>(res);
    double area = cross2(c1 - c0, c2 - c0);
    if (area == 0.0) continue;
    glm::dvec2 lo = glm::min(c0, glm::min(c1, c2)), hi = glm::max(c0, glm::max(c1, c2));
    int x0 = std::max(0, static_cast<int>(std::ceil(lo.x - 0.5)));
    int x1 = std::min(res - 1, static_cast<int>(std::floor(hi.x - 0.5)));
    int y0 = std::max(0, static_cast<int>(std::ceil(lo.y - 0.5)));
    int y1 = std::min(res - 1, static_cast<int>(std::floor(hi.y - 0.5)));
    for (int y = y0; y <= y1; ++y)
      for (int x = x0; x <= x1; ++x) {
        glm::dvec2 p(x + 0.5, y + 0.5);
        double u = cross2(p - c0, c2 - c0) / area, v = cross2(c1 - c0, p - c0) / area;
        if (u < 0.0 || v < 0.0 || u + v > 1.0) continue;
        std::size_t i = static_cast<std::size_t>(y) * res + x;
        if (owner[i] < 0)
          owner[i] = static_cast<std::int32_t>(t);
        else if (!conflict[i] && !adjacent(static_cast<std::size_t>(owner[i]), t))
          conflict[i] = 1;
      }
  }
  std::size_t covered = 0, conflicts = 0;
  for (std::size_t i = 0; i < owner.size(); ++i) {
    covered += owner[i] >= 0;
    conflicts += conflict[i];
  }
  if (covered == 0) return "TEXCOORD_1 covers no texel";
  if (static_cast<double>(conflicts) > 0.01 * static_cast<double>(covered))
    return "TEXCOORD_1 overlaps itself (" + std::to_string(conflicts) + " of " +
           std::to_string(covered) + " texels claimed twice)";
  return {};
}

}  // namespace

bool build_from_file_uv1(const World& world, std::size_t oi, const AtlasOptions& options,
                         float base_density, ObjectLightmap& lm) {
  const WorldObject& wo = world.objects[oi];
  const Mesh& mesh = *wo.source;
  const auto& tris = mesh.triangles;
  double world_area = 0.0, uv_area = 0.0;
  for (std::size_t t = 0; t < tris.size(); ++t) {
    world_area += wo.area(static_cast<std::uint32_t>(t));
    if (mesh.uv1.size() == mesh.positions.size()) {
      glm::dvec2 a(mesh.uv1[tris[t].x]), b(mesh.uv1[tris[t].y]), c(mesh.uv1[tris[t].z]);
      uv_area += 0.5 * std::abs(cross2(b - a, c - a));
    }
  }
  const int cap = std::max(1, options.max_lightmap_size);
  double want = uv_area > 0.0 ? std::sqrt(world_area / uv_area) * base_density : 0.0;
  int size = std::clamp(static_cast<int>(std::ceil(std::isfinite(want) ? want - 1e-3 : 0.0)),
                        std::min(8, cap), cap);
  std::string why = check_file_uv1(wo, std::min(std::max(size, 128), 4096));
  if (!why.empty()) {
    log::warn("atlas", "object " + std::to_string(oi) + " (" + mesh.name + "): " + why +
                           "; generating lightmap charts instead");
    return false;
  }
  lm.width = size;
  lm.height = size;
  lm.from_file_uv1 = true;
  lm.texels_per_unit =
      world_area > 0.0 ? static_cast<float>(size * std::sqrt(uv_area / world_area)) : 0.0f;
  lm.corner_uv.resize(3 * tris.size());
  for (std::size_t t = 0; t < tris.size(); ++t)
    for (int j = 0; j < 3; ++j)
      lm.corner_uv[3 * t + j] = glm::clamp(mesh.uv1[tris[t][j]], glm::vec2(0.0f), glm::vec2(1.0f)) *
                                static_cast<float>(size);
  lm.chart_count = uv_islands(tris, mesh.positions.size(), lm.triangle_chart);
  return true;
}

}  // namespace irradcast::atlas_detail
