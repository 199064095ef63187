#include "common/core/mapped_file.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <string>

#include "tests/common/support/temp_dir.h"

namespace vistream {
namespace {

using ::testing::HasSubstr;
using testing::inputErrorOf;
using testing::TempDir;

TEST(MappedFile, MapsEveryByteOfTheFile) {
  TempDir dir;
  std::string bytes(100000, '\0');
  for (size_t i = 0; i < bytes.size(); ++i) bytes[i] = char((i * 131) & 0xff);
  const MappedFile file = MappedFile::open(dir.write("data.bin", bytes), "test file");
  ASSERT_EQ(file.size(), bytes.size());
  EXPECT_EQ(std::string(reinterpret_cast<const char*>(file.data()), file.size()), bytes);
}

TEST(MappedFile, AnEmptyFileMapsToAnEmptySpan) {
  TempDir dir;
  const MappedFile file = MappedFile::open(dir.write("empty", ""), "test file");
  EXPECT_EQ(file.size(), 0u);
  EXPECT_TRUE(file.bytes().empty());
}

TEST(MappedFile, AMissingFileIsRefusedNamingItAndItsRole) {
  TempDir dir;
  const std::string message =
      inputErrorOf([&] { (void)MappedFile::open(dir / "missing.db", "PVS database"); });
  EXPECT_THAT(message, HasSubstr("missing.db: cannot open PVS database"));
}

TEST(MappedFile, ADirectoryIsNotARegularFile) {
  TempDir dir;
  EXPECT_THAT(inputErrorOf([&] { (void)MappedFile::open(dir.path(), "bake journal"); }),
              HasSubstr("bake journal is not a regular file"));
}

TEST(MappedFile, AMovedMappingKeepsItsBytesAndLeavesTheSourceEmpty) {
  TempDir dir;
  MappedFile a = MappedFile::open(dir.write("f", "abc"), "test file");
  MappedFile b = std::move(a);
  EXPECT_EQ(a.size(), 0u);  // NOLINT(bugprone-use-after-move): the moved-from state is specified
  ASSERT_EQ(b.size(), 3u);
  EXPECT_EQ(b.data()[2], uint8_t('c'));
  b = MappedFile::open(dir.write("g", "xy"), "test file");
  EXPECT_EQ(b.size(), 2u);
}

}  // namespace
}  // namespace vistream
