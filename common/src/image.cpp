#include "irradcast/common/image.h"

#include <ImfChannelList.h>
#include <ImfFrameBuffer.h>
#include <ImfHeader.h>
#include <ImfInputFile.h>
#include <ImfOutputFile.h>
#include <stb_image_write.h>

#include <cmath>
#include <cstdint>
#include <exception>

#include "irradcast/common/error.h"

namespace irradcast {

void write_exr(const std::string& path, const ImageRGB& image) {
  try {
    Imf::Header header(image.width, image.height);
    header.compression() = Imf::ZIP_COMPRESSION;
    const char* names[3] = {"R", "G", "B"};
    for (const char* n : names) header.channels().insert(n, Imf::Channel(Imf::FLOAT));
    Imf::OutputFile file(path.c_str(), header);
    Imf::FrameBuffer fb;
    char* base = reinterpret_cast<char*>(const_cast<glm::vec3*>(image.pixels.data()));
    for (int c = 0; c < 3; ++c)
      fb.insert(names[c], Imf::Slice(Imf::FLOAT, base + c * sizeof(float), sizeof(glm::vec3),
                                     sizeof(glm::vec3) * image.width));
    file.setFrameBuffer(fb);
    file.writePixels(image.height);
  } catch (const std::exception& e) {
    throw Error(path + ": cannot write EXR: " + e.what());
  }
}

ImageRGB read_exr(const std::string& path, int max_width, int max_height) {
  try {
    Imf::InputFile file(path.c_str());
    Imath::Box2i dw = file.header().dataWindow();
    const std::int64_t w64 = std::int64_t{dw.max.x} - dw.min.x + 1,
                       h64 = std::int64_t{dw.max.y} - dw.min.y + 1;
    if (w64 <= 0 || h64 <= 0 || w64 > max_width || h64 > max_height)
      throw Error(path + ": EXR is " + std::to_string(w64) + "x" + std::to_string(h64) +
                  " pixels, outside 1x1 .. " + std::to_string(max_width) + "x" +
                  std::to_string(max_height));
    const int w = static_cast<int>(w64), h = static_cast<int>(h64);
    ImageRGB image(w, h);
    Imf::FrameBuffer fb;
    char* base =
        reinterpret_cast<char*>(image.pixels.data()) -
        (static_cast<std::ptrdiff_t>(dw.min.x) + static_cast<std::ptrdiff_t>(dw.min.y) * w) *
            static_cast<std::ptrdiff_t>(sizeof(glm::vec3));
    const char* names[3] = {"R", "G", "B"};
    for (int c = 0; c < 3; ++c)
      fb.insert(names[c], Imf::Slice(Imf::FLOAT, base + c * sizeof(float), sizeof(glm::vec3),
                                     sizeof(glm::vec3) * w, 1, 1, 0.0));
    file.setFrameBuffer(fb);
    file.readPixels(dw.min.y, dw.max.y);
    return image;
  } catch (const Error&) {
    throw;
  } catch (const std::exception& e) {
    throw Error(path + ": cannot read EXR: " + e.what());
  }
}

void write_png(const std::string& path, int width, int height,
               const std::vector<std::uint8_t>& rgb8) {
  if (rgb8.size() != static_cast<std::size_t>(width) * height * 3)
    throw Error(path + ": PNG data does not match the image size");
  if (!stbi_write_png(path.c_str(), width, height, 3, rgb8.data(), width * 3))
    throw Error(path + ": cannot write PNG");
}

ImageError compare(const ImageRGB& image, const ImageRGB& reference) {
  if (image.width != reference.width || image.height != reference.height)
    throw Error("cannot compare images of different sizes (" + std::to_string(image.width) + "x" +
                std::to_string(image.height) + " vs " + std::to_string(reference.width) + "x" +
                std::to_string(reference.height) + ")");
  double se = 0.0, rel = 0.0, sum_x = 0.0, sum_r = 0.0, sum_r2 = 0.0;
  for (std::size_t i = 0; i < image.pixels.size(); ++i) {
    for (int c = 0; c < 3; ++c) {
      double x = image.pixels[i][c], r = reference.pixels[i][c];
      double d2 = (x - r) * (x - r);
      se += d2;
      rel += d2 / (r * r + 0.01);
      sum_x += x;
      sum_r += r;
      sum_r2 += r * r;
    }
  }
  double n = 3.0 * static_cast<double>(std::max<std::size_t>(1, image.pixels.size()));
  return {std::sqrt(se / n), rel / n, sum_r > 0.0 ? sum_x / sum_r : 0.0,
          sum_r2 > 0.0 ? std::sqrt(se / sum_r2) : 0.0};
}

}  // namespace irradcast
