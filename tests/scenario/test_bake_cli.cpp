#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <array>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "cli.h"
#include "irradcast/common/image.h"

namespace irradcast::test_bake_cli {

namespace fs = std::filesystem;

namespace {

using Result = irradcast::test::CliResult;

Result run_bake(const std::string& args) {
  return irradcast::test::run_cli(IRRADCAST_BAKE_EXE, args);
}

fs::path temp_dir(const std::string& name) {
  fs::path d = fs::temp_directory_path() / ("irradcast_cli_" + name);
  fs::remove_all(d);
  return d;
}

}  // namespace

TEST(BakeCli, WritesEveryFileAndAReport) {
  fs::path out = temp_dir("cornell");
  Result r = run_bake("--scene cornell --out " + out.string() +
                      " --reference 8 --width 48 --height 40 --updates 2"
                      " --texels-per-scene 48 --quiet");
  ASSERT_EQ(r.status, 0) << r.output;
  for (const char* f : {"view.exr", "view.png", "reference.exr", "reference.png",
                        "view_vs_reference.png", "report.json"})
    EXPECT_TRUE(fs::exists(out / f)) << f;
  int lightmaps = 0;
  for (const auto& e : fs::directory_iterator(out / "lightmaps"))
    lightmaps += e.path().extension() == ".exr";
  EXPECT_EQ(lightmaps, 8);  // one per Cornell box object
  irradcast::ImageRGB view = irradcast::read_exr((out / "view.exr").string());
  EXPECT_EQ(view.width, 48);
  EXPECT_EQ(view.height, 40);
  std::ifstream f(out / "report.json");
  nlohmann::json report = nlohmann::json::parse(f);
  EXPECT_EQ(report["scene"]["objects"], 8);
  EXPECT_GT(report["atlas"]["texels"].get<double>(), 0.0);
  EXPECT_GT(report["rays"]["reference"].get<double>(), 48.0 * 40 * 8);
  EXPECT_GT(report["rays_per_s"]["lightmaps"].get<double>(), 0.0);
  for (const char* stage : {"load", "atlas", "gbuffer", "lightmaps", "compose", "reference"})
    EXPECT_TRUE(report["timings_s"].contains(stage)) << stage;
  double rel = report["error"]["rel_mse"].get<double>();
  EXPECT_GT(rel, 0.0);
  EXPECT_LT(rel, 1.0);
  // The defaults as given, and what they gave this 0.56 m box: the fractions (the caps in
  // metres do not bind), a quarter and 0.3 of its largest extent.
  EXPECT_EQ(report["engine"]["cell_size"], "0.25:1m");
  EXPECT_EQ(report["engine"]["tracing_range"], "0.3:1.2m");
  const double cell = report["engine"]["probes"]["cell_m"].get<double>();
  const double range = report["engine"]["probes"]["tracing_range_m"].get<double>();
  EXPECT_NEAR(cell, 0.25 * 0.5592, 0.005);
  EXPECT_NEAR(range / cell, 0.3 / 0.25, 1e-5);
  fs::remove_all(out);
}

TEST(BakeCli, ExportsTheSceneAsGltf) {
  fs::path out = temp_dir("export");
  fs::create_directories(out);
  Result r = run_bake("--scene cornell --export-gltf " + (out / "cb.glb").string());
  ASSERT_EQ(r.status, 0) << r.output;
  EXPECT_GT(fs::file_size(out / "cb.glb"), 1000u);
  // The exported file loads back as a scene.
  Result again = run_bake("--scene " + (out / "cb.glb").string() + " --export-gltf " +
                          (out / "again.gltf").string());
  EXPECT_EQ(again.status, 0) << again.output;
  fs::remove_all(out);
}

TEST(BakeCli, BadInputGetsAClearErrorAndNonZeroExit) {
  struct Case {
    std::string args, expect;
  };
  for (const Case& c : std::vector<Case>{
           {"--scene /nonexistent/scene.gltf --out /tmp/x", "/nonexistent/scene.gltf"},
           {"--scene rooms:abc --out /tmp/x", "rooms:abc"},
           {"--scene cornell --out /tmp/x --camera eye=1,2", "camera spec"},
           {"--scene cornell --out /tmp/x --tonemap sepia", "sepia"},
           {"--scene cornell --width 0 --out /tmp/x", "--width"},
           {"--bogus-flag", "bogus"},
           {"--scene cornell", "--out"},
           {"--scene cornell --out /tmp/x --method photon-map", "photon-map"},
           {"--scene cornell --out /tmp/x --method vpl --vpl-paths 8", "vpl_paths"},
           {"--scene cornell --out /tmp/x --method irradiance-cache --ic-accuracy 0",
            "ic_accuracy"},
       }) {
    Result r = run_bake(c.args);
    EXPECT_NE(r.status, 0) << c.args;
    EXPECT_NE(r.output.find(c.expect), std::string::npos) << c.args << "\n" << r.output;
  }
}

// Every method of docs/METHODS.md bakes from the command line and says which it ran.
TEST(BakeCli, EveryMethodBakesAndNamesItself) {
  for (const char* method : {"cells", "vpl", "irradiance-cache", "reference"}) {
    fs::path out = temp_dir(std::string("method_") + method);
    Result r = run_bake(std::string("--scene cornell --out ") + out.string() +
                        " --width 24 --height 24 --updates 2 --lightmap-spp 2"
                        " --texels-per-scene 24 --quiet --method " +
                        method);
    ASSERT_EQ(r.status, 0) << method << "\n" << r.output;
    std::ifstream f(out / "report.json");
    const nlohmann::json report = nlohmann::json::parse(f);
    EXPECT_EQ(report["settings"]["method"], method) << report.dump();
    EXPECT_GT(report["rays"]["lightmaps"].get<double>(), 0.0) << method;
    fs::remove_all(out);
  }
}

TEST(BakeCli, HelpListsTheOptions) {
  Result r = run_bake("--help");
  EXPECT_EQ(r.status, 0);
  for (const char* opt :
       {"--scene", "--out", "--reference", "--camera", "--export-gltf", "--width"})
    EXPECT_NE(r.output.find(opt), std::string::npos) << opt;
}

// --sky (a colour or an EXR map), --sky-strength and --sun light a scene without lights, the
// report records them, and bad values fail naming the option.
TEST(BakeCli, SkyAndSunLightASceneFromTheCommandLine) {
  fs::path out = temp_dir("sky");
  fs::create_directories(out);
  irradcast::ImageRGB map(8, 4);
  for (glm::vec3& p : map.pixels) p = glm::vec3(0.5f, 0.7f, 1.0f);
  const std::string exr = (out / "sky.exr").string();
  irradcast::write_exr(exr, map);
  // The Cornell box keeps its emitter; the sky and the sun come on top (what they light is
  // tests/test_sky_engine.cpp's part): the log line and the report are what this checks.
  for (const std::string& sky : {std::string("0.2,0.3,0.5"), exr}) {
    fs::path dir = out / (sky == exr ? "map" : "colour");
    Result r = run_bake("--scene cornell --out " + dir.string() + " --sky " + sky +
                        " --sky-strength 2 --sun 0.3,-1,0.2,5 --width 16 --height 16"
                        " --updates 1 --texels-per-scene 16");
    ASSERT_EQ(r.status, 0) << r.output;
    EXPECT_NE(r.output.find("lit by"), std::string::npos) << r.output;
    EXPECT_NE(r.output.find("sun travelling"), std::string::npos) << r.output;
    std::ifstream f(dir / "report.json");
    const nlohmann::json report = nlohmann::json::parse(f);
    const nlohmann::json& scene = report["scene"];
    EXPECT_EQ(scene["sky"]["strength"], 2.0) << scene.dump();
    if (sky == exr) {
      EXPECT_EQ(scene["sky"]["file"], exr) << scene.dump();
      EXPECT_EQ(scene["sky"]["width"], 8);
    } else {
      EXPECT_NEAR(scene["sky"]["color"][2].get<double>(), 0.5, 1e-6) << scene.dump();
    }
    EXPECT_NEAR(scene["sun"]["irradiance"].get<double>(), 5.0, 1e-6) << scene.dump();
    EXPECT_NEAR(scene["sun"]["direction"][1].get<double>(), -1.0 / std::sqrt(1.13), 1e-5);
    EXPECT_EQ(scene["punctual_lights"], 1);
  }
  Result plain = run_bake("--scene cornell --out " + (out / "plain").string() +
                          " --width 8 --height 8 --updates 1 --texels-per-scene 16");
  ASSERT_EQ(plain.status, 0) << plain.output;
  std::ifstream f(out / "plain" / "report.json");
  const nlohmann::json report = nlohmann::json::parse(f);
  EXPECT_TRUE(report["scene"]["sky"].is_null());
  EXPECT_TRUE(report["scene"]["sun"].is_null());
  struct Case {
    std::string args, expect;
  };
  for (const Case& c : std::vector<Case>{
           {"--sky 1,2", "--sky"},
           {"--sky red", "--sky"},
           {"--sky 1,-1,1", "--sky"},
           {"--sky /nonexistent/sky.exr", "--sky"},
           {"--sky 1,1,1 --sky-strength -2", "--sky-strength"},
           {"--sky-strength 2", "--sky-strength"},
           {"--sun 0,0,0,1", "--sun"},
           {"--sun 0,-1,0", "--sun"},
           {"--sun 0,-1,0,-5", "--sun"},
       }) {
    Result r = run_bake("--scene cornell --out " + (out / "bad").string() + " " + c.args);
    EXPECT_NE(r.status, 0) << c.args;
    EXPECT_NE(r.output.find(c.expect), std::string::npos) << c.args << "\n" << r.output;
  }
  Result help = run_bake("--help");
  for (const char* opt : {"--sky", "--sky-strength", "--sun"})
    EXPECT_NE(help.output.find(opt), std::string::npos) << opt;
  fs::remove_all(out);
}

}  // namespace irradcast::test_bake_cli
