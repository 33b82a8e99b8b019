// Lightmap atlas (charts, packing, TEXCOORD_1), texel G-buffer and dilation, on procedural meshes.
#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <limits>
#include <set>
#include <string>
#include <vector>

#include <glm/gtc/matrix_transform.hpp>

#include "irradcast/common/atlas.h"
#include "irradcast/common/scene.h"
#include "irradcast/common/world.h"
#include "irradcast/engine/gbuffer.h"

namespace irradcast::test_atlas {

namespace {

constexpr float kPi = 3.14159265358979f;

// ---- procedural meshes --------------------------------------------------------------------------

void add_quad(Mesh& m, glm::vec3 a, glm::vec3 b, glm::vec3 c, glm::vec3 d, glm::vec3 n) {
  auto base = static_cast<unsigned>(m.positions.size());
  for (glm::vec3 p : {a, b, c, d}) {
    m.positions.push_back(p);
    m.normals.push_back(n);
  }
  m.triangles.push_back({base, base + 1, base + 2});
  m.triangles.push_back({base, base + 2, base + 3});
}

// Axis-aligned cube of half-size h, 24 vertices (split per face, as files store it).
Mesh make_cube(float h = 1.0f) {
  Mesh m;
  m.name = "cube";
  for (int axis = 0; axis < 3; ++axis)
    for (float s : {-1.0f, 1.0f}) {
      glm::vec3 n(0.0f);
      n[axis] = s;
      glm::vec3 u(0.0f), v(0.0f);
      u[(axis + 1) % 3] = 1.0f;
      v[(axis + 2) % 3] = 1.0f;
      if (s < 0.0f) std::swap(u, v);  // keep counter-clockwise seen from outside
      glm::vec3 c = n * h;
      add_quad(m, c - h * u - h * v, c + h * u - h * v, c + h * u + h * v, c - h * u + h * v, n);
    }
  m.triangle_material.assign(m.triangles.size(), 0);
  return m;
}

// Every triangle with its own three vertices (a "triangle soup" that only welding reconnects).
Mesh unshare(const Mesh& in) {
  Mesh m;
  m.name = in.name + "_unshared";
  for (const glm::uvec3& t : in.triangles) {
    auto base = static_cast<unsigned>(m.positions.size());
    for (int k = 0; k < 3; ++k) {
      m.positions.push_back(in.positions[t[k]]);
      if (!in.normals.empty()) m.normals.push_back(in.normals[t[k]]);
    }
    m.triangles.push_back({base, base + 1, base + 2});
  }
  m.triangle_material.assign(m.triangles.size(), 0);
  return m;
}

// UV sphere: (stacks + 1) x (slices + 1) vertices (seam and pole vertices duplicated), smooth
// normals, one triangle per quad at the poles.
Mesh make_sphere(float r, int stacks, int slices) {
  Mesh m;
  m.name = "sphere";
  for (int i = 0; i <= stacks; ++i) {
    float th = kPi * static_cast<float>(i) / static_cast<float>(stacks);
    for (int j = 0; j <= slices; ++j) {
      float ph = 2.0f * kPi * static_cast<float>(j) / static_cast<float>(slices);
      glm::vec3 n(std::sin(th) * std::cos(ph), std::sin(th) * std::sin(ph), std::cos(th));
      if (j == slices) {  // the seam: same position as j = 0, bit for bit
        n = m.positions[static_cast<std::size_t>(i) * (slices + 1)] / r;
      }
      if (i == 0 || i == stacks) n = glm::vec3(0.0f, 0.0f, i == 0 ? 1.0f : -1.0f);
      m.positions.push_back(r * n);
      m.normals.push_back(n);
    }
  }
  auto at = [&](int i, int j) { return static_cast<unsigned>(i * (slices + 1) + j); };
  for (int i = 0; i < stacks; ++i)
    for (int j = 0; j < slices; ++j) {
      // Counter-clockwise seen from outside.
      if (i != 0) m.triangles.push_back({at(i, j), at(i + 1, j), at(i, j + 1)});
      if (i != stacks - 1) m.triangles.push_back({at(i, j + 1), at(i + 1, j), at(i + 1, j + 1)});
    }
  m.triangle_material.assign(m.triangles.size(), 0);
  return m;
}

// Flat grid in z = 0 covering [0, size]^2 with nx x ny quads; uv1 = position / size if asked.
Mesh make_grid(int nx, int ny, float size, bool with_uv1 = false) {
  Mesh m;
  m.name = "grid";
  for (int j = 0; j <= ny; ++j)
    for (int i = 0; i <= nx; ++i) {
      glm::vec2 q(size * static_cast<float>(i) / static_cast<float>(nx),
                  size * static_cast<float>(j) / static_cast<float>(ny));
      m.positions.emplace_back(q, 0.0f);
      m.normals.emplace_back(0.0f, 0.0f, 1.0f);
      if (with_uv1) m.uv1.push_back(q / size);
    }
  auto at = [&](int i, int j) { return static_cast<unsigned>(j * (nx + 1) + i); };
  for (int j = 0; j < ny; ++j)
    for (int i = 0; i < nx; ++i) {
      m.triangles.push_back({at(i, j), at(i + 1, j), at(i + 1, j + 1)});
      m.triangles.push_back({at(i, j), at(i + 1, j + 1), at(i, j + 1)});
    }
  m.triangle_material.assign(m.triangles.size(), 0);
  return m;
}

// A scene of meshes, each placed by its own node.
struct TestScene {
  Scene scene;
  World world;
  void add(Mesh mesh, glm::mat4 transform = glm::mat4(1.0f)) {
    if (scene.materials.empty()) {
      Material mat;
      mat.base_color = glm::vec3(0.25f, 0.5f, 0.75f);
      scene.materials.push_back(mat);
    }
    mesh.triangle_material.assign(mesh.triangles.size(), 0);
    scene.meshes.push_back(std::move(mesh));
    Node node;
    node.local = transform;
    node.mesh = static_cast<int>(scene.meshes.size()) - 1;
    scene.add_node(node);
  }
  void build() { world = World::build(scene); }
};

// ---- independent geometric checks ---------------------------------------------------------------

double cross2(glm::dvec2 a, glm::dvec2 b) {
  return a.x * b.y - a.y * b.x;
}

// Area of triangle c inside the texel square [x, x+1] x [y, y+1] (Sutherland-Hodgman clipping).
double clipped_area(const glm::vec2* c, int x, int y) {
  std::vector<glm::dvec2> poly = {glm::dvec2(c[0]), glm::dvec2(c[1]), glm::dvec2(c[2])};
  if (cross2(poly[1] - poly[0], poly[2] - poly[0]) < 0.0) std::swap(poly[1], poly[2]);
  auto clip = [&](auto inside, auto cut) {
    std::vector<glm::dvec2> out;
    for (std::size_t i = 0; i < poly.size(); ++i) {
      glm::dvec2 a = poly[i], b = poly[(i + 1) % poly.size()];
      bool ia = inside(a), ib = inside(b);
      if (ia) out.push_back(a);
      if (ia != ib) out.push_back(cut(a, b));
    }
    poly = out;
  };
  auto cut_x = [](double X) {
    return [X](glm::dvec2 a, glm::dvec2 b) {
      double t = (X - a.x) / (b.x - a.x);
      return glm::dvec2(X, a.y + t * (b.y - a.y));
    };
  };
  auto cut_y = [](double Y) {
    return [Y](glm::dvec2 a, glm::dvec2 b) {
      double t = (Y - a.y) / (b.y - a.y);
      return glm::dvec2(a.x + t * (b.x - a.x), Y);
    };
  };
  clip([&](glm::dvec2 p) { return p.x >= x; }, cut_x(x));
  clip([&](glm::dvec2 p) { return p.x <= x + 1.0; }, cut_x(x + 1.0));
  clip([&](glm::dvec2 p) { return p.y >= y; }, cut_y(y));
  clip([&](glm::dvec2 p) { return p.y <= y + 1.0; }, cut_y(y + 1.0));
  double a = 0.0;
  for (std::size_t i = 0; i + 2 < poly.size() + 1 && poly.size() >= 3; ++i)
    a += cross2(poly[i] - poly[0], poly[(i + 1) % poly.size()] - poly[0]);
  return 0.5 * std::abs(a);
}

// Barycentrics of p in triangle c (weights of corners 0, 1, 2); false if degenerate.
bool barycentric(const glm::vec2* c, glm::dvec2 p, glm::dvec3& w) {
  glm::dvec2 a(c[0]), b(c[1]), d(c[2]);
  double area = cross2(b - a, d - a);
  if (area == 0.0) return false;
  double u = cross2(p - a, d - a) / area, v = cross2(b - a, p - a) / area;
  w = glm::dvec3(1.0 - u - v, u, v);
  return true;
}

// Distance from p to triangle abc in 3D (Ericson's closest point).
float point_triangle_distance(glm::vec3 p, glm::vec3 a, glm::vec3 b, glm::vec3 c) {
  glm::vec3 ab = b - a, ac = c - a, ap = p - a;
  float d1 = glm::dot(ab, ap), d2 = glm::dot(ac, ap);
  if (d1 <= 0 && d2 <= 0) return glm::length(p - a);
  glm::vec3 bp = p - b;
  float d3 = glm::dot(ab, bp), d4 = glm::dot(ac, bp);
  if (d3 >= 0 && d4 <= d3) return glm::length(p - b);
  float vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0) return glm::length(p - (a + d1 / (d1 - d3) * ab));
  glm::vec3 cp = p - c;
  float d5 = glm::dot(ab, cp), d6 = glm::dot(ac, cp);
  if (d6 >= 0 && d5 <= d6) return glm::length(p - c);
  float vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0) return glm::length(p - (a + d2 / (d2 - d6) * ac));
  float va = d3 * d6 - d5 * d4;
  if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0)
    return glm::length(p - (b + (d4 - d3) / ((d4 - d3) + (d5 - d6)) * (c - b)));
  float denom = 1.0f / (va + vb + vc);
  return glm::length(p - (a + ab * (vb * denom) + ac * (vc * denom)));
}

// Closest point of triangle c (lightmap space) to p, as weights of the corners, and its distance.
double closest_point(const glm::vec2* c, glm::dvec2 p, glm::dvec3& w) {
  if (barycentric(c, p, w) && w.x >= 0.0 && w.y >= 0.0 && w.z >= 0.0) return 0.0;
  double best = std::numeric_limits<double>::infinity();
  for (int e = 0; e < 3; ++e) {
    glm::dvec2 a(c[e]), b(c[(e + 1) % 3]);
    double len2 = glm::dot(b - a, b - a);
    double s = len2 > 0.0 ? std::clamp(glm::dot(p - a, b - a) / len2, 0.0, 1.0) : 0.0;
    double d = glm::length(a + s * (b - a) - p);
    if (d < best) {
      best = d;
      w = glm::dvec3(0.0);
      w[e] = 1.0 - s;
      w[(e + 1) % 3] = s;
    }
  }
  return best;
}

struct Footprint {
  std::vector<int> chart;          // chart of the triangles overlapping each texel, -1 none
  std::vector<int> centre_claims;  // triangles strictly containing each texel centre
  std::vector<double> nearest;     // distance from the centre to the nearest overlapping triangle
  std::size_t overlapped = 0;      // texels with any triangle area
  int cross_chart_texels = 0;      // texels overlapped by two charts
  int double_claims = 0;           // texel centres strictly inside two triangles
};

// Rasterises the lightmap coordinates independently of the implementation.
Footprint footprint(const ObjectLightmap& lm) {
  Footprint f;
  std::size_t size = static_cast<std::size_t>(lm.width) * lm.height;
  f.chart.assign(size, -1);
  f.centre_claims.assign(size, 0);
  f.nearest.assign(size, std::numeric_limits<double>::infinity());
  std::size_t n = lm.corner_uv.size() / 3;
  for (std::size_t t = 0; t < n; ++t) {
    const glm::vec2* c = &lm.corner_uv[3 * t];
    glm::vec2 lo = glm::min(c[0], glm::min(c[1], c[2])), hi = glm::max(c[0], glm::max(c[1], c[2]));
    for (int y = std::max(0, static_cast<int>(lo.y));
         y <= std::min(lm.height - 1, static_cast<int>(hi.y)); ++y)
      for (int x = std::max(0, static_cast<int>(lo.x));
           x <= std::min(lm.width - 1, static_cast<int>(hi.x)); ++x) {
        std::size_t i = static_cast<std::size_t>(y) * lm.width + x;
        if (clipped_area(c, x, y) > 1e-9) {
          int ch = static_cast<int>(lm.triangle_chart[t]);
          if (f.chart[i] >= 0 && f.chart[i] != ch) ++f.cross_chart_texels;
          if (f.chart[i] < 0) ++f.overlapped;
          f.chart[i] = ch;
          glm::dvec3 w;
          f.nearest[i] = std::min(f.nearest[i], closest_point(c, glm::dvec2(x + 0.5, y + 0.5), w));
        }
        glm::dvec3 w;
        if (barycentric(c, glm::dvec2(x + 0.5, y + 0.5), w) && w.x > 1e-4 && w.y > 1e-4 &&
            w.z > 1e-4) {
          if (++f.centre_claims[i] == 2) ++f.double_claims;
        }
      }
  }
  return f;
}

// Smallest Chebyshev distance between texels of two different charts (large if < 2 charts).
int min_chart_separation(const ObjectLightmap& lm, const Footprint& f, int radius) {
  int best = radius + 1;
  for (int y = 0; y < lm.height; ++y)
    for (int x = 0; x < lm.width; ++x) {
      int a = f.chart[static_cast<std::size_t>(y) * lm.width + x];
      if (a < 0) continue;
      for (int dy = -radius; dy <= radius; ++dy)
        for (int dx = -radius; dx <= radius; ++dx) {
          int nx = x + dx, ny = y + dy;
          if (nx < 0 || ny < 0 || nx >= lm.width || ny >= lm.height) continue;
          int b = f.chart[static_cast<std::size_t>(ny) * lm.width + nx];
          if (b >= 0 && b != a) best = std::min(best, std::max(std::abs(dx), std::abs(dy)));
        }
    }
  return best;
}

// The atlas invariants for one object: coordinates inside the map, no overlap within or across
// charts, charts at least `gutter` empty texels apart (generated charts only).
void expect_valid_lightmap(const ObjectLightmap& lm, std::size_t triangles, int gutter) {
  ASSERT_EQ(lm.corner_uv.size(), 3 * triangles);
  ASSERT_EQ(lm.triangle_chart.size(), triangles);
  ASSERT_GT(lm.width, 0);
  ASSERT_GT(lm.height, 0);
  for (glm::vec2 q : lm.corner_uv) {
    ASSERT_GE(q.x, 0.0f);
    ASSERT_GE(q.y, 0.0f);
    ASSERT_LE(q.x, static_cast<float>(lm.width));
    ASSERT_LE(q.y, static_cast<float>(lm.height));
  }
  std::set<std::uint32_t> charts(lm.triangle_chart.begin(), lm.triangle_chart.end());
  EXPECT_EQ(static_cast<int>(charts.size()), lm.chart_count);
  Footprint f = footprint(lm);
  EXPECT_EQ(f.cross_chart_texels, 0) << "texels overlapped by two charts";
  EXPECT_EQ(f.double_claims, 0) << "texel centres inside two triangles";
  if (!lm.from_file_uv1) {
    EXPECT_GT(min_chart_separation(lm, f, gutter), gutter) << "charts closer than the gutter";
    // The gutter also runs along the border.
    for (int y = 0; y < lm.height; ++y)
      for (int x = 0; x < lm.width; ++x)
        if (x < gutter || y < gutter || x >= lm.width - gutter || y >= lm.height - gutter) {
          ASSERT_LT(f.chart[static_cast<std::size_t>(y) * lm.width + x], 0) << x << "," << y;
        }
  }
}

// The G-buffer invariants for one object.
void expect_valid_gbuffer(const World& world, std::size_t oi, const ObjectLightmap& lm,
                          const TexelGBuffer& g, float position_tol) {
  const WorldObject& wo = world.objects[oi];
  const auto& tris = wo.triangles();
  // Samples are pulled up to a quarter texel (at least 2e-4 of the scene size) into their
  // triangle, off shared edges, so the sampled point may sit that far from the texel-centre point.
  const float sample_tol =
      position_tol + std::max(0.26f / lm.texels_per_unit, 2.5e-4f * world.bounds.max_extent());
  ASSERT_EQ(g.width, lm.width);
  ASSERT_EQ(g.height, lm.height);
  ASSERT_EQ(g.size(), static_cast<std::size_t>(lm.width) * lm.height);
  // Every triangle's centroid texel is valid.
  int missing = 0;
  std::vector<std::uint8_t> centroid_texel(g.size(), 0);
  for (std::size_t t = 0; t < tris.size(); ++t) {
    glm::vec2 m = (lm.corner_uv[3 * t] + lm.corner_uv[3 * t + 1] + lm.corner_uv[3 * t + 2]) / 3.0f;
    std::size_t i = static_cast<std::size_t>(m.y) * g.width + static_cast<std::size_t>(m.x);
    centroid_texel[i] = 1;
    if (!g.valid(i)) ++missing;
  }
  EXPECT_EQ(missing, 0) << "triangles without a texel";
  int bad_kind = 0, bad_position = 0, bad_normal = 0, missed = 0, extra = 0, not_nearest = 0;
  Footprint f = footprint(lm);
  for (int y = 0; y < g.height; ++y)
    for (int x = 0; x < g.width; ++x) {
      std::size_t i = static_cast<std::size_t>(y) * g.width + x;
      if (!g.valid(i)) {
        if (g.triangle[i] != -1) ++bad_kind;
        if (f.chart[i] >= 0) ++missed;  // a triangle overlaps it: should be conservative
        continue;
      }
      if (g.triangle[i] < 0 || static_cast<std::size_t>(g.triangle[i]) >= tris.size()) {
        ++bad_kind;
        continue;
      }
      auto t = static_cast<std::uint32_t>(g.triangle[i]);
      const glm::vec2* c = &lm.corner_uv[3 * t];
      glm::dvec3 w(0.0);  // set by barycentric(); GCC 12 -O3 cannot tell
      bool nondegenerate = barycentric(c, glm::dvec2(x + 0.5, y + 0.5), w);
      bool centre_inside = nondegenerate && w.x >= -1e-5 && w.y >= -1e-5 && w.z >= -1e-5;
      if (g.kind[i] == TexelKind::Covered) {
        if (!centre_inside) ++bad_kind;
        // Position is the surface point at the texel centre.
        glm::vec3 p = wo.position(t, static_cast<float>(w.y), static_cast<float>(w.z));
        if (glm::length(p - g.position(wo, i)) > sample_tol) ++bad_position;
      } else {
        // Conservative: the triangle overlaps the texel (or it is the triangle's centroid texel)
        // and no triangle contains the centre.
        if (f.centre_claims[i] > 0) ++bad_kind;
        if (clipped_area(c, x, y) <= 0.0 && !centroid_texel[i]) ++extra;
        // It samples its triangle's point closest to the centre, and no triangle overlapping the
        // texel comes closer.
        glm::dvec3 cw;
        double d = closest_point(c, glm::dvec2(x + 0.5, y + 0.5), cw);
        if (d > f.nearest[i] + 1e-4) ++not_nearest;
        glm::vec3 p = wo.position(t, static_cast<float>(cw.y), static_cast<float>(cw.z));
        if (glm::length(p - g.position(wo, i)) > sample_tol) ++bad_position;
      }
      const glm::uvec3& tri = tris[t];
      float d = point_triangle_distance(g.position(wo, i), wo.positions[tri.x], wo.positions[tri.y],
                                        wo.positions[tri.z]);
      if (d > position_tol) ++bad_position;
      glm::vec3 n = g.point(wo, i).normal;
      if (std::abs(glm::length(n) - 1.0f) > 1e-3f || glm::dot(n, wo.geometric_normal(t)) < 0.5f)
        ++bad_normal;
    }
  EXPECT_EQ(bad_kind, 0);
  EXPECT_EQ(bad_position, 0);
  EXPECT_EQ(bad_normal, 0);
  EXPECT_EQ(missed, 0) << "texels a triangle overlaps left empty";
  EXPECT_EQ(extra, 0) << "conservative texels no triangle overlaps";
  EXPECT_EQ(not_nearest, 0) << "conservative texels not sampling the nearest triangle";
}

}  // namespace

// ---- atlas --------------------------------------------------------------------------------------

TEST(Atlas, CubeGetsSixIsometricChartsWithGutters) {
  TestScene ts;
  ts.add(make_cube(1.0f));
  ts.build();
  AtlasOptions opt;
  opt.texels_per_scene = 32.0f;  // 16 texels per unit
  Atlas atlas = build_atlas(ts.world, opt);
  ASSERT_EQ(atlas.objects.size(), 1u);
  const ObjectLightmap& lm = atlas.objects[0];
  EXPECT_EQ(lm.chart_count, 6);
  EXPECT_FALSE(lm.from_file_uv1);
  EXPECT_FLOAT_EQ(lm.texels_per_unit, 16.0f);
  expect_valid_lightmap(lm, 12, opt.gutter);
  // Flat charts are isometric: lightmap edge lengths are world lengths times the density.
  const WorldObject& wo = ts.world.objects[0];
  for (std::uint32_t t = 0; t < 12; ++t)
    for (int k = 0; k < 3; ++k) {
      float uv_len = glm::length(lm.corner_uv[3 * t + k] - lm.corner_uv[3 * t + (k + 1) % 3]);
      float world_len = glm::length(wo.positions[wo.triangles()[t][k]] -
                                    wo.positions[wo.triangles()[t][(k + 1) % 3]]);
      EXPECT_NEAR(uv_len, 16.0f * world_len, 1e-3f);
    }
  // Both triangles of a face are in the same chart; faces in different ones.
  for (std::uint32_t f = 0; f < 6; ++f)
    EXPECT_EQ(lm.triangle_chart[2 * f], lm.triangle_chart[2 * f + 1]);
  // Six 32x32 faces plus gutters: utilisation well above a third.
  double used = 6.0 * 32.0 * 32.0;
  EXPECT_GT(used / (static_cast<double>(lm.width) * lm.height), 0.45);
}

TEST(Atlas, WeldsSplitVerticesIntoCharts) {
  TestScene ts;
  ts.add(unshare(make_cube(1.0f)));
  ts.add(unshare(make_grid(8, 8, 2.0f)), glm::translate(glm::mat4(1.0f), glm::vec3(3, 0, 0)));
  ts.build();
  Atlas atlas = build_atlas(ts.world);
  EXPECT_EQ(atlas.objects[0].chart_count, 6);  // 12 without welding
  EXPECT_EQ(atlas.objects[1].chart_count, 1);  // 128 without welding
  expect_valid_lightmap(atlas.objects[0], 12, 2);
  expect_valid_lightmap(atlas.objects[1], 128, 2);
}

TEST(Atlas, SphereChartsRespectTheNormalCone) {
  TestScene ts;
  ts.add(make_sphere(1.0f, 24, 48));
  ts.build();
  AtlasOptions opt;
  opt.texels_per_scene = 128.0f;
  Atlas atlas = build_atlas(ts.world, opt);
  const ObjectLightmap& lm = atlas.objects[0];
  const WorldObject& wo = ts.world.objects[0];
  expect_valid_lightmap(lm, wo.triangles().size(), opt.gutter);
  EXPECT_GT(lm.chart_count, 6);
  // Each chart's triangles stay within (about) the cone around the chart's mean normal.
  std::vector<glm::vec3> mean(lm.chart_count, glm::vec3(0.0f));
  for (std::uint32_t t = 0; t < wo.triangles().size(); ++t)
    mean[lm.triangle_chart[t]] += wo.geometric_normal(t) * wo.area(t);
  float worst = 1.0f;
  for (std::uint32_t t = 0; t < wo.triangles().size(); ++t)
    worst = std::min(worst,
                     glm::dot(glm::normalize(mean[lm.triangle_chart[t]]), wo.geometric_normal(t)));
  EXPECT_GE(worst, std::cos(glm::radians(45.0f)) - 1e-4f);
}

TEST(Atlas, FoldingChartsAreSplit) {
  // With an almost unbounded normal cone the whole sphere grows into one chart, whose projection
  // folds over itself: it must be split until no triangle overlaps another in 2D.
  TestScene ts;
  ts.add(make_sphere(1.0f, 16, 32));
  ts.build();
  AtlasOptions opt;
  opt.texels_per_scene = 96.0f;
  opt.chart_max_angle_deg = 179.0f;
  Atlas atlas = build_atlas(ts.world, opt);
  const ObjectLightmap& lm = atlas.objects[0];
  EXPECT_GT(lm.chart_count, 1);
  expect_valid_lightmap(lm, ts.world.objects[0].triangles().size(), opt.gutter);
  // A helicoid ramp (two full turns): every normal within 45 degrees of up, yet it overlaps
  // itself seen from above.
  Mesh ramp;
  const int steps = 200;
  for (int i = 0; i <= steps; ++i) {
    float a = 4.0f * kPi * static_cast<float>(i) / steps;
    glm::vec3 d(std::cos(a), std::sin(a), 0.0f);
    float z = 0.4f * a / (2.0f * kPi);
    ramp.positions.push_back(0.5f * d + glm::vec3(0, 0, z));
    ramp.positions.push_back(1.0f * d + glm::vec3(0, 0, z));
  }
  for (unsigned i = 0; i < static_cast<unsigned>(steps); ++i) {
    ramp.triangles.push_back({2 * i, 2 * i + 1, 2 * i + 3});
    ramp.triangles.push_back({2 * i, 2 * i + 3, 2 * i + 2});
  }
  TestScene ts2;
  ts2.add(ramp);
  ts2.build();
  AtlasOptions opt2;
  opt2.texels_per_scene = 64.0f;
  Atlas atlas2 = build_atlas(ts2.world, opt2);
  EXPECT_GE(atlas2.objects[0].chart_count, 2);
  expect_valid_lightmap(atlas2.objects[0], ramp.triangles.size(), opt2.gutter);
}

TEST(Atlas, DensityFollowsSceneSizeAndCapIsRespected) {
  TestScene ts;
  ts.add(make_cube(1.0f));                                                              // 2 units
  ts.add(make_grid(4, 4, 16.0f), glm::translate(glm::mat4(1.0f), glm::vec3(4, 0, 0)));  // 16
  ts.build();
  AtlasOptions opt;
  opt.texels_per_scene = 512.0f;  // scene extent 20 -> 25.6 texels per unit
  opt.max_lightmap_size = 128;
  Atlas atlas = build_atlas(ts.world, opt);
  float base = atlas_base_density(ts.world, opt);
  EXPECT_NEAR(base, 512.0f / ts.world.bounds.max_extent(), 1e-4f);
  // Neither the cube (6 faces of ~52 texels) nor the grid (16 units -> 410 texels) fits in 128.
  for (const ObjectLightmap& lm : atlas.objects) {
    EXPECT_LE(lm.width, 128);
    EXPECT_LE(lm.height, 128);
    EXPECT_LE(lm.texels_per_unit, base);
  }
  // The grid is one chart: its side is about its world size times the reduced density, and the
  // reduction is not wasteful (the chart fills most of the cap).
  const ObjectLightmap& grid = atlas.objects[1];
  EXPECT_EQ(grid.chart_count, 1);
  EXPECT_LT(grid.texels_per_unit, base * 0.5f);
  EXPECT_GT(16.0f * grid.texels_per_unit, 128.0f - 2.0f * 2.0f - 4.0f);
  expect_valid_lightmap(grid, 32, 2);
  expect_valid_lightmap(atlas.objects[0], 12, 2);
  // Without a binding cap the same cube gets the full density.
  opt.max_lightmap_size = 1024;
  Atlas free = build_atlas(ts.world, opt);
  EXPECT_FLOAT_EQ(free.objects[0].texels_per_unit, base);
  EXPECT_FLOAT_EQ(free.objects[1].texels_per_unit, base);
  EXPECT_GT(free.objects[1].width, 128);
}

TEST(Atlas, EveryChartGetsAtLeastOneTexel) {
  // Many tiny disconnected triangles far below a texel each: every chart is a 1x1 cell.
  Mesh soup;
  for (int i = 0; i < 50; ++i) {
    glm::vec3 o(static_cast<float>(i % 10), static_cast<float>(i / 10), 0.0f);
    auto b = static_cast<unsigned>(soup.positions.size());
    soup.positions.push_back(o);
    soup.positions.push_back(o + glm::vec3(0.01f, 0, 0));
    soup.positions.push_back(o + glm::vec3(0, 0.01f, 0.005f * static_cast<float>(i % 3)));
    soup.triangles.push_back({b, b + 1, b + 2});
  }
  // And a zero-area (collinear) triangle on its own: it has no footprint, only its centroid.
  auto b = static_cast<unsigned>(soup.positions.size());
  soup.positions.push_back(glm::vec3(5.5f, 2.5f, 0.0f));
  soup.positions.push_back(glm::vec3(5.6f, 2.5f, 0.0f));
  soup.positions.push_back(glm::vec3(5.8f, 2.5f, 0.0f));
  soup.triangles.push_back({b, b + 1, b + 2});
  TestScene ts;
  ts.add(soup);
  ts.build();
  AtlasOptions opt;
  opt.texels_per_scene = 10.0f;  // ~1 texel per unit: each triangle is 1% of a texel wide
  Atlas atlas = build_atlas(ts.world, opt);
  const ObjectLightmap& lm = atlas.objects[0];
  EXPECT_EQ(lm.chart_count, 51);
  expect_valid_lightmap(lm, 51, opt.gutter);
  auto g = rasterize_gbuffer(ts.world, atlas);
  expect_valid_gbuffer(ts.world, 0, lm, g[0], 1e-4f);
  EXPECT_GE(g[0].valid_count(), 51u);
  // 51 cells of (1 + gutter)^2 plus the border: about a 22x22 map at best.
  EXPECT_LE(static_cast<std::size_t>(lm.width) * lm.height, 51u * 9u * 2u);
}

TEST(Atlas, UsesValidTexcoord1) {
  TestScene ts;
  ts.add(make_grid(10, 10, 2.0f, /*with_uv1=*/true));
  ts.build();
  AtlasOptions opt;
  opt.texels_per_scene = 64.0f;
  Atlas atlas = build_atlas(ts.world, opt);
  const ObjectLightmap& lm = atlas.objects[0];
  ASSERT_TRUE(lm.from_file_uv1);
  EXPECT_EQ(lm.chart_count, 1);
  EXPECT_EQ(lm.width, 64);  // 2 units at 32 texels per unit, uv covering the whole square
  EXPECT_EQ(lm.height, 64);
  const Mesh& mesh = ts.scene.meshes[0];
  for (std::size_t t = 0; t < mesh.triangles.size(); ++t)
    for (int k = 0; k < 3; ++k)
      EXPECT_EQ(lm.corner_uv[3 * t + k], mesh.uv1[mesh.triangles[t][k]] * 64.0f);
  expect_valid_lightmap(lm, mesh.triangles.size(), 2);
  auto g = rasterize_gbuffer(ts.world, atlas);
  expect_valid_gbuffer(ts.world, 0, lm, g[0], 1e-4f);
  // Ignored on request.
  opt.use_file_uv1 = false;
  EXPECT_FALSE(build_atlas(ts.world, opt).objects[0].from_file_uv1);
}

TEST(Atlas, RejectsOverlappingOrOutOfRangeTexcoord1) {
  // Every quad of a 6x6 grid mapped onto the whole unit square (vertices split per triangle, as
  // exporters do): massively overlapping.
  Mesh overlapping = unshare(make_grid(6, 6, 1.0f));
  for (const glm::uvec3& t : overlapping.triangles) {
    glm::vec3 centroid =
        (overlapping.positions[t.x] + overlapping.positions[t.y] + overlapping.positions[t.z]) *
        2.0f;  // x 6 / 3
    glm::vec2 cell = glm::floor(glm::vec2(centroid));
    for (int k = 0; k < 3; ++k)
      overlapping.uv1.push_back(
          glm::clamp(glm::vec2(overlapping.positions[t[k]]) * 6.0f - cell, 0.0f, 1.0f));
  }
  Mesh out_of_range = make_grid(4, 4, 1.0f, true);
  out_of_range.uv1[3] = glm::vec2(1.5f, 0.2f);
  Mesh good = make_grid(4, 4, 1.0f, true);

  TestScene ts;
  ts.add(overlapping);
  ts.add(out_of_range, glm::translate(glm::mat4(1.0f), glm::vec3(2, 0, 0)));
  ts.add(good, glm::translate(glm::mat4(1.0f), glm::vec3(4, 0, 0)));
  ts.build();
  testing::internal::CaptureStderr();
  Atlas atlas = build_atlas(ts.world);
  std::string err = testing::internal::GetCapturedStderr();
  EXPECT_FALSE(atlas.objects[0].from_file_uv1);
  EXPECT_FALSE(atlas.objects[1].from_file_uv1);
  EXPECT_TRUE(atlas.objects[2].from_file_uv1);
  EXPECT_NE(err.find("overlaps"), std::string::npos) << err;
  EXPECT_NE(err.find("outside [0,1]"), std::string::npos) << err;
  EXPECT_NE(err.find("WARN"), std::string::npos) << err;
  // The replacements are proper generated charts.
  EXPECT_EQ(atlas.objects[0].chart_count, 1);
  expect_valid_lightmap(atlas.objects[0], ts.world.objects[0].triangles().size(), 2);
  expect_valid_lightmap(atlas.objects[1], ts.world.objects[1].triangles().size(), 2);
}

TEST(Atlas, SeveralObjectsEachGetTheirOwnLightmap) {
  TestScene ts;
  ts.add(make_cube(0.5f), glm::rotate(glm::mat4(1.0f), 0.7f, glm::vec3(1, 2, 3)));
  ts.add(make_sphere(0.75f, 12, 24), glm::translate(glm::mat4(1.0f), glm::vec3(2, 0, 0)));
  ts.add(make_grid(20, 5, 3.0f),
         glm::translate(glm::scale(glm::mat4(1.0f), glm::vec3(1, 2, 1)), glm::vec3(-1, -1, -1)));
  ts.add(make_cube(0.25f), glm::translate(glm::mat4(1.0f), glm::vec3(0, 3, 0)));
  ts.build();
  Atlas atlas = build_atlas(ts.world);
  ASSERT_EQ(atlas.objects.size(), 4u);
  std::size_t texels = 0;
  for (std::size_t o = 0; o < 4; ++o) {
    SCOPED_TRACE(o);
    expect_valid_lightmap(atlas.objects[o], ts.world.objects[o].triangles().size(), 2);
    texels += static_cast<std::size_t>(atlas.objects[o].width) * atlas.objects[o].height;
  }
  EXPECT_EQ(atlas.texel_count(), texels);
  // Same density everywhere (no cap reached).
  for (std::size_t o = 1; o < 4; ++o)
    EXPECT_FLOAT_EQ(atlas.objects[o].texels_per_unit, atlas.objects[0].texels_per_unit);
  auto g = rasterize_gbuffer(ts.world, atlas);
  ASSERT_EQ(g.size(), 4u);
  for (std::size_t o = 0; o < 4; ++o) {
    SCOPED_TRACE(o);
    expect_valid_gbuffer(ts.world, o, atlas.objects[o], g[o], 1e-4f);
  }
}

TEST(Atlas, MillionTriangleMeshBuilds) {
  // ~1.0M triangles: a 708 x 708 quad terrain with gentle waves (few charts, one of which is huge)
  // plus nothing else. Checks completion and the basic invariants on a sample.
  const int n = 708;
  Mesh m = make_grid(n, n, 10.0f);
  for (glm::vec3& p : m.positions) p.z = 0.3f * std::sin(p.x) * std::cos(0.7f * p.y);
  TestScene ts;
  ts.add(std::move(m));
  ts.build();
  ASSERT_GE(ts.world.objects[0].triangles().size(), 1000000u);
  AtlasOptions opt;
  opt.texels_per_scene = 1024.0f;
  opt.max_lightmap_size = 1024;
  auto t0 = std::chrono::steady_clock::now();
  Atlas atlas = build_atlas(ts.world, opt);
  auto t1 = std::chrono::steady_clock::now();
  auto g = rasterize_gbuffer(ts.world, atlas);
  auto t2 = std::chrono::steady_clock::now();
  const ObjectLightmap& lm = atlas.objects[0];
  EXPECT_LE(lm.width, 1024);
  EXPECT_LE(lm.height, 1024);
  EXPECT_GE(lm.chart_count, 1);
  // Every triangle's centroid texel is valid.
  std::size_t missing = 0;
  for (std::size_t t = 0; t < lm.corner_uv.size() / 3; ++t) {
    glm::vec2 c = (lm.corner_uv[3 * t] + lm.corner_uv[3 * t + 1] + lm.corner_uv[3 * t + 2]) / 3.0f;
    if (!g[0].valid(static_cast<std::size_t>(c.y) * lm.width + static_cast<std::size_t>(c.x)))
      ++missing;
  }
  EXPECT_EQ(missing, 0u);
  double ms_atlas = std::chrono::duration<double, std::milli>(t1 - t0).count();
  double ms_gbuffer = std::chrono::duration<double, std::milli>(t2 - t1).count();
  std::printf(
      "[          ] %zu triangles: atlas %.0f ms (%d charts, %dx%d), gbuffer %.0f ms, "
      "%.1f%% texels valid\n",
      lm.corner_uv.size() / 3, ms_atlas, lm.chart_count, lm.width, lm.height, ms_gbuffer,
      100.0 * static_cast<double>(g[0].valid_count()) / static_cast<double>(g[0].size()));
}

// ---- G-buffer -----------------------------------------------------------------------------------

TEST(GBuffer, CubeTexelsLieOnTheirTriangles) {
  TestScene ts;
  ts.add(make_cube(1.0f), glm::rotate(glm::mat4(1.0f), 0.4f, glm::vec3(0, 1, 0)));
  ts.build();
  AtlasOptions opt;
  opt.texels_per_scene = 24.0f;
  Atlas atlas = build_atlas(ts.world, opt);
  auto g = rasterize_gbuffer(ts.world, atlas);
  ASSERT_EQ(g.size(), 1u);
  expect_valid_gbuffer(ts.world, 0, atlas.objects[0], g[0], 1e-4f);
  // Flat faces: normals are exactly the face normals.
  const WorldObject& wo = ts.world.objects[0];
  std::size_t covered = 0, conservative = 0;
  for (std::size_t i = 0; i < g[0].size(); ++i) {
    if (!g[0].valid(i)) continue;
    (g[0].kind[i] == TexelKind::Covered ? covered : conservative)++;
    EXPECT_GT(glm::dot(g[0].point(wo, i).normal,
                       wo.geometric_normal(static_cast<std::uint32_t>(g[0].triangle[i]))),
              0.9999f);
  }
  // Each face is a square of side s texels centred in its cells: at least floor(s)^2 covered
  // centres, and partial texels only along its border.
  float side = 2.0f * atlas.objects[0].texels_per_unit;
  EXPECT_GE(covered, 6u * static_cast<std::size_t>(std::floor(side) * std::floor(side)));
  EXPECT_LE(conservative, 6u * 4u * static_cast<std::size_t>(std::ceil(side) + 1.0f));
  EXPECT_EQ(g[0].valid_count(), covered + conservative);
}

TEST(GBuffer, SphereNormalsAndPositions) {
  TestScene ts;
  ts.add(make_sphere(2.0f, 20, 40), glm::translate(glm::mat4(1.0f), glm::vec3(1, 2, 3)));
  ts.build();
  AtlasOptions opt;
  opt.texels_per_scene = 96.0f;
  Atlas atlas = build_atlas(ts.world, opt);
  auto g = rasterize_gbuffer(ts.world, atlas);
  expect_valid_gbuffer(ts.world, 0, atlas.objects[0], g[0], 1e-4f);
  // Smooth normals: close to the radial direction of the (tessellated) sphere.
  float worst = 1.0f;
  std::size_t conservative = 0;
  for (std::size_t i = 0; i < g[0].size(); ++i) {
    if (!g[0].valid(i)) continue;
    const TexelPoint p = g[0].point(ts.world.objects[0], i);
    glm::vec3 radial = glm::normalize(p.position - glm::vec3(1, 2, 3));
    worst = std::min(worst, glm::dot(radial, p.normal));
    conservative += g[0].kind[i] == TexelKind::Conservative;
  }
  EXPECT_GT(worst, 0.99f);
  EXPECT_GT(conservative, 0u);  // curved chart borders only partly cover texels
}

TEST(GBuffer, SubTexelTrianglesEachGetATexel) {
  // 200 x 200 quads (80k triangles) on a plane 1 unit wide, 24 texels across: each triangle is a
  // few hundredths of a texel. Plus a degenerate (zero-area) triangle.
  Mesh m = make_grid(200, 200, 1.0f);
  m.triangles.push_back({0, 1, 2});  // collinear corners along the grid's first row
  TestScene ts;
  ts.add(m);
  ts.build();
  AtlasOptions opt;
  opt.texels_per_scene = 24.0f;
  Atlas atlas = build_atlas(ts.world, opt);
  const ObjectLightmap& lm = atlas.objects[0];
  EXPECT_EQ(lm.chart_count, 1);
  expect_valid_lightmap(lm, m.triangles.size(), 2);
  auto g = rasterize_gbuffer(ts.world, atlas);
  expect_valid_gbuffer(ts.world, 0, lm, g[0], 1e-4f);
  // No Covered texel is claimed by two triangles, and covered texels are the interior.
  std::size_t covered = 0;
  for (TexelKind k : g[0].kind) covered += k == TexelKind::Covered;
  EXPECT_GE(covered, 23u * 23u);
}

TEST(GBuffer, EmptyTexelsStayEmpty) {
  TestScene ts;
  ts.add(make_cube(1.0f));
  ts.build();
  AtlasOptions opt;
  opt.texels_per_scene = 64.0f;
  Atlas atlas = build_atlas(ts.world, opt);
  auto g = rasterize_gbuffer(ts.world, atlas);
  Footprint f = footprint(atlas.objects[0]);
  std::size_t empty = 0;
  for (std::size_t i = 0; i < g[0].size(); ++i) {
    if (g[0].valid(i)) continue;
    ++empty;
    EXPECT_EQ(f.chart[i], -1);
    EXPECT_EQ(g[0].triangle[i], -1);
    EXPECT_EQ(g[0].bary[i], glm::vec2(0.0f));
  }
  EXPECT_GT(empty, 0u);  // at least the gutters
}

// ---- dilation -----------------------------------------------------------------------------------

namespace {
const float kNaN = std::numeric_limits<float>::quiet_NaN();
bool filled(glm::vec3 v) {
  return !std::isnan(v.x) && !std::isnan(v.y) && !std::isnan(v.z);
}
}  // namespace

TEST(Dilate, FillsTheGuttersOfARealLightmap) {
  TestScene ts;
  ts.add(make_sphere(1.0f, 16, 32));
  ts.add(make_cube(0.5f), glm::translate(glm::mat4(1.0f), glm::vec3(3, 0, 0)));
  ts.build();
  Atlas atlas = build_atlas(ts.world);
  auto gbs = rasterize_gbuffer(ts.world, atlas);
  for (std::size_t o = 0; o < gbs.size(); ++o) {
    const TexelGBuffer& g = gbs[o];
    std::vector<glm::vec3> lm(g.size(), glm::vec3(kNaN));
    for (std::size_t i = 0; i < g.size(); ++i)
      if (g.valid(i)) lm[i] = 0.5f * g.point(ts.world.objects[o], i).normal + 0.5f;
    std::vector<glm::vec3> before = lm;
    dilate(lm, g.width, g.height, g.kind);
    std::size_t near = 0;
    for (int y = 0; y < g.height; ++y)
      for (int x = 0; x < g.width; ++x) {
        std::size_t i = static_cast<std::size_t>(y) * g.width + x;
        if (g.valid(i)) {
          ASSERT_EQ(lm[i], before[i]);  // real values untouched
          continue;
        }
        bool within_gutter = false;
        for (int dy = -2; dy <= 2; ++dy)
          for (int dx = -2; dx <= 2; ++dx) {
            int nx = x + dx, ny = y + dy;
            if (nx >= 0 && ny >= 0 && nx < g.width && ny < g.height &&
                g.valid(static_cast<std::size_t>(ny) * g.width + nx))
              within_gutter = true;
          }
        near += within_gutter;
        ASSERT_TRUE(filled(lm[i])) << x << "," << y;
        // Averages of valid values stay inside their range.
        for (int c = 0; c < 3; ++c) {
          EXPECT_GE(lm[i][c], -1e-6f);
          EXPECT_LE(lm[i][c], 1.0f + 1e-6f);
        }
      }
    EXPECT_GT(near, 0u);
  }
}

TEST(Dilate, ConstantStaysExactlyConstant) {
  TestScene ts;
  ts.add(make_sphere(1.0f, 12, 24));
  ts.build();
  Atlas atlas = build_atlas(ts.world);
  TexelGBuffer g = rasterize_gbuffer(ts.world, atlas)[0];
  const glm::vec3 c(1.7f, 2.9f, 0.3f);  // (c + c + c) / 3 != c in float: catches sum / count
  std::vector<glm::vec3> lm(g.size(), glm::vec3(kNaN));
  for (std::size_t i = 0; i < g.size(); ++i)
    if (g.valid(i)) lm[i] = c;
  dilate(lm, g.width, g.height, g.kind);
  for (std::size_t i = 0; i < lm.size(); ++i) ASSERT_EQ(lm[i], c) << i;
}

TEST(Dilate, RingsBoundThePasses) {
  // A single valid texel in the middle of a 9x9 map.
  const int w = 9, h = 9;
  std::vector<TexelKind> kind(w * h, TexelKind::Empty);
  std::vector<glm::vec3> lm(w * h, glm::vec3(kNaN));
  kind[4 * w + 4] = TexelKind::Covered;
  lm[4 * w + 4] = glm::vec3(2.0f);
  std::vector<glm::vec3> two = lm;
  dilate(two, w, h, kind, 2);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      int d = std::max(std::abs(x - 4), std::abs(y - 4));
      glm::vec3 v = two[static_cast<std::size_t>(y) * w + x];
      if (d <= 2)
        EXPECT_EQ(v, glm::vec3(2.0f)) << x << "," << y;
      else
        EXPECT_FALSE(filled(v)) << x << "," << y;
    }
  // Unbounded: everything, and a mix of two values gives their average in between.
  kind[4 * w + 6] = TexelKind::Covered;
  lm[4 * w + 6] = glm::vec3(4.0f);
  dilate(lm, w, h, kind);
  for (const glm::vec3& v : lm) ASSERT_TRUE(filled(v));
  EXPECT_FLOAT_EQ(lm[4 * w + 5].x, 3.0f);
  EXPECT_FLOAT_EQ(lm[4 * w + 3].x, 2.0f);
  EXPECT_FLOAT_EQ(lm[4 * w + 7].x, 4.0f);
}

}  // namespace irradcast::test_atlas
