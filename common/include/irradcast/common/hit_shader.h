// What a viewer sees at a primary hit, with the per-frame look-ups done once: HitShader keeps
// per object its lightmap, atlas corners and triangle materials, and per material what the
// shading needs (colour, texture, emission), so a hit costs one lightmap bilinear lookup, an
// albedo (a texture sample where the material has one) and nothing else. The numbers are those of
// World::albedo / World::emission, bit for bit. shade() is one hit; shade_block() a primary
// packet's 16 lanes in SoA, all 16 at once with AVX-512 where the CPU has it and the packet's hits
// share one object and material, else 4 at a time with SSE2 (the same operations in the same
// order, so the same bits). Used by compose() and the client passes' frame G-buffer, and
// (diffuse()) the engine's scatter pass at its hits.
#pragma once

#include <cstdint>
#include <functional>
#include <vector>

#include <glm/glm.hpp>

#include "irradcast/common/atlas.h"
#include "irradcast/common/lightmap.h"
#include "irradcast/common/primary_hits.h"
#include "irradcast/common/ray_scene.h"
#include "irradcast/common/sampling.h"
#include "irradcast/common/world.h"

namespace irradcast {

// The lightmap term albedo / pi * E (E read bilinearly) and the emission (one-sided unless the
// material is double-sided).
struct HitShade {
  glm::vec3 diffuse{0.0f};
  glm::vec3 emission{0.0f};
};

// The shades of a packet's lanes, SoA: [channel][lane].
struct BlockShade {
  alignas(16) float diffuse[3][PrimaryBlock::kLanes];
  alignas(16) float emission[3][PrimaryBlock::kLanes];
};

class HitShader {
 public:
  // `lightmaps` and `atlas.objects` indexed like world.objects (checked); all three must
  // outlive the shader.
  HitShader(const World& world, const Atlas& atlas, const std::vector<Lightmap>& lightmaps);

  // The shade at hit h of a ray along `direction`.
  [[gnu::always_inline, gnu::flatten]] HitShade shade(glm::vec3 direction, const Hit& h) const {
    const Object& o = objects_[static_cast<std::size_t>(h.object)];
    const glm::vec2 uv = o.atlas->uv(h.triangle, h.u, h.v);
    const glm::vec3 e = o.lightmap->bilinear(uv);
    const Shading& m = shading(o, h.triangle);
    HitShade s;
    if (m.emissive) emission(h, direction, m, s);
    s.diffuse = albedo(o, m, h) * kInvPi * e;
    return s;
  }

  // shade() of every lane of b that hits, bit for bit; the lanes that miss are left undefined.
  // With AVX-512 (avx512() true) a packet whose hits share one object and material is shaded
  // 16 lanes at once; every other one 4 lanes at a time with SSE2.
  void shade_block(const PrimaryBlock& b, BlockShade& s) const;
  // shade_block() of every packet of `packets`, out(b, s) for each in order, three packets in
  // flight so that a packet's memory loads overlap the next packets' traversals (the same bits).
  void shade_stream(PacketStream& packets,
                    const std::function<void(const PrimaryBlock&, const BlockShade&)>& out) const;
  // Whether shade_block uses AVX-512: where the CPU has it, unless turned off (tests compare the
  // two paths).
  bool avx512() const { return avx512_; }
  void set_avx512(bool on) { avx512_ = on && cpu_has_avx512(); }
  static bool cpu_has_avx512();

  // The lightmap term alone, albedo / pi * E, at hit h whose lightmap coordinates are uv (see
  // lightmap_uv): the outgoing radiance of the previous bounce that the engine's scatter pass
  // reads at a hit (radiance_at in pass_data.h, bit for bit).
  [[gnu::always_inline]] glm::vec3 diffuse(const Hit& h, glm::vec2 uv) const {
    const Object& o = objects_[static_cast<std::size_t>(h.object)];
    const glm::vec3 e = o.lightmap->bilinear(uv);
    return albedo(o, shading(o, h.triangle), h) * kInvPi * e;
  }
  glm::vec2 lightmap_uv(const Hit& h) const {
    return objects_[static_cast<std::size_t>(h.object)].atlas->uv(h.triangle, h.u, h.v);
  }

 private:
  static constexpr std::uint32_t kFallback = ~0u;
  struct Object {
    const WorldObject* world = nullptr;
    const ObjectLightmap* atlas = nullptr;
    const Lightmap* lightmap = nullptr;
    const std::uint32_t* triangle_material = nullptr;
    std::size_t triangle_count = 0;
    // The same data one pointer closer, for shade_block.
    const glm::vec2* corner_uv = nullptr;  // atlas corners, 3 per triangle
    const glm::vec3* texels = nullptr;     // the lightmap's
    int lightmap_width = 0, lightmap_height = 0;
    const glm::uvec3* triangles = nullptr;
    const glm::vec2* uv[2] = {nullptr, nullptr};  // TEXCOORD_0 and _1; null where absent
  };
  struct Shading {
    glm::vec3 base_color{0.8f};
    const Texture* texture = nullptr;  // the base colour texture, if any
    int texture_uv = 0;
    bool emissive = false;
    bool double_sided = false;
  };
  // The atlas corners, lightmap and material of each of 4 lanes; see hit_shader.cpp.
  struct Lanes;
  void gather_lanes(const PrimaryBlock& b, int k0, Lanes& l) const;
  void shade_block_sse2(const PrimaryBlock& b, BlockShade& s) const;
  // Prefetches the hits' triangle data (atlas corners, vertex indices).
  void touch_block(const PrimaryBlock& b) const;

 public:
  // A bilinear lookup of a packet's 16 lanes between its halves: the four taps' texel indices,
  // the weights in x and y.
  struct Taps16 {
    alignas(64) std::int32_t at[4][PrimaryBlock::kLanes];
    alignas(64) float a[2][PrimaryBlock::kLanes];
  };

 private:
  // shade_block of a packet with AVX-512 in two halves (hit_shader_avx512.cpp): begin_avx512
  // splits its hits into groups of one object and material (false, nothing done, for a packet
  // with more than kAvx512Groups) and finds each group's texels (prefetching the texture's),
  // finish_avx512 reads them and writes the shades.
  static constexpr int kAvx512Groups = 4;
  struct Avx512Group {
    std::uint16_t mask = 0;  // its lanes
    const Shading* material = nullptr;
    const glm::vec3* lightmap = nullptr;
    const Texture* texture = nullptr;  // null: none
    Taps16 lightmap_taps, texture_taps;
  };
  struct Avx512Loads {
    bool taken = false;
    int groups = 0;
    Avx512Group group[kAvx512Groups];
  };
  void begin_avx512_group(const PrimaryBlock& b, const Object& o, std::uint16_t mask,
                          Avx512Group& g) const;
  bool begin_avx512(const PrimaryBlock& b, Avx512Loads& l) const;
  void finish_avx512(const PrimaryBlock& b, const Avx512Loads& l, BlockShade& s) const;
  const Shading& shading(const Object& o, std::uint32_t t) const {
    const std::uint32_t mi = t < o.triangle_count ? o.triangle_material[t] : kFallback;
    return materials_[mi < materials_.size() - 1 ? mi : materials_.size() - 1];
  }
  // As World::albedo: the base colour, times a texture sample where the material has one.
  static glm::vec3 albedo(const Object& o, const Shading& m, const Hit& h) {
    glm::vec3 a = m.base_color;
    if (m.texture)
      a *= glm::vec3(m.texture->sample_srgb(o.world->uv(m.texture_uv, h.triangle, h.u, h.v)));
    return a;
  }
  // The emission of an emissive material (rare: kept out of line).
  void emission(const Hit& h, glm::vec3 direction, const Shading& m, HitShade& s) const;

  const World* world_;
  bool avx512_ = cpu_has_avx512();
  std::vector<Object> objects_;
  std::vector<Shading> materials_;  // the scene's, then the fallback Material{}
};

}  // namespace irradcast
