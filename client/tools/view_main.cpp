// irradcast-view: a thin viewer. Connects to irradcast-server, gets the scene (cached by hash),
// keeps its tile cache current, and composes its own viewpoint: primary rays, lightmap lookup,
// tone mapping. Headless: writes the final frame to a PNG or EXR file. Optional client passes
// (docs/CLIENT_PASSES.md): --ssao, --reproject, and --camera-path to move along a path.
#include <nlohmann/json.hpp>
#include "irradcast/common/cli.h"

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <optional>
#include <sstream>
#include <string>

#include "irradcast/client/camera_path.h"
#include "irradcast/client/client_passes.h"
#include "irradcast/client/host_port.h"
#include "irradcast/client/view_client.h"
#include "irradcast/common/camera.h"
#include "irradcast/common/error.h"
#include "irradcast/common/image.h"
#include "irradcast/common/log.h"
#include "irradcast/common/tonemap.h"
#include "tool_main.h"

namespace {

using Clock = std::chrono::steady_clock;
namespace fs = std::filesystem;

struct Options {
  std::string connect;
  irradcast::ClientTls tls;
  std::string camera;
  bool presence = false;
  int avatars = 32;
  int width = 512;
  int height = 512;
  std::string out;
  int frames = 1;
  int frame_ms = 250;
  bool until_converged = false;
  double converge_at = 0.02;
  double timeout_s = 120.0;
  std::string cache_dir = "auto";
  std::string encoding = "rgb9e5";
  std::uint64_t max_rate = 0;
  std::string name = "irradcast-view";
  std::string tonemap = "reinhard";
  std::string dynamic_emitters = "traced";
  std::string exposure = "auto";
  std::string json;
  std::string log_level = "info";
  bool no_reconnect = false;
  // Client passes (seed 002).
  bool ssao = false;
  float ssao_radius = irradcast::SsaoParams{}.radius;
  float ssao_strength = irradcast::SsaoParams{}.strength;
  bool reproject = false;
  float reproject_epsilon = irradcast::ReprojectionParams{}.epsilon;
  int reproject_frames = irradcast::ReprojectionParams{}.converge_frames;
  float reproject_refresh = irradcast::ReprojectionParams{}.refresh;
  float reproject_bias = irradcast::ReprojectionParams{}.confidence_bias;
  std::string camera_path;
  double path_dt = 1.0 / 30.0;
  double path_period = 20.0;
  std::uint64_t path_seed = 1;
};

std::string num(double v) {
  std::ostringstream ss;
  ss << v;
  return ss.str();
}

// The pass options from the flags; throws irradcast::Error naming the flag of a bad value.
irradcast::ClientPassOptions pass_options(const Options& o) {
  using irradcast::Error;
  auto range = [](const char* flag, double v, double lo, bool lo_open, double hi,
                  const char* what) {
    if (!((lo_open ? v > lo : v >= lo) && v <= hi))
      throw Error(std::string(flag) + " " + num(v) + " must be in " + (lo_open ? "(" : "[") +
                  num(lo) + ", " + num(hi) + "]" + what);
  };
  range("--ssao-radius", o.ssao_radius, 0.0, true, 1.0,
        " (a fraction of the scene's largest extent)");
  range("--ssao-strength", o.ssao_strength, 0.0, false, 10.0, "");
  range("--reproject-epsilon", o.reproject_epsilon, 0.0, true, 1.0,
        " (a fraction of the scene's largest extent)");
  range("--reproject-frames", o.reproject_frames, 1.0, false, 250.0, "");
  range("--reproject-refresh", o.reproject_refresh, 0.0, false, 1.0,
        " (the fraction of 64 x 64 tiles recomputed per frame)");
  range("--reproject-bias", o.reproject_bias, 0.0, true, 100.0, "");
  range("--path-dt", o.path_dt, 0.0, true, 3600.0, " seconds");
  range("--path-period", o.path_period, 0.0, true, 1e6, " seconds");
  irradcast::ClientPassOptions p;
  p.ssao = o.ssao;
  p.ssao_params.radius = o.ssao_radius;
  p.ssao_params.strength = o.ssao_strength;
  p.reproject = o.reproject;
  p.reprojection.epsilon = o.reproject_epsilon;
  p.reprojection.converge_frames = o.reproject_frames;
  p.reprojection.refresh = o.reproject_refresh;
  p.reprojection.confidence_bias = o.reproject_bias;
  p.validate();
  return p;
}

std::string default_cache_dir() {
  if (const char* x = std::getenv("XDG_CACHE_HOME"); x && *x) return std::string(x) + "/irradcast";
  if (const char* h = std::getenv("HOME"); h && *h) return std::string(h) + "/.cache/irradcast";
  return "";
}

irradcast::ViewClientOptions client_options(const Options& o) {
  using namespace irradcast;
  ViewClientOptions vo;
  vo.servers = tools::start_run(o.log_level, o.connect);
  vo.name = o.name;
  vo.cache_dir = o.cache_dir == "auto"   ? default_cache_dir()
                 : o.cache_dir == "none" ? ""
                                         : o.cache_dir;
  vo.encoding = tools::parse_encoding(o.encoding);
  vo.max_bytes_per_s = o.max_rate;
  vo.reconnect = !o.no_reconnect;
  vo.tls = tools::tls_of(o.tls);
  vo.trace_emitters = o.dynamic_emitters == "traced";
  vo.presence = o.presence;
  vo.avatars = o.avatars;
  return vo;
}

irradcast::ToneMapOptions tone_map_of(const Options& o) {
  using irradcast::Error;
  const std::string ext = fs::path(o.out).extension().string();
  if (ext != ".png" && ext != ".exr") throw Error("--out must end in .png or .exr: " + o.out);
  irradcast::ToneMapOptions tm;
  tm.op = irradcast::parse_tone_operator(o.tonemap);
  if (o.exposure != "auto") {
    tm.auto_exposure = false;
    try {
      tm.exposure_ev = std::stof(o.exposure);
    } catch (const std::exception&) {
      throw Error("--exposure must be 'auto' or a number of stops");
    }
  }
  return tm;
}

// The path of --camera-path over the scene the client holds (none without the flag).
std::optional<irradcast::CameraPath> camera_path_of(
    const Options& o, const irradcast::ViewClient& client,
    const std::vector<irradcast::CameraKeyframe>& keyframes) {
  using irradcast::CameraPath;
  if (o.camera_path == "orbit") return CameraPath::orbit(client.world().bounds, o.path_period, 0.0);
  if (o.camera_path == "random-walk")
    return CameraPath::random_walk(client.world().bounds, o.path_seed);
  if (!o.camera_path.empty()) return CameraPath::keyframes(keyframes, 0.0);
  return std::nullopt;
}

// The frames composed and what they cost.
struct Frames {
  irradcast::ImageRGB last;
  int count = 0;
  bool converged = false;
  double t_converged = -1.0;
  double compose_s = 0.0, ssao_s = 0.0, reproject_s = 0.0, reused = 0.0;
};

// Streams tiles and composes frames: --frames of them, or with --until-converged the one after
// convergence (or the deadline).
Frames compose_frames(const Options& o, irradcast::ViewClient& client,
                      irradcast::ClientPasses& passes,
                      const std::optional<irradcast::CameraPath>& path,
                      irradcast::CameraPose camera, Clock::time_point start,
                      Clock::time_point deadline) {
  using namespace irradcast;
  client.send_camera(camera);
  std::uint64_t revision = client.static_revision();
  Frames f;
  const auto interval = std::chrono::milliseconds(o.frame_ms);
  for (;;) {
    client.poll(interval);
    if (o.until_converged) {
      auto stats = client.request_stats(std::chrono::seconds(5));
      if (stats && client.all_tiles_received() && stats->queue_depth() == 0 &&
          (stats->engine_idle() || stats->convergence() <= o.converge_at)) {
        f.converged = true;
        f.t_converged = std::chrono::duration<double>(Clock::now() - start).count();
      }
    }
    const bool timed_out = Clock::now() > deadline;
    // --frames: a frame per interval. --until-converged: only the final frame (a headless
    // viewer has no one to show the others to, and composing them would take CPU from the
    // server on a shared machine).
    if (!o.until_converged || f.converged || timed_out) {
      if (path) {
        camera = path->at(static_cast<double>(f.count) * o.path_dt);
        client.send_camera(camera);
      }
      if (client.static_revision() != revision) {  // the history shows the old scene
        passes.reset();
        revision = client.static_revision();
      }
      ClientFrameStats fs;
      f.last = client.compose(camera, o.width, o.height, passes, &fs);
      f.compose_s += fs.total_s;
      f.ssao_s += fs.ssao_s;
      f.reproject_s += fs.reproject_s;
      f.reused += fs.reprojection.reused_fraction();
      ++f.count;
    }
    if (o.until_converged ? f.converged : f.count >= o.frames) break;
    if (timed_out) {
      log::warn("view", "timed out after " + std::to_string(o.timeout_s) + " s");
      break;
    }
  }
  return f;
}

// The summary lines on stdout and, with --json, the JSON report.
void report(const Options& o, const irradcast::ViewClientCounters& c, const Frames& f,
            double t_scene, double t_total, bool on_path) {
  char line[512];
  std::snprintf(line, sizeof line,
                "%s: %d frames, %.1f KB received (scene %s, %.1f KB), %llu tiles applied, "
                "scene ready after %.2f s, %s %.2f s, %u connection(s)",
                o.out.c_str(), f.count, c.bytes_received / 1024.0,
                c.scene_from_cache ? "from cache" : "downloaded", c.scene_bytes_downloaded / 1024.0,
                static_cast<unsigned long long>(c.tiles_applied), t_scene,
                o.until_converged ? (f.converged ? "converged image after" : "NOT converged after")
                                  : "done after",
                o.until_converged && f.converged ? f.t_converged : t_total, c.connections);
  std::printf("%s\n", line);
  const double per_frame = f.count > 0 ? 1e3 / f.count : 0.0;
  std::printf(
      "compose: %.2f ms/frame (ssao %.2f ms, reprojection %.2f ms), SSAO reused on "
      "%.1f%% of the pixels%s\n",
      f.compose_s * per_frame, f.ssao_s * per_frame, f.reproject_s * per_frame,
      f.count > 0 ? 100.0 * f.reused / f.count : 0.0, on_path ? " along the camera path" : "");
  if (o.json.empty()) return;
  nlohmann::json j = {{"out", o.out},
                      {"frames", f.count},
                      {"bytes_received", c.bytes_received},
                      {"scene_bytes_downloaded", c.scene_bytes_downloaded},
                      {"scene_from_cache", c.scene_from_cache},
                      {"tiles_applied", c.tiles_applied},
                      {"connections", c.connections},
                      {"connections_lost", c.connections_lost},
                      {"connect_attempts", c.connect_attempts},
                      {"failovers", c.failovers},
                      {"seconds_to_scene", t_scene},
                      {"converged", f.converged},
                      {"seconds_to_converged", f.t_converged},
                      {"seconds_total", t_total},
                      {"compose_ms_per_frame", f.compose_s * per_frame},
                      {"ssao_ms_per_frame", f.ssao_s * per_frame},
                      {"reproject_ms_per_frame", f.reproject_s * per_frame},
                      {"ssao_reused_fraction", f.count > 0 ? f.reused / f.count : 0.0},
                      {"avatar_messages", c.avatar_messages},
                      {"avatars_shown", c.avatars_shown}};
  std::ofstream out(o.json);
  out << j.dump(2) << "\n";
  if (!out) throw irradcast::Error(o.json + ": cannot write");
}

int run(const Options& o) {
  using namespace irradcast;
  ViewClientOptions vo = client_options(o);
  const ToneMapOptions tm = tone_map_of(o);
  // Everything the flags say is checked before connecting.
  ClientPasses passes(pass_options(o));
  std::vector<CameraKeyframe> keyframes;
  if (!o.camera_path.empty() && o.camera_path != "orbit" && o.camera_path != "random-walk")
    keyframes = load_camera_keyframes(o.camera_path);

  const auto start = Clock::now();
  const auto deadline =
      start + std::chrono::milliseconds(static_cast<long long>(o.timeout_s * 1e3));
  // Connecting and every reconnection keep trying (with back-off) until --timeout.
  vo.deadline = deadline;
  ViewClient client(vo);
  client.connect();
  const double t_scene = std::chrono::duration<double>(Clock::now() - start).count();
  CameraPose camera = default_camera(client.scene(), client.world());
  if (!o.camera.empty()) camera = parse_camera(o.camera, camera);
  const std::optional<CameraPath> path = camera_path_of(o, client, keyframes);
  if (path) camera = path->at(0.0);
  const Frames f = compose_frames(o, client, passes, path, camera, start, deadline);
  if (fs::path(o.out).extension() == ".exr")
    write_exr(o.out, f.last);
  else
    write_png(o.out, f.last.width, f.last.height, tonemap_srgb8(f.last, tm));
  const ViewClientCounters c = client.counters();
  client.close();
  const double t_total = std::chrono::duration<double>(Clock::now() - start).count();
  report(o, c, f, t_scene, t_total, path.has_value());
  return o.until_converged && !f.converged ? 3 : 0;
}

}  // namespace

int main(int argc, char** argv) {
  Options o;
  CLI::App app{
      "irradcast-view: a thin viewer of an irradcast-server. Downloads the scene once "
      "(cached by content hash), keeps its irradiance tiles current, and composes its "
      "own viewpoint into FILE.png or FILE.exr.",
      "irradcast-view"};
  app.option_defaults()->always_capture_default();
  irradcast::tools::add_connect_flags(app, o.connect, o.tls);
  app.add_option("--camera", o.camera,
                 "eye=x,y,z:target=x,y,z:fov=deg[:up=x,y,z] (default: the scene's camera)");
  app.add_option("--width", o.width, "image width")->check(CLI::Range(1, 16384));
  app.add_option("--height", o.height, "image height")->check(CLI::Range(1, 16384));
  app.add_option("--out", o.out, "output image (.png tone-mapped, .exr linear)")->required();
  app.add_option("--frames", o.frames, "frames to compose, one per --frame-ms")
      ->check(CLI::Range(1, 1 << 20));
  app.add_option("--frame-ms", o.frame_ms, "milliseconds of tile streaming between frames")
      ->check(CLI::Range(1, 600000));
  app.add_flag("--until-converged", o.until_converged,
               "compose until every tile is current and the server's lightmaps are converged "
               "(or final); exit 3 if --timeout comes first");
  app.add_option("--converge-at", o.converge_at,
                 "convergence target: the server's mean relative standard error")
      ->check(CLI::PositiveNumber);
  app.add_option("--timeout", o.timeout_s,
                 "give up after this many seconds (connecting and reconnecting included: a "
                 "server that is away is retried with back-off until then)")
      ->check(CLI::PositiveNumber);
  app.add_option("--cache-dir", o.cache_dir,
                 "scene cache (auto = $XDG_CACHE_HOME/irradcast or ~/.cache/irradcast; none)");
  app.add_option("--encoding", o.encoding, "tile encoding: rgb9e5 | half");
  app.add_option("--max-rate", o.max_rate, "byte-rate cap for tiles, bytes/s (0 = none)");
  app.add_option("--name", o.name, "client name in the server's logs");
  app.add_option("--tonemap", o.tonemap, "reinhard | aces | clamp");
  app.add_option("--dynamic-emitters", o.dynamic_emitters,
                 "how dynamic objects get the emissive surfaces' direct light: traced (shadow "
                 "rays, the default) | volume (from the probe volume, as the browser page does; "
                 "docs/DYNAMIC.md)")
      ->check(CLI::IsMember({"traced", "volume"}));
  app.add_flag("--presence", o.presence,
               "show this viewer to the others as an avatar at its camera and draw theirs "
               "(irradcast-server --presence; docs/DYNAMIC.md#presence)");
  app.add_option("--avatars", o.avatars, "with --presence: draw at most this many, the nearest")
      ->check(CLI::Range(1, 256));
  app.add_option("--exposure", o.exposure, "auto (key 0.18) or exposure in stops");
  app.add_option("--json", o.json, "also write a JSON report here");
  app.add_flag("--no-reconnect", o.no_reconnect,
               "fail instead of reconnecting when the connection drops after the first session");
  app.add_option("--log-level", o.log_level, "debug | info | warn | error | off");
  // Client passes (seed 002; docs/CLIENT_PASSES.md).
  app.add_flag("--ssao", o.ssao,
               "screen-space ambient occlusion on the lightmap term (contact shadows finer "
               "than a lightmap texel)");
  app.add_option("--ssao-radius", o.ssao_radius,
                 "SSAO search radius, a fraction of the scene's largest extent, in (0, 1]");
  app.add_option("--ssao-strength", o.ssao_strength,
                 "SSAO strength: visibility = 1 - strength * occlusion, in [0, 10]");
  app.add_flag("--reproject", o.reproject,
               "reverse reprojection of the previous frame: reuse converged SSAO while the "
               "camera moves, recompute disoccluded pixels and refresh tiles (needs --ssao)");
  app.add_option("--reproject-epsilon", o.reproject_epsilon,
                 "disocclusion tolerance |W_t - W_t-1|, a fraction of the scene's largest extent");
  app.add_option("--reproject-frames", o.reproject_frames,
                 "frames (turned SSAO patterns) accumulated before a pixel is reused as is");
  app.add_option("--reproject-refresh", o.reproject_refresh,
                 "fraction of the 64 x 64 tiles recomputed from scratch every frame");
  app.add_option("--reproject-bias", o.reproject_bias,
                 "confidence bias of the accumulation (history keeps >= bias / (1 + bias))");
  app.add_option("--camera-path", o.camera_path,
                 "move the camera, one step of --path-dt per frame: orbit | random-walk | FILE "
                 "(keyframes 't ex ey ez tx ty tz [yfov]'); replaces --camera")
      ->excludes("--camera");
  app.add_option("--path-dt", o.path_dt, "seconds along the camera path per frame");
  app.add_option("--path-period", o.path_period, "seconds per turn of the orbit path");
  app.add_option("--path-seed", o.path_seed, "random-walk path seed");
  return irradcast::tools::parse_and_run(app, argc, argv, [&] { return run(o); });
}
