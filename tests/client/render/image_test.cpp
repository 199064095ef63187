#include "client/render/image.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

#include "common/core/error.h"

namespace vistream {
namespace {

TEST(PngImage, RoundTripsEveryPixelExactly) {
  ImageRgb8 img(17, 9);
  for (int y = 0; y < img.height; ++y)
    for (int x = 0; x < img.width; ++x)
      img.set(x, y, {uint8_t(x * 15), uint8_t(y * 28), uint8_t(x ^ y)});
  const auto path = std::filesystem::temp_directory_path() / "vistream_image_test.png";
  writePng(img, path);
  EXPECT_FALSE(std::filesystem::exists(path.string() + ".tmp"));
  const ImageRgb8 back = readPng(path);
  EXPECT_EQ(back.width, img.width);
  EXPECT_EQ(back.height, img.height);
  EXPECT_EQ(back.pixels, img.pixels);
  std::filesystem::remove(path);
}

TEST(PngImage, ReadingAFileThatIsNotAnImageNamesTheFile) {
  const auto path = std::filesystem::temp_directory_path() / "vistream_not_a_png.png";
  { std::ofstream(path) << "hello"; }
  try {
    readPng(path);
    FAIL() << "expected InputError";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find(path.string()), std::string::npos);
  }
  std::filesystem::remove(path);
}

}  // namespace
}  // namespace vistream
