#include "bench/las_export.h"

#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <vector>

#include "base/error.h"
#include "storage/coding.h"
#include "tests/support/temp_dir.h"

namespace octocosm {
namespace {

using testing_support::ReadFileBytes;
using testing_support::TempDir;

void WriteCsv(const std::filesystem::path& path, const std::vector<std::array<double, 3>>& points) {
  std::ofstream out(path);
  out.precision(17);
  out << "x,y,z\n";
  for (const auto& p : points) out << p[0] << "," << p[1] << "," << p[2] << "\n";
}

TEST(LasExport, HeaderAndPointsReadBackWithinHalfAScaleUnit) {
  TempDir dir("las-export");
  const std::vector<std::array<double, 3>> points = {
      {-3.5, 10.0, 2.25}, {96.5, 11.0, 2.0}, {0.123456789, 10.5, 40.0}, {50.0, 60.0, 3.0}};
  WriteCsv(dir.path() / "points.csv", points);
  const auto las = dir.path() / "points.las";
  const LasExportReport report = ExportLas((dir.path() / "points.csv").string(), las.string());
  EXPECT_EQ(report.points, points.size());

  const std::vector<std::uint8_t> bytes = ReadFileBytes(las);
  ASSERT_EQ(bytes.size(), 227 + 20 * points.size());
  EXPECT_EQ(std::memcmp(bytes.data(), "LASF", 4), 0);
  EXPECT_EQ(bytes[24], 1);
  EXPECT_EQ(bytes[25], 2);
  EXPECT_EQ(GetU16(bytes.data() + 94), 227);
  EXPECT_EQ(GetU32(bytes.data() + 96), 227u);
  EXPECT_EQ(GetU32(bytes.data() + 100), 0u);  // no variable-length records
  EXPECT_EQ(bytes[104], 0);
  EXPECT_EQ(GetU16(bytes.data() + 105), 20);
  EXPECT_EQ(GetU32(bytes.data() + 107), points.size());
  EXPECT_EQ(GetU32(bytes.data() + 111), points.size());

  // The largest extent (x: 100) spans the int32 range; the offset is the lower corner.
  const double scale = GetF64(bytes.data() + 131);
  EXPECT_DOUBLE_EQ(scale, 100.0 / 2147483646.0);
  EXPECT_EQ(scale, report.scale);
  EXPECT_EQ(GetF64(bytes.data() + 139), scale);
  EXPECT_EQ(GetF64(bytes.data() + 147), scale);
  const std::array<double, 3> lo = {-3.5, 10.0, 2.0};
  const std::array<double, 3> hi = {96.5, 60.0, 40.0};
  for (int a = 0; a < 3; ++a) {
    EXPECT_EQ(GetF64(bytes.data() + 155 + 8 * a), lo[a]) << "offset, axis " << a;
    EXPECT_EQ(GetF64(bytes.data() + 179 + 16 * a), hi[a]) << "max, axis " << a;
    EXPECT_EQ(GetF64(bytes.data() + 187 + 16 * a), lo[a]) << "min, axis " << a;
  }
  for (std::size_t i = 0; i < points.size(); ++i) {
    const std::uint8_t* record = bytes.data() + 227 + 20 * i;
    for (int a = 0; a < 3; ++a) {
      const auto units = static_cast<std::int32_t>(GetU32(record + 4 * a));
      EXPECT_GE(units, 0);
      EXPECT_NEAR(lo[a] + units * scale, points[i][a], 0.5 * scale * (1 + 1e-9)) << "point " << i << " axis " << a;
    }
    EXPECT_EQ(record[14], 0x09) << "return 1 of 1";
  }
}

TEST(LasExport, CoincidentPointsGetANonZeroScale) {
  TempDir dir("las-export");
  WriteCsv(dir.path() / "same.csv", {{1.0, 2.0, 3.0}, {1.0, 2.0, 3.0}});
  const auto las = dir.path() / "same.las";
  const LasExportReport report = ExportLas((dir.path() / "same.csv").string(), las.string());
  EXPECT_GT(report.scale, 0);
  const std::vector<std::uint8_t> bytes = ReadFileBytes(las);
  ASSERT_EQ(bytes.size(), 227u + 40u);
  for (int k = 0; k < 6; ++k) EXPECT_EQ(GetU32(bytes.data() + 227 + 20 * (k / 3) + 4 * (k % 3)), 0u);
}

TEST(LasExport, MissingSnapshotIsAnErrorNamingIt) {
  TempDir dir("las-export");
  const std::string missing = (dir.path() / "nothing.csv").string();
  try {
    ExportLas(missing, (dir.path() / "out.las").string());
    FAIL() << "expected an error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("nothing.csv"), std::string::npos) << e.what();
  }
  EXPECT_FALSE(std::filesystem::exists(dir.path() / "out.las"));
}

}  // namespace
}  // namespace octocosm
