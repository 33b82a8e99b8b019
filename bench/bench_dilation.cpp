// The lightmaps' gap fill (issue 35 part 1's first step): dilate(), which searches the gutters
// outward from the valid texels on every call, as the engine did for every bounce, against
// DilationPlan::apply, the same fill from a plan made once from the texel kinds (the engine's
// now; the same bits). Every object's map of the scene, in parallel over objects, as
// Engine::to_lightmaps fills them.
//   ./build/bench/irradcast_bench --benchmark_filter=GapFill
#include <benchmark/benchmark.h>

#include <string>
#include <vector>

#include <tbb/parallel_for.h>

#include "dilation_plan.h"
#include "irradcast/common/builtin.h"
#include "irradcast/common/log.h"
#include "irradcast/common/progress.h"
#include "irradcast/engine/prepared_scene.h"

namespace {

using namespace irradcast;

struct Maps {
  PreparedScene scene;
  std::vector<std::vector<glm::vec3>> values;  // every texel set, the gutters filled over
  std::vector<DilationPlan> plans;
};

const Maps& maps_of(const std::string& spec) {
  static std::vector<std::pair<std::string, Maps*>> made;  // kept for the program's life
  for (const auto& [name, m] : made)
    if (name == spec) return *m;
  log::set_level(log::Level::Warn);
  Progress::set_enabled(false);
  auto* m = new Maps{PreparedScene::build(load_scene(spec), PreparedSceneOptions{}), {}, {}};
  for (const TexelGBuffer& g : m->scene.gbuffers()) {
    std::vector<glm::vec3> v(g.size());
    for (std::size_t i = 0; i < v.size(); ++i)
      v[i] = glm::vec3(static_cast<float>(i % 97), 1.0f, static_cast<float>(i % 13));
    m->values.push_back(std::move(v));
    m->plans.emplace_back(g.width, g.height, g.kind);
  }
  made.emplace_back(spec, m);
  return *m;
}

const char* const kScenes[] = {"cornell", "rooms:2", "rooms:8"};

void GapFillSearchingEachTime(benchmark::State& state) {
  const Maps& m = maps_of(kScenes[state.range(0)]);
  const auto& g = m.scene.gbuffers();
  for (auto _ : state) {
    state.PauseTiming();
    std::vector<std::vector<glm::vec3>> v = m.values;
    state.ResumeTiming();
    tbb::parallel_for(std::size_t(0), g.size(),
                      [&](std::size_t o) { dilate(v[o], g[o].width, g[o].height, g[o].kind); });
    benchmark::DoNotOptimize(v.data());
  }
  state.SetLabel(kScenes[state.range(0)]);
}

void GapFillFromPlans(benchmark::State& state) {
  const Maps& m = maps_of(kScenes[state.range(0)]);
  std::size_t filled = 0;
  for (const DilationPlan& p : m.plans) filled += p.target().size();
  for (auto _ : state) {
    state.PauseTiming();
    std::vector<std::vector<glm::vec3>> v = m.values;
    state.ResumeTiming();
    tbb::parallel_for(std::size_t(0), m.plans.size(),
                      [&](std::size_t o) { m.plans[o].apply(v[o]); });
    benchmark::DoNotOptimize(v.data());
  }
  state.counters["filled_texels"] = static_cast<double>(filled);
  state.counters["plan_bytes"] = static_cast<double>(filled * 5);
  state.SetLabel(kScenes[state.range(0)]);
}

}  // namespace

BENCHMARK(GapFillSearchingEachTime)->DenseRange(0, 2)->Unit(benchmark::kMillisecond);
BENCHMARK(GapFillFromPlans)->DenseRange(0, 2)->Unit(benchmark::kMillisecond);
