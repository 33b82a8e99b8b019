// irradcast-bench-crossover: the report. The cross-over table (one row per scene and target) on
// stdout, the scenes' JSON, and three PNGs per scene: error against CPU seconds
// (crossover_error_*.png), CPU seconds to reach a target against users (crossover_users_*.png)
// and the views at the middle target (crossover_views_*.png).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <utility>

#include "bench_util.h"
#include "crossover.h"
#include "irradcast/common/tonemap.h"

namespace irradcast::bench {

namespace {

std::string kstar_text(double k) {
  if (!(k < kInf)) return "inf";
  return fmt(k < 10 ? "%.2f" : "%.1f", k);
}

json num(double v) {
  return v < kInf ? json(v) : json(nullptr);
}

// The panel drawn of each image: all of it up to 320 x 180 pixels, else its centre at 1:1 (a
// 1280x720 picture of three columns would be megabytes; scaling down would hide the noise).
constexpr int kPanelW = 320, kPanelH = 180;

void image_to_canvas(plot::Canvas& c, const ImageRGB& img, int x0, int y0, float exposure_ev) {
  ToneMapOptions tm;
  tm.auto_exposure = false;
  tm.exposure_ev = exposure_ev;
  std::vector<std::uint8_t> rgb = tonemap_srgb8(img, tm);
  const int w = std::min(img.width, kPanelW), h = std::min(img.height, kPanelH);
  const int sx = (img.width - w) / 2, sy = (img.height - h) / 2;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      std::size_t k = (static_cast<std::size_t>(sy + y) * img.width + sx + x) * 3;
      c.blend(x0 + x, y0 + y, {rgb[k], rgb[k + 1], rgb[k + 2]}, 1.0);
    }
}

// The rows of one scene in the table.
void print_rows(const SceneResult& r) {
  for (const Row& row : r.rows) {
    const bool reach = row.updates > 0;
    std::printf(
        "%-8s %8.4f | %4s %9s %9s | %9.2f %5.0f %4d/%zu | %8s %8s | %4s %8s | %10s\n",
        r.spec.c_str(), row.target, reach ? std::to_string(row.updates).c_str() : "-",
        reach ? fmt("%.2f", row.server_s).c_str() : "-",
        reach ? fmt("%.3f", row.client_s).c_str() : "-", row.pt_s, row.mean_spp,
        row.pt_extrapolated, r.views.size(), kstar_text(row.kstar).c_str(),
        row.kstar < kInf
            ? std::to_string(static_cast<long long>(std::max(1.0, std::ceil(row.kstar)))).c_str()
            : "never",
        row.updates_all > 0 ? std::to_string(row.updates_all).c_str() : "-",
        kstar_text(row.kstar_all).c_str(),
        reach ? fmt("%.1f", 1e3 * row.client_compose_s / row.updates).c_str() : "-");
  }
}

// The JSON of one scene (noise: the reference's relative noise, mean over the views).
json scene_json(const SceneResult& r, double noise) {
  json js;
  js["scene"] = r.spec;
  js["texels_in_lightmaps"] = r.texels;
  js["tiles"] = r.tiles;
  js["lightmaps"] = r.lightmaps;
  js["triangles"] = r.triangles;
  js["server_setup_cpu_s"] = r.setup_cpu_s;
  js["client_setup_cpu_s_bvh"] = r.client_setup_cpu_s;
  js["engine_floor_mean"] = r.floor_mean;
  js["engine_floor_every_view"] = r.floor_all;
  js["reference_rel_noise_mean"] = noise;
  json views = json::array();
  for (std::size_t v = 0; v < r.views.size(); ++v) {
    json jv = pose_json(r.views[v].pose);
    jv["name"] = r.views[v].name;
    jv["reference_mean_radiance"] = r.refs[v].mean;
    jv["reference_rel_noise"] = r.refs[v].rel_noise();
    jv["reference_noise_mse"] = r.refs[v].noise_mse;
    jv["reference_noise_mse_se"] = r.refs[v].noise_mse_se;
    jv["engine_last_err_corrected_se"] = r.refs[v].corrected_se(r.engine.back().err[v].corrected);
    jv["reference_cpu_s"] = r.refs[v].cpu_s;
    jv["reference_cached"] = r.refs[v].cached;
    json pts = json::array();
    for (const PtPoint& p : r.pt[v])
      pts.push_back({{"spp", p.spp},
                     {"cpu_s", p.cpu_s},
                     {"wall_s", p.wall_s},
                     {"err_raw", p.err.raw},
                     {"err_corrected", p.err.corrected}});
    jv["path_tracer"] = pts;
    views.push_back(jv);
  }
  js["views"] = views;
  json eng = json::array();
  for (const EngineStep& s : r.engine) {
    json errs_raw = json::array(), errs_cor = json::array();
    for (const Err& e : s.err) {
      errs_raw.push_back(e.raw);
      errs_cor.push_back(e.corrected);
    }
    eng.push_back({{"server_cpu_s", s.server_cpu_s},
                   {"server_wall_s", s.server_wall_s},
                   {"client_decode_cpu_s", s.decode_cpu_s},
                   {"client_compose_cpu_s", s.compose_cpu_s},
                   {"tiles_changed", s.tiles_changed},
                   {"bytes", s.bytes},
                   {"convergence", s.convergence},
                   {"err_raw", errs_raw},
                   {"err_corrected", errs_cor}});
  }
  js["engine_updates"] = eng;
  json rows = json::array();
  for (const Row& row : r.rows)
    rows.push_back({{"target", row.target},
                    {"updates", row.updates},
                    {"server_cpu_s", num(row.server_s)},
                    {"client_cpu_s", num(row.client_s)},
                    {"pt_cpu_s_per_user", num(row.pt_s)},
                    {"pt_mean_spp", row.mean_spp},
                    {"pt_views_extrapolated", row.pt_extrapolated},
                    {"kstar", num(row.kstar)},
                    {"updates_every_view", row.updates_all},
                    {"server_cpu_s_every_view", num(row.server_all_s)},
                    {"client_cpu_s_every_view", num(row.client_all_s)},
                    {"kstar_every_view", num(row.kstar_all)},
                    {"client_compose_cpu_s", num(row.client_compose_s)}});
  js["crossover"] = rows;
  return js;
}

// The path tracer as the cross-over sees it: for each error e, the mean over the views of the
// CPU time to reach e; the second series (thin) where a view's time is extrapolated (t ~ e^-2).
std::pair<plot::Series, plot::Series> pt_curve(const SceneResult& r, bool corrected) {
  plot::Series pt, ptx;
  pt.label = "path tracer, 1 user (mean over views)";
  pt.color = plot::kOrange;
  pt.lines = true;
  pt.points = false;
  pt.line_width = 2.5;
  ptx.label = "  extrapolated, t ~ 1/error^2";
  ptx.color = plot::kOrange;
  ptx.lines = true;
  ptx.points = false;
  ptx.line_width = 1.0;
  double e_hi = 0, e_lo = kInf;
  for (const auto& c : r.pt) e_hi = std::max(e_hi, c.front().err.get(corrected));
  for (double t : r.targets) e_lo = std::min(e_lo, t);
  for (const auto& c : r.pt) e_lo = std::min(e_lo, c.back().err.get(corrected));
  const int n = 48;
  for (int k = 0; k <= n; ++k) {
    const double e = e_hi * std::pow(e_lo / e_hi, static_cast<double>(k) / n);
    double t = 0, spp = 0;
    bool any = false;
    for (const auto& c : r.pt) {
      bool ex = false;
      t += pt_time_to(c, e, corrected, &ex, &spp) / static_cast<double>(r.pt.size());
      any = any || ex;
    }
    if (!any) {
      pt.x.push_back(t);
      pt.y.push_back(e);
      continue;
    }
    if (ptx.x.empty() && !pt.x.empty()) {  // starts where the measured part ends
      ptx.x.push_back(pt.x.back());
      ptx.y.push_back(pt.y.back());
    }
    ptx.x.push_back(t);
    ptx.y.push_back(e);
  }
  return {pt, ptx};
}

// (a) Error against CPU seconds.
void plot_error(const SceneResult& r, const Options& o, const std::string& metric,
                int used_threads) {
  const std::string key = file_key(r.spec);
  plot::XYPlot a;
  a.title = r.spec + ": error vs CPU time";
  a.note = std::to_string(r.views.size()) + " views at " + std::to_string(o.width) + "x" +
           std::to_string(o.height) + ", " + metric + " relative RMSE (mean over views) vs a " +
           std::to_string(o.ref_spp) + " spp reference; " + std::to_string(used_threads) +
           " threads";
  a.x_label = "CPU seconds (log)";
  a.y_label = "relative RMSE (log)";
  a.x_log = a.y_log = true;
  a.legend = plot::XYPlot::Legend::TopRight;
  plot::Series srv, srv1;
  auto [pt, ptx] = pt_curve(r, o.corrected);
  srv.label = "engine: server alone (updates 1, 2 ...)";
  srv.color = plot::kBlue;
  srv.lines = true;
  srv1.label = "engine: server + 1 client";
  srv1.color = plot::kGreen;
  srv1.lines = true;
  srv1.points = false;
  double s = 0, c = 0;
  for (const EngineStep& st : r.engine) {
    s += st.server_cpu_s;
    c += st.decode_cpu_s + st.mean_compose();
    srv.x.push_back(s);
    srv.y.push_back(st.mean_err(o.corrected));
    srv1.x.push_back(s + c);
    srv1.y.push_back(st.mean_err(o.corrected));
  }
  plot::Series noise;
  double nz = 0;
  for (const Reference& ref : r.refs) nz += ref.rel_noise() / r.refs.size();
  noise.label = "reference noise" + std::string(o.corrected ? " (subtracted)" : "");
  noise.color = plot::kDarkGrey;
  noise.points = false;
  noise.lines = true;
  noise.line_width = 1.0;
  double xlo = std::min(pt.x.empty() ? 1.0 : pt.x.front(), srv.x.front());
  double xhi = std::max(pt.x.empty() ? 1.0 : pt.x.back(), srv1.x.back());
  noise.x = {xlo, xhi};
  noise.y = {nz, nz};
  a.series = {pt, srv, srv1, noise};
  if (!ptx.x.empty()) a.series.insert(a.series.begin() + 1, ptx);
  const std::string png = (fs::path(o.out) / ("crossover_error_" + key + ".png")).string();
  plot::write_xy_plot(png, a);
  std::printf("wrote %s\n", png.c_str());
}

// (b) CPU seconds to reach a target against users, for up to three targets.
void plot_users(const SceneResult& r, const Options& o) {
  const std::string key = file_key(r.spec);
  std::vector<const Row*> picks;
  {
    std::vector<const Row*> reach;
    for (const Row& row : r.rows)
      if (row.updates > 0) reach.push_back(&row);
    if (!reach.empty()) {
      picks.push_back(reach.front());
      if (reach.size() > 2) picks.push_back(reach[reach.size() / 2]);
      if (reach.size() > 1) picks.push_back(reach.back());
    }
  }
  double kmax = 8;
  for (const Row* row : picks)
    if (row->kstar < kInf) kmax = std::max(kmax, std::ceil(1.5 * row->kstar));
  kmax = std::min(kmax, 64.0);
  plot::XYPlot b;
  b.title = r.spec + ": CPU time to reach a target error vs users";
  b.note = "lines: K path tracers; with dots: server + K clients; black dot: the cross-over K*; " +
           std::to_string(o.width) + "x" + std::to_string(o.height) + " pixels";
  b.x_label = "users K";
  b.y_log = true;
  b.y_headroom = 0.6;
  b.y_label = "CPU seconds to reach the target (log)";
  const plot::Color colors[3] = {plot::kBlue, plot::kGreen, plot::kRed};
  for (std::size_t k = 0; k < picks.size(); ++k) {
    const Row& row = *picks[k];
    plot::Series p, e, x;
    p.label = "path tracers, error " + fmt("%.3f", row.target);
    p.color = colors[k];
    p.points = false;
    p.lines = true;
    e.label = "shared engine, error " + fmt("%.3f", row.target) + ", K* = " + kstar_text(row.kstar);
    e.color = colors[k];
    e.lines = true;
    e.line_width = 1.0;
    // From half a user (K* can be below 1), finely enough for a smooth line on the log axis.
    for (int q = 2; q <= 4 * static_cast<int>(kmax); ++q) {
      const double K = 0.25 * q;
      p.x.push_back(K);
      p.y.push_back(K * row.pt_s);
      const int step = std::max(1, static_cast<int>(kmax) / 16);
      if (q % 4 == 0 && (q / 4) % step == 0) {
        e.x.push_back(K);
        e.y.push_back(row.server_s + K * row.client_s);
      }
    }
    b.series.push_back(p);
    b.series.push_back(e);
    if (row.kstar < kInf) {
      x.label = "";
      x.color = plot::kBlack;
      x.x = {row.kstar};
      x.y = {row.kstar * row.pt_s};
      x.labels = {"K* = " + kstar_text(row.kstar)};
      x.labels_above_left = row.kstar > 0.2 * kmax;  // else right of it, off the axis
      b.series.push_back(x);
    }
  }
  const std::string png = (fs::path(o.out) / ("crossover_users_" + key + ".png")).string();
  plot::write_xy_plot(png, b);
  std::printf("wrote %s\n", png.c_str());
}

// (c) The views at the middle target: reference | engine | path tracer.
void plot_views(const SceneResult& r, const Options& o) {
  if (r.engine_at_mid.empty()) return;
  const std::string key = file_key(r.spec);
  const int w = std::min(o.width, kPanelW), h = std::min(o.height, kPanelH);
  const int gap = 6, head = 60, label = 18;
  const bool cropped = w < o.width || h < o.height;
  const int nv = static_cast<int>(r.views.size());
  const int cols = nv > 4 ? 2 : 1, rows = (nv + cols - 1) / cols;
  const int cw = 3 * w + 2 * gap + 3 * gap;
  plot::Canvas cv(std::max(cols * cw + gap, 760), head + rows * (h + label + gap) + gap);
  const double target = r.mid_target;
  cv.text(cv.width() / 2.0, 8, r.spec + ": reference | shared engine | path tracer", 2.0,
          plot::kBlack, plot::Align::Center);
  cv.text(cv.width() / 2.0, 32,
          "engine after " + std::to_string(r.mid_update) +
              " updates, path tracer at the first checkpoint with error <= " + fmt("%.3f", target) +
              " per view; same exposure per view" +
              (cropped ? "; centre " + std::to_string(w) + "x" + std::to_string(h) + " at 1:1"
                       : std::string()),
          1.2, plot::kDarkGrey, plot::Align::Center);
  for (int v = 0; v < nv; ++v) {
    const int x0 = gap + (v / rows) * cw, y0 = head + (v % rows) * (h + label + gap);
    ToneMapOptions tm;
    const float ev = std::log2(exposure_scale(r.refs[static_cast<std::size_t>(v)].image, tm));
    const std::size_t sv = static_cast<std::size_t>(v);
    image_to_canvas(cv, r.refs[sv].image, x0, y0 + label, ev);
    image_to_canvas(cv, r.engine_at_mid[sv], x0 + w + gap, y0 + label, ev);
    image_to_canvas(cv, r.pt_at_mid[sv], x0 + 2 * (w + gap), y0 + label, ev);
    const Err ee = error_of(r.engine_at_mid[sv], r.refs[sv]);
    const Err pe = error_of(r.pt_at_mid[sv], r.refs[sv]);
    cv.text(x0, y0 + 3,
            std::to_string(v + 1) + ". " + r.views[sv].name + ": engine " +
                fmt("%.3f", ee.get(o.corrected)) + ", PT " + std::to_string(r.mid_spp[sv]) +
                " spp " + fmt("%.3f", pe.get(o.corrected)),
            1.0, plot::kBlack);
  }
  const std::string png = (fs::path(o.out) / ("crossover_views_" + key + ".png")).string();
  cv.write_png(png);
  std::printf("wrote %s\n", png.c_str());
}

}  // namespace

json report_scenes(const std::vector<SceneResult>& results, const Options& o) {
  std::printf(
      "\nCross-over at equal error (CPU seconds; server = update + publish with RGB9E5 "
      "encoding, all threads;\nclient = per client: decode of the changed tiles + one compose "
      "per update, one thread; PT = per user, mean over the views)\n");
  std::printf("%-8s %8s | %4s %9s %9s | %9s %5s %7s | %8s %8s | %4s %8s | %10s\n", "scene",
              "target", "upd", "server s", "client s", "PT s/user", "spp", "extrap", "K*", "users",
              "upd*", "K*(all)", "compose ms");
  json scenes = json::array();
  for (const SceneResult& r : results) {
    print_rows(r);
    double noise = 0, floor_se = 0;
    for (std::size_t v = 0; v < r.refs.size(); ++v) {
      noise += r.refs[v].rel_noise() / r.refs.size();
      floor_se += r.refs[v].corrected_se(r.engine.back().err[v].corrected) / r.refs.size();
    }
    std::printf(
        "%-8s engine floor (lowest error over %d updates): mean %.4f, every view %.4f; the "
        "reference's own noise: %.4f (relative RMS, mean over views); the corrected error at "
        "the last update is uncertain by +-%.4f (1 sigma, from the noise estimate)\n",
        r.spec.c_str(), o.updates, r.floor_mean, r.floor_all, noise, floor_se);
    scenes.push_back(scene_json(r, noise));
  }
  std::printf(
      "upd: engine updates until the error averaged over the views is <= target ('-': never, "
      "below the engine's floor); K* = server / (PT - client), users = the smallest whole "
      "K;\nupd*, K*(all): the same when every view must be <= target. extrap: views whose "
      "PT time is extrapolated (t ~ e^-2) past the last checkpoint.\ncompose ms: one client "
      "frame at this size (CPU ms, one thread, mean over the updates and views).\n");
  return scenes;
}

void plot_scene(const SceneResult& r, const Options& o, const std::string& metric,
                int used_threads) {
  plot_error(r, o, metric, used_threads);
  plot_users(r, o);
  plot_views(r, o);
}

}  // namespace irradcast::bench
