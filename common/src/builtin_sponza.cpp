// The "sponza" scene spec: the Dabrovic Sponza atrium from the shared sample data
// (dabrovic-sponza/sponza.gltf: 66 k triangles, textured, open to the sky, no lights), lit as
// the outdoor courtyard it is: a daylight sky and a sun through the open roof, and the sample
// data README's view down the long axis as its camera.
#include <cstdlib>
#include <filesystem>
#include <string>
#include <vector>

#include <glm/gtc/matrix_transform.hpp>

#include "irradcast/common/builtin.h"
#include "irradcast/common/error.h"
#include "irradcast/common/gltf.h"

namespace irradcast {
namespace {

namespace fs = std::filesystem;

// The node transform whose local -Z points along `forward` (glTF cameras and directional
// lights both look / shine down their -Z).
glm::mat4 facing(glm::vec3 position, glm::vec3 forward) {
  return glm::inverse(glm::lookAt(position, position + forward, glm::vec3(0.0f, 1.0f, 0.0f)));
}

}  // namespace

std::string find_sample_data(const std::string& relative) {
  std::vector<std::string> tried;
  if (const char* env = std::getenv("IRRADCAST_TESTDATA"); env != nullptr && *env != '\0')
    tried.push_back(env);
  tried.push_back("../shared/testdata");
  tried.push_back("shared/testdata");
  std::string where;
  for (const std::string& dir : tried) {
    std::error_code ec;
    if (fs::is_regular_file(fs::path(dir) / relative, ec))
      return (fs::path(dir) / relative).string();
    where += (where.empty() ? "" : ", ") + dir;
  }
  throw Error("sample data '" + relative + "' not found under " + where +
              " (set IRRADCAST_TESTDATA to the folder that holds it)");
}

Scene make_sponza(const std::string& scene_root) {
  Scene s = load_gltf(find_sample_data("dabrovic-sponza/sponza.gltf"), nullptr, scene_root);
  s.name = "sponza";
  // A clear day: sky radiance giving ~1 W/m^2 on open ground (pi x 0.32), a sun of 6 W/m^2.
  s.sky.color = glm::vec3(0.25f, 0.33f, 0.45f);
  Light sun;
  sun.name = "sun";
  sun.type = Light::Type::Directional;
  sun.color = glm::vec3(1.0f, 0.92f, 0.8f);
  sun.intensity = 6.0f;
  s.lights.push_back(sun);
  Node sun_node;
  sun_node.name = "sun";
  sun_node.light = static_cast<int>(s.lights.size() - 1);
  sun_node.local =
      facing(glm::vec3(0.0f, 30.0f, 0.0f), glm::normalize(glm::vec3(0.35f, -1.0f, 0.22f)));
  s.add_node(sun_node);
  Camera cam;
  cam.name = "sponza_view";
  cam.yfov = glm::radians(75.0f);
  s.cameras.push_back(cam);
  Node cam_node;
  cam_node.name = "view";
  cam_node.camera = static_cast<int>(s.cameras.size() - 1);
  const glm::vec3 eye(-14.0f, 2.0f, 0.0f), target(10.0f, 5.0f, 0.0f);
  cam_node.local = facing(eye, glm::normalize(target - eye));
  s.add_node(cam_node);
  return s;
}

}  // namespace irradcast
