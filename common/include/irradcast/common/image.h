// Linear RGB float images and their files: OpenEXR (float32, linear) and PNG (8-bit sRGB).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include <glm/glm.hpp>

namespace irradcast {

struct ImageRGB {
  int width = 0;
  int height = 0;
  std::vector<glm::vec3> pixels;  // row-major, row 0 at the top

  ImageRGB() = default;
  ImageRGB(int w, int h, glm::vec3 fill = glm::vec3(0.0f))
      : width(w), height(h), pixels(static_cast<std::size_t>(w) * h, fill) {}
  glm::vec3& at(int x, int y) { return pixels[static_cast<std::size_t>(y) * width + x]; }
  const glm::vec3& at(int x, int y) const {
    return pixels[static_cast<std::size_t>(y) * width + x];
  }
};

// Throws irradcast::Error naming the file on failure.
void write_exr(const std::string& path, const ImageRGB& image);
// Throws irradcast::Error naming `path` if the file is not a readable EXR or (checked before
// anything is allocated) its size is not positive or exceeds max_width x max_height.
ImageRGB read_exr(const std::string& path, int max_width = 1 << 30, int max_height = 1 << 30);
// rgb8: width * height * 3 bytes, sRGB encoded.
void write_png(const std::string& path, int width, int height,
               const std::vector<std::uint8_t>& rgb8);

// Error of `image` against `reference` (same size), over all pixels and channels:
// rmse = sqrt(mean((x - r)^2)); relative MSE = mean((x - r)^2 / (r^2 + 0.01)); mean ratio =
// mean(x) / mean(r) (0 for a black reference): a bias, where the other two mix bias and noise;
// RMS relative = sqrt(sum (x - r)^2 / sum r^2) (0 for a black reference): the error's energy
// against the reference's, which bright pixels dominate.
struct ImageError {
  double rmse = 0.0;
  double rel_mse = 0.0;
  double mean_ratio = 0.0;
  double rms_relative = 0.0;
};
ImageError compare(const ImageRGB& image, const ImageRGB& reference);

}  // namespace irradcast
