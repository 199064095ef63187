#include "client/render/image.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

#include "common/core/error.h"
#include "tests/common/support/temp_dir.h"

namespace vistream {
namespace {

TEST(PngImage, RoundTripsEveryPixelExactly) {
  ImageRgb8 img(17, 9);
  for (int y = 0; y < img.height; ++y)
    for (int x = 0; x < img.width; ++x)
      img.set(x, y, {uint8_t(x * 15), uint8_t(y * 28), uint8_t(x ^ y)});
  const testing::TempDir dir;
  const auto path = dir / "image.png";
  writePng(img, path);
  EXPECT_EQ(dir.filenames(), std::vector<std::string>{"image.png"});
  const ImageRgb8 back = readPng(path);
  EXPECT_EQ(back.width, img.width);
  EXPECT_EQ(back.height, img.height);
  EXPECT_EQ(back.pixels, img.pixels);
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

// Half black, half white (luminance 0 and 255): two colours, and a
// standard deviation of half the range, 127.5.
TEST(ImageContrast, CountsDistinctColoursAndTheLuminanceSpread) {
  ImageRgb8 img(4, 2, {0, 0, 0});
  for (int x = 0; x < 4; ++x) img.set(x, 1, {255, 255, 255});
  const ImageContrast c = imageContrast(img);
  EXPECT_EQ(c.distinctColours, 2u);
  EXPECT_NEAR(c.luminanceStd, 127.5, 1e-6);
  const ImageContrast flat = imageContrast(ImageRgb8(5, 5, {10, 20, 30}));
  EXPECT_EQ(flat.distinctColours, 1u);
  EXPECT_NEAR(flat.luminanceStd, 0.0, 1e-9);
}

TEST(ContactSheet, TilesFramesInRowsWithGapsAndStacksSheets) {
  std::vector<ImageRgb8> tiles;
  for (uint8_t k = 0; k < 5; ++k) tiles.emplace_back(3, 2, glm::u8vec3(k * 50, 1, 2));
  const ImageRgb8 sheet = contactSheet(tiles, 4, 1, {9, 9, 9});
  EXPECT_EQ(sheet.width, 1 + 4 * (3 + 1));
  EXPECT_EQ(sheet.height, 1 + 2 * (2 + 1));
  EXPECT_EQ(sheet.at(0, 0), glm::u8vec3(9, 9, 9));            // the border
  EXPECT_EQ(sheet.at(1, 1), glm::u8vec3(0, 1, 2));            // tile 0
  EXPECT_EQ(sheet.at(1 + 3 * 4, 2), glm::u8vec3(150, 1, 2));  // tile 3, end of row 1
  EXPECT_EQ(sheet.at(1, 1 + 3), glm::u8vec3(200, 1, 2));      // tile 4 starts row 2
  EXPECT_EQ(sheet.at(5, 1 + 3), glm::u8vec3(9, 9, 9));        // nothing beside it
  const ImageRgb8 both = stackImages(sheet, ImageRgb8(2, 1, {7, 7, 7}), {9, 9, 9});
  EXPECT_EQ(both.width, sheet.width);
  EXPECT_EQ(both.height, sheet.height + 1);
  EXPECT_EQ(both.at(1, sheet.height), glm::u8vec3(7, 7, 7));
  EXPECT_EQ(both.at(2, sheet.height), glm::u8vec3(9, 9, 9));
  EXPECT_EQ(contactSheet({}, 4).width, 0);
}

}  // namespace
}  // namespace vistream
