// load_gltf on deep node hierarchies (issue 16): a chain of N nodes, each the only child of the
// one before, the last with a triangle. The loader's cycle check used to walk every parent
// chain (quadratic: ~50 s for 100 000 nodes); it is linear now.
//   ./build/bench/irradcast_bench --benchmark_filter=GltfChain
#include <benchmark/benchmark.h>

#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <string>

#include <nlohmann/json.hpp>

#include "irradcast/common/gltf.h"
#include "irradcast/common/log.h"

namespace {

std::string chain_gltf(int n) {
  using nlohmann::json;
  // One triangle (0,0,0) (1,0,0) (0,1,0) as a data URI (36 bytes of floats, base64).
  const std::string triangle =
      "data:application/octet-stream;base64,AAAAAAAAAAAAAAAAAACAPwAAAAAAAAAAAAAAAAAAgD8AAAAA";
  json nodes = json::array();
  for (int i = 0; i < n; ++i) {
    json node = {{"translation", {0.001, 0, 0}}};
    if (i + 1 < n) node["children"] = {i + 1};
    if (i + 1 == n) node["mesh"] = 0;
    nodes.push_back(std::move(node));
  }
  json g = {{"asset", {{"version", "2.0"}}},
            {"buffers", {{{"byteLength", 36}, {"uri", triangle}}}},
            {"bufferViews", {{{"buffer", 0}, {"byteLength", 36}}}},
            {"accessors",
             {{{"bufferView", 0},
               {"componentType", 5126},
               {"count", 3},
               {"type", "VEC3"},
               {"min", {0, 0, 0}},
               {"max", {1, 1, 0}}}}},
            {"meshes", {{{"primitives", {{{"attributes", {{"POSITION", 0}}}}}}}}},
            {"nodes", std::move(nodes)},
            {"scenes", {{{"nodes", {0}}}}},
            {"scene", 0}};
  return g.dump();
}

void GltfChain(benchmark::State& state) {
  irradcast::log::set_level(irradcast::log::Level::Warn);
  const int n = static_cast<int>(state.range(0));
  const std::filesystem::path path =
      std::filesystem::temp_directory_path() /
      ("irradcast_bench_chain_" + std::to_string(n) + "_" + std::to_string(::getpid()) + ".gltf");
  std::ofstream(path) << chain_gltf(n);
  for (auto _ : state) {
    const irradcast::Scene scene = irradcast::load_gltf(path.string());
    benchmark::DoNotOptimize(scene.nodes.data());
  }
  state.counters["nodes"] = n;
  std::filesystem::remove(path);
}

BENCHMARK(GltfChain)->Arg(100000)->Arg(200000)->Unit(benchmark::kMillisecond)->Iterations(1);

}  // namespace
