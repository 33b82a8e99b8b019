// The Halton sequence (radical inverses in successive prime bases), the quasi-random source of
// instant radiosity (seeds 003 and 000): light paths drawn from it cover the lights and their
// directions more evenly than random ones, so fewer virtual point lights do.
#pragma once

#include <cstdint>

namespace irradcast {

// Radical inverse of `index` in the `dimension`-th prime base (0: base 2, 1: base 3, ...), with
// a Cranley-Patterson rotation by `shift` (modulo 1) so independent seeds give independent but
// still evenly spread sequences. Result in [0, 1). Dimensions up to 31.
float halton(std::uint64_t index, int dimension, float shift = 0.0f);

}  // namespace irradcast
