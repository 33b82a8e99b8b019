// Lightmap atlas: chart generation. Vertices are welded by position; triangles grow into charts
// over shared edges while their normals stay near the chart's mean; each chart is projected onto
// its plane and rotated to its minimum-area rectangle; charts that fold over themselves are split
// until none does.
#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <limits>
#include <numeric>
#include <vector>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_sort.h>

#include "atlas_internal.h"

namespace irradcast::atlas_detail {
namespace {

// ------------------------------------------------------------------------------------------------
// Mesh connectivity.

// Welded vertex id per vertex: vertices at exactly the same position share an id.
std::vector<std::uint32_t> weld_vertices(const std::vector<glm::vec3>& p) {
  struct Key {
    std::uint32_t k[3];
    std::uint32_t index;
  };
  std::vector<Key> keys(p.size());
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, p.size(), 4096),
                    [&](const tbb::blocked_range<std::size_t>& r) {
                      for (std::size_t i = r.begin(); i < r.end(); ++i) {
                        for (int c = 0; c < 3; ++c) {
                          float f = p[i][c] == 0.0f ? 0.0f : p[i][c];  // -0 == +0
                          std::memcpy(&keys[i].k[c], &f, 4);
                        }
                        keys[i].index = static_cast<std::uint32_t>(i);
                      }
                    });
  auto less = [](const Key& a, const Key& b) {
    if (a.k[0] != b.k[0]) return a.k[0] < b.k[0];
    if (a.k[1] != b.k[1]) return a.k[1] < b.k[1];
    if (a.k[2] != b.k[2]) return a.k[2] < b.k[2];
    return a.index < b.index;
  };
  tbb::parallel_sort(keys.begin(), keys.end(), less);
  std::vector<std::uint32_t> id(p.size());
  std::uint32_t next = 0;
  for (std::size_t i = 0; i < keys.size(); ++i) {
    if (i > 0 && std::memcmp(keys[i].k, keys[i - 1].k, sizeof keys[i].k) != 0) ++next;
    id[keys[i].index] = next;
  }
  return id;
}

struct Connectivity {
  std::vector<glm::uvec3> tri;      // welded corners
  std::vector<std::uint32_t> nb;    // 3 per triangle: neighbour across edge (k, k+1), or kNone
  std::vector<glm::vec3> normal;    // unit geometric normal
  std::vector<float> area;          // world area
  std::vector<std::uint8_t> degen;  // no reliable normal
  std::uint32_t vertex_count = 0;
};

Connectivity build_connectivity(const WorldObject& wo) {
  const auto& tris = wo.triangles();
  const std::size_t n = tris.size();
  Connectivity c;
  std::vector<std::uint32_t> wid = weld_vertices(wo.positions);
  for (std::uint32_t w : wid) c.vertex_count = std::max(c.vertex_count, w + 1);
  c.tri.resize(n);
  c.normal.resize(n);
  c.area.resize(n);
  c.degen.resize(n);
  tbb::parallel_for(
      tbb::blocked_range<std::size_t>(0, n, 4096), [&](const tbb::blocked_range<std::size_t>& r) {
        for (std::size_t t = r.begin(); t < r.end(); ++t) {
          const glm::uvec3& v = tris[t];
          c.tri[t] = glm::uvec3(wid[v.x], wid[v.y], wid[v.z]);
          glm::vec3 p0 = wo.positions[v.x], p1 = wo.positions[v.y], p2 = wo.positions[v.z];
          glm::vec3 cr = glm::cross(p1 - p0, p2 - p0);
          float len = glm::length(cr);
          float e = std::max(glm::dot(p1 - p0, p1 - p0),
                             std::max(glm::dot(p2 - p1, p2 - p1), glm::dot(p0 - p2, p0 - p2)));
          bool bad = !(len > 1e-7f * e) || !std::isfinite(len);
          c.degen[t] = bad ? 1 : 0;
          c.normal[t] = bad ? glm::vec3(0.0f, 0.0f, 1.0f) : cr / len;
          c.area[t] = bad ? 0.0f : 0.5f * len;
        }
      });
  // Vertex -> triangles (CSR), then edge neighbours: an edge shared by exactly two triangles.
  std::vector<std::uint32_t> start(c.vertex_count + 1, 0);
  for (const glm::uvec3& t : c.tri)
    for (int k = 0; k < 3; ++k) ++start[t[k] + 1];
  for (std::size_t i = 0; i < c.vertex_count; ++i) start[i + 1] += start[i];
  std::vector<std::uint32_t> fill(start.begin(), start.end() - 1);
  std::vector<std::uint32_t> vt(start.back());
  for (std::size_t t = 0; t < n; ++t)
    for (int k = 0; k < 3; ++k) vt[fill[c.tri[t][k]]++] = static_cast<std::uint32_t>(t);
  c.nb.assign(3 * n, kNone);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, 4096),
                    [&](const tbb::blocked_range<std::size_t>& r) {
                      for (std::size_t t = r.begin(); t < r.end(); ++t) {
                        for (int k = 0; k < 3; ++k) {
                          std::uint32_t a = c.tri[t][k], b = c.tri[t][(k + 1) % 3];
                          if (a == b) continue;
                          std::uint32_t found = kNone;
                          int count = 0;
                          for (std::uint32_t i = start[a]; i < start[a + 1]; ++i) {
                            std::uint32_t s = vt[i];
                            if (s == t || (i > start[a] && vt[i - 1] == s)) continue;
                            const glm::uvec3& q = c.tri[s];
                            if (q.x == b || q.y == b || q.z == b) found = s, ++count;
                          }
                          if (count == 1) c.nb[3 * t + k] = found;
                        }
                      }
                    });
  return c;
}

// ------------------------------------------------------------------------------------------------
// Charts.

// Triangles of a list of pieces, piece i being tris[start[i] .. start[i+1]).
struct Pieces {
  std::vector<std::uint32_t> tris;
  std::vector<std::size_t> start{0};
  std::size_t size() const { return start.size() - 1; }
  void close() { start.push_back(tris.size()); }
};

// Appends the connected components (over shared edges) of the triangles tris[0 .. k) to `out`,
// each in breadth-first order. `mark` holds per-triangle scratch labels (never reset: labels
// come from `next_mark`). `tris` must not point into `out`.
void append_components(const Connectivity& c, const std::uint32_t* tris, std::size_t k,
                       std::vector<std::uint32_t>& mark, std::uint32_t& next_mark, Pieces& out) {
  const std::uint32_t member = ++next_mark, done = ++next_mark;
  for (std::size_t j = 0; j < k; ++j) mark[tris[j]] = member;
  for (std::size_t j = 0; j < k; ++j) {
    if (mark[tris[j]] != member) continue;
    std::size_t head = out.tris.size();
    out.tris.push_back(tris[j]);
    mark[tris[j]] = done;
    while (head < out.tris.size()) {
      std::uint32_t t = out.tris[head++];
      for (int e = 0; e < 3; ++e) {
        std::uint32_t s = c.nb[3 * t + e];
        if (s != kNone && mark[s] == member) {
          mark[s] = done;
          out.tris.push_back(s);
        }
      }
    }
    out.close();
  }
}

glm::dvec3 mean_normal(const Connectivity& c, const std::uint32_t* tris, std::size_t k) {
  glm::dvec3 sum(0.0);
  for (std::size_t i = 0; i < k; ++i)
    sum += glm::dvec3(c.normal[tris[i]]) * static_cast<double>(c.area[tris[i]]);
  double len = glm::length(sum);
  return len > 0.0 ? sum / len : glm::dvec3(0.0);
}

bool outside_cone(const Connectivity& c, std::uint32_t t, glm::dvec3 axis, double cos_max) {
  return !c.degen[t] && glm::length(axis) > 0.0 &&
         glm::dot(glm::dvec3(c.normal[t]), axis) < cos_max - 1e-6;
}

double angle_between(glm::dvec3 a, glm::dvec3 b) {
  return std::acos(std::clamp(glm::dot(a, b), -1.0, 1.0));
}

// Grows charts over shared edges while every triangle stays strictly within `max_angle` of the
// chart's area-weighted mean normal. Candidates are taken best-aligned first (a heap on their
// alignment with the mean when they were reached), so a chart spreads over its flat region before
// it reaches across a crease. The mean moves as the chart grows; an upper bound of the members'
// deviation (grown by each move of the mean, recomputed exactly when it reaches the limit and the
// chart has grown by a quarter since) keeps the invariant without revisiting the chart for every
// candidate. Each chart lists its triangles in the order they joined (every prefix connected).
Pieces grow_charts(const Connectivity& c, double max_angle) {
  const std::size_t n = c.tri.size();
  const double limit = max_angle - 1e-6;
  std::vector<std::uint8_t> taken(n, 0);
  std::vector<std::pair<float, std::uint32_t>> heap;
  Pieces p;
  p.tris.reserve(n);
  for (std::size_t seed = 0; seed < n; ++seed) {
    if (taken[seed]) continue;
    const std::size_t first = p.tris.size();
    glm::dvec3 sum(0.0), mean(0.0);
    double bound = 0.0;
    std::size_t exact_size = 1;
    heap.clear();
    heap.emplace_back(1.0f, static_cast<std::uint32_t>(seed));
    while (!heap.empty()) {
      std::pop_heap(heap.begin(), heap.end());
      std::uint32_t s = heap.back().second;
      heap.pop_back();
      if (taken[s]) continue;
      if (!c.degen[s]) {
        glm::dvec3 ns(c.normal[s]);
        glm::dvec3 new_sum = sum + ns * static_cast<double>(c.area[s]);
        double len = glm::length(new_sum);
        if (!(len > 0.0)) continue;
        glm::dvec3 new_mean = new_sum / len;
        double drift = glm::length(mean) > 0.0 ? angle_between(mean, new_mean) : 0.0;
        double dev = angle_between(ns, new_mean);
        if (std::max(bound + drift, dev) >= limit) {
          std::size_t size = p.tris.size() - first;
          if (size < exact_size + exact_size / 4 + 8) continue;
          bound = 0.0;  // exact deviation of the members from the current mean
          for (std::size_t i = first; i < p.tris.size(); ++i)
            if (!c.degen[p.tris[i]])
              bound = std::max(bound, angle_between(glm::dvec3(c.normal[p.tris[i]]), mean));
          exact_size = size;
          if (std::max(bound + drift, dev) >= limit) continue;
        }
        bound = std::max(bound + drift, dev);
        sum = new_sum;
        mean = new_mean;
      }
      taken[s] = 1;
      p.tris.push_back(s);
      for (int k = 0; k < 3; ++k) {
        std::uint32_t q = c.nb[3 * s + k];
        if (q == kNone || taken[q]) continue;
        float align =
            c.degen[q] ? 1.0f : static_cast<float>(glm::dot(glm::dvec3(c.normal[q]), mean));
        heap.emplace_back(align, q);
        std::push_heap(heap.begin(), heap.end());
      }
    }
    p.close();
  }
  return p;
}

// True if two triangles of the piece overlap in their 2D projection `uv` (3 corners per
// triangle, indexed by triangle). Uniform grid over the triangles' bounding boxes.
bool piece_folds(const std::uint32_t* tris, std::size_t k, const std::vector<glm::vec2>& uv) {
  if (k < 2) return false;
  std::vector<glm::vec4> box(k);  // lo.x, lo.y, hi.x, hi.y
  glm::vec2 lo(std::numeric_limits<float>::max()), hi(-std::numeric_limits<float>::max());
  double ext_sum = 0.0;
  for (std::size_t i = 0; i < k; ++i) {
    const glm::vec2* q = &uv[3 * static_cast<std::size_t>(tris[i])];
    glm::vec2 a = glm::min(q[0], glm::min(q[1], q[2])), b = glm::max(q[0], glm::max(q[1], q[2]));
    box[i] = glm::vec4(a, b);
    lo = glm::min(lo, a);
    hi = glm::max(hi, b);
    ext_sum += std::max(b.x - a.x, b.y - a.y);
  }
  // Coordinates are floats relative to the piece's first vertex: a few ulps of their magnitude.
  const double abs_tol =
      1e-6 * std::max({std::abs(lo.x), std::abs(lo.y), std::abs(hi.x), std::abs(hi.y)});
  double w = std::max(1e-30, static_cast<double>(hi.x - lo.x));
  double h = std::max(1e-30, static_cast<double>(hi.y - lo.y));
  double cell = std::max(ext_sum / static_cast<double>(k), std::sqrt(w * h / (4.0 * k)));
  cell = std::max(cell, std::max(w, h) / 4096.0);
  int gx = std::max(1, std::min(4096, static_cast<int>(std::ceil(w / cell))));
  int gy = std::max(1, std::min(4096, static_cast<int>(std::ceil(h / cell))));
  auto cx = [&](float x) { return std::clamp(static_cast<int>((x - lo.x) / cell), 0, gx - 1); };
  auto cy = [&](float y) { return std::clamp(static_cast<int>((y - lo.y) / cell), 0, gy - 1); };
  std::vector<std::uint32_t> cstart(static_cast<std::size_t>(gx) * gy + 1, 0);
  for (std::size_t i = 0; i < k; ++i)
    for (int y = cy(box[i].y); y <= cy(box[i].w); ++y)
      for (int x = cx(box[i].x); x <= cx(box[i].z); ++x)
        ++cstart[static_cast<std::size_t>(y) * gx + x + 1];
  for (std::size_t i = 1; i < cstart.size(); ++i) cstart[i] += cstart[i - 1];
  std::vector<std::uint32_t> fill(cstart.begin(), cstart.end() - 1);
  std::vector<std::uint32_t> items(cstart.back());
  for (std::size_t i = 0; i < k; ++i)
    for (int y = cy(box[i].y); y <= cy(box[i].w); ++y)
      for (int x = cx(box[i].x); x <= cx(box[i].z); ++x)
        items[fill[static_cast<std::size_t>(y) * gx + x]++] = static_cast<std::uint32_t>(i);
  for (int y = 0; y < gy; ++y) {
    for (int x = 0; x < gx; ++x) {
      std::size_t cidx = static_cast<std::size_t>(y) * gx + x;
      for (std::uint32_t i = cstart[cidx]; i < cstart[cidx + 1]; ++i) {
        const glm::vec4& A = box[items[i]];
        for (std::uint32_t j = i + 1; j < cstart[cidx + 1]; ++j) {
          const glm::vec4& B = box[items[j]];
          if (A.z <= B.x || B.z <= A.x || A.w <= B.y || B.w <= A.y) continue;
          // Test each pair once: in the first cell of their boxes' intersection.
          if (cx(std::max(A.x, B.x)) != x || cy(std::max(A.y, B.y)) != y) continue;
          if (triangles_overlap(&uv[3 * static_cast<std::size_t>(tris[items[i]])],
                                &uv[3 * static_cast<std::size_t>(tris[items[j]])], abs_tol))
            return true;
        }
      }
    }
  }
  return false;
}

// Projects a piece onto the plane of its area-weighted normal (writing uv of its triangles).
void project_piece(const WorldObject& wo, const Connectivity& c, const std::uint32_t* tris,
                   std::size_t k, std::vector<glm::vec2>& uv) {
  glm::dvec3 mean = mean_normal(c, tris, k);
  std::uint32_t largest = tris[0];
  for (std::size_t i = 0; i < k; ++i)
    if (c.area[tris[i]] > c.area[largest]) largest = tris[i];
  glm::vec3 n = glm::length(mean) > 0.5 ? glm::vec3(mean) : c.normal[largest];
  glm::vec3 tu, tv;
  tangent_frame(n, tu, tv);
  const auto& src = wo.triangles();
  glm::vec3 origin = wo.positions[src[tris[0]].x];
  for (std::size_t i = 0; i < k; ++i) {
    std::uint32_t t = tris[i];
    for (int j = 0; j < 3; ++j) {
      glm::vec3 d = wo.positions[src[t][j]] - origin;
      glm::vec2 q(glm::dot(d, tu), glm::dot(d, tv));
      if (!std::isfinite(q.x) || !std::isfinite(q.y)) q = glm::vec2(0.0f);
      uv[3 * static_cast<std::size_t>(t) + j] = q;
    }
  }
}

// Rotates a (non-folding) piece to its minimum-area rectangle and moves it to the origin.
Chart finish_piece(const std::uint32_t* tris, std::size_t k, std::vector<glm::vec2>& uv) {
  std::vector<glm::vec2> pts;
  pts.reserve(3 * k);
  for (std::size_t i = 0; i < k; ++i)
    for (int j = 0; j < 3; ++j) pts.push_back(uv[3 * static_cast<std::size_t>(tris[i]) + j]);
  float angle = min_area_rect_angle(convex_hull(pts));
  float cs = std::cos(angle), sn = std::sin(angle);
  glm::vec2 lo(std::numeric_limits<float>::max()), hi(-std::numeric_limits<float>::max());
  for (glm::vec2& p : pts) {
    p = glm::vec2(cs * p.x - sn * p.y, sn * p.x + cs * p.y);
    lo = glm::min(lo, p);
    hi = glm::max(hi, p);
  }
  std::size_t m = 0;
  for (std::size_t i = 0; i < k; ++i)
    for (int j = 0; j < 3; ++j) uv[3 * static_cast<std::size_t>(tris[i]) + j] = pts[m++] - lo;
  Chart chart;
  chart.extent = hi - lo;
  return chart;
}

}  // namespace

ChartSet make_charts(const WorldObject& wo, const AtlasOptions& options) {
  Connectivity c = build_connectivity(wo);
  const std::size_t n = c.tri.size();
  const double max_angle =
      glm::radians(static_cast<double>(std::clamp(options.chart_max_angle_deg, 0.0f, 180.0f)));
  const double cos_max = std::cos(max_angle);
  std::vector<std::uint32_t> mark(n, 0);
  std::uint32_t next_mark = 0;
  Pieces pending = grow_charts(c, max_angle);
  ChartSet out;
  out.uv.resize(3 * n);
  out.tri_chart.assign(n, kNone);
  enum Status : std::uint8_t { Ok, Cone, Folds };
  std::vector<std::uint32_t> inside, outside;
  while (pending.size() > 0) {
    std::vector<Status> status(pending.size(), Ok);
    std::vector<Chart> done(pending.size());
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, pending.size(), 1),
                      [&](const tbb::blocked_range<std::size_t>& r) {
                        for (std::size_t i = r.begin(); i < r.end(); ++i) {
                          const std::uint32_t* tris = pending.tris.data() + pending.start[i];
                          std::size_t k = pending.start[i + 1] - pending.start[i];
                          glm::dvec3 axis = mean_normal(c, tris, k);
                          if (k > 1)
                            for (std::size_t j = 0; j < k && status[i] == Ok; ++j)
                              if (outside_cone(c, tris[j], axis, cos_max)) status[i] = Cone;
                          if (status[i] != Ok) continue;
                          project_piece(wo, c, tris, k, out.uv);
                          if (piece_folds(tris, k, out.uv))
                            status[i] = Folds;
                          else
                            done[i] = finish_piece(tris, k, out.uv);
                        }
                      });
    Pieces next;
    for (std::size_t i = 0; i < pending.size(); ++i) {
      const std::uint32_t* tris = pending.tris.data() + pending.start[i];
      std::size_t k = pending.start[i + 1] - pending.start[i];
      if (status[i] == Ok) {
        auto id = static_cast<std::uint32_t>(out.charts.size());
        for (std::size_t j = 0; j < k; ++j) out.tri_chart[tris[j]] = id;
        out.charts.push_back(done[i]);
        continue;
      }
      if (status[i] == Cone) {
        // Peel the triangles outside the cone of this piece's mean normal.
        glm::dvec3 axis = mean_normal(c, tris, k);
        inside.clear();
        outside.clear();
        for (std::size_t j = 0; j < k; ++j)
          (outside_cone(c, tris[j], axis, cos_max) ? outside : inside).push_back(tris[j]);
        if (!inside.empty() && !outside.empty()) {
          append_components(c, inside.data(), inside.size(), mark, next_mark, next);
          append_components(c, outside.data(), outside.size(), mark, next_mark, next);
          continue;
        }
      }
      // Breadth-first prefix (connected), then the components of the rest.
      std::size_t half = k / 2;
      next.tris.insert(next.tris.end(), tris, tris + half);
      next.close();
      append_components(c, tris + half, k - half, mark, next_mark, next);
    }
    pending = std::move(next);
  }
  return out;
}

}  // namespace irradcast::atlas_detail
