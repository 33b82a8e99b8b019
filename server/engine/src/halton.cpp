#include "halton.h"

#include <cmath>

#include "irradcast/common/error.h"

namespace irradcast {
namespace {
constexpr std::uint32_t kPrimes[] = {2,  3,  5,  7,   11,  13,  17,  19,  23,  29, 31,
                                     37, 41, 43, 47,  53,  59,  61,  67,  71,  73, 79,
                                     83, 89, 97, 101, 103, 107, 109, 113, 127, 131};
}  // namespace

float halton(std::uint64_t index, int dimension, float shift) {
  if (dimension < 0 || dimension >= static_cast<int>(sizeof(kPrimes) / sizeof(kPrimes[0])))
    throw Error("halton: dimension " + std::to_string(dimension) + " out of range 0..31");
  const std::uint64_t base = kPrimes[dimension];
  const double inv = 1.0 / static_cast<double>(base);
  double f = inv, r = 0.0;
  for (std::uint64_t i = index; i > 0; i /= base) {
    r += f * static_cast<double>(i % base);
    f *= inv;
  }
  r += static_cast<double>(shift);
  r -= std::floor(r);
  // Never 1.0 after rounding to float.
  const float v = static_cast<float>(r);
  return v < 1.0f ? v : 0x1.fffffep-1f;
}

}  // namespace irradcast
