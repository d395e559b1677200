// Issue 21 through the command line, as a printer user would: a measurements file with 7 bed
// heights and 12 caliper distances between printed positions (no other observation there);
// a terminal summary with --json FILE; nothing identifiable -> exit 1; bad input -> exit 3 with
// file:line and the problem.
#include "cli/command_registry.hpp"
#include "printer_scenario.hpp"
#include "robocal/calib/measurements_file.hpp"
#include "run_robocal.hpp"
#include "scratch_dir.hpp"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <cctype>
#include <fstream>
#include <string>

namespace {

// True when `text` holds `prefix`, then at least one digit, then `suffix` (a file:line or
// "line N" in an error message). Written by hand: std::regex trips GCC 12's
// -Wmaybe-uninitialized inside libstdc++ under the sanitizer build.
bool names_number_after(const std::string& text, const std::string& prefix,
                        const std::string& suffix) {
  for (auto at = text.find(prefix); at != std::string::npos; at = text.find(prefix, at + 1)) {
    auto end = at + prefix.size();
    const auto digits_from = end;
    while (end < text.size() && std::isdigit(static_cast<unsigned char>(text[end])) != 0) ++end;
    if (end > digits_from && text.compare(end, suffix.size(), suffix) == 0) return true;
  }
  return false;
}

using namespace robocal::calib;
using robocal::test::read_text;
using robocal::test::run_robocal;

struct PrinterCli : robocal::test::ScratchDirTest {
  PrinterCli() : ScratchDirTest("robocal_printer_cli_") {}
  std::string robot = std::string(ROBOCAL_TESTDATA_DIR) + "/robots/linear_delta.yaml";

  // Heights (on a bed tilted by `tilt_x`, `tilt_y`) and, optionally, the printed part.
  std::string write_file(bool distances, double tilt_x = 0.0, double tilt_y = 0.0) {
    const Mechanism model = load_robot_file(robot);
    std::mt19937 rng(21);
    const Eigen::VectorXd truth = robocal::test::printer_truth(model, rng);
    robocal::test::PrinterData data;
    robocal::test::add_probe_heights(model, truth, robocal::test::probe_pattern(0.08), 10e-6, rng,
                                     data, 0.0, tilt_x, tilt_y);
    if (distances)
      robocal::test::add_printed_distances(model, truth, robocal::test::printed_points(),
                                           robocal::test::printed_pairs(), 10e-6, rng, data);
    MeasurementsFile f;
    f.robot = model.name;
    f.measurements = data.measurements;
    const std::string path = file(distances ? "heights_distances.yaml" : "heights.yaml");
    save_measurements_file(f, path);
    return path;
  }
  std::vector<std::string> printer_free() {
    return {"--free", "carriage_*.encoder_offset",
            "--free", "rod_*.length",
            "--free", "tower_a.x",
            "--free", "tower_b.x",
            "--free", "tower_c.y"};
  }
};

TEST_F(PrinterCli, HeightsAndDistanceOnlyPosesIdentifyWithASummary) {
  const std::string m = write_file(true);
  std::vector<std::string> args = {"identify", "--robot", robot,         "--measurements",
                                   m,          "--json",  file("r.json")};
  for (const auto& a : printer_free()) args.push_back(a);
  testing::internal::CaptureStdout();
  ASSERT_EQ(run_robocal(args), 0);
  const std::string out = testing::internal::GetCapturedStdout();
  EXPECT_NE(out.find("Identified 9 of the 9 free parameters"), std::string::npos) << out;
  EXPECT_NE(out.find("Noise (stated -> estimated"), std::string::npos) << out;
  // Fit residuals in the data's own terms: heights and distances, not a position figure.
  EXPECT_NE(out.find("probe height RMS"), std::string::npos) << out;
  EXPECT_NE(out.find("distance RMS"), std::string::npos) << out;
  EXPECT_EQ(out.find("Fit residuals: position"), std::string::npos) << out;
  const auto doc = nlohmann::json::parse(read_text(file("r.json")));
  EXPECT_EQ(doc["status"], "converged");
  EXPECT_EQ(doc["excluded_poses"].size(), 0u);
  EXPECT_TRUE(doc.contains("noise"));
  ASSERT_EQ(doc["residuals"]["by_type"].size(), 2u) << doc["residuals"].dump(2);
  EXPECT_EQ(doc["residuals"]["by_type"][0]["type"], "probe height");
  EXPECT_EQ(doc["residuals"]["by_type"][1]["type"], "distance");
  EXPECT_EQ(doc["residuals"]["by_type"][1]["count"], 12);
  // --quiet: nothing on the terminal.
  args.push_back("--quiet");
  testing::internal::CaptureStdout();
  ASSERT_EQ(run_robocal(args), 0);
  EXPECT_EQ(testing::internal::GetCapturedStdout(), "");
}

// --bed-tilt on a bed tilted by 3 and −2 mm/m: the JSON reports both slopes, estimated, within
// 4 σ of the truth.
TEST_F(PrinterCli, BedTiltIsEstimatedAndReported) {
  const std::string m = write_file(true, 3e-3, -2e-3);
  std::vector<std::string> args = {"identify", "--robot",      robot,        "--measurements", m,
                                   "--json",   file("r.json"), "--bed-tilt", "--quiet"};
  for (const auto& a : printer_free()) args.push_back(a);
  ASSERT_EQ(run_robocal(args), 0);
  const auto doc = nlohmann::json::parse(read_text(file("r.json")));
  ASSERT_TRUE(doc.contains("bed")) << doc.dump(2);
  for (const auto& [key, truth] : {std::pair{"tilt_x", 3.0}, std::pair{"tilt_y", -2.0}}) {
    const auto& t = doc["bed"][key];
    ASSERT_TRUE(t["estimated"].get<bool>()) << doc["bed"].dump();
    EXPECT_LT(std::abs(t["mm_per_m"].get<double>() - truth),
              4.0 * t["sigma_mm_per_m"].get<double>())
        << doc["bed"].dump();
  }
  // The calibrated robot file never carries the bed.
  args.push_back("--out-robot");
  args.push_back(file("cal.yaml"));
  ASSERT_EQ(run_robocal(args), 0);
  EXPECT_EQ(read_text(file("cal.yaml")).find("bed."), std::string::npos);
}

TEST_F(PrinterCli, SevenHeightsAreIdentifiedAsFarAsTheyGoAndNothingIdentifiableIsExit1) {
  const std::string m = write_file(false);
  std::vector<std::string> args = {"identify", "--robot", robot, "--measurements", m};
  for (const auto& a : printer_free()) args.push_back(a);
  testing::internal::CaptureStdout();
  ASSERT_EQ(run_robocal(args), 0);
  const std::string out = testing::internal::GetCapturedStdout();
  EXPECT_NE(out.find("Little data"), std::string::npos) << out;
  EXPECT_NE(out.find("held at their nominal values"), std::string::npos) << out;
  // What to measure next, and where: distances on a printed part separate the rest.
  EXPECT_NE(out.find("measure next"), std::string::npos) << out;
  EXPECT_NE(out.find("the distance between the positions at"), std::string::npos) << out;
  args.push_back("--json");
  args.push_back(file("advice.json"));
  args.push_back("--quiet");
  ASSERT_EQ(run_robocal(args), 0);
  const auto doc = nlohmann::json::parse(read_text(file("advice.json")));
  ASSERT_TRUE(doc.contains("advice"));
  EXPECT_EQ(doc["advice"]["identifiable_with_suggestions"].get<int>(), 9) << doc["advice"].dump(2);
  EXPECT_LT(doc["advice"]["identifiable_now"].get<int>(), 9);
  // --priors: the robot file's tolerances are information, all nine are estimated (MAP).
  std::vector<std::string> with_priors = {"identify", "--robot",  robot,    "--measurements",
                                          m,          "--priors", "--json", file("priors.json"),
                                          "--quiet"};
  for (const auto& a : printer_free()) with_priors.push_back(a);
  ASSERT_EQ(run_robocal(with_priors), 0);
  const auto pj = nlohmann::json::parse(read_text(file("priors.json")));
  int estimated = 0;
  for (const auto& p : pj["parameters"]) estimated += p["estimated"].get<bool>() ? 1 : 0;
  EXPECT_EQ(estimated, 9) << pj["gauge"];
  EXPECT_TRUE(pj["limited_data"].get<bool>());
  // Horizontal tool offsets do not move bed heights: nothing identifiable, exit 1, said so.
  testing::internal::CaptureStderr();
  EXPECT_EQ(run_robocal({"identify", "--robot", robot, "--measurements", m, "--free", "tool.z",
                         "--fix", "tool.z", "--free", "base.x", "--free", "base.y", "--quiet"}),
            1);
  const std::string err = testing::internal::GetCapturedStderr();
  EXPECT_NE(err.find("nothing is identifiable"), std::string::npos) << err;
  // Horizontal offsets need a horizontal measurement: the advice names 3-D points.
  EXPECT_NE(err.find("a 3-D point at"), std::string::npos) << err;
}

TEST_F(PrinterCli, BadInputNamesFileLineAndProblem) {
  const std::string good = read_text(write_file(true));
  auto expect_refused = [&](const std::string& text, const std::string& what) {
    std::ofstream(file("bad.yaml")) << text;
    testing::internal::CaptureStderr();
    EXPECT_EQ(run_robocal({"identify", "--robot", robot, "--measurements", file("bad.yaml")}), 3)
        << what;
    const std::string err = testing::internal::GetCapturedStderr();
    EXPECT_NE(err.find(what), std::string::npos) << err;
    return err;
  };
  // A distance naming a pose that does not exist.
  std::string t = good;
  t.replace(t.find("a: print0"), 9, "a: print99");
  const std::string e1 = expect_refused(t, "distance names pose 'print99'");
  EXPECT_TRUE(names_number_after(e1, "bad.yaml:", ":")) << e1;
  // A negative σ.
  t = good;
  const auto s = t.find("sigma: ");
  t.replace(s, 7, "sigma: -");
  const std::string e2 = expect_refused(t, "must be > 0");
  EXPECT_TRUE(names_number_after(e2, "bad.yaml:", ":")) << e2;
  // Heights in millimetres declared as metres.
  const MeasurementsFile f = load_measurements_file(file("heights_distances.yaml"));
  MeasurementsFile mm = f;
  for (auto& p : mm.measurements.poses)
    for (auto& o : p.observations)
      if (auto* h = std::get_if<ProbeHeightObservation>(&o))
        h->measured_height = 1e3 * (h->measured_height + 1e-3);  // bed 1 mm lower, in mm
  save_measurements_file(mm, file("mm.yaml"));
  testing::internal::CaptureStderr();
  EXPECT_EQ(run_robocal({"identify", "--robot", robot, "--measurements", file("mm.yaml")}), 3);
  const std::string e3 = testing::internal::GetCapturedStderr();
  EXPECT_NE(e3.find("implausible in metres"), std::string::npos) << e3;
  EXPECT_TRUE(names_number_after(e3, "line ", "")) << e3;
}

}  // namespace
