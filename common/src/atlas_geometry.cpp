// Lightmap atlas: 2D geometry helpers for chart generation (triangle overlap, tangent frames,
// convex hulls, minimum-area bounding rectangles), in double precision on float inputs.
#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <vector>

#include "atlas_internal.h"

namespace irradcast::atlas_detail {

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

}  // namespace irradcast::atlas_detail
