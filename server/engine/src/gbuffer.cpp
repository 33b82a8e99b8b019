// Texel G-buffer: rasterises every object's triangles in lightmap space (centre sampling plus
// conservative coverage; texels whose sample point is cut out hold no estimate), and dilation of
// lightmap values into empty texels.
#include "irradcast/engine/gbuffer.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>

#include <tbb/parallel_for.h>

#include "dilation_plan.h"
#include "irradcast/common/cutout.h"
#include "irradcast/common/error.h"

namespace irradcast {
namespace {

double cross2(glm::dvec2 a, glm::dvec2 b) {
  return a.x * b.y - a.y * b.x;
}

// Closest point of triangle c to p (2D), as barycentrics (u, v) of corners 1 and 2, and the
// squared distance. Works for degenerate triangles too.
double closest_on_triangle(const glm::dvec2* c, glm::dvec2 p, glm::vec2& uv) {
  double area = cross2(c[1] - c[0], c[2] - c[0]);
  if (area != 0.0) {
    double u = cross2(p - c[0], c[2] - c[0]) / area, v = cross2(c[1] - c[0], p - c[0]) / area;
    if (u >= 0.0 && v >= 0.0 && u + v <= 1.0) {
      uv = glm::vec2(static_cast<float>(u), static_cast<float>(v));
      return 0.0;
    }
  }
  double best = std::numeric_limits<double>::infinity();
  for (int e = 0; e < 3; ++e) {
    int i = e, j = (e + 1) % 3;
    glm::dvec2 d = c[j] - c[i];
    double len2 = glm::dot(d, d);
    double s = len2 > 0.0 ? std::clamp(glm::dot(p - c[i], d) / len2, 0.0, 1.0) : 0.0;
    glm::dvec2 q = c[i] + s * d;
    double dist = glm::dot(q - p, q - p);
    if (dist < best) {
      best = dist;
      double w[3] = {0.0, 0.0, 0.0};
      w[i] = 1.0 - s;
      w[j] = s;
      uv = glm::vec2(static_cast<float>(w[1]), static_cast<float>(w[2]));
    }
  }
  return best;
}

// Strict overlap of triangle c with the texel square [x, x+1) x [y, y+1) (separating axes).
bool overlaps_texel(const glm::dvec2* c, int x, int y) {
  double x0 = x, x1 = x + 1.0, y0 = y, y1 = y + 1.0;
  double lx = std::min({c[0].x, c[1].x, c[2].x}), hx = std::max({c[0].x, c[1].x, c[2].x});
  double ly = std::min({c[0].y, c[1].y, c[2].y}), hy = std::max({c[0].y, c[1].y, c[2].y});
  if (hx <= x0 || lx >= x1 || hy <= y0 || ly >= y1) return false;
  for (int e = 0; e < 3; ++e) {
    glm::dvec2 d = c[(e + 1) % 3] - c[e];
    glm::dvec2 axis(-d.y, d.x);
    if (axis.x == 0.0 && axis.y == 0.0) continue;
    double t = glm::dot(axis, c[e]);
    double t2 = glm::dot(axis, c[(e + 2) % 3]);
    double tlo = std::min(t, t2), thi = std::max(t, t2);
    double b[4] = {glm::dot(axis, glm::dvec2(x0, y0)), glm::dot(axis, glm::dvec2(x1, y0)),
                   glm::dot(axis, glm::dvec2(x0, y1)), glm::dot(axis, glm::dvec2(x1, y1))};
    double blo = std::min({b[0], b[1], b[2], b[3]}), bhi = std::max({b[0], b[1], b[2], b[3]});
    if (thi <= blo || bhi <= tlo) return false;
  }
  return true;
}

constexpr int kBand = 16;  // rows per parallel band

// Corners of triangle t in texel units.
void corners(const ObjectLightmap& lm, std::size_t t, glm::dvec2* c) {
  for (int j = 0; j < 3; ++j) c[j] = glm::dvec2(lm.corner_uv[3 * t + j]);
}

// Rows [y0, y1] triangle t covers; false when it covers none (or is NaN).
bool row_range(const ObjectLightmap& lm, int height, std::size_t t, int& y0, int& y1) {
  glm::dvec2 c[3];
  corners(lm, t, c);
  double lo = std::min({c[0].y, c[1].y, c[2].y}), hi = std::max({c[0].y, c[1].y, c[2].y});
  if (!(lo <= hi)) return false;  // NaN
  y0 = static_cast<int>(std::clamp(std::floor(lo), 0.0, height - 1.0));
  y1 = static_cast<int>(std::clamp(std::floor(hi), 0.0, height - 1.0));
  return hi >= 0.0 && lo < height;
}

// Triangles binned into bands of kBand rows (a triangle goes to every band it touches): band b
// holds triangles[start[b] .. start[b + 1]).
struct Bands {
  std::vector<std::size_t> start;
  std::vector<std::uint32_t> triangles;
};

Bands bin_triangles(const ObjectLightmap& lm, int height, std::size_t n) {
  const int bands = (height + kBand - 1) / kBand;
  Bands out;
  std::vector<std::size_t>& bstart = out.start;
  bstart.assign(static_cast<std::size_t>(bands) + 1, 0);
  for (std::size_t t = 0; t < n; ++t) {
    int y0, y1;
    if (!row_range(lm, height, t, y0, y1)) continue;
    for (int b = y0 / kBand; b <= y1 / kBand; ++b) ++bstart[b + 1];
  }
  for (int b = 0; b < bands; ++b) bstart[b + 1] += bstart[b];
  std::vector<std::size_t> bfill(bstart.begin(), bstart.end() - 1);
  out.triangles.resize(bstart.back());
  for (std::size_t t = 0; t < n; ++t) {
    int y0, y1;
    if (!row_range(lm, height, t, y0, y1)) continue;
    for (int b = y0 / kBand; b <= y1 / kBand; ++b)
      out.triangles[bfill[b]++] = static_cast<std::uint32_t>(t);
  }
  return out;
}

// Per texel while rasterising: barycentrics of its sample and its distance to the triangle.
struct Samples {
  std::vector<glm::vec2> bary;
  std::vector<float> dist;
};

// Triangle t (corners c) over rows [band_y0, band_y1]: texels whose centre it covers, and
// texels it only overlaps where no nearer triangle does (conservative).
void rasterize_triangle(const glm::dvec2* c, std::uint32_t t, int band_y0, int band_y1,
                        TexelGBuffer& g, Samples& s) {
  double area = cross2(c[1] - c[0], c[2] - c[0]);
  if (area == 0.0) return;  // no footprint: it keeps its centroid texel (keep_centroids)
  double lx = std::min({c[0].x, c[1].x, c[2].x}), hx = std::max({c[0].x, c[1].x, c[2].x});
  double ly = std::min({c[0].y, c[1].y, c[2].y}), hy = std::max({c[0].y, c[1].y, c[2].y});
  if (!(lx <= hx) || hx < 0.0 || lx >= g.width) return;
  int x0 = static_cast<int>(std::clamp(std::floor(lx), 0.0, g.width - 1.0));
  int x1 = static_cast<int>(std::clamp(std::floor(hx), 0.0, g.width - 1.0));
  int y0 = std::max(band_y0, static_cast<int>(std::clamp(std::floor(ly), 0.0, g.height - 1.0)));
  int y1 = std::min(band_y1, static_cast<int>(std::clamp(std::floor(hy), 0.0, g.height - 1.0)));
  for (int y = y0; y <= y1; ++y) {
    for (int x = x0; x <= x1; ++x) {
      const std::size_t i = static_cast<std::size_t>(y) * g.width + x;
      if (g.kind[i] == TexelKind::Covered) continue;
      glm::dvec2 p(x + 0.5, y + 0.5);
      double u = cross2(p - c[0], c[2] - c[0]) / area;
      double v = cross2(c[1] - c[0], p - c[0]) / area;
      if (u >= 0.0 && v >= 0.0 && u + v <= 1.0) {
        g.kind[i] = TexelKind::Covered;
        g.triangle[i] = static_cast<std::int32_t>(t);
        s.bary[i] = glm::vec2(static_cast<float>(u), static_cast<float>(v));
        s.dist[i] = 0.0f;
        continue;
      }
      if (!overlaps_texel(c, x, y)) continue;
      glm::vec2 uv;
      auto d = static_cast<float>(closest_on_triangle(c, p, uv));
      if (d < s.dist[i] || g.kind[i] == TexelKind::Empty) {
        g.kind[i] = TexelKind::Conservative;
        g.triangle[i] = static_cast<std::int32_t>(t);
        s.bary[i] = uv;
        s.dist[i] = d;
      }
    }
  }
}

// Every triangle keeps at least the texel of its centroid.
void keep_centroids(const ObjectLightmap& lm, std::size_t n, TexelGBuffer& g, Samples& s) {
  for (std::size_t t = 0; t < n; ++t) {
    glm::dvec2 c[3];
    corners(lm, t, c);
    glm::dvec2 m = (c[0] + c[1] + c[2]) / 3.0;
    if (!(m.x >= 0.0 && m.y >= 0.0 && m.x < g.width && m.y < g.height)) continue;
    int x = std::min(g.width - 1, static_cast<int>(m.x));
    int y = std::min(g.height - 1, static_cast<int>(m.y));
    const std::size_t i = static_cast<std::size_t>(y) * g.width + x;
    if (g.kind[i] != TexelKind::Empty) continue;
    glm::vec2 uv;
    closest_on_triangle(c, glm::dvec2(x + 0.5, y + 0.5), uv);
    g.kind[i] = TexelKind::Conservative;
    g.triangle[i] = static_cast<std::int32_t>(t);
    s.bary[i] = uv;
  }
}

// Surface attributes of every valid texel, its sample pulled `inset` toward the centroid. A
// texel whose sample is cut out (cutout.h) becomes Hidden: rays pass through its point, so no
// view shows it; like a texel inside geometry it holds no estimate, no pass traces it, and
// dilation fills it from its neighbours without ever reading it as a value.
void fill_attributes(const World& world, std::size_t oi, float inset, const Samples& s,
                     TexelGBuffer& g) {
  const WorldObject& wo = world.objects[oi];
  const bool cut_outs = has_cut_outs(world, static_cast<int>(oi));
  tbb::parallel_for(0, g.height, [&](int y) {
    for (int x = 0; x < g.width; ++x) {
      const std::size_t i = static_cast<std::size_t>(y) * g.width + x;
      if (g.kind[i] == TexelKind::Empty) continue;
      auto t = static_cast<std::uint32_t>(g.triangle[i]);
      float u = s.bary[i].x, v = s.bary[i].y;
      // Pull the sample a hair toward the triangle's centroid: points exactly on an edge (chart
      // borders put texel centres there) lie in the plane of the neighbouring face too, and rays
      // leaving them would hit that face at t = 0.
      glm::vec3 p = wo.position(t, u, v);
      float to_centroid = glm::length(wo.position(t, 1.0f / 3.0f, 1.0f / 3.0f) - p);
      if (to_centroid > 0.0f) {
        float k = std::min(0.5f, inset / to_centroid);
        u += k * (1.0f / 3.0f - u);
        v += k * (1.0f / 3.0f - v);
      }
      g.bary[i] = glm::vec2(u, v);
      if (cut_outs && cut_out(world, static_cast<int>(oi), t, u, v)) g.kind[i] = TexelKind::Hidden;
    }
  });
}

TexelGBuffer rasterize_object(const World& world, std::size_t oi, const ObjectLightmap& lm) {
  // Inset of sample points into their triangle: a quarter texel, and at least twice the ray
  // offset RayScene uses (1e-4 of the scene size). Off the edge, a sample neither lies in the
  // plane of the neighbouring face nor sits where light sampling of an adjacent emitter has an
  // unbounded 1/d^2 integrand.
  const float inset = std::max(lm.texels_per_unit > 0.0f ? 0.25f / lm.texels_per_unit : 0.0f,
                               2e-4f * std::max(world.bounds.max_extent(), 1e-6f));
  TexelGBuffer g;
  g.width = std::max(0, lm.width);
  g.height = std::max(0, lm.height);
  const std::size_t size = static_cast<std::size_t>(g.width) * static_cast<std::size_t>(g.height);
  g.bary.assign(size, glm::vec2(0.0f));
  g.triangle.assign(size, -1);
  g.kind.assign(size, TexelKind::Empty);
  if (size == 0) return g;
  const std::size_t n = std::min(world.objects[oi].triangles().size(), lm.corner_uv.size() / 3);
  Samples s{std::vector<glm::vec2>(size, glm::vec2(0.0f)),
            std::vector<float>(size, std::numeric_limits<float>::infinity())};
  const Bands bands = bin_triangles(lm, g.height, n);
  tbb::parallel_for(0, static_cast<int>(bands.start.size()) - 1, [&](int b) {
    const int band_y0 = b * kBand, band_y1 = std::min(g.height, band_y0 + kBand) - 1;
    for (std::size_t k = bands.start[b]; k < bands.start[b + 1]; ++k) {
      glm::dvec2 c[3];
      corners(lm, bands.triangles[k], c);
      rasterize_triangle(c, bands.triangles[k], band_y0, band_y1, g, s);
    }
  });
  keep_centroids(lm, n, g, s);
  fill_attributes(world, oi, inset, s, g);
  return g;
}

}  // namespace

TexelPoint TexelGBuffer::point(const WorldObject& object, std::size_t i) const {
  if (triangle[i] < 0) return {};
  const auto t = static_cast<std::uint32_t>(triangle[i]);
  TexelPoint p;
  p.position = object.position(t, bary[i].x, bary[i].y);
  p.normal = object.shading_normal(t, bary[i].x, bary[i].y);
  p.geo_normal = object.geometric_normal(t);
  if (glm::dot(p.geo_normal, p.normal) < 0.0f) p.geo_normal = -p.geo_normal;
  return p;
}

glm::vec3 TexelGBuffer::position(const WorldObject& object, std::size_t i) const {
  if (triangle[i] < 0) return glm::vec3(0.0f);
  return object.position(static_cast<std::uint32_t>(triangle[i]), bary[i].x, bary[i].y);
}

std::size_t TexelGBuffer::valid_count() const {
  return static_cast<std::size_t>(std::count_if(kind.begin(), kind.end(), holds_estimate));
}

std::vector<TexelGBuffer> rasterize_gbuffer(const World& world, const Atlas& atlas) {
  if (atlas.objects.size() != world.objects.size())
    throw Error("rasterize_gbuffer: the atlas has " + std::to_string(atlas.objects.size()) +
                " lightmaps for " + std::to_string(world.objects.size()) + " objects");
  std::vector<TexelGBuffer> out(atlas.objects.size());
  tbb::parallel_for(std::size_t(0), atlas.objects.size(), [&](std::size_t oi) {
    out[oi] = rasterize_object(world, oi, atlas.objects[oi]);
  });
  return out;
}

void rasterize_gbuffer(const World& world, const Atlas& atlas, std::vector<TexelGBuffer>& gbuffers,
                       const std::vector<std::uint8_t>& which) {
  if (atlas.objects.size() != world.objects.size() || gbuffers.size() != world.objects.size())
    throw Error("rasterize_gbuffer: the atlas or G-buffers do not match the scene's objects");
  tbb::parallel_for(std::size_t(0), atlas.objects.size(), [&](std::size_t oi) {
    if (oi < which.size() && which[oi])
      gbuffers[oi] = rasterize_object(world, oi, atlas.objects[oi]);
  });
}

void dilate(std::vector<glm::vec3>& texels, int width, int height,
            const std::vector<TexelKind>& valid, int rings) {
  const std::size_t size =
      static_cast<std::size_t>(std::max(0, width)) * static_cast<std::size_t>(std::max(0, height));
  if (texels.size() != size)
    throw Error("dilate: buffer sizes do not match the " + std::to_string(width) + "x" +
                std::to_string(height) + " lightmap");
  DilationPlan(width, height, valid, rings).apply(texels);
}

}  // namespace irradcast
