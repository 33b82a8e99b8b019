#include "irradcast/wire/scene_package.h"

#include <google/protobuf/io/coded_stream.h>
#include <google/protobuf/io/zero_copy_stream_impl_lite.h>
#include <zstd.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <utility>

#include "irradcast/common/error.h"
#include "irradcast/wire/sky_message.h"

namespace irradcast::wire {
namespace {

static_assert(sizeof(glm::vec3) == 3 * sizeof(float) && sizeof(glm::vec2) == 2 * sizeof(float));
static_assert(sizeof(glm::mat4) == 16 * sizeof(float));

constexpr int kSceneZstdLevel = 3;
constexpr int kMaxTextureSize = 1 << 15;
constexpr std::uint32_t kMaxLightmapSize = 1 << 16;

[[noreturn]] void fail(const std::string& problem) {
  throw irradcast::Error("scene package: " + problem);
}

std::string idx(const char* what, std::size_t i) {
  return std::string(what) + " " + std::to_string(i);
}

bool finite(float f) {
  return std::isfinite(f);
}
bool finite(glm::vec3 v) {
  return finite(v.x) && finite(v.y) && finite(v.z);
}
bool finite(glm::vec2 v) {
  return finite(v.x) && finite(v.y);
}

// --- Scene validation: everything World::build, RayScene and compose() index without checks ---

void validate_scene(const Scene& s) {
  const std::size_t nodes = s.nodes.size();
  auto in = [](long v, std::size_t n) { return v >= 0 && static_cast<std::size_t>(v) < n; };
  for (std::size_t i = 0; i < s.meshes.size(); ++i) {
    const Mesh& m = s.meshes[i];
    const std::size_t n = m.positions.size();
    for (const glm::vec3& p : m.positions)
      if (!finite(p)) fail(idx("mesh", i) + " has non-finite positions");
    if (!m.normals.empty() && m.normals.size() != n)
      fail(idx("mesh", i) + " has " + std::to_string(m.normals.size()) + " normals for " +
           std::to_string(n) + " vertices");
    if (!m.uv0.empty() && m.uv0.size() != n)
      fail(idx("mesh", i) + " has " + std::to_string(m.uv0.size()) + " TEXCOORD_0 for " +
           std::to_string(n) + " vertices");
    if (!m.uv1.empty() && m.uv1.size() != n)
      fail(idx("mesh", i) + " has " + std::to_string(m.uv1.size()) + " TEXCOORD_1 for " +
           std::to_string(n) + " vertices");
    for (std::size_t t = 0; t < m.triangles.size(); ++t) {
      const glm::uvec3& tri = m.triangles[t];
      if (tri.x >= n || tri.y >= n || tri.z >= n)
        fail(idx("mesh", i) + " triangle " + std::to_string(t) +
             " refers to a vertex out of range (" + std::to_string(n) + " vertices)");
    }
    if (!m.triangle_material.empty() && m.triangle_material.size() != m.triangles.size())
      fail(idx("mesh", i) + " has " + std::to_string(m.triangle_material.size()) +
           " triangle materials for " + std::to_string(m.triangles.size()) + " triangles");
  }
  for (std::size_t i = 0; i < s.materials.size(); ++i) {
    const Material& m = s.materials[i];
    if (m.base_color_texture != -1 && !in(m.base_color_texture, s.textures.size()))
      fail(idx("material", i) + " refers to texture " + std::to_string(m.base_color_texture) +
           ", which does not exist");
    if (m.emissive_texture != -1 && !in(m.emissive_texture, s.textures.size()))
      fail(idx("material", i) + " refers to texture " + std::to_string(m.emissive_texture) +
           ", which does not exist");
    if (!finite(m.alpha_cutoff) || !finite(m.base_alpha) || m.base_alpha < 0.0f ||
        m.base_alpha > 1.0f)
      fail(idx("material", i) + " has a non-finite alpha cutoff or an alpha outside [0, 1]");
  }
  validate_sky(s.sky, "scene package");
  for (std::size_t i = 0; i < s.textures.size(); ++i) {
    const Texture& t = s.textures[i];
    if (t.width < 0 || t.height < 0 || t.width > kMaxTextureSize || t.height > kMaxTextureSize ||
        t.rgba8.size() !=
            static_cast<std::size_t>(t.width) * static_cast<std::size_t>(t.height) * 4)
      fail(idx("texture", i) + " (" + std::to_string(t.width) + " x " + std::to_string(t.height) +
           ") has " + std::to_string(t.rgba8.size()) + " bytes of RGBA8 data");
  }
  for (std::size_t i = 0; i < nodes; ++i) {
    const Node& n = s.nodes[i];
    if (n.parent != -1 && !in(n.parent, nodes))
      fail(idx("node", i) + " has parent " + std::to_string(n.parent) + ", which does not exist");
    for (int c : n.children)
      if (!in(c, nodes))
        fail(idx("node", i) + " has child " + std::to_string(c) + ", which does not exist");
    if (n.mesh != -1 && !in(n.mesh, s.meshes.size()))
      fail(idx("node", i) + " refers to mesh " + std::to_string(n.mesh) + ", which does not exist");
    if (n.camera != -1 && !in(n.camera, s.cameras.size()))
      fail(idx("node", i) + " refers to camera " + std::to_string(n.camera) +
           ", which does not exist");
    if (n.light != -1 && !in(n.light, s.lights.size()))
      fail(idx("node", i) + " refers to light " + std::to_string(n.light) +
           ", which does not exist");
    for (int c = 0; c < 4; ++c)
      for (int r = 0; r < 4; ++r)
        if (!finite(n.local[c][r])) fail(idx("node", i) + " has a non-finite transform");
  }
  for (int r : s.roots)
    if (!in(r, nodes)) fail("root node " + std::to_string(r) + " does not exist");
}

void validate_layout(const Scene& s, const Atlas& atlas) {
  const std::vector<Object> objects = s.objects();
  if (atlas.objects.size() != objects.size())
    fail("the lightmap layout has " + std::to_string(atlas.objects.size()) +
         " objects but the scene has " + std::to_string(objects.size()));
  const std::vector<bool> dynamic = s.dynamic_nodes();
  for (std::size_t i = 0; i < objects.size(); ++i) {
    const ObjectLightmap& o = atlas.objects[i];
    const std::size_t tris = s.meshes[objects[i].mesh].triangles.size();
    if (dynamic[static_cast<std::size_t>(objects[i].node)]) {  // no lightmap
      if (o.width != 0 || o.height != 0 || !o.corner_uv.empty())
        fail(idx("object", i) + " (\"" + objects[i].name +
             "\") is dynamic and has a lightmap layout");
      continue;
    }
    if (o.width < 0 || o.height < 0 || static_cast<std::uint32_t>(o.width) > kMaxLightmapSize ||
        static_cast<std::uint32_t>(o.height) > kMaxLightmapSize)
      fail(idx("object", i) + " has an invalid lightmap size " + std::to_string(o.width) + " x " +
           std::to_string(o.height));
    if (o.corner_uv.size() != 3 * tris)
      fail(idx("object", i) + " (\"" + objects[i].name + "\") has lightmap coordinates for " +
           std::to_string(o.corner_uv.size() / 3) + " triangles but its mesh has " +
           std::to_string(tris));
    if (!o.triangle_chart.empty() && o.triangle_chart.size() != tris)
      fail(idx("object", i) + " has charts for " + std::to_string(o.triangle_chart.size()) +
           " triangles but its mesh has " + std::to_string(tris));
  }
}

// --- Conversion -------------------------------------------------------------------------------

template <typename V>
void put_floats(google::protobuf::RepeatedField<float>* dst, const std::vector<V>& src) {
  constexpr int k = sizeof(V) / sizeof(float);
  dst->Resize(static_cast<int>(src.size() * k), 0.0f);
  if (!src.empty()) std::memcpy(dst->mutable_data(), src.data(), src.size() * sizeof(V));
}

template <typename V>
std::vector<V> get_floats(const google::protobuf::RepeatedField<float>& src,
                          const std::string& what) {
  constexpr std::size_t k = sizeof(V) / sizeof(float);
  const std::size_t n = static_cast<std::size_t>(src.size());
  if (n % k != 0)
    fail(what + " has " + std::to_string(n) + " values, not a multiple of " + std::to_string(k));
  std::vector<V> out(n / k);
  if (n) std::memcpy(static_cast<void*>(out.data()), src.data(), n * sizeof(float));
  return out;
}

void put_vec3(Vec3* dst, glm::vec3 v) {
  dst->set_x(v.x);
  dst->set_y(v.y);
  dst->set_z(v.z);
}
glm::vec3 get_vec3(const Vec3& v) {
  return glm::vec3(v.x(), v.y(), v.z());
}

int to_int(std::int32_t v) {
  return static_cast<int>(v);
}

void put_nodes(SceneData& d, const Scene& s) {
  for (const Node& n : s.nodes) {
    SceneNode* o = d.add_nodes();
    o->set_name(n.name);
    if (n.local != glm::mat4(1.0f)) {
      o->mutable_local()->Resize(16, 0.0f);
      std::memcpy(o->mutable_local()->mutable_data(), &n.local[0][0], 16 * sizeof(float));
    }
    o->set_parent(n.parent);
    for (int c : n.children) o->add_children(c);
    o->set_mesh(n.mesh);
    o->set_camera(n.camera);
    o->set_light(n.light);
    o->set_hidden(!n.visible);
    o->set_dynamic(n.dynamic);
  }
  for (int r : s.roots) d.add_roots(r);
}

void put_meshes(SceneData& d, const Scene& s) {
  for (const Mesh& m : s.meshes) {
    SceneMesh* o = d.add_meshes();
    o->set_name(m.name);
    put_floats(o->mutable_positions(), m.positions);
    put_floats(o->mutable_normals(), m.normals);
    put_floats(o->mutable_uv0(), m.uv0);
    put_floats(o->mutable_uv1(), m.uv1);
    o->mutable_triangles()->Reserve(static_cast<int>(3 * m.triangles.size()));
    for (const glm::uvec3& t : m.triangles) {
      o->add_triangles(t.x);
      o->add_triangles(t.y);
      o->add_triangles(t.z);
    }
    o->mutable_triangle_material()->Add(m.triangle_material.begin(), m.triangle_material.end());
  }
}

void put_materials(SceneData& d, const Scene& s) {
  for (const Material& m : s.materials) {
    SceneMaterial* o = d.add_materials();
    o->set_name(m.name);
    put_vec3(o->mutable_base_color(), m.base_color);
    o->set_base_color_texture(m.base_color_texture);
    o->set_base_color_uv(static_cast<std::uint32_t>(m.base_color_uv));
    put_vec3(o->mutable_emissive(), m.emissive);
    o->set_emissive_texture(m.emissive_texture);
    o->set_emissive_uv(static_cast<std::uint32_t>(m.emissive_uv));
    o->set_emissive_strength(m.emissive_strength);
    o->set_double_sided(m.double_sided);
    // Defaults are left out: a package of opaque materials keeps the bytes (and hash) it had.
    if (m.alpha_mode == Material::AlphaMode::Mask) o->set_alpha_mode(ALPHA_MASK);
    if (m.alpha_cutoff != Material{}.alpha_cutoff) o->set_alpha_cutoff(m.alpha_cutoff);
    if (m.base_alpha != Material{}.base_alpha) o->set_base_alpha(m.base_alpha);
  }
}

void put_textures(SceneData& d, const Scene& s) {
  for (const Texture& t : s.textures) {
    SceneTexture* o = d.add_textures();
    o->set_name(t.name);
    o->set_width(static_cast<std::uint32_t>(t.width));
    o->set_height(static_cast<std::uint32_t>(t.height));
    o->set_rgba8(t.rgba8.data(), t.rgba8.size());
  }
}

void put_lights(SceneData& d, const Scene& s) {
  for (const Light& l : s.lights) {
    SceneLight* o = d.add_lights();
    o->set_name(l.name);
    o->set_type(l.type == Light::Type::Spot          ? LIGHT_SPOT
                : l.type == Light::Type::Directional ? LIGHT_DIRECTIONAL
                                                     : LIGHT_POINT);
    put_vec3(o->mutable_color(), l.color);
    o->set_intensity(l.intensity);
    o->set_range(l.range);
    o->set_inner_cone_angle(l.inner_cone_angle);
    o->set_outer_cone_angle(l.outer_cone_angle);
  }
}

void put_cameras(SceneData& d, const Scene& s) {
  for (const Camera& c : s.cameras) {
    SceneCamera* o = d.add_cameras();
    o->set_name(c.name);
    o->set_yfov(c.yfov);
    o->set_aspect_ratio(c.aspect_ratio);
    o->set_znear(c.znear);
    o->set_zfar(c.zfar);
  }
}

void put_layouts(SceneData& d, const Atlas& atlas) {
  for (const ObjectLightmap& l : atlas.objects) {
    ObjectLayout* o = d.add_layouts();
    o->set_width(static_cast<std::uint32_t>(l.width));
    o->set_height(static_cast<std::uint32_t>(l.height));
    put_floats(o->mutable_corner_uv(), l.corner_uv);
    // A non-finite coordinate (degenerate triangle) would be undefined behaviour in a lookup;
    // it is sent as texel (0, 0), which is what the layout means for a triangle with no area.
    for (float& f : *o->mutable_corner_uv())
      if (!finite(f)) f = 0.0f;
    o->mutable_triangle_chart()->Add(l.triangle_chart.begin(), l.triangle_chart.end());
    o->set_chart_count(static_cast<std::uint32_t>(std::max(l.chart_count, 0)));
    o->set_from_file_uv1(l.from_file_uv1);
    o->set_texels_per_unit(l.texels_per_unit);
  }
}

SceneData to_proto(const Scene& s, const Atlas& atlas, std::uint64_t revision) {
  SceneData d;
  d.set_format(kSceneFormat);
  d.set_name(s.name);
  d.set_revision(revision);
  put_nodes(d, s);
  put_meshes(d, s);
  put_materials(d, s);
  put_textures(d, s);
  put_lights(d, s);
  put_cameras(d, s);
  put_layouts(d, atlas);
  // No sky: no field, so a sky-less package keeps the bytes (and hash) it had.
  if (!is_default_sky(s.sky)) sky_to_proto(s.sky, d.mutable_sky());
  return d;
}

void get_nodes(const SceneData& d, Scene& s) {
  for (int i = 0; i < d.nodes_size(); ++i) {
    const SceneNode& o = d.nodes(i);
    Node n;
    n.name = o.name();
    if (o.local_size() == 16)
      std::memcpy(&n.local[0][0], o.local().data(), 16 * sizeof(float));
    else if (o.local_size() != 0)
      fail(idx("node", i) + " has a transform of " + std::to_string(o.local_size()) +
           " values (expected 16)");
    n.parent = to_int(o.parent());
    n.children.assign(o.children().begin(), o.children().end());
    n.mesh = to_int(o.mesh());
    n.camera = to_int(o.camera());
    n.light = to_int(o.light());
    n.visible = !o.hidden();
    n.dynamic = o.dynamic();
    s.nodes.push_back(std::move(n));
  }
  s.roots.assign(d.roots().begin(), d.roots().end());
}

void get_meshes(const SceneData& d, Scene& s) {
  for (int i = 0; i < d.meshes_size(); ++i) {
    const SceneMesh& o = d.meshes(i);
    const std::string what = idx("mesh", i);
    Mesh m;
    m.name = o.name();
    m.positions = get_floats<glm::vec3>(o.positions(), what + " positions");
    m.normals = get_floats<glm::vec3>(o.normals(), what + " normals");
    m.uv0 = get_floats<glm::vec2>(o.uv0(), what + " TEXCOORD_0");
    m.uv1 = get_floats<glm::vec2>(o.uv1(), what + " TEXCOORD_1");
    if (o.triangles_size() % 3 != 0)
      fail(what + " has " + std::to_string(o.triangles_size()) +
           " triangle indices, not a multiple of 3");
    m.triangles.resize(static_cast<std::size_t>(o.triangles_size() / 3));
    for (std::size_t t = 0; t < m.triangles.size(); ++t)
      m.triangles[t] =
          glm::uvec3(o.triangles(static_cast<int>(3 * t)), o.triangles(static_cast<int>(3 * t + 1)),
                     o.triangles(static_cast<int>(3 * t + 2)));
    m.triangle_material.assign(o.triangle_material().begin(), o.triangle_material().end());
    s.meshes.push_back(std::move(m));
  }
}

void get_materials(const SceneData& d, Scene& s) {
  for (int i = 0; i < d.materials_size(); ++i) {
    const SceneMaterial& o = d.materials(i);
    Material m;
    m.name = o.name();
    m.base_color = get_vec3(o.base_color());
    m.base_color_texture = to_int(o.base_color_texture());
    m.base_color_uv = o.base_color_uv() == 1 ? 1 : 0;
    if (o.base_color_uv() > 1 || o.emissive_uv() > 1)
      fail(idx("material", i) + " uses a TEXCOORD set other than 0 or 1");
    m.emissive = get_vec3(o.emissive());
    m.emissive_texture = to_int(o.emissive_texture());
    m.emissive_uv = o.emissive_uv() == 1 ? 1 : 0;
    m.emissive_strength = o.emissive_strength();
    m.double_sided = o.double_sided();
    switch (o.alpha_mode()) {
      case ALPHA_OPAQUE:
        m.alpha_mode = Material::AlphaMode::Opaque;
        break;
      case ALPHA_MASK:
        m.alpha_mode = Material::AlphaMode::Mask;
        break;
      default:
        fail(idx("material", i) + " has an unknown alpha mode " + std::to_string(o.alpha_mode()));
    }
    if (o.has_alpha_cutoff()) m.alpha_cutoff = o.alpha_cutoff();
    if (o.has_base_alpha()) m.base_alpha = o.base_alpha();
    s.materials.push_back(std::move(m));
  }
}

void get_textures(const SceneData& d, Scene& s) {
  for (int i = 0; i < d.textures_size(); ++i) {
    const SceneTexture& o = d.textures(i);
    if (o.width() > static_cast<std::uint32_t>(kMaxTextureSize) ||
        o.height() > static_cast<std::uint32_t>(kMaxTextureSize))
      fail(idx("texture", i) + " is too large (" + std::to_string(o.width()) + " x " +
           std::to_string(o.height()) + ")");
    Texture t;
    t.name = o.name();
    t.width = static_cast<int>(o.width());
    t.height = static_cast<int>(o.height());
    t.rgba8.assign(o.rgba8().begin(), o.rgba8().end());
    s.textures.push_back(std::move(t));
  }
}

void get_lights(const SceneData& d, Scene& s) {
  for (int i = 0; i < d.lights_size(); ++i) {
    const SceneLight& o = d.lights(i);
    Light l;
    l.name = o.name();
    switch (o.type()) {
      case LIGHT_POINT:
        l.type = Light::Type::Point;
        break;
      case LIGHT_SPOT:
        l.type = Light::Type::Spot;
        break;
      case LIGHT_DIRECTIONAL:
        l.type = Light::Type::Directional;
        break;
      default:
        fail(idx("light", i) + " has an unknown type " + std::to_string(o.type()));
    }
    l.color = get_vec3(o.color());
    l.intensity = o.intensity();
    l.range = o.range();
    l.inner_cone_angle = o.inner_cone_angle();
    l.outer_cone_angle = o.outer_cone_angle();
    s.lights.push_back(std::move(l));
  }
}

void get_cameras(const SceneData& d, Scene& s) {
  for (int i = 0; i < d.cameras_size(); ++i) {
    const SceneCamera& o = d.cameras(i);
    Camera c;
    c.name = o.name();
    c.yfov = o.yfov();
    c.aspect_ratio = o.aspect_ratio();
    c.znear = o.znear();
    c.zfar = o.zfar();
    s.cameras.push_back(std::move(c));
  }
}

void get_layouts(const SceneData& d, Atlas& atlas) {
  for (int i = 0; i < d.layouts_size(); ++i) {
    const ObjectLayout& o = d.layouts(i);
    if (o.width() > kMaxLightmapSize || o.height() > kMaxLightmapSize)
      fail(idx("object", i) + " has an invalid lightmap size " + std::to_string(o.width()) + " x " +
           std::to_string(o.height()));
    ObjectLightmap l;
    l.width = static_cast<int>(o.width());
    l.height = static_cast<int>(o.height());
    l.corner_uv = get_floats<glm::vec2>(o.corner_uv(), idx("object", i) + " lightmap coordinates");
    for (const glm::vec2& uv : l.corner_uv)
      if (!finite(uv)) fail(idx("object", i) + " has non-finite lightmap coordinates");
    l.triangle_chart.assign(o.triangle_chart().begin(), o.triangle_chart().end());
    if (o.chart_count() > static_cast<std::uint32_t>(std::numeric_limits<int>::max()))
      fail(idx("object", i) + " has an invalid chart count");
    l.chart_count = static_cast<int>(o.chart_count());
    l.from_file_uv1 = o.from_file_uv1();
    l.texels_per_unit = o.texels_per_unit();
    atlas.objects.push_back(std::move(l));
  }
}

UnpackedScene from_proto(const SceneData& d) {
  if (d.format() != kSceneFormat)
    fail("format " + std::to_string(d.format()) + " is not supported (expected " +
         std::to_string(kSceneFormat) + ")");
  UnpackedScene out;
  out.revision = d.revision();
  Scene& s = out.scene;
  s.name = d.name();
  get_nodes(d, s);
  get_meshes(d, s);
  get_materials(d, s);
  get_textures(d, s);
  get_lights(d, s);
  get_cameras(d, s);
  get_layouts(d, out.atlas);
  if (d.has_sky()) s.sky = sky_from_proto(d.sky(), "scene package");
  validate_scene(s);
  validate_layout(s, out.atlas);
  return out;
}

}  // namespace

namespace {
// `data` serialized deterministically (the same scene gives the same bytes, so the same hash).
std::string serialize_deterministic(const SceneData& data) {
  const std::size_t size = data.ByteSizeLong();
  if (size > kMaxSceneDataBytes)
    fail("the scene is too large to send (" + std::to_string(size) + " bytes, limit " +
         std::to_string(kMaxSceneDataBytes) + ")");
  std::string raw(size, '\0');
  google::protobuf::io::ArrayOutputStream array(raw.data(), static_cast<int>(size));
  google::protobuf::io::CodedOutputStream coded(&array);
  coded.SetSerializationDeterministic(true);
  data.SerializeWithCachedSizes(&coded);
  if (coded.HadError()) fail("serialization failed");
  return raw;
}
}  // namespace

std::string scene_content_hash(const Scene& scene) {
  validate_scene(scene);
  return sha256(serialize_deterministic(to_proto(scene, Atlas{}, 0)));
}

ScenePackage make_scene_package(const Scene& scene, const Atlas& atlas, std::uint64_t revision) {
  validate_scene(scene);
  validate_layout(scene, atlas);
  const std::string raw = serialize_deterministic(to_proto(scene, atlas, revision));
  ZSTD_CCtx* ctx = ZSTD_createCCtx();
  if (!ctx) fail("out of memory (zstd)");
  ZSTD_CCtx_setParameter(ctx, ZSTD_c_compressionLevel, kSceneZstdLevel);
  ZSTD_CCtx_setParameter(ctx, ZSTD_c_checksumFlag, 1);
  ZSTD_CCtx_setPledgedSrcSize(ctx, raw.size());
  ScenePackage pkg;
  pkg.bytes.resize(ZSTD_compressBound(raw.size()));
  const std::size_t n =
      ZSTD_compress2(ctx, pkg.bytes.data(), pkg.bytes.size(), raw.data(), raw.size());
  ZSTD_freeCCtx(ctx);
  if (ZSTD_isError(n)) fail(std::string("compression failed: ") + ZSTD_getErrorName(n));
  pkg.bytes.resize(n);
  pkg.hash = sha256(pkg.bytes);
  return pkg;
}

UnpackedScene open_scene_package(const std::string& bytes, const std::string& expected_hash) {
  if (!expected_hash.empty()) {
    const std::string got = sha256(bytes);
    if (got != expected_hash)
      fail("hash mismatch: expected " + hex(expected_hash) + ", the " +
           std::to_string(bytes.size()) + " bytes received hash to " + hex(got));
  }
  const unsigned long long size = ZSTD_getFrameContentSize(bytes.data(), bytes.size());
  if (size == ZSTD_CONTENTSIZE_ERROR)
    fail("corrupt data: not a zstd frame (" + std::to_string(bytes.size()) + " bytes)");
  if (size == ZSTD_CONTENTSIZE_UNKNOWN)
    fail("corrupt data: the zstd frame does not declare its size");
  if (size > kMaxSceneDataBytes)
    fail("the scene is too large (" + std::to_string(size) + " bytes, limit " +
         std::to_string(kMaxSceneDataBytes) + ")");
  std::string raw(static_cast<std::size_t>(size), '\0');
  const std::size_t n = ZSTD_decompress(raw.data(), raw.size(), bytes.data(), bytes.size());
  if (ZSTD_isError(n)) fail(std::string("corrupt data: zstd: ") + ZSTD_getErrorName(n));
  if (n != raw.size())
    fail("corrupt data: " + std::to_string(n) + " bytes decompressed, " + std::to_string(size) +
         " declared");
  SceneData data;
  if (!data.ParseFromArray(raw.data(), static_cast<int>(raw.size())))
    fail("corrupt data: the scene description does not parse");
  return from_proto(data);
}

std::vector<std::string> chunk(const std::string& bytes, std::size_t chunk_size) {
  if (chunk_size == 0) throw irradcast::Error("chunk size must be positive");
  std::vector<std::string> out;
  out.reserve((bytes.size() + chunk_size - 1) / chunk_size);
  for (std::size_t i = 0; i < bytes.size(); i += chunk_size)
    out.push_back(bytes.substr(i, chunk_size));
  return out;
}

SceneAssembler::SceneAssembler(std::string expected_hash, std::uint64_t total)
    : hash_(std::move(expected_hash)), total_(total) {
  if (total_ > kMaxSceneDataBytes)
    fail("the announced package of " + std::to_string(total_) + " bytes is above the limit of " +
         std::to_string(kMaxSceneDataBytes));
  bytes_.reserve(static_cast<std::size_t>(total_));
}

bool SceneAssembler::add(const SceneChunk& c) {
  if (c.scene_hash() != hash_)
    fail("a chunk for scene " + hex(c.scene_hash()) + " arrived while downloading " + hex(hash_));
  if (c.total() != total_)
    fail("a chunk announces " + std::to_string(c.total()) + " bytes in all, expected " +
         std::to_string(total_));
  if (c.offset() != bytes_.size())
    fail("a chunk starts at byte " + std::to_string(c.offset()) + ", expected " +
         std::to_string(bytes_.size()));
  if (c.data().size() > total_ - bytes_.size())
    fail("a chunk of " + std::to_string(c.data().size()) + " bytes at " +
         std::to_string(c.offset()) + " runs past the end (" + std::to_string(total_) + " bytes)");
  bytes_ += c.data();
  return complete();
}

}  // namespace irradcast::wire
