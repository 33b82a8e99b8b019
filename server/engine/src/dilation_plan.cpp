// DilationPlan (dilation_plan.h): the rings of a lightmap's gap fill, found once by a search
// outward from the texels holding estimates, and their application.
#include "dilation_plan.h"

#include <string>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include "irradcast/common/error.h"

namespace irradcast {

namespace {

constexpr int kDx[8] = {-1, 0, 1, -1, 1, -1, 0, 1};
constexpr int kDy[8] = {-1, -1, -1, 0, 0, 1, 1, 1};

// Calls f(b, j) for each neighbour b (0..7, row by row, the centre left out) of texel i that lies
// in the width x height map, j its index.
template <class F>
void for_each_neighbour(std::uint32_t i, int width, int height, F f) {
  const auto w = static_cast<std::uint32_t>(width);
  const int x = static_cast<int>(i % w), y = static_cast<int>(i / w);
  for (int b = 0; b < 8; ++b) {
    const int nx = x + kDx[b], ny = y + kDy[b];
    if (nx < 0 || ny < 0 || nx >= width || ny >= height) continue;
    f(b, static_cast<std::size_t>(ny) * static_cast<std::size_t>(width) + nx);
  }
}

}  // namespace

DilationPlan::DilationPlan(int width, int height, const std::vector<TexelKind>& valid, int rings)
    : width_(std::max(0, width)), height_(std::max(0, height)) {
  const std::size_t size = static_cast<std::size_t>(width_) * static_cast<std::size_t>(height_);
  if (valid.size() != size)
    throw Error("dilate: buffer sizes do not match the " + std::to_string(width) + "x" +
                std::to_string(height) + " lightmap");
  if (size == 0 || rings == 0) return;
  std::vector<std::uint8_t> state(size, 0);  // 0 empty, 1 filled, 2 queued
  for (std::size_t i = 0; i < size; ++i) state[i] = holds_estimate(valid[i]) ? 1 : 0;
  std::vector<std::uint32_t> frontier, next;
  // Queues the empty neighbours of texel i (row by row), as dilate() always has.
  auto push_neighbours = [&](std::uint32_t i, std::vector<std::uint32_t>& out) {
    for_each_neighbour(i, width_, height_, [&](int, std::size_t j) {
      if (state[j] != 0) return;
      state[j] = 2;
      out.push_back(static_cast<std::uint32_t>(j));
    });
  };
  for (std::size_t i = 0; i < size; ++i)
    if (state[i] == 1) push_neighbours(static_cast<std::uint32_t>(i), frontier);
  for (int ring = 0; !frontier.empty() && (rings < 0 || ring < rings); ++ring) {
    const std::size_t first = target_.size();
    target_.insert(target_.end(), frontier.begin(), frontier.end());
    sources_.resize(target_.size());
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, frontier.size(), 4096),
                      [&](const tbb::blocked_range<std::size_t>& r) {
                        for (std::size_t k = r.begin(); k < r.end(); ++k) {
                          std::uint8_t mask = 0;
                          for_each_neighbour(frontier[k], width_, height_,
                                             [&](int bit, std::size_t j) {
                                               if (state[j] == 1)
                                                 mask |= static_cast<std::uint8_t>(1u << bit);
                                             });
                          sources_[first + k] = mask;
                        }
                      });
    ring_end_.push_back(static_cast<std::uint32_t>(target_.size()));
    for (std::uint32_t i : frontier) state[i] = 1;
    next.clear();
    for (std::uint32_t i : frontier) push_neighbours(i, next);
    frontier.swap(next);
  }
}

void DilationPlan::apply(std::vector<glm::vec3>& texels) const {
  const std::size_t size = static_cast<std::size_t>(width_) * static_cast<std::size_t>(height_);
  if (texels.size() != size)
    throw Error("dilate: " + std::to_string(texels.size()) + " values for a " +
                std::to_string(width_) + "x" + std::to_string(height_) + " lightmap");
  for (std::size_t r = 0; r < rings(); ++r) {
    // A ring's texels read only texels filled before it, so it fills in place.
    tbb::parallel_for(
        tbb::blocked_range<std::size_t>(ring_begin(r), ring_end(r), 4096),
        [&](const tbb::blocked_range<std::size_t>& range) {
          for (std::size_t k = range.begin(); k < range.end(); ++k) {
            const std::uint32_t i = target_[k];
            const int x = static_cast<int>(i % static_cast<std::uint32_t>(width_));
            const int y = static_cast<int>(i / static_cast<std::uint32_t>(width_));
            // Average of the sources as first + mean difference, so that equal neighbours
            // reproduce their value exactly.
            glm::vec3 first(0.0f), diff(0.0f);
            int count = 0;
            for (int b = 0; b < 8; ++b) {
              if ((sources_[k] >> b & 1u) == 0) continue;
              const glm::vec3 v =
                  texels[static_cast<std::size_t>(y + kDy[b]) * width_ + (x + kDx[b])];
              if (count++ == 0)
                first = v;
              else
                diff += v - first;
            }
            texels[i] = count > 1 ? first + diff / static_cast<float>(count) : first;
          }
        });
  }
}

}  // namespace irradcast
