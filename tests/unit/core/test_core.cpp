// The foundation library: chi-square functions against closed forms, atomic writes, YAML errors
// with file:line, the pose-covariance reordering.
#include "robocal/core/chi_square.hpp"
#include "robocal/core/files.hpp"
#include "robocal/core/input_error.hpp"
#include "robocal/core/parallel.hpp"
#include "robocal/core/pose_covariance.hpp"
#include "robocal/core/text_lines.hpp"
#include "robocal/core/yaml.hpp"

#include <gtest/gtest.h>

#include <atomic>
#include <cmath>
#include <filesystem>
#include <stdexcept>

namespace rc = robocal::core;
namespace fs = std::filesystem;

TEST(ChiSquare, MatchesClosedFormsForTwoAndOneDegreesOfFreedom) {
  // dof 2: an exponential with mean 2, P(X > x) = exp(-x/2), also deep in the tail.
  for (double x : {0.01, 0.5, 2.0, 7.3, 40.0, 300.0}) {
    EXPECT_NEAR(rc::chi_square_cdf(x, 2), -std::expm1(-x / 2), 1e-14) << x;
    EXPECT_NEAR(rc::chi_square_survival(x, 2) / std::exp(-x / 2), 1.0, 1e-12) << x;
  }
  // dof 1: the square of a standard normal, P(X <= x) = erf(sqrt(x/2)).
  for (double x : {0.1, 1.0, 3.841458820694124, 9.0})
    EXPECT_NEAR(rc::chi_square_cdf(x, 1), std::erf(std::sqrt(x / 2)), 1e-13) << x;
  EXPECT_EQ(rc::chi_square_survival(0.0, 3), 1.0);
  EXPECT_EQ(rc::chi_square_survival(INFINITY, 3), 0.0);
}

TEST(ChiSquare, QuantilesInvertTheDistribution) {
  for (int dof : {1, 3, 6, 20})
    for (double p : {0.01, 0.5, 0.95, 0.999}) {
      EXPECT_NEAR(rc::chi_square_cdf(rc::chi_square_quantile(p, dof), dof), p, 1e-12);
      EXPECT_NEAR(rc::chi_square_survival(rc::chi_square_quantile_upper(1 - p, dof), dof), 1 - p,
                  1e-12);
    }
  EXPECT_THROW(rc::chi_square_quantile(1.5, 3), std::invalid_argument);
  EXPECT_THROW(rc::chi_square_quantile(0.5, 0), std::invalid_argument);
}

TEST(Files, AtomicWriteRefusesToOverwriteRecordedDataAndReplacesResults) {
  const fs::path dir = fs::temp_directory_path() / "robocal_unit_core_files";
  fs::remove_all(dir);
  const fs::path f = dir / "sub" / "a.txt";  // missing parent folders are created
  rc::write_file_atomic(f, "first", rc::Overwrite::kRefuse);
  EXPECT_EQ(rc::read_text_file(f), "first");
  EXPECT_THROW(rc::write_file_atomic(f, "second", rc::Overwrite::kRefuse), rc::InputError);
  EXPECT_EQ(rc::read_text_file(f), "first");
  rc::write_file_atomic(f, "third");
  EXPECT_EQ(rc::read_text_file(f), "third");
  EXPECT_FALSE(fs::exists(dir / "sub" / "a.txt.tmp"));
  try {
    rc::read_text_file(dir / "missing.txt");
    ADD_FAILURE() << "no error for a missing file";
  } catch (const rc::InputError& e) {
    EXPECT_EQ(std::string(e.what()),
              (dir / "missing.txt").string() + ": cannot open file (No such file or directory)");
  }
  fs::remove_all(dir);
}

TEST(TextLines, KeepTheLineNumbersOfLinesWithContentOnly) {
  const std::string text = "# header\n\n1 drop  # first\n   \t\r\n\nbody.length = 2 # x\r\n#\nlast";
  const auto lines = rc::content_lines(text);
  ASSERT_EQ(lines.size(), 3U);
  EXPECT_EQ(lines[0].number, 3);
  EXPECT_EQ(lines[0].text, "1 drop  ");
  EXPECT_EQ(lines[1].number, 6);
  EXPECT_EQ(lines[1].text, "body.length = 2 ");
  EXPECT_EQ(lines[2].number, 8);
  EXPECT_EQ(lines[2].text, "last");
  EXPECT_TRUE(rc::content_lines("").empty());
  EXPECT_THROW((void)rc::read_content_lines("/nonexistent/robocal/script.txt"), rc::InputError);
}

TEST(Yaml, ErrorsNameTheFileAndLine) {
  const rc::YamlContext ctx{"x.yaml"};
  const YAML::Node root = rc::load_yaml_text("a: 1\nb: abc\nc: {d: 2}\n", "x.yaml");
  EXPECT_EQ(ctx.required<int>(root, "a"), 1);
  EXPECT_EQ(ctx.optional<int>(root, "z", 7), 7);
  const auto message = [&](auto fn) {
    try {
      fn();
    } catch (const rc::InputError& e) {
      return std::string(e.what());
    }
    return std::string();
  };
  EXPECT_EQ(message([&] { ctx.to_double(root["b"], "b"); }),
            "x.yaml:2: 'b' must be a number (got 'abc')");
  EXPECT_EQ(message([&] { ctx.required<double>(root, "b"); }),
            "x.yaml:2: 'b' has a value of the wrong type");
  EXPECT_EQ(message([&] { ctx.require(root, "q"); }), "x.yaml:1: missing required key 'q'");
  EXPECT_EQ(message([&] { ctx.require_map(root, "a"); }), "x.yaml:1: 'a' must be a mapping");
  EXPECT_TRUE(ctx.require_map(root, "c")["d"]);
  EXPECT_NE(message([&] { rc::load_yaml_text("a: [1\n", "y.yaml"); }).find("y.yaml:"),
            std::string::npos);
}

TEST(PoseCovariance, ReordersBlocksBothWays) {
  Eigen::Matrix<double, 6, 6> rotation_first;
  for (int r = 0; r < 6; ++r)
    for (int c = 0; c < 6; ++c) rotation_first(r, c) = 10 * r + c;
  const rc::PoseCovariance p = rc::position_first(rotation_first);
  // position (rows 3..5 of the rotation-first matrix) comes first.
  EXPECT_EQ(p(0, 0), rotation_first(3, 3));
  EXPECT_EQ(p(0, 3), rotation_first(3, 0));
  EXPECT_EQ(p(3, 0), rotation_first(0, 3));
  EXPECT_EQ(p(5, 5), rotation_first(2, 2));
  EXPECT_EQ(rc::rotation_first(p), rotation_first);
}

TEST(Parallel, RunsEveryItemOnceAndRethrows) {
  std::vector<std::atomic<int>> count(100);
  rc::parallel_for(100, 3, [&](int i) { ++count[static_cast<std::size_t>(i)]; });
  for (const auto& c : count) EXPECT_EQ(c.load(), 1);
  EXPECT_THROW(rc::parallel_for(10, 2,
                                [](int i) {
                                  if (i == 7) throw std::runtime_error("item 7");
                                }),
               std::runtime_error);
}
