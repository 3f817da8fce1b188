// The real data the README's commands use, shipped in the repository so that they work in a plain
// clone: data/figaroh_ur10/ (FIGAROH's 23 UR10 poses) and config/robots/ur10.urdf. They are
// FIGAROH's files unmodified, byte for byte those of ../shared/data/figaroh_ur10 (checked when that
// folder is beside the repository; CI, RCAL_REQUIRE_ALL_TESTS, requires it), with their licence and
// a README naming the source and the columns.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>

#include "io_test_util.hpp"
#include "rcal/io/pose_dataset.hpp"

namespace rcal::io {
namespace {

namespace fs = std::filesystem;

std::string ReadBytes(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  EXPECT_TRUE(in) << p;
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

TEST(ShippedData, TheUr10IsTheSharedFoldersFilesUnmodified) {
  const fs::path shared = testing::SharedDir() / "data/figaroh_ur10";
  if (!fs::exists(shared)) {
#if RCAL_REQUIRE_ALL_TESTS
    GTEST_FAIL() << shared << " not found, and every test must run (RCAL_REQUIRE_ALL_TESTS)";
#else
    GTEST_SKIP() << shared << " not found (the project's shared folder beside the repository)";
#endif
  }
  const fs::path src = testing::SourceDir();
  EXPECT_TRUE(ReadBytes(src / "data/figaroh_ur10/calibration.csv") ==
              ReadBytes(shared / "calibration.csv"))
      << "data/figaroh_ur10/calibration.csv differs from " << shared / "calibration.csv";
  EXPECT_TRUE(ReadBytes(src / "config/robots/ur10.urdf") == ReadBytes(shared / "robot.urdf"))
      << "config/robots/ur10.urdf differs from " << shared / "robot.urdf";
}

TEST(ShippedData, TheUr10ComesWithItsLicenceSourceAndColumns) {
  const fs::path dir = testing::SourceDir() / "data/figaroh_ur10";
  EXPECT_NE(ReadBytes(dir / "LICENSE.Apache-2.0").find("Apache License"), std::string::npos);
  EXPECT_EQ(ReadBytes(dir / "LICENSE.Apache-2.0"),
            ReadBytes(testing::SourceDir() / "config/robots/LICENSE.Apache-2.0"));
  const std::string readme = ReadBytes(dir / "README.md");
  for (const char* s : {"thanhndv212/figaroh-plus", "c3b5172849b744984b7181fd9d517c83fb4242e1",
                        "Apache-2.0", "LICENSE.Apache-2.0", "config/robots/ur10.urdf", "x1,y1,z1",
                        "phix1,phiy1,phiz1", "shoulder_pan_joint"})
    EXPECT_NE(readme.find(s), std::string::npos) << s << " in " << dir / "README.md";
  // Only what is named: the data, its licence and its README.
  int files = 0;
  for (const auto& e : fs::directory_iterator(dir)) {
    ++files;
    const std::string name = e.path().filename().string();
    EXPECT_TRUE(name == "calibration.csv" || name == "LICENSE.Apache-2.0" || name == "README.md")
        << name;
  }
  EXPECT_EQ(files, 3);
  EXPECT_EQ(LoadFigarohUr10(dir / "calibration.csv").samples.size(), 23u);
}

}  // namespace
}  // namespace rcal::io
