// irradcast-bench-dynamic: what dynamic objects cost (issue 32 part 6, docs/BENCHMARKS.md), side by
// side in one run:
//   - a viewer's frame time with 0, 16 and 256 dynamic spheres (--counts), plain compose() and
//     the client passes (SSAO + reprojection), the counts interleaved frame by frame so that load
//     from other processes hits them alike; medians and the ratio to the frame without spheres;
//   - the probe volume's bytes per update (the message with the layout, and a later version)
//     against the scene's lightmaps' bytes (every tile, RGB9E5 + zstd, as a viewer downloads it).
// The engine's lightmaps first (--updates updates); dynamic objects change nothing of them.
#include <tbb/global_control.h>
#include <nlohmann/json.hpp>
#include "irradcast/common/cli.h"

#include <atomic>
#include <cmath>
#include <cstdio>
#include <memory>
#include <string>
#include <vector>

#include "bench_options.h"
#include "bench_util.h"
#include "embree_backend.h"
#include "irradcast/client/client_passes.h"
#include "irradcast/common/builtin.h"
#include "irradcast/common/camera.h"
#include "irradcast/common/compositor.h"
#include "irradcast/common/dynamic_view.h"
#include "irradcast/common/error.h"
#include "irradcast/common/progress.h"
#include "irradcast/common/shapes.h"
#include "irradcast/engine/engine.h"
#include "irradcast/engine/irradiance_volume_builder.h"
#include "irradcast/engine/prepared_scene.h"
#include "irradcast/wire/probe_volume_message.h"
#include "irradcast/wire/tile_codec.h"

using namespace irradcast;
using namespace irradcast::bench;

namespace {

struct Options {
  std::string scene = "sponza";
  float texels = 160.0f;
  int updates = 4;
  std::string counts = "0,16,256";
  int frames = 20;
  int width = 640, height = 360;
  int threads = 0;
  std::string out = "out/bench-dynamic";
};

// `n` white spheres on a grid over the middle of the static scene's floor area, radius 1/60 of
// the largest extent, their centres one radius above the lowest 10 % of the bounds.
Scene with_spheres(Scene s, const Bounds& b, int n) {
  if (n == 0) return s;
  Material m;
  m.base_color = glm::vec3(0.8f);
  s.materials.push_back(m);
  const auto mat = static_cast<std::uint32_t>(s.materials.size() - 1);
  const float r = b.max_extent() / 60.0f;
  s.meshes.push_back(uv_sphere("sphere", r, 16, 32, mat));
  const int mesh = static_cast<int>(s.meshes.size() - 1);
  const int side = static_cast<int>(std::ceil(std::sqrt(float(n))));
  const glm::vec3 lo = b.lo + 0.25f * b.extent(), hi = b.hi - 0.25f * b.extent();
  for (int i = 0; i < n; ++i) {
    Node node;
    node.name = "sphere" + std::to_string(i);
    node.mesh = mesh;
    node.dynamic = true;
    const float u = (float(i % side) + 0.5f) / float(side),
                v = (float(i / side) + 0.5f) / float(side);
    node.local[3] = glm::vec4(lo.x + u * (hi.x - lo.x), b.lo.y + 0.1f * b.extent().y + r,
                              lo.z + v * (hi.z - lo.z), 1.0f);
    s.add_node(std::move(node));
  }
  return s;
}

// Bytes of every tile of the lightmaps (ts x ts, RGB9E5 + zstd).
std::size_t all_tile_bytes(const std::vector<Lightmap>& maps, int ts) {
  std::size_t bytes = 0;
  for (const Lightmap& m : maps)
    for (int ty = 0; ty < wire::tiles_along(m.height, ts); ++ty)
      for (int tx = 0; tx < wire::tiles_along(m.width, ts); ++tx)
        bytes += wire::encode_tile(m, wire::tile_rect(m.width, m.height, ts, tx, ty),
                                   wire::TILE_RGB9E5_ZSTD)
                     .size();
  return bytes;
}

// The lightmaps indexed like each scene's objects: the static ones first, then the dynamic
// spheres' (no texels).
std::vector<std::vector<Lightmap>> maps_per_scene(
    const std::vector<std::unique_ptr<PreparedScene>>& scenes, const std::vector<Lightmap>& maps) {
  std::vector<std::vector<Lightmap>> scene_maps;
  for (const auto& s : scenes) {
    std::vector<Lightmap> m;
    for (std::size_t k = 0; k < s->atlas().objects.size(); ++k) {
      const ObjectLightmap& a = s->atlas().objects[k];
      if (k < maps.size() && (a.width != maps[k].width || a.height != maps[k].height))
        throw Error("the scenes' static objects differ");
      m.push_back(k < maps.size() ? maps[k] : Lightmap(a.width, a.height));
    }
    scene_maps.push_back(std::move(m));
  }
  return scene_maps;
}

// Per count, each frame's milliseconds three ways, and the pixels the spheres cover.
struct FrameTimes {
  std::vector<std::vector<double>> plain, full, volume_only;
  std::vector<std::size_t> covered;
};

// Frame times, interleaved by count: compose() as irradcast-view draws (the emitters' direct
// light traced: 8 shadow rays per dynamic pixel where the scene has emitters), with the client
// passes, and as the browser page does (from the volume).
FrameTimes time_frames(const Options& o, const std::vector<std::unique_ptr<PreparedScene>>& scenes,
                       const std::vector<Lightmap>& maps, const IrradianceVolume& v) {
  const PreparedScene& first = *scenes.front();
  const CameraPose camera = default_camera(first.scene(), first.world());
  std::vector<std::unique_ptr<RayScene>> dynamic;
  std::vector<ClientPasses> passes;
  for (const auto& s : scenes) {
    dynamic.push_back(std::make_unique<RayScene>(s->world(), true, RaySceneContent::Dynamic));
    ClientPassOptions cpo;
    cpo.ssao = cpo.reproject = true;
    passes.emplace_back(cpo);
  }
  const std::vector<std::vector<Lightmap>> scene_maps = maps_per_scene(scenes, maps);
  const std::size_t n = scenes.size();
  FrameTimes ft{std::vector<std::vector<double>>(n), std::vector<std::vector<double>>(n),
                std::vector<std::vector<double>>(n), std::vector<std::size_t>(n, 0)};
  for (int f = 0; f < o.frames; ++f)
    for (std::size_t i = 0; i < n; ++i) {
      const PreparedScene& s = *scenes[i];
      const DynamicView view{dynamic[i].get(), &v, &s.lights()};
      Stopwatch t;
      compose(s.world(), s.rays(), s.atlas(), scene_maps[i], camera, o.width, o.height, nullptr,
              &view);
      ft.plain[i].push_back(1e3 * t.seconds());
      const DynamicView page{dynamic[i].get(), &v, nullptr};
      t.restart();
      compose(s.world(), s.rays(), s.atlas(), scene_maps[i], camera, o.width, o.height, nullptr,
              &page);
      ft.volume_only[i].push_back(1e3 * t.seconds());
      t.restart();
      passes[i].compose(s.world(), s.rays(), s.atlas(), scene_maps[i], camera, o.width, o.height,
                        nullptr, &view);
      ft.full[i].push_back(1e3 * t.seconds());
      if (f == 0) {
        std::atomic<std::size_t> covered{0};
        trace_dynamic(s.world(), s.rays(), view, camera, o.width, o.height,
                      [&](const DynamicPixel&) { ++covered; });
        ft.covered[i] = covered;
      }
    }
  return ft;
}

int run(const Options& o) {
  std::string json_path;
  const auto threads = start_run(o.threads, o.out, json_path, "dynamic.json");
  const std::vector<int> counts = parse_ints(o.counts);
  PreparedSceneOptions po;
  po.atlas.texels_per_scene = o.texels;
  const Scene base = load_scene(o.scene);
  const Bounds bounds = World::build(base).bounds;
  // One prepared scene per count (the static part is the same in each: lightmaps from the first).
  std::vector<std::unique_ptr<PreparedScene>> scenes;
  for (int n : counts)
    scenes.push_back(
        std::make_unique<PreparedScene>(PreparedScene::build(with_spheres(base, bounds, n), po)));
  const PreparedScene& first = *scenes.front();
  Engine engine(first.world(), first.atlas(), first.gbuffers(), first.rays(),
                std::make_unique<EmbreeBackend>(first.rays(), first.lights()), EngineParams{},
                &first.lights());
  Stopwatch sw;
  for (int u = 0; u < o.updates; ++u) engine.update();
  const std::vector<Lightmap> maps = engine.lightmaps();
  std::printf("%s: %zu texels, %d updates in %.1f s\n", o.scene.c_str(),
              first.atlas().texel_count(), o.updates, sw.seconds());
  sw.restart();
  IrradianceVolumeBuilder volume(first.world(), first.rays(), first.atlas());
  const double place_s = sw.seconds();
  sw.restart();
  volume.refine(maps);
  const double refine_s = sw.seconds();
  for (int r = 1; r < 32; ++r) volume.refine(maps);
  const IrradianceVolume& v = volume.volume();

  // Bytes: the volume's messages against every tile of the lightmaps.
  const std::size_t with_layout = wire::probe_volume_to_proto(v, 1, 1, true).ByteSizeLong();
  const std::size_t sh_only = wire::probe_volume_to_proto(v, 1, 2, false).ByteSizeLong();
  const int ts = 32;
  const std::size_t tile_bytes = all_tile_bytes(maps, ts);
  std::printf("probe volume: %zu probes (spacing %.2f), placed in %.2f s, %.2f s per refine\n",
              v.probe_count(), v.grid.spacing, place_s, refine_s);
  std::printf(
      "bytes: volume %zu with its layout, %zu per later version; lightmaps %zu (every "
      "tile of %d x %d, RGB9E5 + zstd): a version is %.2f %% of the lightmaps\n",
      with_layout, sh_only, tile_bytes, ts, ts, 100.0 * double(sh_only) / double(tile_bytes));

  const FrameTimes ft = time_frames(o, scenes, maps, v);
  const auto& [plain, full, volume_only, covered] = ft;
  json j = {{"scene", o.scene},
            {"machine", machine_json(tbb_threads())},
            {"width", o.width},
            {"height", o.height},
            {"frames", o.frames},
            {"probes", v.probe_count()},
            {"spacing", v.grid.spacing},
            {"volume_bytes_with_layout", with_layout},
            {"volume_bytes_per_version", sh_only},
            {"lightmap_bytes", tile_bytes},
            {"refine_s", refine_s},
            {"place_s", place_s}};
  std::printf("%-8s %10s %12s %8s %16s %8s %15s\n", "objects", "px covered", "compose ms", "ratio",
              "ssao+reproj ms", "ratio", "volume-only ms");
  for (std::size_t i = 0; i < counts.size(); ++i) {
    const double a = median(plain[i]), b = median(full[i]), c = median(volume_only[i]);
    std::printf("%-8d %10zu %12.2f %8.2f %16.2f %8.2f %15.2f\n", counts[i], covered[i], a,
                a / median(plain[0]), b, b / median(full[0]), c);
    j["frames_by_count"].push_back({{"objects", counts[i]},
                                    {"pixels_covered", covered[i]},
                                    {"compose_ms", a},
                                    {"compose_ratio", a / median(plain[0])},
                                    {"compose_volume_only_ms", c},
                                    {"passes_ms", b},
                                    {"passes_ratio", b / median(full[0])}});
  }
  write_json(json_path, j);
  std::printf("wrote %s\n", json_path.c_str());
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  Options o;
  CLI::App app{
      "irradcast-bench-dynamic: a viewer's frame time with dynamic objects, and the probe "
      "volume's bytes against the lightmaps'"};
  app.add_option("--scene", o.scene, "scene spec (default sponza)");
  add_texels_per_scene(app, o.texels);
  app.add_option("--updates", o.updates, "engine updates before measuring");
  app.add_option("--counts", o.counts, "dynamic sphere counts, comma-separated (first: baseline)");
  app.add_option("--frames", o.frames, "frames per count");
  app.add_option("--width", o.width, "image width");
  app.add_option("--height", o.height, "image height");
  app.add_option("--threads", o.threads, "TBB threads (0: all cores)");
  app.add_option("--out", o.out, "output directory");
  CLI11_PARSE(app, argc, argv);
  return run_guarded("irradcast-bench-dynamic: ", [&] { return run(o); });
}
