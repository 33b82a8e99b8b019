// The Cornell box from the published measurements (Cornell University Program of Computer
// Graphics, "Cornell Box Data"), in metres: the five walls, the two blocks, the ceiling light
// (a hole in the ceiling holds it, so the two never overlap) and the standard camera
// (eye (278, 273, -800) mm looking +z, 35 mm focal length on a 25 mm film: 39.3 degrees).
// RGB reflectances and the light's radiance follow the widely used RGB conversion of the
// measured spectra (white 0.725/0.71/0.68, red 0.63/0.065/0.05, green 0.14/0.45/0.091,
// light radiance 17/12/4).
#include <cmath>
#include <initializer_list>

#include "irradcast/common/builtin.h"

namespace irradcast {
namespace {

constexpr float kMm = 0.001f;

// Adds the quad a-b-c-d (in mm) as two triangles wound so that their normal points along `toward`.
void add_quad(Mesh& mesh, glm::vec3 a, glm::vec3 b, glm::vec3 c, glm::vec3 d, glm::vec3 toward) {
  glm::vec3 n = glm::normalize(glm::cross(b - a, c - a));
  if (glm::dot(n, toward) < 0.0f) {
    std::swap(b, d);
    n = -n;
  }
  auto base = static_cast<std::uint32_t>(mesh.positions.size());
  for (glm::vec3 p : {a, b, c, d}) {
    mesh.positions.push_back(p * kMm);
    mesh.normals.push_back(n);
  }
  mesh.triangles.push_back({base, base + 1, base + 2});
  mesh.triangles.push_back({base, base + 2, base + 3});
  mesh.triangle_material.push_back(0);
  mesh.triangle_material.push_back(0);
}

// A block given by its top quad (4 corners at height h, in order) standing on the floor.
void add_block(Mesh& mesh, std::initializer_list<glm::vec2> top_xz, float h) {
  std::vector<glm::vec2> c(top_xz);
  glm::vec2 centre(0.0f);
  for (glm::vec2 p : c) centre += p * 0.25f;
  add_quad(mesh, {c[0].x, h, c[0].y}, {c[1].x, h, c[1].y}, {c[2].x, h, c[2].y}, {c[3].x, h, c[3].y},
           {0, 1, 0});
  for (int i = 0; i < 4; ++i) {
    glm::vec2 p = c[i], q = c[(i + 1) % 4];
    glm::vec2 mid = 0.5f * (p + q);
    glm::vec3 out(mid.x - centre.x, 0.0f, mid.y - centre.y);
    add_quad(mesh, {p.x, 0, p.y}, {q.x, 0, q.y}, {q.x, h, q.y}, {p.x, h, p.y}, out);
  }
}

}  // namespace

Scene make_cornell_box() {
  Scene s;
  s.name = "cornell";
  auto material = [&](const char* name, glm::vec3 albedo, glm::vec3 emission = glm::vec3(0.0f)) {
    Material m;
    m.name = name;
    m.base_color = albedo;
    m.emissive = emission;
    s.materials.push_back(m);
    return static_cast<std::uint32_t>(s.materials.size() - 1);
  };
  std::uint32_t white = material("white", {0.725f, 0.71f, 0.68f});
  std::uint32_t red = material("red", {0.63f, 0.065f, 0.05f});
  std::uint32_t green = material("green", {0.14f, 0.45f, 0.091f});
  std::uint32_t light = material("light", {0.78f, 0.78f, 0.78f}, {17.0f, 12.0f, 4.0f});

  auto object = [&](const char* name, std::uint32_t mat, auto build) {
    Mesh mesh;
    mesh.name = name;
    build(mesh);
    for (auto& m : mesh.triangle_material) m = mat;
    s.meshes.push_back(std::move(mesh));
    Node node;
    node.name = name;
    node.mesh = static_cast<int>(s.meshes.size() - 1);
    s.add_node(node);
  };
  const glm::vec3 inward_x(-1, 0, 0), up(0, 1, 0), down(0, -1, 0);
  object("floor", white, [&](Mesh& m) {
    add_quad(m, {552.8f, 0, 0}, {0, 0, 0}, {0, 0, 559.2f}, {549.6f, 0, 559.2f}, up);
  });
  object("ceiling", white, [&](Mesh& m) {
    // The ceiling with a 130 x 105 mm hole where the light sits.
    const float y = 548.8f;
    add_quad(m, {556, y, 0}, {0, y, 0}, {0, y, 227}, {556, y, 227}, down);
    add_quad(m, {556, y, 332}, {0, y, 332}, {0, y, 559.2f}, {556, y, 559.2f}, down);
    add_quad(m, {556, y, 227}, {343, y, 227}, {343, y, 332}, {556, y, 332}, down);
    add_quad(m, {213, y, 227}, {0, y, 227}, {0, y, 332}, {213, y, 332}, down);
  });
  object("back_wall", white, [&](Mesh& m) {
    add_quad(m, {549.6f, 0, 559.2f}, {0, 0, 559.2f}, {0, 548.8f, 559.2f}, {556, 548.8f, 559.2f},
             {0, 0, -1});
  });
  object("right_wall_green", green, [&](Mesh& m) {
    add_quad(m, {0, 0, 559.2f}, {0, 0, 0}, {0, 548.8f, 0}, {0, 548.8f, 559.2f}, {1, 0, 0});
  });
  object("left_wall_red", red, [&](Mesh& m) {
    add_quad(m, {552.8f, 0, 0}, {549.6f, 0, 559.2f}, {556, 548.8f, 559.2f}, {556, 548.8f, 0},
             inward_x);
  });
  object("short_block", white, [&](Mesh& m) {
    add_block(m, {{130, 65}, {82, 225}, {240, 272}, {290, 114}}, 165.0f);
  });
  object("tall_block", white, [&](Mesh& m) {
    add_block(m, {{423, 247}, {265, 296}, {314, 456}, {472, 406}}, 330.0f);
  });
  object("light", light, [&](Mesh& m) {
    add_quad(m, {343, 548.8f, 227}, {343, 548.8f, 332}, {213, 548.8f, 332}, {213, 548.8f, 227},
             down);
  });

  Camera cam;
  cam.name = "cornell_camera";
  cam.yfov = 2.0f * std::atan(12.5f / 35.0f);
  cam.aspect_ratio = 1.0f;
  cam.znear = 0.01f;
  s.cameras.push_back(cam);
  Node camera_node;
  camera_node.name = "camera";
  camera_node.camera = 0;
  // Rotate 180 degrees about +y so the camera's -z looks down the world's +z.
  camera_node.local = glm::mat4(glm::vec4(-1, 0, 0, 0), glm::vec4(0, 1, 0, 0),
                                glm::vec4(0, 0, -1, 0), glm::vec4(0.278f, 0.273f, -0.8f, 1));
  s.add_node(camera_node);
  return s;
}

}  // namespace irradcast
