#include "rcal/io/csv_table.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>

#include "io_test_util.hpp"
#include "rcal/io/atomic_file.hpp"

namespace rcal::io {
namespace {

using testing::ErrorOf;

TEST(CsvTable, ReadsColumnsByName) {
  const CsvTable t = CsvTable::Parse("b, a ,c\n1,2,3\n4.5,-5e-3,+6\n", "mem.csv");
  EXPECT_EQ(t.rows(), 2);
  EXPECT_EQ(t.header(), (std::vector<std::string>{"b", "a", "c"}));
  EXPECT_EQ(t.Index("a"), 1);
  EXPECT_FALSE(t.Index("d").has_value());
  EXPECT_EQ(t.Column("a"), Eigen::Vector2d(2, -5e-3));
  EXPECT_EQ(t.At(1, "c"), 6.0);
  EXPECT_EQ(t.Text(1, "b"), "4.5");
  EXPECT_EQ(t.source(), "mem.csv");
}

TEST(CsvTable, CommentsBeforeTheHeaderAreKeptAndBetweenRowsSkipped) {
  const CsvTable t = CsvTable::Parse("# first\n\n#second\nx\n# between\n1\n\n2\n");
  EXPECT_EQ(t.comments(), (std::vector<std::string>{" first", "second"}));
  EXPECT_EQ(t.rows(), 2);
  EXPECT_EQ(t.Column("x"), Eigen::Vector2d(1, 2));
}

TEST(CsvTable, EmptyAndNanCellsReadAsNan) {
  const CsvTable t = CsvTable::Parse("a,b,c\n,nan,NaN\nNAN,1,\n");
  EXPECT_TRUE(std::isnan(t.At(0, "a")));
  EXPECT_TRUE(std::isnan(t.At(0, "b")));
  EXPECT_TRUE(std::isnan(t.At(0, "c")));
  EXPECT_TRUE(std::isnan(t.At(1, "a")));
  EXPECT_EQ(t.At(1, "b"), 1.0);
  EXPECT_TRUE(std::isnan(t.At(1, "c")));  // a trailing empty cell
  EXPECT_TRUE(std::isnan(t.Column("c")(0)));
}

TEST(CsvTable, SpellingsOfNanAndInfinityAreValues) {
  const CsvTable t = CsvTable::Parse("a,b,c\n-nan,inf,-inf\n");
  EXPECT_TRUE(std::isnan(t.At(0, "a")));
  EXPECT_EQ(t.At(0, "b"), std::numeric_limits<double>::infinity());
  EXPECT_EQ(t.At(0, "c"), -std::numeric_limits<double>::infinity());
}

TEST(CsvTable, ByteOrderMarkAndCrLfAreTolerated) {
  const CsvTable t = CsvTable::Parse("\xEF\xBB\xBFq1,x\r\n1,2\r\n", "excel.csv");
  EXPECT_EQ(t.header(), (std::vector<std::string>{"q1", "x"}));
  EXPECT_EQ(t.At(0, "x"), 2.0);
}

TEST(CsvTable, MissingColumnIsNamed) {
  const CsvTable t = CsvTable::Parse("a\n1\n", "poses.csv");
  EXPECT_EQ(ErrorOf([&] { t.Column("q7"); }), "missing column 'q7' in poses.csv");
  EXPECT_EQ(ErrorOf([&] { t.At(0, "x"); }), "missing column 'x' in poses.csv");
  EXPECT_EQ(ErrorOf([&] { t.Text(0, "set"); }), "missing column 'set' in poses.csv");
}

TEST(CsvTable, BadCellIsNamedWithRowAndColumn) {
  const CsvTable t = CsvTable::Parse("a,b\n1,2\n3,4x\n", "poses.csv");
  EXPECT_EQ(t.At(0, "b"), 2.0);
  EXPECT_EQ(ErrorOf([&] { t.At(1, "b"); }), "poses.csv: row 2 column 'b' is not a number: '4x'");
  EXPECT_EQ(ErrorOf([&] { t.Column("b"); }), "poses.csv: row 2 column 'b' is not a number: '4x'");
  EXPECT_EQ(t.Text(1, "b"), "4x");  // text columns stay readable
}

TEST(CsvTable, MalformedTablesAreErrors) {
  EXPECT_EQ(ErrorOf([] { CsvTable::Parse("a,b\n1,2,3\n", "f.csv"); }),
            "f.csv: line 2 has 3 cells, the header has 2");
  EXPECT_EQ(ErrorOf([] { CsvTable::Parse("a,b,a\n", "f.csv"); }),
            "f.csv: column 'a' appears twice");
  EXPECT_EQ(ErrorOf([] { CsvTable::Parse("# nothing\n", "f.csv"); }), "f.csv: no header row");
}

TEST(CsvTable, LoadNamesTheFile) {
  testing::ScratchDir dir;
  AtomicWriteFile(dir / "t.csv", "# c\nq1\n0.25\n");
  const CsvTable t = CsvTable::Load(dir / "t.csv");
  EXPECT_EQ(t.At(0, "q1"), 0.25);
  EXPECT_NE(t.source().find("t.csv"), std::string::npos);
  EXPECT_NE(ErrorOf([&] { CsvTable::Load(dir / "absent.csv"); }).find("absent.csv"),
            std::string::npos);
}

}  // namespace
}  // namespace rcal::io
