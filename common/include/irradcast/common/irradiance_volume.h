// The irradiance volume that lights dynamic objects (docs/DYNAMIC.md "The probe volume"): a
// regular grid of probes over the static scene, each holding the irradiance arriving at it as
// spherical harmonics up to L2 (E(n) for any normal n, Ramamoorthi and Hanrahan's cosine-convolved
// form) and what it sees around it as DDGI-style distance moments (an octahedral map of the mean
// and mean square distance to the nearest surface), so that interpolating between probes does
// not carry light through walls. Probes inside geometry are moved out or switched off. The server
// computes it (engine/irradiance_volume_builder.h); viewers evaluate irradiance(p, n).
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <vector>

#include <glm/glm.hpp>

#include "irradcast/common/octahedral.h"

namespace irradcast {

// Real spherical harmonics of bands 0..2 (9 functions), in the usual order
// (Y00; Y1-1, Y10, Y11; Y2-2, Y2-1, Y20, Y21, Y22) of a unit direction.
inline constexpr int kShCoefficients = 9;
std::array<float, kShCoefficients> sh_basis(glm::vec3 d);
// Lambert's cosine kernel per band (pi, 2 pi / 3, pi / 4): the radiance coefficients L_lm times
// it are the irradiance coefficients E_lm, and E(n) = sum E_lm Y_lm(n).
inline constexpr float kShCosineBand[3] = {3.14159265f, 2.09439510f, 0.78539816f};
using ShIrradiance = std::array<glm::vec3, kShCoefficients>;
// E(n) of irradiance coefficients, clamped at 0 (an L2 fit rings below zero opposite a bright
// source).
glm::vec3 sh_irradiance(const ShIrradiance& e, glm::vec3 n);

struct VolumeGrid {
  glm::vec3 origin{0.0f};  // probe (0, 0, 0)
  float spacing = 1.0f;    // between neighbours, every axis
  glm::ivec3 counts{0};    // probes per axis

  std::size_t probe_count() const {
    return static_cast<std::size_t>(counts.x) * static_cast<std::size_t>(counts.y) *
           static_cast<std::size_t>(counts.z);
  }
  std::size_t index(glm::ivec3 c) const {
    return (static_cast<std::size_t>(c.z) * static_cast<std::size_t>(counts.y) +
            static_cast<std::size_t>(c.y)) *
               static_cast<std::size_t>(counts.x) +
           static_cast<std::size_t>(c.x);
  }
  glm::ivec3 cell_of(std::size_t index) const;
  glm::vec3 position(glm::ivec3 c) const { return origin + spacing * glm::vec3(c); }
  // The largest distance a probe's moments record: beyond it a surface counts as far.
  float max_distance() const { return 1.5f * spacing * 1.7320508f; }
};

struct IrradianceVolume {
  // Texels per side of a probe's octahedral distance map.
  static constexpr int kDepthSize = 16;
  static constexpr int kDepthTexels = kDepthSize * kDepthSize;

  VolumeGrid grid;
  // Per probe (VolumeGrid::index order):
  std::vector<glm::vec3> offsets;    // where it was moved, from its grid position
  std::vector<std::uint8_t> active;  // 0: switched off (inside geometry), never used
  // Irradiance coefficients of the light the probe sees reflected by the static surfaces (the
  // lightmaps' albedo / pi x E) and of the sky; `emitted`, of the light it sees straight from
  // emissive surfaces. They are kept apart because a viewer that can trace the static scene
  // draws the emitters' direct light itself, with shadow rays, as it does the punctual lights':
  // near an area light that light changes faster than any probe grid follows (dynamic_view.h).
  std::vector<ShIrradiance> sh;
  std::vector<ShIrradiance> emitted;  // all zero in a scene without emissive surfaces
  std::vector<glm::vec2> depth;       // kDepthTexels per probe: (mean, mean square) distance

  std::size_t probe_count() const { return grid.probe_count(); }
  glm::vec3 probe_position(std::size_t i) const {
    return grid.position(grid.cell_of(i)) + offsets[i];
  }
  // Sizes the per-probe arrays for `grid`: every probe active, at its grid point, dark, and
  // seeing nothing within max_distance.
  void reset(const VolumeGrid& g);
  // The moments a probe recorded towards direction d (bilinear in its octahedral map).
  glm::vec2 moments(std::size_t probe, glm::vec3 d) const;
  // The irradiance at p on a surface of normal n: the 8 probes around p, weighted trilinearly,
  // by how much each faces the surface, and by DDGI's Chebyshev visibility test on its distance
  // moments (a probe behind a wall from p gets almost no weight); switched-off probes get none.
  // p outside the grid takes the nearest probes. Zero without an active probe around p.
  // With `with_emitted` false, the emitters' direct light is left out (`sh` alone).
  glm::vec3 irradiance(glm::vec3 p, glm::vec3 n, bool with_emitted = true) const;
};

}  // namespace irradcast
