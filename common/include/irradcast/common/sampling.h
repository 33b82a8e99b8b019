// Random numbers and the sampling warps every estimator shares.
#pragma once

#include <bit>
#include <cmath>
#include <cstdint>

#include <glm/glm.hpp>

namespace irradcast {

inline constexpr float kPi = 3.14159265358979323846f;
inline constexpr float kInvPi = 0.31830988618379067154f;

// 64-bit mix (splitmix64 finaliser): turns (seed, stream, index) into independent RNG states.
inline std::uint64_t mix64(std::uint64_t x) {
  x ^= x >> 30;
  x *= 0xbf58476d1ce4e5b9ull;
  x ^= x >> 27;
  x *= 0x94d049bb133111ebull;
  x ^= x >> 31;
  return x;
}

// PCG32 (O'Neill): small, fast, statistically solid; one per work item, seeded by its index so
// results do not depend on thread scheduling.
class Rng {
 public:
  explicit Rng(std::uint64_t seed = 0, std::uint64_t stream = 0) {
    inc_ = (mix64(stream) << 1u) | 1u;
    state_ = 0;
    next_u32();
    state_ += mix64(seed);
    next_u32();
  }
  std::uint32_t next_u32() {
    std::uint64_t old = state_;
    state_ = old * 6364136223846793005ull + inc_;
    auto xorshifted = static_cast<std::uint32_t>(((old >> 18u) ^ old) >> 27u);
    auto rot = static_cast<std::uint32_t>(old >> 59u);
    return (xorshifted >> rot) | (xorshifted << ((~rot + 1u) & 31u));
  }
  // Uniform in [0, 1).
  float next_float() { return static_cast<float>(next_u32() >> 8) * 0x1p-24f; }
  glm::vec2 next_2d() {
    float a = next_float();
    return {a, next_float()};
  }

 private:
  std::uint64_t state_ = 0;
  std::uint64_t inc_ = 1;
};

// Orthonormal basis around a unit normal (Duff et al. 2017).
struct Frame {
  glm::vec3 t, b, n;
  explicit Frame(glm::vec3 normal) : n(normal) {
    float sign = std::copysign(1.0f, n.z);
    float a = -1.0f / (sign + n.z);
    float bb = n.x * n.y * a;
    t = glm::vec3(1.0f + sign * n.x * n.x * a, sign * bb, -sign * n.x);
    b = glm::vec3(bb, sign + n.y * n.y * a, -n.y);
  }
  glm::vec3 to_world(glm::vec3 v) const { return v.x * t + v.y * b + v.z * n; }
};

// Cosine-weighted direction on the +z hemisphere; pdf = cos(theta) / pi.
inline glm::vec3 cosine_hemisphere(glm::vec2 u) {
  float r = std::sqrt(u.x);
  float phi = 2.0f * kPi * u.y;
  return {r * std::cos(phi), r * std::sin(phi), std::sqrt(glm::max(0.0f, 1.0f - u.x))};
}

// (cos 2 pi u, sin 2 pi u) for u in [0, 1] without a call into libm: the angle is taken to
// [-pi/4, pi/4] around the nearest quarter turn, where both are Taylor polynomials (to the 9th and
// 8th order: truncation error below 3e-8, under float rounding), then turned by that quarter.
// Inlined and branch-free; within 1e-6 of std::cos / std::sin (tests/test_sampling.cpp).
inline glm::vec2 cos_sin_2pi(float u) {
  const float t = 4.0f * u;
  // The nearest quarter turn, 0..4 (t >= 0, so truncation rounds down: no floor(), a library
  // call on the baseline x86-64 instruction set).
  const auto q = static_cast<std::uint32_t>(t + 0.5f);
  const float x = (t - static_cast<float>(q)) * (0.5f * kPi);  // in [-pi/4, pi/4]
  const float x2 = x * x;
  const float s =
      x * (1.0f + x2 * (-1.0f / 6.0f +
                        x2 * (1.0f / 120.0f + x2 * (-1.0f / 5040.0f + x2 * (1.0f / 362880.0f)))));
  const float c =
      1.0f + x2 * (-0.5f + x2 * (1.0f / 24.0f + x2 * (-1.0f / 720.0f + x2 * (1.0f / 40320.0f))));
  // Turned by q quarter turns: (c, s), (-s, c), (-c, -s), (s, -c); with bit masks, not branches
  // (q is random: a branch on it would be mispredicted half the time).
  const std::uint32_t cb = std::bit_cast<std::uint32_t>(c), sb = std::bit_cast<std::uint32_t>(s);
  const std::uint32_t swap = 0u - (q & 1u);
  const std::uint32_t ab = ((cb & ~swap) | (sb & swap)) ^ (((q + 1u) & 2u) << 30);
  const std::uint32_t bb = ((sb & ~swap) | (cb & swap)) ^ ((q & 2u) << 30);
  return {std::bit_cast<float>(ab), std::bit_cast<float>(bb)};
}

// cosine_hemisphere's distribution (the same map of u, to float rounding) with cos_sin_2pi for
// the azimuth: no trigonometric call per sample. The scatter passes draw their rays with it.
inline glm::vec3 cosine_hemisphere_fast(glm::vec2 u) {
  const glm::vec2 cs = std::sqrt(u.x) * cos_sin_2pi(u.y);
  return {cs.x, cs.y, std::sqrt(glm::max(0.0f, 1.0f - u.x))};
}

// Uniform barycentrics (b1, b2) on a triangle; the point is (1-b1-b2) p0 + b1 p1 + b2 p2.
inline glm::vec2 uniform_triangle(glm::vec2 u) {
  float s = std::sqrt(u.x);
  return {1.0f - s, u.y * s};
}

inline float luminance(glm::vec3 c) {
  return 0.2126f * c.x + 0.7152f * c.y + 0.0722f * c.z;
}

}  // namespace irradcast
