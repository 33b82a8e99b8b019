#include "plot.h"

#include <stb_easy_font.h>
#include <stb_image_write.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <stdexcept>

namespace irradcast::plot {
namespace {

struct Quad {
  float x0, y0, x1, y1;
};

// The glyph quads of a (single-line) string in glyph pixels, y down, top-left at (0, 0).
std::vector<Quad> glyph_quads(const std::string& s) {
  struct Vertex {
    float x, y, z;
    unsigned char color[4];
  };
  static_assert(sizeof(Vertex) == 16, "stb_easy_font vertex layout");
  std::vector<char> text(s.begin(), s.end());
  text.push_back('\0');
  std::vector<Vertex> buffer(64 * (s.size() + 1));
  int quads = stb_easy_font_print(0.0f, 0.0f, text.data(), nullptr, buffer.data(),
                                  static_cast<int>(buffer.size() * sizeof(Vertex)));
  std::vector<Quad> out;
  out.reserve(static_cast<std::size_t>(quads));
  for (int q = 0; q < quads; ++q) {
    const Vertex* v = &buffer[4 * static_cast<std::size_t>(q)];
    Quad r{v[0].x, v[0].y, v[0].x, v[0].y};
    for (int k = 1; k < 4; ++k) {
      r.x0 = std::min(r.x0, v[k].x);
      r.y0 = std::min(r.y0, v[k].y);
      r.x1 = std::max(r.x1, v[k].x);
      r.y1 = std::max(r.y1, v[k].y);
    }
    out.push_back(r);
  }
  return out;
}

double clamp01(double v) {
  return std::clamp(v, 0.0, 1.0);
}

// Distance from p to the segment a-b.
double segment_distance(double px, double py, double ax, double ay, double bx, double by) {
  double dx = bx - ax, dy = by - ay;
  double len2 = dx * dx + dy * dy;
  double t = len2 > 0.0 ? clamp01(((px - ax) * dx + (py - ay) * dy) / len2) : 0.0;
  double ex = ax + t * dx - px, ey = ay + t * dy - py;
  return std::sqrt(ex * ex + ey * ey);
}

std::vector<std::string> split_lines(const std::string& s) {
  std::vector<std::string> lines(1);
  for (char c : s) {
    if (c == '\n')
      lines.emplace_back();
    else
      lines.back() += c;
  }
  return lines;
}

struct Range {
  double lo = 0.0, hi = 1.0;
  std::vector<double> ticks;
  double step() const { return ticks.size() > 1 ? ticks[1] - ticks[0] : hi - lo; }
};

Range axis_range(double lo, double hi, bool from_zero) {
  if (from_zero) lo = std::min(lo, 0.0);
  if (!(hi > lo)) hi = lo + (lo != 0.0 ? std::fabs(lo) : 1.0);
  Range r;
  r.ticks = nice_ticks(lo, hi);
  r.lo = r.ticks.front();
  r.hi = r.ticks.back();
  return r;
}

// A log axis over the decimal logarithms [lo, hi] of the data: ticks (as logarithms) at 1, 2 and
// 5 x 10^k when the range spans fewer than 4 decades, else at the decades only; the range runs
// from the last tick at or below lo to the first at or above hi.
Range log_axis_range(double lo, double hi) {
  if (!(hi > lo)) lo -= 0.5, hi += 0.5;
  const bool decades_only = hi - lo >= 4.0;
  std::vector<double> marks;
  for (long long k = static_cast<long long>(std::floor(lo)) - 1;
       k <= static_cast<long long>(std::ceil(hi)) + 1; ++k)
    for (double m : decades_only ? std::vector<double>{1.0} : std::vector<double>{1.0, 2.0, 5.0})
      marks.push_back(static_cast<double>(k) + std::log10(m));
  Range r;
  std::size_t first = 0, last = marks.size() - 1;
  for (std::size_t i = 0; i < marks.size(); ++i)
    if (marks[i] <= lo + 1e-9) first = i;
  for (std::size_t i = marks.size(); i-- > 0;)
    if (marks[i] >= hi - 1e-9) last = i;
  r.ticks.assign(marks.begin() + static_cast<long>(first),
                 marks.begin() + static_cast<long>(last) + 1);
  r.lo = r.ticks.front();
  r.hi = r.ticks.back();
  return r;
}

// The label of a log-axis tick (a logarithm): the value itself, in as few digits as it needs.
std::string log_tick_label(double log_value) {
  const double v = std::pow(10.0, log_value);
  char buf[64];
  if (v >= 1e5 || v < 1e-4)
    std::snprintf(buf, sizeof(buf), "%.0e", v);
  else
    std::snprintf(buf, sizeof(buf), "%.*f",
                  std::max(0, static_cast<int>(-std::floor(log_value + 1e-9))), v);
  return buf;
}

void draw_title(Canvas& c, const std::string& title, const std::string& note) {
  c.text(c.width() / 2.0, 14.0, title, 3.0, kBlack, Align::Center);
  if (!note.empty()) c.text(c.width() / 2.0, 44.0, note, 1.5, kDarkGrey, Align::Center);
}

}  // namespace

Canvas::Canvas(int width, int height, Color background)
    : width_(width), height_(height), rgb_(static_cast<std::size_t>(width) * height * 3) {
  for (std::size_t i = 0; i < rgb_.size(); i += 3) {
    rgb_[i] = background.r;
    rgb_[i + 1] = background.g;
    rgb_[i + 2] = background.b;
  }
}

void Canvas::blend(int x, int y, Color c, double coverage) {
  if (x < 0 || y < 0 || x >= width_ || y >= height_ || !(coverage > 0.0)) return;
  double a = std::min(coverage, 1.0);
  std::uint8_t* p = &rgb_[(static_cast<std::size_t>(y) * width_ + x) * 3];
  const std::uint8_t src[3] = {c.r, c.g, c.b};
  for (int k = 0; k < 3; ++k)
    p[k] = static_cast<std::uint8_t>(std::lround(p[k] * (1.0 - a) + src[k] * a));
}

void Canvas::fill_rect(double x0, double y0, double x1, double y1, Color c) {
  if (x1 < x0) std::swap(x0, x1);
  if (y1 < y0) std::swap(y0, y1);
  int ix0 = static_cast<int>(std::floor(x0)), ix1 = static_cast<int>(std::ceil(x1));
  int iy0 = static_cast<int>(std::floor(y0)), iy1 = static_cast<int>(std::ceil(y1));
  for (int y = std::max(iy0, 0); y < std::min(iy1, height_); ++y) {
    double cy = std::min(y1, y + 1.0) - std::max(y0, static_cast<double>(y));
    for (int x = std::max(ix0, 0); x < std::min(ix1, width_); ++x) {
      double cx = std::min(x1, x + 1.0) - std::max(x0, static_cast<double>(x));
      blend(x, y, c, cx * cy);  // area of the pixel the rectangle covers
    }
  }
}

void Canvas::line(double x0, double y0, double x1, double y1, double width, Color c) {
  const double half = 0.5 * width;
  int bx0 = static_cast<int>(std::floor(std::min(x0, x1) - half - 1.0));
  int bx1 = static_cast<int>(std::ceil(std::max(x0, x1) + half + 1.0));
  int by0 = static_cast<int>(std::floor(std::min(y0, y1) - half - 1.0));
  int by1 = static_cast<int>(std::ceil(std::max(y0, y1) + half + 1.0));
  for (int y = std::max(by0, 0); y < std::min(by1, height_); ++y)
    for (int x = std::max(bx0, 0); x < std::min(bx1, width_); ++x) {
      double d = segment_distance(x + 0.5, y + 0.5, x0, y0, x1, y1);
      blend(x, y, c, clamp01(half + 0.5 - d));
    }
}

void Canvas::disc(double cx, double cy, double radius, Color c) {
  for (int y = std::max(static_cast<int>(cy - radius - 1.0), 0);
       y < std::min(static_cast<int>(cy + radius + 2.0), height_); ++y)
    for (int x = std::max(static_cast<int>(cx - radius - 1.0), 0);
         x < std::min(static_cast<int>(cx + radius + 2.0), width_); ++x) {
      double d = std::hypot(x + 0.5 - cx, y + 0.5 - cy);
      blend(x, y, c, clamp01(radius + 0.5 - d));
    }
}

double Canvas::text_width(const std::string& s, double scale) {
  std::vector<char> text(s.begin(), s.end());
  text.push_back('\0');
  return stb_easy_font_width(text.data()) * scale;
}

void Canvas::text(double x, double y, const std::string& s, double scale, Color c, Align align,
                  bool vertical) {
  double w = text_width(s, scale);
  double shift = align == Align::Left ? 0.0 : align == Align::Center ? 0.5 * w : w;
  x = std::round(x);
  y = std::round(y);
  for (const Quad& q : glyph_quads(s)) {
    if (!vertical) {
      double ox = x - shift;
      fill_rect(ox + q.x0 * scale, y + q.y0 * scale, ox + q.x1 * scale, y + q.y1 * scale, c);
    } else {
      // Glyph x runs up the canvas, glyph y to the right.
      double oy = y + shift;
      fill_rect(x + q.y0 * scale, oy - q.x1 * scale, x + q.y1 * scale, oy - q.x0 * scale, c);
    }
  }
}

void Canvas::write_png(const std::string& path) const {
  if (!stbi_write_png(path.c_str(), width_, height_, 3, rgb_.data(), width_ * 3))
    throw std::runtime_error(path + ": cannot write PNG");
}

std::vector<double> nice_ticks(double lo, double hi, int target) {
  if (!(hi > lo)) hi = lo + 1.0;
  double raw = (hi - lo) / std::max(target - 1, 1);
  double mag = std::pow(10.0, std::floor(std::log10(raw)));
  double norm = raw / mag;
  double step = (norm < 1.5 ? 1.0 : norm < 3.0 ? 2.0 : norm < 7.0 ? 5.0 : 10.0) * mag;
  auto first = static_cast<long long>(std::floor(lo / step + 1e-9));
  auto last = static_cast<long long>(std::ceil(hi / step - 1e-9));
  std::vector<double> ticks;
  for (long long k = first; k <= last; ++k) ticks.push_back(static_cast<double>(k) * step);
  if (ticks.size() < 2) ticks.push_back(ticks.back() + step);
  return ticks;
}

std::string tick_label(double value, double step) {
  int decimals = std::max(0, static_cast<int>(-std::floor(std::log10(step) + 1e-9)));
  if (std::fabs(value) < 0.5 * step * 1e-6) value = 0.0;  // no "-0"
  char buf[64];
  std::snprintf(buf, sizeof(buf), "%.*f", decimals, value);
  return buf;
}

namespace {

// On a log axis the series are drawn in decimal logarithms; points that have none are dropped.
XYPlot to_log_axes(const XYPlot& in) {
  XYPlot plot = in;
  if (plot.x_log || plot.y_log)
    for (Series& s : plot.series) {
      Series t = s;
      t.x.clear();
      t.y.clear();
      t.labels.clear();
      for (std::size_t i = 0; i < s.x.size() && i < s.y.size(); ++i) {
        if ((plot.x_log && !(s.x[i] > 0.0)) || (plot.y_log && !(s.y[i] > 0.0))) continue;
        t.x.push_back(plot.x_log ? std::log10(s.x[i]) : s.x[i]);
        t.y.push_back(plot.y_log ? std::log10(s.y[i]) : s.y[i]);
        if (i < s.labels.size()) {
          t.labels.resize(t.x.size() - 1);
          t.labels.push_back(s.labels[i]);
        }
      }
      s = std::move(t);
    }
  return plot;
}

// The legend, in the chosen corner inside the plot area (px0..px1 x py0..py1).
void draw_legend(Canvas& c, const XYPlot& plot, double px0, double px1, double py0, double py1) {
  double lw = 0;
  std::size_t rows = 0;
  for (const Series& s : plot.series)
    if (!s.label.empty()) {
      lw = std::max(lw, Canvas::text_width(s.label, 2.0));
      ++rows;
    }
  if (lw > 0) {
    const double row = 26, bw = lw + 62, bh = row * static_cast<double>(rows) + 10;
    const bool right =
        plot.legend == XYPlot::Legend::TopRight || plot.legend == XYPlot::Legend::BottomRight;
    const bool bottom =
        plot.legend == XYPlot::Legend::BottomLeft || plot.legend == XYPlot::Legend::BottomRight;
    const double lx = right ? px1 - 16 - bw : px0 + 16, ly = bottom ? py1 - 16 - bh : py0 + 12;
    c.fill_rect(lx, ly, lx + bw, ly + bh, kWhite);
    c.line(lx, ly, lx + bw, ly, 1.0, kGrey);
    c.line(lx + bw, ly, lx + bw, ly + bh, 1.0, kGrey);
    c.line(lx + bw, ly + bh, lx, ly + bh, 1.0, kGrey);
    c.line(lx, ly + bh, lx, ly, 1.0, kGrey);
    double y = ly + 8;
    for (const Series& s : plot.series) {
      if (s.label.empty()) continue;
      double my = y + Canvas::text_height(2.0) / 2;
      if (s.lines) c.line(lx + 8, my, lx + 40, my, s.line_width, s.color);
      if (s.points) c.disc(lx + 24, my, 5.0, s.color);
      c.text(lx + 50, y, s.label, 2.0, kBlack);
      y += row;
    }
  }
}

}  // namespace

void write_xy_plot(const std::string& path, const XYPlot& in) {
  const XYPlot plot = to_log_axes(in);
  Canvas c(plot.width, plot.height);
  const double left = 110, right = 40, top = plot.note.empty() ? 70 : 80, bottom = 80;
  const double px0 = left, px1 = plot.width - right, py0 = top, py1 = plot.height - bottom;

  double xmin = std::numeric_limits<double>::infinity(), xmax = -xmin;
  double ymin = xmin, ymax = -xmin;
  for (const Series& s : plot.series)
    for (std::size_t i = 0; i < s.x.size() && i < s.y.size(); ++i) {
      xmin = std::min(xmin, s.x[i]);
      xmax = std::max(xmax, s.x[i]);
      ymin = std::min(ymin, s.y[i]);
      ymax = std::max(ymax, s.y[i]);
    }
  if (!(xmax >= xmin)) xmin = 0.0, xmax = 1.0;
  if (!(ymax >= ymin)) ymin = 0.0, ymax = 1.0;
  ymax += plot.y_headroom * (ymax - ymin);
  Range xr = plot.x_log ? log_axis_range(xmin, xmax) : axis_range(xmin, xmax, plot.x_from_zero);
  Range yr = plot.y_log ? log_axis_range(ymin, ymax) : axis_range(ymin, ymax, plot.y_from_zero);
  auto x_label = [&](double t) {
    return plot.x_log ? log_tick_label(t) : tick_label(t, xr.step());
  };
  auto y_label = [&](double t) {
    return plot.y_log ? log_tick_label(t) : tick_label(t, yr.step());
  };
  auto sx = [&](double v) { return px0 + (v - xr.lo) / (xr.hi - xr.lo) * (px1 - px0); };
  auto sy = [&](double v) { return py1 - (v - yr.lo) / (yr.hi - yr.lo) * (py1 - py0); };

  draw_title(c, plot.title, plot.note);
  // Grid, ticks and their numbers.
  for (double t : xr.ticks) {
    double x = sx(t);
    c.line(x, py0, x, py1, 1.0, kGrey);
    c.line(x, py1, x, py1 + 6, 1.5, kBlack);
    c.text(x, py1 + 12, x_label(t), 2.0, kBlack, Align::Center);
  }
  for (double t : yr.ticks) {
    double y = sy(t);
    c.line(px0, y, px1, y, 1.0, kGrey);
    c.line(px0 - 6, y, px0, y, 1.5, kBlack);
    c.text(px0 - 10, y - Canvas::text_height(2.0) / 2, y_label(t), 2.0, kBlack, Align::Right);
  }
  c.line(px0, py1, px1, py1, 2.0, kBlack);
  c.line(px0, py0, px0, py1, 2.0, kBlack);
  c.text((px0 + px1) / 2, py1 + 44, plot.x_label, 2.0, kBlack, Align::Center);
  c.text(18, (py0 + py1) / 2, plot.y_label, 2.0, kBlack, Align::Center, true);

  for (const Series& s : plot.series) {
    const std::size_t n = std::min(s.x.size(), s.y.size());
    if (s.lines)
      for (std::size_t i = 1; i < n; ++i)
        c.line(sx(s.x[i - 1]), sy(s.y[i - 1]), sx(s.x[i]), sy(s.y[i]), s.line_width, s.color);
    if (s.points)
      for (std::size_t i = 0; i < n; ++i) c.disc(sx(s.x[i]), sy(s.y[i]), 5.0, s.color);
    for (std::size_t i = 0; i < n && i < s.labels.size(); ++i) {
      if (s.labels_above_left)
        c.text(sx(s.x[i]) - 8, sy(s.y[i]) - 20, s.labels[i], 1.5, kDarkGrey, Align::Right);
      else
        c.text(sx(s.x[i]) + 10, std::min(sy(s.y[i]) + 4, py1 - 16), s.labels[i], 1.5, kDarkGrey);
    }
  }

  draw_legend(c, plot, px0, px1, py0, py1);
  c.write_png(path);
}

void write_bar_chart(const std::string& path, const BarChart& chart) {
  Canvas c(chart.width, chart.height);
  const double left = 110, right = 30, top = chart.note.empty() ? 110 : 120, bottom = 90;
  const double px0 = left, px1 = chart.width - right, py0 = top, py1 = chart.height - bottom;
  const std::size_t ns = chart.values.size(), nc = chart.categories.size();

  double vmax = 0.0;
  for (const auto& row : chart.values)
    for (double v : row) vmax = std::max(vmax, v);
  Range yr = axis_range(0.0, vmax * 1.08, true);
  auto sy = [&](double v) { return py1 - (v - yr.lo) / (yr.hi - yr.lo) * (py1 - py0); };

  draw_title(c, chart.title, chart.note);
  for (double t : yr.ticks) {
    double y = sy(t);
    c.line(px0, y, px1, y, 1.0, kGrey);
    c.line(px0 - 6, y, px0, y, 1.5, kBlack);
    c.text(px0 - 10, y - Canvas::text_height(2.0) / 2, tick_label(t, yr.step()), 2.0, kBlack,
           Align::Right);
  }
  c.text(18, (py0 + py1) / 2, chart.y_label, 2.0, kBlack, Align::Center, true);

  const double slot = (px1 - px0) / std::max<std::size_t>(nc, 1);
  const double bar = 0.8 * slot / std::max<std::size_t>(ns, 1);
  for (std::size_t k = 0; k < nc; ++k) {
    const double sx0 = px0 + k * slot + 0.1 * slot;
    for (std::size_t s = 0; s < ns; ++s) {
      double v = k < chart.values[s].size() ? chart.values[s][k] : 0.0;
      double x0 = sx0 + s * bar, x1 = x0 + bar - 2.0;
      Color col = s < chart.colors.size() ? chart.colors[s] : kBlue;
      c.fill_rect(x0, sy(v), x1, py1, col);
      if (chart.value_labels) {
        char buf[64];
        std::snprintf(buf, sizeof(buf), "%.*f", chart.value_decimals, v);
        double scale = Canvas::text_width(buf, 2.0) <= bar ? 2.0 : 1.5;
        if (Canvas::text_width(buf, scale) > bar + 6) scale = 1.0;
        c.text((x0 + x1) / 2, sy(v) - Canvas::text_height(scale) - 5, buf, scale, kBlack,
               Align::Center);
      }
    }
    if (k < chart.marks.size()) {
      const double ym = sy(chart.marks[k]);
      for (double x = sx0 - 4; x < sx0 + ns * bar + 2; x += 12)
        c.line(x, ym, std::min(x + 7, sx0 + ns * bar + 2), ym, 2.5, chart.mark_color);
    }
    double y = py1 + 14;
    for (const std::string& line : split_lines(chart.categories[k])) {
      c.text(px0 + (k + 0.5) * slot, y, line, 2.0, kBlack, Align::Center);
      y += 22;
    }
  }
  c.line(px0, py1, px1, py1, 2.0, kBlack);
  c.line(px0, py0, px0, py1, 2.0, kBlack);

  // Legend: one row under the title.
  double total = 0;
  for (const std::string& l : chart.series_labels) total += Canvas::text_width(l, 2.0) + 60;
  if (!chart.mark_label.empty()) total += Canvas::text_width(chart.mark_label, 2.0) + 60;
  double x = (chart.width - total) / 2;
  const double ly = top - 34;
  for (std::size_t s = 0; s < chart.series_labels.size(); ++s) {
    Color col = s < chart.colors.size() ? chart.colors[s] : kBlue;
    c.fill_rect(x, ly, x + 22, ly + 16, col);
    c.text(x + 30, ly + 1, chart.series_labels[s], 2.0, kBlack);
    x += Canvas::text_width(chart.series_labels[s], 2.0) + 60;
  }
  if (!chart.mark_label.empty()) {
    for (double dx = 0; dx < 22; dx += 12)
      c.line(x + dx, ly + 8, x + std::min(dx + 7, 22.0), ly + 8, 2.5, chart.mark_color);
    c.text(x + 30, ly + 1, chart.mark_label, 2.0, kBlack);
  }
  c.write_png(path);
}

}  // namespace irradcast::plot
