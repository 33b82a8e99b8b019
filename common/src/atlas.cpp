// Lightmap atlas: per-object lightmap coordinates from TEXCOORD_1 (validated) or from generated
// charts (weld, grow by normal over shared edges, project, split folds, shelf-pack with gutters).
#include "irradcast/common/atlas.h"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstring>
#include <limits>
#include <numeric>
#include <string>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_sort.h>

#include "irradcast/common/log.h"

namespace irradcast {
namespace {

constexpr std::uint32_t kNone = ~0u;

// ------------------------------------------------------------------------------------------------
// Small 2D geometry helpers (double precision on float inputs).

double cross2(glm::dvec2 a, glm::dvec2 b) {
  return a.x * b.y - a.y * b.x;
}

// Strict 2D triangle-triangle interior overlap by separating axes. A tolerance (relative to the
// pair's size, plus `abs_tol` for the rounding of the float coordinates) keeps triangles sharing
// an edge or a vertex, and slivers touching within rounding, from counting as overlapping.
bool triangles_overlap(const glm::vec2* a, const glm::vec2* b, double abs_tol) {
  glm::dvec2 pa[3] = {glm::dvec2(a[0]), glm::dvec2(a[1]), glm::dvec2(a[2])};
  glm::dvec2 pb[3] = {glm::dvec2(b[0]), glm::dvec2(b[1]), glm::dvec2(b[2])};
  glm::dvec2 lo = glm::min(glm::min(pa[0], pa[1]), glm::min(pa[2], glm::min(pb[0], pb[1])));
  lo = glm::min(lo, pb[2]);
  glm::dvec2 hi = glm::max(glm::max(pa[0], pa[1]), glm::max(pa[2], glm::max(pb[0], pb[1])));
  hi = glm::max(hi, pb[2]);
  double scale = std::max(hi.x - lo.x, hi.y - lo.y);
  if (!(scale > 0.0)) return false;
  const glm::dvec2* tris[2] = {pa, pb};
  for (const glm::dvec2* tri : tris) {
    for (int e = 0; e < 3; ++e) {
      glm::dvec2 d = tri[(e + 1) % 3] - tri[e];
      glm::dvec2 axis(-d.y, d.x);
      double len = std::sqrt(glm::dot(axis, axis));
      if (!(len > 0.0)) continue;
      double tol = len * (1e-5 * scale + abs_tol);
      double amin = 1e300, amax = -1e300, bmin = 1e300, bmax = -1e300;
      for (int k = 0; k < 3; ++k) {
        double x = glm::dot(axis, pa[k]);
        amin = std::min(amin, x);
        amax = std::max(amax, x);
        double y = glm::dot(axis, pb[k]);
        bmin = std::min(bmin, y);
        bmax = std::max(bmax, y);
      }
      if (amax <= bmin + tol || bmax <= amin + tol) return false;
    }
  }
  return true;
}

// Orthonormal tangent frame of a unit normal (Duff et al. 2017).
void tangent_frame(glm::vec3 n, glm::vec3& t, glm::vec3& b) {
  float sign = std::copysign(1.0f, n.z);
  float a = -1.0f / (sign + n.z);
  float c = n.x * n.y * a;
  t = glm::vec3(1.0f + sign * n.x * n.x * a, sign * c, -sign * n.x);
  b = glm::vec3(c, sign + n.y * n.y * a, -n.y);
}

// Convex hull (Andrew's monotone chain), counter-clockwise, after discarding the points strictly
// inside the polygon of the extreme points in 8 directions (Akl-Toussaint).
std::vector<glm::vec2> convex_hull(const std::vector<glm::vec2>& pts) {
  if (pts.size() < 3) return pts;
  static const glm::vec2 dirs[8] = {{1, 0},  {1, 1},   {0, 1},  {-1, 1},
                                    {-1, 0}, {-1, -1}, {0, -1}, {1, -1}};
  glm::vec2 ext[8];
  float best[8];
  for (int k = 0; k < 8; ++k) {
    ext[k] = pts[0];
    best[k] = glm::dot(pts[0], dirs[k]);
  }
  for (const glm::vec2& p : pts)
    for (int k = 0; k < 8; ++k) {
      float d = glm::dot(p, dirs[k]);
      if (d > best[k]) best[k] = d, ext[k] = p;
    }
  std::vector<glm::vec2> poly;
  for (int k = 0; k < 8; ++k)
    if (poly.empty() || poly.back() != ext[k]) poly.push_back(ext[k]);
  while (poly.size() > 1 && poly.back() == poly.front()) poly.pop_back();
  std::vector<glm::vec2> cand;
  cand.reserve(poly.size() >= 3 ? pts.size() / 4 + 16 : pts.size());
  for (const glm::vec2& p : pts) {
    bool inside = poly.size() >= 3;
    for (std::size_t k = 0; inside && k < poly.size(); ++k) {
      glm::dvec2 a(poly[k]), b(poly[(k + 1) % poly.size()]);
      if (!(cross2(b - a, glm::dvec2(p) - a) > 0.0)) inside = false;
    }
    if (!inside) cand.push_back(p);
  }
  std::sort(cand.begin(), cand.end(),
            [](glm::vec2 a, glm::vec2 b) { return a.x < b.x || (a.x == b.x && a.y < b.y); });
  cand.erase(std::unique(cand.begin(), cand.end()), cand.end());
  if (cand.size() < 3) return cand;
  std::vector<glm::vec2> hull(2 * cand.size());
  std::size_t k = 0;
  auto turn = [](glm::vec2 o, glm::vec2 a, glm::vec2 b) {
    return cross2(glm::dvec2(a) - glm::dvec2(o), glm::dvec2(b) - glm::dvec2(o));
  };
  for (std::size_t i = 0; i < cand.size(); ++i) {
    while (k >= 2 && turn(hull[k - 2], hull[k - 1], cand[i]) <= 0.0) --k;
    hull[k++] = cand[i];
  }
  for (std::size_t i = cand.size() - 1, t = k + 1; i > 0; --i) {
    while (k >= t && turn(hull[k - 2], hull[k - 1], cand[i - 1]) <= 0.0) --k;
    hull[k++] = cand[i - 1];
  }
  hull.resize(k - 1);
  return hull;
}

// Angle that, applied as a rotation, gives the hull's minimum-area bounding rectangle.
float min_area_rect_angle(const std::vector<glm::vec2>& hull) {
  if (hull.size() < 3) {
    if (hull.size() == 2) {
      glm::vec2 d = hull[1] - hull[0];
      return -std::atan2(d.y, d.x);
    }
    return 0.0f;
  }
  std::vector<float> angles;
  if (hull.size() <= 128) {
    for (std::size_t i = 0; i < hull.size(); ++i) {
      glm::vec2 d = hull[(i + 1) % hull.size()] - hull[i];
      angles.push_back(-std::atan2(d.y, d.x));
    }
  } else {
    for (int i = 0; i < 180; ++i) angles.push_back(static_cast<float>(i) * 3.14159265f / 360.0f);
  }
  float best_angle = 0.0f;
  double best_area = std::numeric_limits<double>::infinity();
  for (float a : angles) {
    double c = std::cos(a), s = std::sin(a);
    double x0 = 1e300, x1 = -1e300, y0 = 1e300, y1 = -1e300;
    for (const glm::vec2& p : hull) {
      double x = c * p.x - s * p.y, y = s * p.x + c * p.y;
      x0 = std::min(x0, x), x1 = std::max(x1, x);
      y0 = std::min(y0, y), y1 = std::max(y1, y);
    }
    double area = (x1 - x0) * (y1 - y0);
    if (area < best_area * (1.0 - 1e-6)) best_area = area, best_angle = a;
  }
  return best_angle;
}

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

struct Chart {
  glm::vec2 extent{0.0f};  // world units, after rotation, corners start at (0, 0)
};

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

// Charts of an object: grown, projected, folds split (bisection in breadth-first order, then
// connected components) until no chart overlaps itself.
struct ChartSet {
  std::vector<Chart> charts;
  std::vector<std::uint32_t> tri_chart;
  std::vector<glm::vec2> uv;  // world units within the chart, 3 per triangle
};

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

// ------------------------------------------------------------------------------------------------
// Packing.

struct Placement {
  int x = 0, y = 0;      // lower corner of the chart's cell block
  int cw = 1, ch = 1;    // cells before rotation
  bool rotated = false;  // rotated by +90 degrees
};

struct Packing {
  int width = 0, height = 0;
  std::vector<Placement> place;
};

int cells(float extent_texels) {
  // At least 0.01 texel of slack on each side, at least one texel.
  double c = std::floor(static_cast<double>(extent_texels) + 0.02) + 1.0;
  return static_cast<int>(std::clamp(c, 1.0, 1e9));
}

// Shelf packing, tallest first, charts turned landscape, `gutter` empty texels between charts and
// along the border. Tries a few shelf widths and keeps the most square result.
Packing pack(const std::vector<Chart>& charts, float density, int gutter) {
  const std::size_t m = charts.size();
  std::vector<Placement> place(m);
  double area = 0.0;
  int widest = 0;
  for (std::size_t i = 0; i < m; ++i) {
    Placement& p = place[i];
    p.cw = cells(charts[i].extent.x * density);
    p.ch = cells(charts[i].extent.y * density);
    p.rotated = p.ch > p.cw;
    int w = (p.rotated ? p.ch : p.cw) + gutter;
    int h = (p.rotated ? p.cw : p.ch) + gutter;
    area += static_cast<double>(w) * h;
    widest = std::max(widest, w);
  }
  std::vector<std::uint32_t> order(m);
  std::iota(order.begin(), order.end(), 0u);
  auto hw = [&](std::uint32_t i) {
    const Placement& p = place[i];
    return p.rotated ? std::pair(p.cw, p.ch) : std::pair(p.ch, p.cw);
  };
  std::sort(order.begin(), order.end(), [&](std::uint32_t a, std::uint32_t b) {
    auto ha = hw(a), hb = hw(b);
    if (ha != hb) return ha > hb;
    return a < b;
  });
  Packing best;
  long best_side = std::numeric_limits<long>::max();
  double best_area = 0.0;
  for (double f : {0.9, 1.0, 1.1, 1.25, 1.5}) {
    long shelf = std::max<long>(widest, static_cast<long>(std::ceil(std::sqrt(area) * f)));
    long x = gutter, y = gutter, shelf_h = 0, used_w = gutter;
    std::vector<Placement> trial = place;
    for (std::uint32_t i : order) {
      auto [h, w] = hw(i);
      h += gutter;
      w += gutter;
      if (x + w > gutter + shelf && x > gutter) {
        y += shelf_h;
        x = gutter;
        shelf_h = 0;
      }
      trial[i].x = static_cast<int>(x);
      trial[i].y = static_cast<int>(y);
      x += w;
      shelf_h = std::max<long>(shelf_h, h);
      used_w = std::max(used_w, x);
    }
    long width = used_w, height = y + shelf_h;
    long side = std::max(width, height);
    double a = static_cast<double>(width) * height;
    if (side < best_side || (side == best_side && a < best_area)) {
      best_side = side;
      best_area = a;
      best.width = static_cast<int>(std::min<long>(width, std::numeric_limits<int>::max()));
      best.height = static_cast<int>(std::min<long>(height, std::numeric_limits<int>::max()));
      best.place = std::move(trial);
    }
  }
  return best;
}

void build_generated(const World& world, std::size_t oi, const AtlasOptions& options,
                     float base_density, ObjectLightmap& lm) {
  const WorldObject& wo = world.objects[oi];
  const std::size_t n = wo.triangles().size();
  const auto t0 = std::chrono::steady_clock::now();
  ChartSet cs = make_charts(wo, options);
  const auto t1 = std::chrono::steady_clock::now();
  const int gutter = std::max(0, options.gutter);
  const int cap = std::max(1, options.max_lightmap_size);
  auto fits = [&](const Packing& p) { return p.width <= cap && p.height <= cap; };

  float density = base_density;
  Packing packing = pack(cs.charts, density, gutter);
  if (!fits(packing)) {
    float max_extent = 0.0f;
    for (const Chart& ch : cs.charts) max_extent = std::max({max_extent, ch.extent.x, ch.extent.y});
    // Below this density every chart is a single cell: the smallest packing there is.
    float floor_density = max_extent > 0.0f ? 0.5f / max_extent : base_density;
    floor_density = std::min(floor_density, base_density);
    Packing smallest = pack(cs.charts, floor_density, gutter);
    if (!fits(smallest)) {
      log::warn("atlas", "object " + std::to_string(oi) + ": " + std::to_string(cs.charts.size()) +
                             " charts do not fit in " + std::to_string(cap) + "x" +
                             std::to_string(cap) + " texels even at one texel each; using " +
                             std::to_string(smallest.width) + "x" +
                             std::to_string(smallest.height));
      density = floor_density;
      packing = std::move(smallest);
    } else {
      // Largest density that fits: bisection in log space between floor (fits) and base.
      double lo = std::log(floor_density), hi = std::log(base_density);
      Packing best = std::move(smallest);
      double guess = std::log(base_density) +
                     std::log(static_cast<double>(cap) / std::max(packing.width, packing.height));
      if (guess > lo && guess < hi) {
        Packing p = pack(cs.charts, static_cast<float>(std::exp(guess)), gutter);
        if (fits(p))
          lo = guess, best = std::move(p);
        else
          hi = guess;
      }
      for (int it = 0; it < 16 && hi - lo > 1e-3; ++it) {
        double mid = 0.5 * (lo + hi);
        Packing p = pack(cs.charts, static_cast<float>(std::exp(mid)), gutter);
        if (fits(p))
          lo = mid, best = std::move(p);
        else
          hi = mid;
      }
      density = static_cast<float>(std::exp(lo));
      packing = std::move(best);
    }
  }

  lm.width = packing.width;
  lm.height = packing.height;
  lm.texels_per_unit = density;
  lm.chart_count = static_cast<int>(cs.charts.size());
  lm.from_file_uv1 = false;
  lm.triangle_chart = std::move(cs.tri_chart);
  lm.corner_uv.resize(3 * n);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, 4096),
                    [&](const tbb::blocked_range<std::size_t>& r) {
                      for (std::size_t t = r.begin(); t < r.end(); ++t) {
                        std::uint32_t ci = lm.triangle_chart[t];
                        const Placement& p = packing.place[ci];
                        glm::vec2 ext = cs.charts[ci].extent * density;
                        glm::vec2 off = 0.5f * (glm::vec2(p.cw, p.ch) - ext);
                        for (int j = 0; j < 3; ++j) {
                          glm::vec2 q = cs.uv[3 * t + j] * density + off;
                          if (p.rotated) q = glm::vec2(static_cast<float>(p.ch) - q.y, q.x);
                          lm.corner_uv[3 * t + j] = q + glm::vec2(p.x, p.y);
                        }
                      }
                    });
  if (log::level() <= log::Level::Debug) {
    const auto t2 = std::chrono::steady_clock::now();
    double used = 0.0;
    for (const Placement& p : packing.place) used += static_cast<double>(p.cw) * p.ch;
    auto ms = [](auto a, auto b) {
      return std::to_string(std::chrono::duration<double, std::milli>(b - a).count());
    };
    log::debug("atlas",
               "object " + std::to_string(oi) + ": " + std::to_string(n) + " triangles, " +
                   std::to_string(cs.charts.size()) + " charts, " + std::to_string(lm.width) + "x" +
                   std::to_string(lm.height) + " at " + std::to_string(density) +
                   " texels/unit, chart cells " +
                   std::to_string(100.0 * used / std::max(1.0, 1.0 * lm.width * lm.height)) +
                   "% of the map; charts " + ms(t0, t1) + " ms, packing " + ms(t1, t2) + " ms");
  }
}

// ------------------------------------------------------------------------------------------------
// File TEXCOORD_1.

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

}  // namespace

std::size_t Atlas::texel_count() const {
  std::size_t n = 0;
  for (const ObjectLightmap& o : objects)
    n += static_cast<std::size_t>(o.width) * static_cast<std::size_t>(o.height);
  return n;
}

float atlas_base_density(const World& world, const AtlasOptions& options) {
  float extent = world.bounds.max_extent();
  float d = extent > 0.0f && std::isfinite(extent) ? options.texels_per_scene / extent
                                                   : options.texels_per_scene;
  return d > 0.0f && std::isfinite(d) ? d : 1.0f;
}

Atlas build_atlas(const World& world, const AtlasOptions& options) {
  Atlas atlas;
  atlas.objects.resize(world.objects.size());
  const float density = atlas_base_density(world, options);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, world.objects.size(), 1),
                    [&](const tbb::blocked_range<std::size_t>& r) {
                      for (std::size_t oi = r.begin(); oi < r.end(); ++oi) {
                        const WorldObject& wo = world.objects[oi];
                        ObjectLightmap& lm = atlas.objects[oi];
                        if (wo.triangles().empty()) continue;
                        if (options.use_file_uv1 && !wo.source->uv1.empty() &&
                            build_from_file_uv1(world, oi, options, density, lm))
                          continue;
                        build_generated(world, oi, options, density, lm);
                      }
                    });
  return atlas;
}

}  // namespace irradcast
