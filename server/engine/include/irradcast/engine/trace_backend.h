// The one interface the GI engine's passes run behind: an Embree (CPU) backend and a Vulkan
// compute backend (backend_select.h picks one). A backend owns its acceleration structure; the
// engine owns the data (texels, probes, accumulated estimates) and calls one pass at a time.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include <glm/glm.hpp>

#include "irradcast/common/atlas.h"
#include "irradcast/engine/engine_params.h"
#include "irradcast/common/lightmap.h"
#include "irradcast/common/ray_scene.h"
#include "irradcast/common/world.h"

namespace irradcast {

// Every valid lightmap texel of the scene in one flat array (the global G-buffer), ordered
// object by object.
struct SurfaceTexels {
  std::vector<glm::vec3> position;
  std::vector<glm::vec3> normal;      // shading normal
  std::vector<glm::vec3> geo_normal;  // geometric normal, same side as `normal`
  std::vector<glm::vec3> albedo;
  std::vector<std::uint32_t> object;  // object index
  std::vector<std::uint32_t> texel;   // index in that object's lightmap
  std::vector<std::uint32_t> cell;    // radiance cell containing the texel
  std::size_t size() const { return position.size(); }
};

// Up to 8 probes a texel reads for distant light, with weights summing to 1.
struct ProbeWeights {
  std::uint32_t probe[8];
  float weight[8];
  std::uint8_t count = 0;
};

struct ProbeGrid {
  glm::ivec3 dims{0};
  glm::vec3 origin{0.0f};            // corner of cell (0,0,0)
  float cell = 1.0f;                 // cell edge, world units
  int resolution = 8;                // octahedral map side
  std::vector<glm::vec3> position;   // one per cell (centre, or relocated)
  std::vector<std::uint8_t> usable;  // 0: inside geometry and could not be moved
  std::size_t count() const { return position.size(); }
  std::size_t texels_per_probe() const { return static_cast<std::size_t>(resolution) * resolution; }
  int cell_index(glm::vec3 p) const;
};

// Octahedral mapping of unit directions to [0,1]^2 and back.
glm::vec2 octahedral_encode(glm::vec3 d);
glm::vec3 octahedral_decode(glm::vec2 uv);

// The previous bounce's outgoing radiance: albedo / pi * E_prev, read bilinearly at a hit.
struct RadianceField {
  const World* world = nullptr;
  const Atlas* atlas = nullptr;
  const std::vector<Lightmap>* irradiance = nullptr;  // E_prev per object, dilated
};

// Outgoing radiance albedo / pi * E_prev at a hit (bilinear in the hit object's lightmap).
glm::vec3 radiance_at(const RadianceField& f, const Hit& h);

struct PassInput {
  const World& world;
  const Atlas& atlas;
  const SurfaceTexels& texels;
  const std::vector<ProbeWeights>& probe_weights;  // per texel (empty in unbiased mode)
  const ProbeGrid& probes;
  const EngineParams& params;
  // Work units in dispatch order: texel index ranges [begin, end) of one cell or one object.
  const std::vector<std::uint32_t>& unit_texels;   // texel indices grouped by unit
  const std::vector<std::uint32_t>& unit_offsets;  // size units + 1
  std::uint32_t update = 0;
  std::uint32_t bounce = 0;  // 0 for the direct pass, k for the k-th indirect bounce
  // Changes whenever the texels, units, probes or probe weights change (a scene edit, a batch
  // of texels): backends that keep copies compare it.
  std::uint64_t generation = 0;
};

struct PassResult {
  std::uint64_t rays = 0;
  double seconds = 0.0;
};

class TraceBackend {
 public:
  virtual ~TraceBackend() = default;
  virtual std::string name() const = 0;
  // The name and the device it runs on ("vulkan on NVIDIA H100 ..."), for logs and reports.
  virtual std::string describe() const { return name(); }
  // The world, the lights or the materials changed (a scene edit; the objects are the same):
  // a backend that copied scene data (geometry, materials, lights) copies it again.
  virtual void scene_changed() {}

  // Direct irradiance per texel (one update's estimate).
  virtual PassResult direct(const PassInput& in, std::vector<glm::vec3>& out) = 0;
  // One update's estimate of every probe texel's radiance from the previous bounce.
  virtual PassResult gather_probes(const PassInput& in, const RadianceField& prev,
                                   std::vector<glm::vec3>& out) = 0;
  // One indirect bounce: irradiance per texel from hemisphere rays within the tracing range,
  // probes beyond it.
  virtual PassResult scatter(const PassInput& in, const RadianceField& prev,
                             const std::vector<glm::vec3>& probe_radiance,
                             std::vector<glm::vec3>& out) = 0;
};

}  // namespace irradcast
