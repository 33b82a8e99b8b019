// A small, self-contained plotting helper for the benchmarks: an RGB canvas with anti-aliased
// lines and discs, text from stb_easy_font (scaled, optionally vertical), PNG output through
// stb_image_write, and two chart types on top of it: an x-y plot (points and/or lines, "nice"
// numbered ticks, axis labels, title, legend) and a grouped bar chart.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace irradcast::plot {

struct Color {
  std::uint8_t r = 0, g = 0, b = 0;
};

inline constexpr Color kBlack{0, 0, 0};
inline constexpr Color kWhite{255, 255, 255};
inline constexpr Color kGrey{200, 200, 200};
inline constexpr Color kDarkGrey{90, 90, 90};
inline constexpr Color kBlue{31, 119, 180};
inline constexpr Color kOrange{255, 127, 14};
inline constexpr Color kGreen{44, 160, 44};
inline constexpr Color kRed{214, 39, 40};

enum class Align { Left, Center, Right };

class Canvas {
 public:
  Canvas(int width, int height, Color background = kWhite);
  int width() const { return width_; }
  int height() const { return height_; }

  // Pixel (x, y) covers [x, x+1) x [y, y+1), y down. Coverage in [0, 1] blends towards c.
  void blend(int x, int y, Color c, double coverage);
  void fill_rect(double x0, double y0, double x1, double y1, Color c);
  void line(double x0, double y0, double x1, double y1, double width, Color c);
  void disc(double cx, double cy, double radius, Color c);
  // Text with its top-left corner at (x, y) (for Align::Left; Center / Right anchor the top
  // middle / top right). Vertical text reads bottom to top and (x, y) anchors its left edge
  // (the glyph tops) with the alignment along the y axis. One glyph pixel is `scale` pixels.
  void text(double x, double y, const std::string& s, double scale, Color c,
            Align align = Align::Left, bool vertical = false);
  static double text_width(const std::string& s, double scale);
  static double text_height(double scale) { return 7.0 * scale; }

  // Throws std::runtime_error when the file cannot be written.
  void write_png(const std::string& path) const;

 private:
  int width_, height_;
  std::vector<std::uint8_t> rgb_;
};

// "Nice" tick values (1, 2 or 5 times a power of ten) covering [lo, hi], about `target` of them.
std::vector<double> nice_ticks(double lo, double hi, int target = 6);
// A tick label with as many decimals as the tick step needs.
std::string tick_label(double value, double step);

struct Series {
  std::string label;
  std::vector<double> x, y;
  Color color = kBlue;
  bool points = true;  // a disc per point
  bool lines = false;  // a polyline through the points, in order
  double line_width = 2.0;
  std::vector<std::string> labels;  // optional text next to each point
  bool labels_above_left = false;   // else below right of the point
};

struct XYPlot {
  std::string title, x_label, y_label;
  std::vector<Series> series;
  bool x_from_zero = true;  // axis ranges start at 0 (else at the data minimum)
  bool y_from_zero = true;
  // Logarithmic axes (ticks at 1, 2, 5 x 10^k, or decades only over a wide range; points with
  // values <= 0 are left out). *_from_zero does not apply to a log axis.
  bool x_log = false;
  bool y_log = false;
  std::string note;  // optional line of text under the title
  // Series with an empty label are left out of the legend.
  enum class Legend { TopLeft, TopRight, BottomLeft, BottomRight } legend = Legend::TopLeft;
  double y_headroom = 0.0;  // extra room above the data, as a fraction of its y range (legend)
  int width = 960, height = 620;
};
void write_xy_plot(const std::string& path, const XYPlot& plot);

struct BarChart {
  std::string title, y_label, note;
  std::vector<std::string> categories;      // along x; '\n' splits a label into lines
  std::vector<std::string> series_labels;   // one bar per series in every category
  std::vector<Color> colors;                // per series
  std::vector<std::vector<double>> values;  // [series][category]
  std::vector<double> marks;  // optional per category: a horizontal line across its bars
  std::string mark_label;     // legend entry of the marks
  Color mark_color = kRed;
  bool value_labels = true;  // print each bar's value above it
  int value_decimals = 1;
  int width = 1100, height = 620;
};
void write_bar_chart(const std::string& path, const BarChart& chart);

}  // namespace irradcast::plot
