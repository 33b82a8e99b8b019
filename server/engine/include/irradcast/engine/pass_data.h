// The data the engine's passes share (docs/ARCHITECTURE.md): the scene's texels, the grid of
// radiance cells with one probe each, one pass's input and result, and what a scene edit
// changed. The engine owns it; the trace backends (trace_backend.h) and the indirect methods
// (indirect_method.h) read it.
#pragma once

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <vector>

#include <glm/glm.hpp>

#include "irradcast/common/atlas.h"
#include "irradcast/common/lightmap.h"
#include "irradcast/common/octahedral.h"
#include "irradcast/common/ray_scene.h"
#include "irradcast/common/world.h"
#include "irradcast/engine/engine_params.h"

namespace irradcast {

// Every valid lightmap texel of the scene in one flat array (the global G-buffer), ordered
// object by object.
struct SurfaceTexels {
  std::vector<glm::vec3> position;
  std::vector<glm::vec3> normal;        // shading normal
  std::vector<std::uint32_t> object;    // object index
  std::vector<std::uint32_t> texel;     // index in that object's lightmap
  std::vector<std::uint32_t> triangle;  // in that object
  std::size_t size() const { return position.size(); }
  // Texel i's geometric normal (its triangle's in `world`, the world these texels were built
  // from), turned to the side of its shading normal.
  glm::vec3 geo_normal(const World& world, std::size_t i) const {
    const glm::vec3 ng = world.objects[object[i]].geometric_normal(triangle[i]);
    return glm::dot(ng, normal[i]) < 0.0f ? -ng : ng;
  }
};

// Up to 8 probes a texel reads for distant light, with weights summing to 1; none (count 0)
// when it sees none of its neighbour probes, and then its scatter rays go on to their hit.
// A texel's probes: the usable ones of the 8 around it (the corners of the cell block below and
// above it) that it can see, in corner order, with their trilinear weights (summing to one).
// Named by the block's lower corner and 3 bits per probe rather than by 8 indices. The engine
// keeps only which corners a texel reads (one byte, Probes::corners); probe_weights() works the
// rest out where it is read.
struct ProbeWeights {
  std::int32_t base = 0;      // linear index of the lower corner's cell (may lie outside the grid)
  std::uint32_t corners = 0;  // probe k's corner in bits 3k..3k+2; the count in bits 24..31
  float weight[8];
  int count() const { return static_cast<int>(corners >> 24); }
  // Adds the probe at `corner` (bit 0: +x, 1: +y, 2: +z) with `w`.
  void add(int corner, float w) {
    const int k = count();
    corners = (corners & 0xffffffu) | (static_cast<std::uint32_t>(corner) << (3 * k)) |
              (static_cast<std::uint32_t>(k + 1) << 24);
    weight[k] = w;
  }
  // Probe k's index in a grid of `dims` cells.
  std::uint32_t probe(int k, glm::ivec3 dims) const {
    const std::uint32_t c = (corners >> (3 * k)) & 7u;
    return static_cast<std::uint32_t>(base + static_cast<std::int32_t>(c & 1u) +
                                      static_cast<std::int32_t>((c >> 1) & 1u) * dims.x +
                                      static_cast<std::int32_t>(c >> 2) * dims.x * dims.y);
  }
};

// The grid of radiance cells over the scene's bounds, one probe per cell: the engine's work
// units (EngineParams::dispatch) and, for the cells method, the probes that stand in for light
// from beyond the tracing range.
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
  // The centre of cell i (where its probe stands unless it was relocated).
  glm::vec3 centre(std::size_t i) const;
  // The cells over `bounds` (cubes of params.cell_size: metres, or that fraction of the largest
  // extent), every probe at its cell's centre and usable. Throws irradcast::Error for more than
  // 256 cells along the largest extent. A fraction capped in metres (the default) whose cap
  // binds gives cubes of the cap, grown in 1 % steps until 256 lie along the largest extent and
  // kMaxCappedCells in all (a default refuses no scene of finite size); where the cap does not
  // bind it is the fraction's grid, whatever its count.
  static ProbeGrid cells_of(const Bounds& bounds, const EngineParams& params);
  // The edge of cells_of's cubes (the same checks, no grid built).
  static float cell_edge(const Bounds& bounds, const EngineParams& params);
  static constexpr std::size_t kMaxCappedCells = std::size_t{1} << 16;
};

// The block of 8 cells whose probes surround p: its lower corner (may lie outside the grid) and
// p's trilinear weights for corner c (bit 0: +x, 1: +y, 2: +z), before any probe is left out.
struct ProbeBlock {
  glm::ivec3 base{0};
  glm::vec3 frac{0.0f};
  ProbeBlock(const ProbeGrid& grid, glm::vec3 p);
  float trilinear(int c) const;
};

// The probes of a texel at p that reads the corners in `mask` (bit c: corner c), with their
// weights: the trilinear ones, at least 1e-4 each, divided by their sum. A pure function of p,
// the grid and the mask: the same bits wherever it is worked out.
ProbeWeights probe_weights(const ProbeGrid& grid, glm::vec3 p, std::uint8_t mask);

// The previous bounce's outgoing radiance: albedo / pi * E_prev, read bilinearly at a hit.
struct RadianceField {
  const World* world = nullptr;
  const Atlas* atlas = nullptr;
  const std::vector<Lightmap>* irradiance = nullptr;  // E_prev per object, dilated
};

// Outgoing radiance albedo / pi * E_prev at a hit (bilinear in the hit object's lightmap).
glm::vec3 radiance_at(const RadianceField& f, const Hit& h);

// What one pass reads (the engine builds it per update).
struct PassInput {
  const World& world;
  const Atlas& atlas;
  const SurfaceTexels& texels;
  // Per texel, the corners of its cell block whose probes it reads (empty in unbiased mode).
  const std::vector<std::uint8_t>& probe_corners;
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
  // Whether texel i reads probes (a texel that sees none, or the unbiased mode, does not).
  bool reads_probes(std::uint32_t i) const {
    return !params.unbiased() && !probe_corners.empty() && probe_corners[i] != 0;
  }
  // Texel i's probes and weights (probe_weights() at its position).
  ProbeWeights probe_weights(std::uint32_t i) const {
    return irradcast::probe_weights(probes, texels.position[i], probe_corners[i]);
  }
};

// What one pass cost. `seconds` is wall time around the whole pass (uploads, submission, waits
// and read-back included); the rest is what a device backend measures (zero on the CPU).
struct PassResult {
  std::uint64_t rays = 0;
  double seconds = 0.0;
  double device_seconds = 0.0;    // the device's own time (timestamp queries) for its commands
  std::uint64_t bytes_up = 0;     // host to device: written in place or through staging
  std::uint64_t bytes_down = 0;   // device to host: results read back
  std::uint32_t submissions = 0;  // queue submissions, each waited for on a fence
  // Adds every field (totals over passes or updates).
  PassResult& operator+=(const PassResult& o) {
    rays += o.rays;
    seconds += o.seconds;
    device_seconds += o.device_seconds;
    bytes_up += o.bytes_up;
    bytes_down += o.bytes_down;
    submissions += o.submissions;
    return *this;
  }
};

// What one indirect bounce cost: the probe gather (zero for methods without probes) and the
// bounce itself.
struct BounceResult {
  PassResult probes;
  PassResult scatter;
};

struct ProbeStats {
  std::size_t probes = 0;
  std::size_t relocated = 0;  // moved out of or away from geometry
  std::size_t unusable = 0;   // inside geometry with no free spot in their cell
};

// The engine's probes: the grid, where each probe stands, and which probes each texel reads.
// The method that reads probes (cells_method.h) places and weighs them; for the others every
// probe stays at its cell's centre and `weights` is empty.
struct Probes {
  ProbeGrid grid;
  // Per texel, the corners whose probes it reads (empty when no probes are read): one byte
  // instead of its 40-byte ProbeWeights, which probe_weights() works out from it.
  std::vector<std::uint8_t> corners;
  ProbeStats stats;
};

// What a scene edit changed, for Engine::scene_changed.
struct SceneChange {
  bool geometry = false;  // objects moved, shown or hidden: texels, probes and visibility change
  // A material changed (albedo, emission, cut-out): the texels a cut-out hides or shows change.
  bool surfaces = false;
  // The sky changed (colour, strength or map): its light reaches every texel that sees out, so
  // every texel restarts, as after a changed light.
  bool sky = false;
  // World-space boxes where it happened: moved objects before and after, changed lights and
  // emitters. Texels near one (within the tracing range or a cell) are affected.
  std::vector<Bounds> regions;
  // Light positions whose direct light changed (a light moved, recoloured or dimmed, an emitter
  // changed): texels that see one are affected.
  std::vector<glm::vec3> light_points;
  // Emitters that did not change (centres): texels whose path to one crosses a region are in a
  // shadow that moved, so they are affected too.
  std::vector<glm::vec3> other_lights;
  // Distance from p to the nearest region (0 inside one; +inf without regions).
  float distance(glm::vec3 p) const;
  // Nothing of the static scene changed (an edit of dynamic nodes only): no texel is affected.
  bool empty() const {
    return !geometry && !surfaces && !sky && regions.empty() && light_points.empty();
  }
};

}  // namespace irradcast
