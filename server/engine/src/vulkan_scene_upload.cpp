// What the Vulkan backend uploads (vulkan_backend_impl.h): the scene (BVH, materials, textures,
// lights, normals, sky), the surfaces with their lightmaps, the engine's pass data (texels, units,
// probes, probe weights), the previous bounce's lightmaps, and each pass's push constants.
#include "vulkan_backend_impl.h"

#include <algorithm>
#include <cstring>
#include <vector>

#include "gpu_bvh.h"
#include "irradcast/common/error.h"
#include "irradcast/common/lights.h"
#include "irradcast/common/sky.h"

namespace irradcast {

void VulkanBackend::Impl::upload_scene() {
  const GpuBvh bvh = build_gpu_bvh(*world);
  write(kNodes, bvh.nodes);
  write(kTris, bvh.triangles);
  upload_materials();
  upload_lights();
  std::vector<glm::vec4> normals;
  for (const WorldObject& o : world->objects) {
    const bool has = !o.normals.empty();
    for (const glm::uvec3& t : o.triangles())
      for (int k = 0; k < 3; ++k)
        normals.emplace_back(has ? o.normals[t[k]] : glm::vec3(0.0f), k == 0 && has ? 1.0f : 0.0f);
  }
  write(kTriNormals, normals);
  write_surfaces(nullptr);
  upload_sky();
}

// Materials (base colour, emission, alpha; texture indices) and the textures' texels.
void VulkanBackend::Impl::upload_materials() {
  const Scene& scene = *world->scene;
  const int textures = static_cast<int>(scene.textures.size());
  auto texture = [&](int t) { return as_float(t >= 0 && t < textures ? t : -1); };
  std::vector<glm::vec4> mats;
  std::vector<Material> all(scene.materials.begin(), scene.materials.end());
  all.push_back(Material{});  // World::material's fallback
  for (const Material& m : all) {
    mats.emplace_back(m.base_color, texture(m.base_color_texture));
    mats.emplace_back(m.is_emissive() ? m.emission() : glm::vec3(0.0f),
                      texture(m.emissive_texture));
    mats.emplace_back(m.base_alpha, m.alpha_cutoff, 0.0f, 0.0f);
  }
  write(kMaterials, mats);
  std::vector<glm::uvec4> headers;
  std::vector<std::uint32_t> texels;
  for (const Texture& t : scene.textures) {
    headers.emplace_back(static_cast<std::uint32_t>(texels.size()), t.width, t.height, 0u);
    const std::size_t n = static_cast<std::size_t>(t.width) * t.height;
    const std::size_t at = texels.size();
    texels.resize(at + n);
    if (n > 0 && t.rgba8.size() >= 4 * n) std::memcpy(&texels[at], t.rgba8.data(), 4 * n);
  }
  write(kTexHeaders, headers);
  write(kTexTexels, texels);
}

// The emissive triangles with the light hierarchy's nodes, the punctual lights, and each
// triangle's entry in the emissive list.
void VulkanBackend::Impl::upload_lights() {
  std::vector<glm::vec4> em;
  const auto& tris = lights->emissive_triangles();
  for (std::size_t k = 0; k < tris.size(); ++k) {
    const EmissiveTriangle& e = tris[k];
    const WorldObject& o = world->objects[e.object];
    const Material& m = world->material(e.object, e.triangle);
    em.emplace_back(e.p0, e.reach);  // reach: direct.comp's surely_rejected
    em.emplace_back(e.e1, 0.0f);
    em.emplace_back(e.e2, e.double_sided ? 1.0f : 0.0f);
    em.emplace_back(e.normal, e.area);
    em.emplace_back(lights->pick_cdf()[k], lights->pick_pdf()[k],
                    as_float(material_index(e.object, e.triangle)), 0.0f);
    const int set = m.emissive_uv;
    em.emplace_back(o.uv(set, e.triangle, 0.0f, 0.0f), o.uv(set, e.triangle, 1.0f, 0.0f));
    em.emplace_back(o.uv(set, e.triangle, 0.0f, 1.0f), glm::vec2(0.0f));
  }
  // The light hierarchy's nodes after the triangles (lights.glsl's tree_node).
  for (const LightTree::Node& nd : lights->tree().nodes()) {
    const std::uint32_t flags = (nd.leaf ? 1u : 0u) | (nd.two_sided ? 2u : 0u);
    em.emplace_back(nd.lo, nd.phi);
    em.emplace_back(nd.hi, nd.cos_o);
    em.emplace_back(nd.w, as_float(flags));
    em.emplace_back(as_float(nd.index), 0.0f, 0.0f, 0.0f);
  }
  write(kEmissive, em);
  emissive_count = static_cast<std::uint32_t>(tris.size());

  std::vector<glm::vec4> pl;
  for (const WorldLight& l : world->lights) {
    float type = l.type == Light::Type::Directional ? 0.0f
                 : l.type == Light::Type::Spot      ? 2.0f
                                                    : 1.0f;
    pl.emplace_back(l.position, type);
    pl.emplace_back(l.direction, l.range);
    pl.emplace_back(l.intensity, l.cos_inner);
    pl.emplace_back(l.cos_outer, 0.0f, 0.0f, 0.0f);
  }
  write(kPunctual, pl);
  punctual_count = static_cast<std::uint32_t>(world->lights.size());

  // Per triangle (global index, objects in order): its entry in the emissive list or -1.
  std::vector<std::size_t> base;
  std::size_t triangles = 0;
  for (const WorldObject& o : world->objects) {
    base.push_back(triangles);
    triangles += o.triangles().size();
  }
  emissive_of.assign(triangles, -1);
  for (std::size_t k = 0; k < tris.size(); ++k)
    emissive_of[base[static_cast<std::size_t>(tris[k].object)] + tris[k].triangle] =
        static_cast<std::int32_t>(k);
}

// The sky as common.glsl describes it: a header (a constant's radiance x strength, the map's
// size), then a map's radiance x strength and LightSampler's sampling tables. A map that is
// black everywhere (no tables) is a black constant: its rays are traced, its light is 0.
void VulkanBackend::Impl::upload_sky() {
  std::vector<float> data(8, 0.0f);
  sky_flags = 0;
  const Sky* sky = lights->sky();
  if (sky) {
    sky_flags = kFlagSky;
    const SkyDistribution& dist = lights->sky_distribution();
    if (sky->map.width <= 0 || sky->map.height <= 0) {
      const glm::vec3 l = sky->color * sky->strength;
      data[0] = l.x;
      data[1] = l.y;
      data[2] = l.z;
    } else if (dist.valid() && dist.width() == sky->map.width && dist.height() == sky->map.height &&
               sky->map.pixels.size() == static_cast<std::size_t>(dist.width()) * dist.height()) {
      sky_flags |= kFlagSkyMap;
      const VkDeviceSize bytes =
          4 * (8 + 5 * sky->map.pixels.size() + 2 * static_cast<std::size_t>(dist.height()) + 1);
      if (bytes > max_buffer)
        throw Error("Vulkan: the " + std::to_string(dist.width()) + "x" +
                    std::to_string(dist.height()) + " sky map needs a " +
                    std::to_string(bytes >> 20) + " MiB buffer, beyond " + context.device().name +
                    "'s limit of " + std::to_string(max_buffer >> 20) +
                    " MiB (maxStorageBufferRange); use a smaller map or --backend embree");
      data.reserve(bytes / 4);
      data[3] = as_float(static_cast<std::uint32_t>(dist.width()));
      data[4] = as_float(static_cast<std::uint32_t>(dist.height()));
      for (const glm::vec3& c : sky->map.pixels)
        for (int k = 0; k < 3; ++k) data.push_back(c[k] * sky->strength);
      for (const auto* table : {&dist.marginal_cdf(), &dist.conditional_cdf(), &dist.density()})
        data.insert(data.end(), table->begin(), table->end());
    }
  }
  write(kSky, data);
}

std::uint32_t VulkanBackend::Impl::material_index(int object, std::uint32_t t) const {
  const Mesh& mesh = *world->objects[object].source;
  const std::size_t materials = world->scene->materials.size();
  std::uint32_t m = t < mesh.triangle_material.size() ? mesh.triangle_material[t] : ~0u;
  return m < materials ? m : static_cast<std::uint32_t>(materials);
}

// Per object: triangle base, lightmap offset and size; per triangle: lightmap and base-colour
// uv corners, material. Without an atlas (the reference path tracer reads no lightmap) the
// lightmap fields are zero.
void VulkanBackend::Impl::write_surfaces(const Atlas* atlas) {
  std::vector<glm::uvec4> objects;
  std::vector<glm::vec4> attr;
  std::uint32_t lightmap_texels = 0;
  object_offsets.clear();
  const ObjectLightmap none;
  for (const WorldObject& o : world->objects) {
    const ObjectLightmap& lm = atlas ? atlas->objects[o.object] : none;
    objects.emplace_back(static_cast<std::uint32_t>(attr.size() / 4), lightmap_texels,
                         static_cast<std::uint32_t>(lm.width),
                         static_cast<std::uint32_t>(lm.height));
    object_offsets.push_back(lightmap_texels);
    lightmap_texels += static_cast<std::uint32_t>(lm.width * lm.height);
    const auto& tris = o.triangles();
    for (std::uint32_t t = 0; t < tris.size(); ++t) {
      const std::size_t c = 3 * static_cast<std::size_t>(t);
      const glm::vec2 zero(0.0f);
      glm::vec2 l0 = c + 2 < lm.corner_uv.size() ? lm.corner_uv[c] : zero;
      glm::vec2 l1 = c + 2 < lm.corner_uv.size() ? lm.corner_uv[c + 1] : zero;
      glm::vec2 l2 = c + 2 < lm.corner_uv.size() ? lm.corner_uv[c + 2] : zero;
      const int set = world->material(o.object, t).base_color_uv;
      attr.emplace_back(l0, l1);
      attr.emplace_back(l2, o.uv(set, t, 0.0f, 0.0f));
      attr.emplace_back(o.uv(set, t, 1.0f, 0.0f), o.uv(set, t, 0.0f, 1.0f));
      const std::size_t global = attr.size() / 4;
      attr.emplace_back(as_float(material_index(o.object, t)),
                        as_float(global < emissive_of.size() ? emissive_of[global] : -1), 0.0f,
                        0.0f);
    }
  }
  lightmap_total = lightmap_texels;
  write(kObjects, objects);
  write(kTriAttr, attr);
}

void VulkanBackend::Impl::prepare(const PassInput& in) {
  EngineKey key{&in.atlas,
                in.texels.position.data(),
                in.texels.size(),
                in.unit_texels.data(),
                in.unit_texels.size(),
                in.probes.position.data(),
                in.probes.count(),
                in.probe_corners.data(),
                in.probe_corners.size(),
                in.generation};
  if (key == engine_key) return;
  if (in.atlas.objects.size() != world->objects.size())
    throw Error("Vulkan backend: the atlas has " + std::to_string(in.atlas.objects.size()) +
                " objects, the world " + std::to_string(world->objects.size()));
  write_surfaces(&in.atlas);
  const SurfaceTexels& st = in.texels;
  write(kTexels, st.size() * 3 * sizeof(glm::vec4), [&](void* dst) {
    auto* v = static_cast<glm::vec4*>(dst);
    for (std::size_t i = 0; i < st.size(); ++i) {
      v[3 * i] = glm::vec4(st.position[i], 0.0f);
      v[3 * i + 1] = glm::vec4(st.normal[i], 0.0f);
      v[3 * i + 2] = glm::vec4(st.geo_normal(*world, i), 0.0f);
    }
  });
  write(kUnits, in.unit_texels);
  std::vector<glm::vec4> probes;
  for (std::size_t p = 0; p < in.probes.count(); ++p)
    probes.emplace_back(in.probes.position[p], in.probes.usable[p] ? 1.0f : 0.0f);
  write(kProbes, probes);
  write(kProbeWeights, in.probe_corners.size() * 20 * sizeof(std::uint32_t), [&](void* dst) {
    auto* w = static_cast<std::uint32_t*>(dst);
    for (std::size_t i = 0; i < in.probe_corners.size(); ++i) {
      const ProbeWeights pw = in.probe_weights(static_cast<std::uint32_t>(i));
      std::uint32_t* o = w + 20 * i;
      for (int k = 0; k < 8; ++k) {
        const bool used = k < pw.count();
        o[k] = used ? pw.probe(k, in.probes.dims) : 0u;
        o[8 + k] = used ? bits(pw.weight[k]) : 0u;
      }
      o[16] = static_cast<std::uint32_t>(pw.count());
      o[17] = o[18] = o[19] = 0;
    }
  });
  engine_key = key;
}

// The previous bounce's lightmaps: the gather and the scatter of one bounce read the same
// ones, so the scatter does not upload them again.
void VulkanBackend::Impl::write_previous(const RadianceField& prev, const PassInput& in) {
  const PrevKey key{prev.irradiance, in.update, in.bounce};
  if (key == prev_key) return;
  prev_key = key;
  const std::vector<Lightmap>& maps = *prev.irradiance;
  if (maps.size() != object_offsets.size())
    throw Error("Vulkan backend: " + std::to_string(maps.size()) + " lightmaps for " +
                std::to_string(object_offsets.size()) + " objects");
  write(kPrev, static_cast<VkDeviceSize>(lightmap_total) * sizeof(glm::vec4), [&](void* dst) {
    auto* v = static_cast<glm::vec4*>(dst);
    for (std::size_t o = 0; o < maps.size(); ++o) {
      const std::size_t n = std::min<std::size_t>(
          maps[o].texels.size(),
          (o + 1 < object_offsets.size() ? object_offsets[o + 1] : lightmap_total) -
              object_offsets[o]);
      for (std::size_t i = 0; i < n; ++i)
        v[object_offsets[o] + i] = glm::vec4(maps[o].texels[i], 0.0f);
    }
  });
}

PushConstants VulkanBackend::Impl::constants(const PassInput& in) const {
  PushConstants pc;
  pc.update = in.update;
  pc.bounce = in.bounce;
  pc.seed_lo = static_cast<std::uint32_t>(in.params.seed);
  pc.seed_hi = static_cast<std::uint32_t>(in.params.seed >> 32);
  pc.epsilon = rays->epsilon();
  pc.extent = in.world.bounds.max_extent();
  pc.range = in.params.unbiased() ? 3.4e38f : in.params.tracing_range.resolve(pc.extent);
  pc.punctual_count = punctual_count;
  pc.emissive_count = emissive_count;
  for (int a = 0; a < 3; ++a) {
    pc.bounds_lo[a] = in.world.bounds.lo[a];
    pc.bounds_hi[a] = in.world.bounds.hi[a];
  }
  pc.probe_res = in.probes.resolution;
  if (emissive_count > 0) pc.flags |= kFlagArea;
  if (!lights->tree().empty()) pc.flags |= kFlagLightTree;
  pc.flags |= sky_flags;
  if (in.params.unbiased()) pc.flags |= kFlagUnbiased;
  if (in.params.distant_point == DistantPoint::FixedDistance) pc.flags |= kFlagFixed;
  if (!in.probe_corners.empty()) pc.flags |= kFlagProbes;
  return pc;
}

}  // namespace irradcast
