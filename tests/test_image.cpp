#include <gtest/gtest.h>

#include <filesystem>

#include "irradcast/common/camera.h"
#include "irradcast/common/error.h"
#include "irradcast/common/image.h"
#include "irradcast/common/tonemap.h"

namespace irradcast::test_image {

namespace fs = std::filesystem;

TEST(Image, ExrRoundTripIsLossless) {
  ImageRGB img(7, 5);
  for (std::size_t i = 0; i < img.pixels.size(); ++i)
    img.pixels[i] = glm::vec3(0.1f * i, 1e-3f * i * i, 100.0f + i);
  fs::path p = fs::temp_directory_path() / "irradcast_test_roundtrip.exr";
  write_exr(p.string(), img);
  ImageRGB back = read_exr(p.string());
  ASSERT_EQ(back.width, 7);
  ASSERT_EQ(back.height, 5);
  EXPECT_EQ(back.pixels, img.pixels);
  fs::remove(p);
}

TEST(Image, ReadingAMissingOrBrokenExrNamesTheFile) {
  fs::path p = fs::temp_directory_path() / "irradcast_test_broken.exr";
  {
    FILE* f = std::fopen(p.string().c_str(), "wb");
    std::fputs("not an exr", f);
    std::fclose(f);
  }
  try {
    read_exr(p.string());
    FAIL() << "no error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find(p.string()), std::string::npos);
  }
  EXPECT_THROW(read_exr("/nonexistent/x.exr"), Error);
  fs::remove(p);
}

TEST(Image, CompareComputesRmseRelativeMseAndMeanRatio) {
  ImageRGB a(2, 1, glm::vec3(1.0f)), b(2, 1, glm::vec3(1.0f));
  b.pixels[1] = glm::vec3(3.0f);
  ImageError e = compare(b, a);
  EXPECT_NEAR(e.rmse, std::sqrt(2.0), 1e-9);  // half the values differ by 2
  EXPECT_NEAR(e.rel_mse, 0.5 * 4.0 / 1.01, 1e-9);
  EXPECT_NEAR(e.mean_ratio, 2.0, 1e-9);                   // (1 + 3) / (1 + 1)
  EXPECT_EQ(compare(a, ImageRGB(2, 1)).mean_ratio, 0.0);  // a black reference
  EXPECT_THROW(compare(a, ImageRGB(1, 1)), Error);
}

TEST(ToneMap, ReinhardMapsLuminanceToLOverOnePlusL) {
  ToneMapOptions o;
  o.auto_exposure = false;
  o.exposure_ev = 0.0f;
  ImageRGB img(3, 1);
  img.pixels = {glm::vec3(1.0f), glm::vec3(0.0f), glm::vec3(1000.0f)};
  auto px = tonemap_srgb8(img, o);
  // L = 1 -> 0.5 linear -> sRGB 188.
  EXPECT_EQ(px[0], 188);
  EXPECT_EQ(px[3], 0);
  EXPECT_EQ(px[6], 255);  // 1000/1001 -> 254.9
  o.exposure_ev = -1.0f;  // L = 0.5 -> 1/3
  auto dark = tonemap_srgb8(img, o);
  EXPECT_EQ(dark[0], 156);
}

TEST(ToneMap, AutoExposureMapsTheLogAverageToTheKey) {
  ImageRGB img(2, 2, glm::vec3(4.0f));
  ToneMapOptions o;
  EXPECT_NEAR(exposure_scale(img, o), 0.18f / 4.0f, 1e-4f);
  EXPECT_THROW(parse_tone_operator("filmic"), Error);
  EXPECT_EQ(parse_tone_operator("aces"), ToneOperator::Aces);
}

TEST(Camera, SpecOverridesAndRejectsBadInput) {
  CameraPose base;
  CameraPose p = parse_camera("eye=0,1,2:target=0,1,0:fov=90", base);
  EXPECT_EQ(p.eye, glm::vec3(0, 1, 2));
  EXPECT_NEAR(p.forward.z, -1.0f, 1e-6f);
  EXPECT_NEAR(p.yfov, glm::radians(90.0f), 1e-6f);
  EXPECT_THROW(parse_camera("eye=0,1", base), Error);
  EXPECT_THROW(parse_camera("eye=0,1,x", base), Error);
  EXPECT_THROW(parse_camera("fov=200", base), Error);
  EXPECT_THROW(parse_camera("zoom=2", base), Error);
  EXPECT_THROW(parse_camera("eye=0,0,0:target=0,0,0", base), Error);
  // The centre ray looks straight ahead.
  Ray r = camera_ray(p, 101, 101, 50.5f, 50.5f);
  EXPECT_NEAR(r.direction.z, -1.0f, 1e-6f);
}

}  // namespace irradcast::test_image
