// Session folders end to end on rendered images (small, --quick): simulate -> measure ->
// identify -> validate against the truth; the pipeline runs with truth/ moved away; batch on two
// sessions gives the single runs' numbers; bad input (missing image, NaN readings, corrupted
// session.yaml, a robot file that does not match) is reported and recorded data is never changed.
#include "session_test_support.hpp"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <filesystem>
#include <fstream>
#include <string>

namespace {

namespace fs = std::filesystem;
using robocal::test::copy_recorded;
using robocal::test::load_json;
using robocal::test::read_file;
using robocal::test::recorded_fingerprint;
using robocal::test::run_cli;

fs::path scratch(const std::string& name) {
  const auto dir = fs::temp_directory_path() / ("robocal_e2e_session_" + name);
  fs::remove_all(dir);
  return dir;
}

void expect_same_numbers(const fs::path& a, const fs::path& b) {
  const auto ia = load_json(a / "results" / "identification.json");
  const auto ib = load_json(b / "results" / "identification.json");
  ASSERT_EQ(ia["estimate"].size(), ib["estimate"].size());
  for (const auto& [name, value] : ia["estimate"].items())
    EXPECT_EQ(value.get<double>(), ib["estimate"][name].get<double>()) << name;
  EXPECT_EQ(ia["result"]["residuals"]["position_rms_m"].get<double>(),
            ib["result"]["residuals"]["position_rms_m"].get<double>());
  const auto va = load_json(a / "results" / "validation.json");
  const auto vb = load_json(b / "results" / "validation.json");
  for (const char* key : {"nominal", "calibrated", "calibrated_registered"})
    EXPECT_EQ(va[key]["rms_m"].get<double>(), vb[key]["rms_m"].get<double>()) << key;
  EXPECT_EQ(va["held_out_poses"], vb["held_out_poses"]);
}

TEST(SessionEndToEnd, PipelineWithoutTruthThenValidateThenBatchEqualsSingleRuns) {
  const fs::path a = scratch("A"), b = scratch("B");
  const fs::path hidden = scratch("A_truth_hidden");
  ASSERT_EQ(run_cli({"simulate", "--quick", "--poses", "24", "--seed", "3", "--out", a.string()}),
            0);
  ASSERT_EQ(run_cli({"simulate", "--quick", "--poses", "24", "--seed", "4", "--out", b.string()}),
            0);
  ASSERT_TRUE(fs::exists(a / "truth" / "truth.json"));
  // simulate never writes into an existing session.
  EXPECT_EQ(run_cli({"simulate", "--quick", "--out", a.string()}), 3);

  // The pipeline's inputs contain no truth: move truth/ out of the session until validate.
  fs::rename(a / "truth", hidden);
  const auto before = recorded_fingerprint(a);
  ASSERT_EQ(run_cli({"measure", a.string()}), 0);
  ASSERT_EQ(run_cli({"identify", a.string()}), 0);
  testing::internal::CaptureStderr();
  EXPECT_EQ(run_cli({"validate", a.string()}), 3);
  const std::string message = testing::internal::GetCapturedStderr();
  EXPECT_NE(message.find("truth"), std::string::npos) << message;
  EXPECT_NE(message.find("missing"), std::string::npos) << message;
  EXPECT_EQ(recorded_fingerprint(a), before) << "recorded data changed";
  EXPECT_FALSE(fs::exists(a / "truth"));
  EXPECT_TRUE(fs::exists(a / "results" / "calibrated_robot.yaml"));
  EXPECT_TRUE(fs::exists(a / "results" / "pixel_observations.json"));

  fs::rename(hidden, a / "truth");
  ASSERT_EQ(run_cli({"validate", a.string()}), 0);
  const auto v = load_json(a / "results" / "validation.json");
  const double nominal = v["nominal"]["rms_m"];
  const double calibrated = v["calibrated"]["rms_m"];
  EXPECT_GE(v["held_out_poses"].get<int>(), 400);
  EXPECT_GT(nominal, 5e-4) << "the perturbed robot should be millimetres off nominally";
  EXPECT_LT(calibrated, 0.6e-3) << "calibrated error against truth";
  EXPECT_LT(calibrated, nominal / 10.0);
  for (const auto& cam : v["cameras"])
    EXPECT_LT(cam["projection_vs_truth_px"].get<double>(), 0.2) << cam["camera"];
  // Every recorded pose was measured and used.
  const auto m = load_json(a / "results" / "measure.json");
  EXPECT_EQ(m["poses"]["used"].get<int>(), 24);
  const auto pixels = load_json(a / "results" / "pixel_observations.json");
  ASSERT_EQ(pixels["poses"].size(), 24U);
  EXPECT_EQ(pixels["poses"][0]["observations"].size(), 2U);
  EXPECT_EQ(pixels["poses"][0]["observations"][0]["corners"][0].size(), 4U);

  // Single runs on B, then batch on fresh copies of both recorded sessions, two at a time.
  ASSERT_EQ(run_cli({"measure", b.string()}), 0);
  ASSERT_EQ(run_cli({"identify", b.string()}), 0);
  ASSERT_EQ(run_cli({"validate", b.string()}), 0);
  const fs::path a2 = scratch("A2"), b2 = scratch("B2");
  copy_recorded(a, a2);
  copy_recorded(b, b2);
  const auto before_a2 = recorded_fingerprint(a2);
  const fs::path summary = scratch("batch.json");
  ASSERT_EQ(run_cli({"batch", "--jobs", "2", a2.string(), b2.string(), "--json", summary.string()}),
            0);
  expect_same_numbers(a, a2);
  expect_same_numbers(b, b2);
  const auto s = load_json(summary);
  ASSERT_EQ(s["sessions"].size(), 2U);
  EXPECT_EQ(s["failed"].get<int>(), 0);
  EXPECT_EQ(s["sessions"][0]["calibrated_rms_m"].get<double>(), calibrated);
  // The batch summary counts the estimated parameters as identify does.
  int estimated = 0;
  const auto ident = load_json(a / "results" / "identification.json");
  for (const auto& p : ident["result"]["parameters"])
    estimated += p["estimated"].get<bool>() ? 1 : 0;
  EXPECT_GT(estimated, 10);
  EXPECT_EQ(s["sessions"][0]["estimated_parameters"].get<int>(), estimated);
  // Each session gets its report page, named in the summary.
  for (const auto& dir : {a2, b2}) EXPECT_TRUE(fs::exists(dir / "results" / "report.html")) << dir;
  EXPECT_EQ(s["sessions"][0]["report"].get<std::string>(),
            (a2 / "results" / "report.html").string());
  EXPECT_EQ(recorded_fingerprint(a2), before_a2) << "batch changed recorded data";
}

TEST(SessionEndToEnd, BadInputIsExplainedAndRecordedDataIsKept) {
  const fs::path c = scratch("C");
  ASSERT_EQ(run_cli({"simulate", "--quick", "--poses", "20", "--seed", "5", "--out", c.string()}),
            0);
  // A missing image and a pose with NaN readings: the damaged session as it was recorded.
  fs::remove(c / "poses" / "pose_003" / "cam1.png");
  {
    std::ofstream out(c / "poses" / "pose_005" / "pose.yaml");
    out << "actuators: [0.1, .nan, 0.2]\ntimestamp: 10.0\n";
  }
  const auto before = recorded_fingerprint(c);

  // A robot file that does not match the session: refused before anything is written.
  const std::string other = std::string(ROBOCAL_TESTDATA_DIR) + "/robots/linear_delta.yaml";
  testing::internal::CaptureStderr();
  EXPECT_EQ(run_cli({"measure", c.string(), "--robot", other}), 3);
  std::string err = testing::internal::GetCapturedStderr();
  EXPECT_NE(err.find("linear_delta.yaml"), std::string::npos) << err;
  EXPECT_NE(err.find("does not match"), std::string::npos) << err;
  EXPECT_FALSE(fs::exists(c / "results" / "measure.json"));

  ASSERT_EQ(run_cli({"measure", c.string()}), 0);
  const auto poses = load_json(c / "results" / "measured_poses.json")["poses"];
  ASSERT_EQ(poses.size(), 20U);
  int used = 0;
  for (const auto& p : poses) {
    const std::string name = p["pose"];
    if (name == "pose_003") {
      ASSERT_FALSE(p["problems"].empty());
      EXPECT_NE(p["problems"][0].get<std::string>().find("cam1"), std::string::npos);
    } else if (name == "pose_005") {
      EXPECT_FALSE(p["used"].get<bool>());
      const std::string reason = p["excluded"];
      EXPECT_NE(reason.find("pose.yaml"), std::string::npos) << reason;
      EXPECT_NE(reason.find("nan"), std::string::npos) << reason;
    } else {
      EXPECT_TRUE(p["used"].get<bool>()) << name << ": " << p.dump();
    }
    used += p["used"].get<bool>() ? 1 : 0;
  }
  EXPECT_GE(used, 18);
  ASSERT_EQ(run_cli({"identify", c.string()}), 0);
  testing::internal::CaptureStderr();
  EXPECT_EQ(run_cli({"identify", c.string(), "--robot", other}), 3);
  err = testing::internal::GetCapturedStderr();
  EXPECT_NE(err.find("does not match"), std::string::npos) << err;
  ASSERT_EQ(run_cli({"validate", c.string()}), 0);
  EXPECT_EQ(recorded_fingerprint(c), before) << "recorded data changed";

  // A corrupted session.yaml: file and line named, nothing processed.
  const fs::path d = scratch("D");
  copy_recorded(c, d);
  {
    std::string text = read_file(d / "session.yaml");
    const auto at = text.find("actuators: 3");
    ASSERT_NE(at, std::string::npos) << text;
    text.replace(at, 12, "actuators: [3");
    std::ofstream(d / "session.yaml", std::ios::trunc) << text;
  }
  const auto before_d = recorded_fingerprint(d);
  testing::internal::CaptureStderr();
  EXPECT_EQ(run_cli({"measure", d.string()}), 3);
  err = testing::internal::GetCapturedStderr();
  EXPECT_NE(err.find("session.yaml:"), std::string::npos) << err;
  EXPECT_FALSE(fs::exists(d / "results"));
  EXPECT_EQ(recorded_fingerprint(d), before_d);
}

}  // namespace
