// irradcast-bench-sky: what a sky and a sun cost the engine. The Dabrovic Sponza (the "sponza"
// scene spec, shared sample data) is lit four ways: sky + sun (the spec's own light), sky only,
// sun only, and emitters only (no sky, no sun, four emissive panels under the open roof). Each
// gets its own engine (default parameters, Embree backend); after a warm-up update, rounds of
// one timed update per variant interleave, so every variant sees the same machine state. Reports
// the median time per update, the rays per update (direct pass and all), and each variant's
// time as a ratio to emitters only, as a table and JSON (docs/BENCHMARKS.md, "Sky and sun").
//   irradcast-bench-sky --rounds 5 --out out/sky
#include "irradcast/common/cli.h"

#include <cstdio>
#include <memory>
#include <string>
#include <vector>

#include "bench_options.h"
#include "bench_scene.h"
#include "bench_util.h"
#include "embree_backend.h"
#include "irradcast/common/builtin.h"
#include "irradcast/engine/engine.h"

using namespace irradcast;
using namespace irradcast::bench;

namespace {

// Four emissive panels facing down at 13 m, inside the courtyard's opening (emission chosen so
// the floor gets light of the order of the sun's).
void add_panels(Scene& s) {
  Material m;
  m.name = "panel";
  m.base_color = glm::vec3(0.0f);
  m.emissive = glm::vec3(1.0f, 0.95f, 0.9f);
  m.emissive_strength = 40.0f;
  s.materials.push_back(m);
  const auto mat = static_cast<std::uint32_t>(s.materials.size() - 1);
  Mesh mesh;
  mesh.name = "panels";
  for (float x : {-9.0f, -3.0f, 3.0f, 9.0f}) {
    const auto b = static_cast<std::uint32_t>(mesh.positions.size());
    const float y = 13.0f, h = 1.0f;
    // Counter-clockwise seen from below: the front side faces -Y.
    mesh.positions.insert(mesh.positions.end(),
                          {{x - h, y, -h}, {x + h, y, -h}, {x + h, y, h}, {x - h, y, h}});
    mesh.triangles.push_back({b, b + 1, b + 2});
    mesh.triangles.push_back({b, b + 2, b + 3});
    mesh.triangle_material.insert(mesh.triangle_material.end(), {mat, mat});
  }
  s.meshes.push_back(mesh);
  Node n;
  n.name = "panels";
  n.mesh = static_cast<int>(s.meshes.size() - 1);
  s.add_node(n);
}

void remove_sun(Scene& s) {
  for (Node& n : s.nodes)
    if (n.light >= 0 && s.lights[n.light].name == "sun") n.light = -1;
}

struct Variant {
  std::string label;
  std::unique_ptr<PreparedScene> prepared;
  std::unique_ptr<Engine> engine;
  std::vector<double> seconds;
  UpdateStats last;
};

Variant make_variant(const std::string& label, Scene scene, float texels) {
  Variant v;
  v.label = label;
  v.prepared = std::make_unique<PreparedScene>(prepare(std::move(scene), density(texels)));
  const PreparedScene& p = *v.prepared;
  v.engine = std::make_unique<Engine>(p.world(), p.atlas(), p.gbuffers(), p.rays(),
                                      std::make_unique<EmbreeBackend>(p.rays(), p.lights()),
                                      EngineParams{}, &p.lights());
  v.engine->update();  // warm-up: caches, first-touch of the running means
  return v;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"irradcast-bench-sky: engine update time on Sponza with a sky and a sun"};
  int rounds = 5, threads = 0;
  float texels = 256.0f;
  std::string out_dir = "docs/images", json_path;
  app.add_option("--rounds", rounds, "timed updates per variant (interleaved)")
      ->check(CLI::Range(1, 1000));
  add_texels_per_scene(app, texels)->check(CLI::Range(16.0f, 4096.0f));
  add_threads(app, threads);
  app.add_option("--out", out_dir, "output directory");
  app.add_option("--json", json_path, "JSON report (default OUT/sky_bench.json)");
  CLI11_PARSE(app, argc, argv);
  return run_guarded("irradcast-bench-sky: error: ", [&] {
    auto limit = start_run(threads, out_dir, json_path, "sky_bench.json");
    const Scene base = make_sponza();
    Scene sky_only = base, sun_only = base, emitters = base;
    remove_sun(sky_only);
    sun_only.sky = Sky{};
    emitters.sky = Sky{};
    remove_sun(emitters);
    add_panels(emitters);
    std::vector<Variant> variants;
    variants.push_back(make_variant("emitters", std::move(emitters), texels));
    variants.push_back(make_variant("sky + sun", base, texels));
    variants.push_back(make_variant("sky", std::move(sky_only), texels));
    variants.push_back(make_variant("sun", std::move(sun_only), texels));
    for (int r = 0; r < rounds; ++r)
      for (Variant& v : variants) {
        const Stopwatch t;
        v.last = v.engine->update();
        v.seconds.push_back(t.seconds());
      }
    const double base_s = median(variants[0].seconds);
    std::printf("\nSponza, %zu texels, %d interleaved rounds, %d threads\n",
                variants[0].engine->texel_count(), rounds, tbb_threads());
    std::printf("%-10s %12s %14s %14s %10s\n", "light", "ms/update", "direct rays", "all rays",
                "vs emit.");
    json rows = json::array();
    for (const Variant& v : variants) {
      const double s = median(v.seconds);
      std::printf("%-10s %12.1f %14llu %14llu %10.2f\n", v.label.c_str(), s * 1e3,
                  static_cast<unsigned long long>(v.last.direct.rays),
                  static_cast<unsigned long long>(v.last.total_rays()), s / base_s);
      rows.push_back({{"light", v.label},
                      {"median_ms", s * 1e3},
                      {"direct_rays", v.last.direct.rays},
                      {"total_rays", v.last.total_rays()},
                      {"ratio_to_emitters", s / base_s}});
    }
    json report = {{"bench", "irradcast-bench-sky"},
                   {"scene", "sponza"},
                   {"rounds", rounds},
                   {"texels", variants[0].engine->texel_count()},
                   {"machine", machine_json(tbb_threads())},
                   {"variants", rows}};
    write_json(json_path, report);
    std::printf("wrote %s\n", json_path.c_str());
    return 0;
  });
}
