// irradcast-bench-engine, part 2: full updates (1 direct + K indirect bounces, default
// parameters) on rooms:N for growing N at a constant number of texels per metre, and on one
// rooms:M at growing density, all measured in interleaved rounds (fastest kept); a least-squares
// line through update time against texel count gives the cost per texel and R^2; optionally a
// third series of many-light buildings (rooms:N:lit, rooms:N:trim). Per point also the set-up
// time (scene, atlas, G-buffers, BVH, engine), the resident bytes it added per texel, rays per
// second and the share of the direct pass's shadow rays that ended occluded. Prints a table,
// adds the series to the JSON and writes bench_update_vs_texels.png and
// bench_cost_per_texel.png.
#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>
#include <stdexcept>
#include <string>

#include "bench_util.h"
#include "embree_backend.h"
#include "engine_bench.h"
#include "irradcast/common/builtin.h"
#include "irradcast/engine/engine.h"
#include "plot.h"

namespace irradcast::bench {
namespace {

struct ScalePoint {
  std::string scene;  // rooms:N, rooms:N:lit, rooms:N:trim
  int n = 0;
  float density = 0;  // texels per metre
  float texels_per_scene = 0;
  std::size_t texels = 0, atlas_texels = 0, triangles = 0;
  std::uint64_t rays = 0;
  double setup_s = 0, update_s = 0, direct_s = 0, probes_s = 0, scatter_s = 0;
  double resident_bytes = 0;  // what building the case and its first update added
  double occluded = 0;        // share of the direct pass's area-light shadow rays
  std::vector<double> updates_s;
};

// The process's resident set, in bytes (Linux; 0 elsewhere).
double resident_bytes() {
  std::ifstream statm("/proc/self/statm");
  double pages = 0, resident = 0;
  if (!(statm >> pages >> resident)) return 0.0;
  return resident * 4096.0;
}

// Builds rooms:N for every size, then runs rounds of one update per size (interleaved, so that
// a burst of other load on the machine spreads over all sizes instead of skewing one).
struct CaseSpec {
  int n = 1;
  float density = 16.0f;  // texels per metre
  std::string variant;    // "", "lit" or "trim"
  bool operator==(const CaseSpec&) const = default;
};

std::string scene_name(const CaseSpec& c) {
  return "rooms:" + std::to_string(c.n) + (c.variant.empty() ? "" : ":" + c.variant);
}

std::vector<ScalePoint> bench_updates(const std::vector<CaseSpec>& specs, int updates,
                                      const EngineParams& params) {
  struct Case {
    std::unique_ptr<PreparedScene> setup;
    std::unique_ptr<Engine> engine;
    const EmbreeBackend* backend = nullptr;
    std::vector<double> direct, probes, scatter, occluded;
  };
  std::vector<ScalePoint> pts(specs.size());
  std::vector<Case> cases(specs.size());
  for (std::size_t k = 0; k < specs.size(); ++k) {
    std::fprintf(stderr, "scaling: building %s at %.0f texels/m ...\n",
                 scene_name(specs[k]).c_str(), specs[k].density);
    ScalePoint& pt = pts[k];
    Case& c = cases[k];
    pt.scene = scene_name(specs[k]);
    pt.n = specs[k].n;
    const double resident_before = resident_bytes();
    pt.density = specs[k].density;
    auto t0 = Clock::now();
    RoomsOptions ro;
    ro.n = specs[k].n;
    ro.every_room_lit = specs[k].variant == "lit";
    ro.trim = specs[k].variant == "trim";
    Scene scene = make_rooms(ro);
    float extent = World::build(scene).bounds.max_extent();
    pt.texels_per_scene = pt.density * extent;
    c.setup =
        std::make_unique<PreparedScene>(prepare(std::move(scene), density(pt.texels_per_scene)));
    const PreparedScene& s = *c.setup;
    auto backend = std::make_unique<EmbreeBackend>(s.rays(), s.lights());
    c.backend = backend.get();
    c.engine = std::make_unique<Engine>(s.world(), s.atlas(), s.gbuffers(), s.rays(),
                                        std::move(backend), params);
    pt.setup_s = seconds_since(t0);
    pt.texels = c.engine->texel_count();
    pt.atlas_texels = s.atlas().texel_count();
    for (const auto& o : s.world().objects) pt.triangles += o.triangles().size();
    c.engine->update();  // warm-up
    pt.resident_bytes = resident_bytes() - resident_before;
  }
  for (int u = 0; u < updates; ++u) {
    std::fprintf(stderr, "scaling: round %d of %d ...\n", u + 1, updates);
    for (std::size_t k = 0; k < specs.size(); ++k) {
      ScalePoint& pt = pts[k];
      Case& c = cases[k];
      UpdateStats st = c.engine->update();
      pt.updates_s.push_back(st.total_seconds);
      c.direct.push_back(st.direct.seconds);
      const auto area = static_cast<double>(c.backend->direct_area_rays());
      c.occluded.push_back(area > 0 ? static_cast<double>(c.backend->direct_occluded_rays()) / area
                                    : 0.0);
      double p = 0, sc = 0;
      for (const auto& x : st.probes) p += x.seconds;
      for (const auto& x : st.scatter) sc += x.seconds;
      c.probes.push_back(p);
      c.scatter.push_back(sc);
      pt.rays = st.total_rays();
    }
  }
  for (std::size_t k = 0; k < specs.size(); ++k) {
    // The fastest round, and its passes: the cost without interference from other load.
    const auto& u = pts[k].updates_s;
    const std::size_t best =
        static_cast<std::size_t>(std::min_element(u.begin(), u.end()) - u.begin());
    pts[k].update_s = u[best];
    pts[k].direct_s = cases[k].direct[best];
    pts[k].probes_s = cases[k].probes[best];
    pts[k].scatter_s = cases[k].scatter[best];
    pts[k].occluded = cases[k].occluded[best];
  }
  return pts;
}

struct Fit {
  double intercept = 0, slope = 0, r2 = 0;
};

Fit fit_line(const std::vector<double>& x, const std::vector<double>& y) {
  const double n = static_cast<double>(x.size());
  double mx = 0, my = 0;
  for (std::size_t i = 0; i < x.size(); ++i) mx += x[i] / n, my += y[i] / n;
  double sxx = 0, sxy = 0, syy = 0;
  for (std::size_t i = 0; i < x.size(); ++i) {
    sxx += (x[i] - mx) * (x[i] - mx);
    sxy += (x[i] - mx) * (y[i] - my);
    syy += (y[i] - my) * (y[i] - my);
  }
  Fit f;
  f.slope = sxx > 0 ? sxy / sxx : 0;
  f.intercept = my - f.slope * mx;
  double ss_res = 0;
  for (std::size_t i = 0; i < x.size(); ++i) {
    double e = y[i] - (f.intercept + f.slope * x[i]);
    ss_res += e * e;
  }
  f.r2 = syy > 0 ? 1.0 - ss_res / syy : 1.0;
  return f;
}

// The two series of the benchmark.
struct Sweep {
  std::string key, title;
  std::vector<ScalePoint> pts;
  Fit fit;
  double cmin = INFINITY, cmax = 0, cmean = 0;
};

// Measures rooms:N at the fixed density and rooms:M at the sweep densities, the configuration in
// both series (rooms:M at the fixed density) once; the points in the order of the two series.
std::vector<ScalePoint> measure_series(const ScalingOptions& o, const std::vector<int>& sizes,
                                       const std::vector<int>& densities,
                                       const std::vector<CaseSpec>& many) {
  std::vector<CaseSpec> specs;
  for (int n : sizes) specs.push_back({n, o.density, ""});
  for (int d : densities) specs.push_back({o.sweep_size, static_cast<float>(d), ""});
  specs.insert(specs.end(), many.begin(), many.end());
  std::vector<CaseSpec> unique;
  std::vector<std::size_t> slot;
  for (const CaseSpec& c : specs) {
    auto it = std::find(unique.begin(), unique.end(), c);
    slot.push_back(static_cast<std::size_t>(it - unique.begin()));
    if (it == unique.end()) unique.push_back(c);
  }
  const std::vector<ScalePoint> measured = bench_updates(unique, o.updates, o.params);
  std::vector<ScalePoint> all;
  for (std::size_t k : slot) all.push_back(measured[k]);
  return all;
}

// Fits the series, prints its rows and fit, and adds them to `result`.
void report_sweep(Sweep& sw, json& result) {
  std::vector<double> x, y;
  for (const auto& p : sw.pts) {
    x.push_back(static_cast<double>(p.texels));
    y.push_back(p.update_s);
    double c = p.update_s / p.texels;
    sw.cmin = std::min(sw.cmin, c);
    sw.cmax = std::max(sw.cmax, c);
    sw.cmean += c / sw.pts.size();
  }
  sw.fit = fit_line(x, y);
  json rows = json::array();
  for (const auto& p : sw.pts) {
    double other = p.update_s - p.direct_s - p.probes_s - p.scatter_s;
    std::printf(
        "%-13s %5.0f %9zu %9zu %9zu %10llu %9.1f %9.1f %9.1f %9.1f %8.1f %8.3f %7.1f %7.1f "
        "%6.1f %6.1f\n",
        p.scene.c_str(), p.density, p.texels, p.atlas_texels, p.triangles,
        static_cast<unsigned long long>(p.rays), p.update_s * 1e3, p.direct_s * 1e3,
        p.probes_s * 1e3, p.scatter_s * 1e3, other * 1e3, p.update_s / p.texels * 1e6,
        p.resident_bytes / p.texels, p.rays / p.update_s * 1e-6, 100 * p.occluded, p.setup_s);
    rows.push_back({{"scene", p.scene},
                    {"texels_per_metre", p.density},
                    {"texels_per_scene", p.texels_per_scene},
                    {"texels", p.texels},
                    {"atlas_texels", p.atlas_texels},
                    {"triangles", p.triangles},
                    {"rays_per_update", p.rays},
                    {"setup_s", p.setup_s},
                    {"update_s_min", p.update_s},
                    {"update_s_median", median(p.updates_s)},
                    {"updates_s", p.updates_s},
                    {"direct_s", p.direct_s},
                    {"probes_s", p.probes_s},
                    {"scatter_s", p.scatter_s},
                    {"other_s", other},
                    {"us_per_texel", p.update_s / p.texels * 1e6},
                    {"resident_bytes", p.resident_bytes},
                    {"resident_bytes_per_texel", p.resident_bytes / p.texels},
                    {"rays_per_s", p.rays / p.update_s},
                    {"direct_occluded_share", p.occluded}});
  }
  std::printf(
      "  %s: update = %.2f ms + %.4f us x texels, R^2 = %.5f; per-texel cost %.3f .. "
      "%.3f us (spread %.1f%% of the mean)\n",
      sw.title.c_str(), sw.fit.intercept * 1e3, sw.fit.slope * 1e6, sw.fit.r2, sw.cmin * 1e6,
      sw.cmax * 1e6, 100 * (sw.cmax - sw.cmin) / sw.cmean);
  result[sw.key] = rows;
  result[sw.key + "_fit"] = {{"series", sw.title},
                             {"intercept_s", sw.fit.intercept},
                             {"slope_s_per_texel", sw.fit.slope},
                             {"r2", sw.fit.r2},
                             {"us_per_texel_min", sw.cmin * 1e6},
                             {"us_per_texel_max", sw.cmax * 1e6},
                             {"us_per_texel_mean", sw.cmean * 1e6},
                             {"spread_of_mean", (sw.cmax - sw.cmin) / sw.cmean}};
}

// The measured points of series k and its fitted line.
void add_sweep_series(plot::XYPlot& xy, const Sweep& sw, std::size_t k) {
  const plot::Color colors[3][2] = {
      {plot::kBlue, plot::kBlue}, {plot::kGreen, plot::kGreen}, {plot::kRed, plot::kRed}};
  plot::Series meas, line;
  meas.label = sw.title;
  meas.color = colors[k][0];
  meas.labels_above_left = k != 1;
  line.label = fmt("fit: %.0f ms", sw.fit.intercept * 1e3) +
               fmt(" + %.3f us/texel", sw.fit.slope * 1e6) + fmt(", R^2 %.4f", sw.fit.r2);
  line.color = colors[k][1];
  line.points = false;
  line.lines = true;
  line.line_width = 1.5;
  double sxmax = 0;
  for (const auto& p : sw.pts) {
    meas.x.push_back(p.texels * 1e-3);
    meas.y.push_back(p.update_s * 1e3);
    meas.labels.push_back(k == 1 ? fmt("%.0f/m", p.density) : p.scene);
    sxmax = std::max(sxmax, static_cast<double>(p.texels));
  }
  // The line from where it crosses zero time (or zero texels) to the largest point.
  double x0 = sw.fit.intercept < 0 && sw.fit.slope > 0 ? -sw.fit.intercept / sw.fit.slope : 0.0;
  for (double xv : {x0, sxmax}) {
    line.x.push_back(xv * 1e-3);
    line.y.push_back((sw.fit.intercept + sw.fit.slope * xv) * 1e3);
  }
  xy.series.push_back(meas);
  xy.series.push_back(line);
}

// "cells 0.25, range 0.3, 1 direct + 2 bounces": what the plots' notes say of the engine.
std::string engine_text(const EngineParams& p) {
  return "cells " + param_text(p.cell_size) + ", range " + param_text(p.tracing_range) +
         ", 1 direct + " + std::to_string(p.indirect_bounces) + " bounces";
}

void plot_sweeps(const std::vector<Sweep>& sweeps, int used_threads, int updates,
                 const std::string& engine, const std::string& out_dir) {
  plot::XYPlot xy;
  xy.title = "Full update time vs texel count";
  xy.note = std::to_string(used_threads) + " threads, " + engine + ", fastest of " +
            std::to_string(updates) + " updates; lines: least-squares fits";
  xy.x_label = "valid texels (thousands)";
  xy.y_label = "update time (ms)";
  xy.legend = plot::XYPlot::Legend::BottomRight;
  for (std::size_t k = 0; k < sweeps.size(); ++k)
    if (!sweeps[k].pts.empty()) add_sweep_series(xy, sweeps[k], k);
  std::string png = (fs::path(out_dir) / "bench_update_vs_texels.png").string();
  plot::write_xy_plot(png, xy);
  std::printf("wrote %s\n", png.c_str());
}

// Cost per texel and update, and resident bytes per texel, against texels: flat when the method
// keeps its promise for large scenes.
void plot_per_texel(const std::vector<Sweep>& sweeps, int used_threads, int updates,
                    const std::string& engine, const std::string& out_dir) {
  const plot::Color colors[] = {plot::kBlue, plot::kGreen, plot::kRed};
  for (int which = 0; which < 2; ++which) {
    plot::XYPlot xy;
    xy.title = which == 0 ? "Update time per texel" : "Resident bytes per texel";
    xy.note = std::to_string(used_threads) + " threads, " + engine + ", fastest of " +
              std::to_string(updates) +
              (which == 0 ? " updates" : " updates; resident set each scene added");
    xy.x_label = "valid texels (thousands)";
    xy.y_label = which == 0 ? "us per texel and update" : "bytes per texel";
    xy.x_log = true;
    xy.legend = plot::XYPlot::Legend::BottomRight;
    for (std::size_t k = 0; k < sweeps.size(); ++k) {
      if (sweeps[k].pts.empty()) continue;
      plot::Series s;
      s.label = sweeps[k].title;
      s.color = colors[k % 3];
      s.lines = k != 2;
      s.labels_above_left = true;  // the largest point sits at the plot's right edge
      for (const ScalePoint& p : sweeps[k].pts) {
        s.x.push_back(static_cast<double>(p.texels) / 1e3);
        s.y.push_back(which == 0 ? p.update_s / p.texels * 1e6 : p.resident_bytes / p.texels);
        s.labels.push_back(k == 1 ? fmt("%.0f/m", p.density) : p.scene);
      }
      xy.series.push_back(s);
    }
    const std::string png = (fs::path(out_dir) / (which == 0 ? "bench_cost_per_texel.png"
                                                             : "bench_bytes_per_texel.png"))
                                .string();
    plot::write_xy_plot(png, xy);
    std::printf("wrote %s\n", png.c_str());
  }
}

// "N:lit,N:trim" -> the many-light cases at `density`.
std::vector<CaseSpec> parse_many(const std::string& text, float density) {
  std::vector<CaseSpec> out;
  std::size_t at = 0;
  while (at < text.size()) {
    std::size_t end = text.find(',', at);
    if (end == std::string::npos) end = text.size();
    const std::string item = text.substr(at, end - at);
    const std::size_t colon = item.find(':');
    const std::string variant = colon == std::string::npos ? "" : item.substr(colon + 1);
    if (variant != "lit" && variant != "trim")
      throw std::runtime_error("--many-lights: '" + item + "' is not N:lit or N:trim");
    int n = 0;
    const std::string digits = item.substr(0, colon);
    const auto [end_n, ec] = std::from_chars(digits.data(), digits.data() + digits.size(), n);
    if (ec != std::errc() || end_n != digits.data() + digits.size() || n < 1)
      throw std::runtime_error("--many-lights: '" + item + "' does not start with a number N >= 1");
    out.push_back({n, density, variant});
    at = end + 1;
  }
  return out;
}

}  // namespace

// Update time against texel count: rooms:N at a fixed density (the building grows), and rooms:M
// at growing density (the same building, more texels).
void run_scaling(const ScalingOptions& o, int used_threads, const std::string& out_dir,
                 json& result) {
  const std::vector<int> sizes = parse_ints(o.sizes_text);
  const std::vector<int> densities = parse_ints(o.sweep_text);
  const std::vector<CaseSpec> many = parse_many(o.many_text, o.density);
  const std::vector<ScalePoint> all = measure_series(o, sizes, densities, many);
  std::vector<Sweep> sweeps(3);
  sweeps[0].key = "scaling";
  sweeps[0].title = "rooms:N at " + fmt("%.0f", o.density) + " texels/m";
  sweeps[0].pts.assign(all.begin(), all.begin() + static_cast<long>(sizes.size()));
  sweeps[1].key = "density_sweep";
  sweeps[1].title = "rooms:" + std::to_string(o.sweep_size) + " at " + o.sweep_text + " texels/m";
  const auto sweep_end = static_cast<long>(sizes.size() + densities.size());
  sweeps[1].pts.assign(all.begin() + static_cast<long>(sizes.size()), all.begin() + sweep_end);
  sweeps[2].key = "many_lights";
  sweeps[2].title = "many lights at " + fmt("%.0f", o.density) + " texels/m";
  sweeps[2].pts.assign(all.begin() + sweep_end, all.end());
  std::printf("\nFull update (%s) vs texels, fastest of %d interleaved rounds\n",
              engine_text(o.params).c_str(), o.updates);
  std::printf("%-13s %5s %9s %9s %9s %10s %9s %9s %9s %9s %8s %8s %7s %7s %6s %6s\n", "scene",
              "tex/m", "texels", "atlas tex", "triangles", "rays", "update ms", "direct ms",
              "probes ms", "scatter ms", "other ms", "us/texel", "B/texel", "Mrays/s", "occl%",
              "load s");
  for (Sweep& sw : sweeps)
    if (!sw.pts.empty()) report_sweep(sw, result);
  plot_sweeps(sweeps, used_threads, o.updates, engine_text(o.params), out_dir);
  plot_per_texel(sweeps, used_threads, o.updates, engine_text(o.params), out_dir);
}

}  // namespace irradcast::bench
