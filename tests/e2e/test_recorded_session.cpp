// The same answer on every machine: a small recorded session committed under
// testdata/sessions/delta_quick/ is measured and identified, and the results are compared with
// the values stored beside it (testdata/sessions/delta_quick.expected.json); the session's images
// are rendered again from its seed and compared by the SHA-256 of their pixels.
//
// The session is what `robocal simulate` writes with kSimulateArgs below (rotary Delta, quick
// 1280x960 images, few views, 14 poses, no sensor noise and a truth the model can follow, so that
// the PNG files stay small — 5 MB in all — and the pose route's fit is clean). Its stored values
// are regenerated only deliberately, after a change that is meant to move them (a new renderer,
// detector or solver), and the change reviewed in the diff of the JSON:
//
//     nice -n 19 bash scripts/build.sh release test_e2e_recorded_session
//     ROBOCAL_REGENERATE_RECORDED_SESSION=1 build/release/tests/e2e/test_e2e_recorded_session
//         --gtest_filter='*Regenerate*'     (one command line)
//
// which simulates the session again into testdata/sessions/delta_quick/ (the folder is replaced)
// and writes the JSON from its measure + identify results and its images' hashes.
//
// Tolerances (kTolerance*): the pipeline gives bitwise the same results for any thread count and
// from run to run; what remains between machines is glibc's libm, which picks FMA or non-FMA code
// for the CPU at run time and so differs in the last bit of ~0.07 % of sin/cos/exp/pow results.
// Run with those variants switched off (GLIBC_TUNABLES=glibc.cpu.hwcaps=-AVX2,-FMA,-AVX512F), the
// measure results stay within the bounds below (board positions moved by < 1e-10 m, intrinsics
// by < 1e-7 px), which sit about ten times above that and far below what a real change does (a
// corner-refinement or noise-model change moves board positions by 0.1-10 um and intrinsics by
// 1e-3 px or more). The identified parameters are compared by value when the same set is
// estimated; the rotary Delta's alike arms can make the analysis keep a mirror-image set on
// another libm (it does under the tunable above), and then the calibrated model is compared by
// what it predicts: its held-out error against the truth (validate, 500 configurations).
#include "session_test_support.hpp"
#include "sha256.hpp"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <span>
#include <string>
#include <vector>

namespace {

namespace fs = std::filesystem;
using nlohmann::json;
using robocal::test::copy_recorded;
using robocal::test::run_cli;

// How the committed session was recorded (and is recorded again by the hash test).
const std::vector<std::string> kSimulateArgs = {
    "simulate",          "--quick", "--seed",      "5", "--poses",      "14",
    "--intrinsic-views", "6",       "--rig-views", "3", "--read-noise", "0",
    "--idealised-truth"};

constexpr double kTolerancePx = 1e-6;          // intrinsics (focal, centre), RMS in px
constexpr double kToleranceDistortion = 1e-8;  // distortion coefficients (unitless)
constexpr double kTolerancePosition = 1e-9;    // board positions, baseline (m)
constexpr double kToleranceRotation = 1e-9;    // rotation-matrix entries (unitless)
constexpr double kToleranceParameter = 1e-7;   // identified parameters (m or rad)
constexpr double kToleranceRelative = 1e-6;    // residual RMS figures, relative

fs::path session_dir() {
  return fs::path(ROBOCAL_TESTDATA_DIR) / "sessions" / "delta_quick";
}
fs::path expected_file() {
  return fs::path(ROBOCAL_TESTDATA_DIR) / "sessions" / "delta_quick.expected.json";
}

fs::path scratch(const std::string& name) {
  const auto dir = fs::temp_directory_path() / ("robocal_recorded_session_" + name);
  fs::remove_all(dir);
  return dir;
}

json load_json(const fs::path& p) {
  std::ifstream in(p);
  if (!in) throw std::runtime_error("cannot read " + p.string());
  return json::parse(in);
}

// SHA-256 of an image's pixels (rows without padding, after its size and type), so that the hash
// does not depend on the PNG encoder's settings.
std::string pixel_hash(const fs::path& png) {
  const cv::Mat img = cv::imread(png.string(), cv::IMREAD_UNCHANGED);
  if (img.empty()) throw std::runtime_error("cannot read image " + png.string());
  robocal::test::Sha256 h;
  const std::string header = std::to_string(img.cols) + "x" + std::to_string(img.rows) + ":" +
                             std::to_string(img.type()) + ";";
  h.update(std::span(reinterpret_cast<const std::uint8_t*>(header.data()), header.size()));
  const auto row_bytes = img.cols * static_cast<int>(img.elemSize());
  for (int r = 0; r < img.rows; ++r)
    h.update(std::span(img.ptr<std::uint8_t>(r), static_cast<std::size_t>(row_bytes)));
  return h.hex();
}

// Every PNG of a session, by its path relative to the session.
json image_hashes(const fs::path& session) {
  std::vector<fs::path> files;
  for (const auto& e : fs::recursive_directory_iterator(session))
    if (e.is_regular_file() && e.path().extension() == ".png") files.push_back(e.path());
  std::sort(files.begin(), files.end());
  json out = json::object();
  for (const auto& f : files) out[fs::relative(f, session).generic_string()] = pixel_hash(f);
  return out;
}

// The key results of measure + identify, from a measured and identified session's results/.
json key_results(const fs::path& session) {
  const fs::path r = session / "results";
  const json measure = load_json(r / "measure.json");
  const json poses = load_json(r / "measured_poses.json");
  const json ident = load_json(r / "identification.json");
  json out;
  for (const auto& cam : measure["intrinsics"])
    out["intrinsics"][cam["camera"].get<std::string>()] = {{"params", cam["params"]},
                                                           {"rms_px", cam["rms_px"]}};
  out["rig"] = {{"baseline_m", measure["rig"]["baseline_m"]}, {"rms_px", measure["rig"]["rms_px"]}};
  out["poses_used"] = measure["poses"]["used"];
  for (const auto& p : poses["poses"])
    if (p.value("used", false))
      out["rig_T_target"][p["pose"].get<std::string>()] = p["rig_T_target_matrix"];
  const json& res = ident["result"]["residuals"];
  out["pose_route"] = {{"estimate", ident["estimate"]},
                       {"position_rms_m", res["position_rms_m"]},
                       {"orientation_rms_rad", res["orientation_rms_rad"]},
                       {"outliers", res["outliers"]}};
  json estimated = json::array();
  for (const auto& p : ident["result"]["parameters"])
    if (p["estimated"].get<bool>()) estimated.push_back(p["name"]);
  out["pose_route"]["estimated"] = estimated;
  const json& pix = ident["pixel_route"];
  json pix_estimated = json::array();
  for (const auto& p : pix["result"]["parameters"])
    if (p["estimated"].get<bool>()) pix_estimated.push_back(p["name"]);
  const json held_out = load_json(r / "validation.json")["calibrated"];
  out["held_out"] = {{"rms_m", held_out["rms_m"]},
                     {"max_m", held_out["max_m"]},
                     {"failures", held_out["failures"]}};
  out["pixel_route"] = {{"status", pix["result"]["status"]},
                        {"estimated", pix_estimated},
                        {"estimate", pix["estimate"]},
                        {"reprojection_rms_px", pix["reprojection_rms_px"]}};
  return out;
}

// measure + identify on a copy of the committed session (recorded data is never written to).
json measure_and_identify(const std::string& name) {
  const fs::path work = scratch(name);
  copy_recorded(session_dir(), work);
  if (run_cli({"measure", work.string()}) != 0) throw std::runtime_error("measure failed");
  if (run_cli({"identify", work.string()}) != 0) throw std::runtime_error("identify failed");
  if (run_cli({"validate", work.string(), "--held-out", "500"}) != 0)
    throw std::runtime_error("validate failed");
  return key_results(work);
}

void expect_near_relative(const json& got, const json& want, const std::string& what) {
  const double w = want.get<double>();
  EXPECT_NEAR(got.get<double>(), w, kToleranceRelative * std::abs(w)) << what;
}

void expect_estimate(const json& got, const json& want, const std::string& route) {
  ASSERT_EQ(got.size(), want.size()) << route << ": number of parameters";
  for (const auto& [name, value] : want.items()) {
    ASSERT_TRUE(got.contains(name)) << route << ": " << name << " missing";
    EXPECT_NEAR(got[name].get<double>(), value.get<double>(), kToleranceParameter)
        << route << ": " << name;
  }
}

TEST(RecordedSession, MeasureAndIdentifyGiveTheStoredValues) {
  ASSERT_TRUE(fs::exists(session_dir() / "session.yaml")) << session_dir();
  const json want = load_json(expected_file())["results"];
  const json got = measure_and_identify("check");

  for (const auto& [camera, w] : want["intrinsics"].items()) {
    const json& g = got["intrinsics"][camera];
    ASSERT_EQ(g["params"].size(), w["params"].size()) << camera;
    for (std::size_t i = 0; i < w["params"].size(); ++i)
      EXPECT_NEAR(g["params"][i].get<double>(), w["params"][i].get<double>(),
                  i < 4 ? kTolerancePx : kToleranceDistortion)
          << camera << " intrinsic " << i << " (fx fy cx cy, then distortion)";
    EXPECT_NEAR(g["rms_px"].get<double>(), w["rms_px"].get<double>(), kTolerancePx) << camera;
  }
  EXPECT_NEAR(got["rig"]["baseline_m"].get<double>(), want["rig"]["baseline_m"].get<double>(),
              kTolerancePosition);
  EXPECT_NEAR(got["rig"]["rms_px"].get<double>(), want["rig"]["rms_px"].get<double>(),
              kTolerancePx);

  EXPECT_EQ(got["poses_used"], want["poses_used"]);
  ASSERT_EQ(got["rig_T_target"].size(), want["rig_T_target"].size());
  for (const auto& [pose, w] : want["rig_T_target"].items()) {
    ASSERT_TRUE(got["rig_T_target"].contains(pose)) << pose << " not used";
    const json& g = got["rig_T_target"][pose];
    for (std::size_t row = 0; row < 3; ++row) {
      for (std::size_t col = 0; col < 4; ++col) {
        EXPECT_NEAR(g[row][col].get<double>(), w[row][col].get<double>(),
                    col == 3 ? kTolerancePosition : kToleranceRotation)
            << pose << " rig_T_target(" << row << "," << col << ")";
      }
    }
  }

  const json& gp = got["pose_route"];
  const json& wp = want["pose_route"];
  EXPECT_EQ(gp["outliers"], wp["outliers"]) << "pose route: another outlier decision";
  if (gp["estimated"] == wp["estimated"]) {
    expect_estimate(gp["estimate"], wp["estimate"], "pose route");
    expect_near_relative(gp["position_rms_m"], wp["position_rms_m"], "pose route position RMS");
    expect_near_relative(gp["orientation_rms_rad"], wp["orientation_rms_rad"],
                         "pose route orientation RMS");
  } else {
    // The rotary Delta's three arms are alike: parameters of one arm and their mirror images on
    // another move this session's measurements alike up to rounding, and which of them the
    // analysis keeps follows libm's last bits. The parameter values are then not comparable;
    // what the calibrated model predicts is, below.
    std::cout << "pose route: another set of " << gp["estimated"].size()
              << " parameters estimated (stored: " << wp["estimated"].size()
              << "); compared by the held-out predictions\n";
  }
  // The calibrated model against the truth at 500 held-out configurations: the answer a user
  // gets. libm's FMA and non-FMA variants (GLIBC_TUNABLES=glibc.cpu.hwcaps=-AVX2,-FMA,-AVX512F)
  // give 30.49 and 29.74 um RMS here (2.5 %), with mirror-image parameter sets; a discrete flip
  // that matters to a user (an outlier decision, a parameter held wrongly) moves such figures by
  // tens of percent.
  constexpr double kToleranceHeldOut = 0.10;  // relative
  const json& gh = got["held_out"];
  const json& wh = want["held_out"];
  EXPECT_NEAR(gh["rms_m"].get<double>(), wh["rms_m"].get<double>(),
              kToleranceHeldOut * wh["rms_m"].get<double>())
      << "held-out RMS against the truth";
  EXPECT_NEAR(gh["max_m"].get<double>(), wh["max_m"].get<double>(),
              kToleranceHeldOut * wh["max_m"].get<double>())
      << "held-out max against the truth";
  // A configuration at an assembly-mode boundary may be answered on one machine and not another.
  EXPECT_LE(std::abs(gh["failures"].get<int>() - wh["failures"].get<int>()), 1)
      << "held-out configurations the calibrated model cannot answer";

  const json& gx = got["pixel_route"];
  const json& wx = want["pixel_route"];
  EXPECT_EQ(gx["estimated"], wx["estimated"]) << "pixel route: another set of parameters estimated";
  EXPECT_EQ(gx["status"], wx["status"]) << "pixel route";
  // A solve stopped by its iteration cap (this session's camera-in-the-loop fit: 14 poses, 32
  // parameters, not converged in 200 iterations from either start) is where it stopped, not a
  // minimum: rounding differences grow over 200 steps, so only a converged solve is compared by
  // value.
  if (wx["status"] == "converged") {
    expect_estimate(gx["estimate"], wx["estimate"], "pixel route");
    expect_near_relative(gx["reprojection_rms_px"], wx["reprojection_rms_px"],
                         "pixel route reprojection RMS");
  }
}

// The renderer for one seed: simulating the session again gives the same pixels in every image
// (compared by hash; rendering is bitwise the same for any number of threads).
TEST(RecordedSession, SimulateRendersTheStoredImages) {
  const json want = load_json(expected_file())["image_sha256"];
  ASSERT_GE(want.size(), 10U);
  const fs::path out = scratch("render");
  std::vector<std::string> args = kSimulateArgs;
  args.insert(args.end(), {"--out", out.string()});
  ASSERT_EQ(run_cli(args), 0);
  const json got = image_hashes(out);
  ASSERT_EQ(got.size(), want.size());
  for (const auto& [file, hash] : want.items()) {
    ASSERT_TRUE(got.contains(file)) << file << " not rendered";
    EXPECT_EQ(got[file], hash) << file << ": other pixels for the same seed";
  }
}

// Not a check: with ROBOCAL_REGENERATE_RECORDED_SESSION=1 it records the session again and
// writes the stored values (see the header); otherwise it is skipped.
TEST(RecordedSession, Regenerate) {
  const char* flag = std::getenv("ROBOCAL_REGENERATE_RECORDED_SESSION");
  if (flag == nullptr || std::string(flag) != "1")
    GTEST_SKIP() << "set ROBOCAL_REGENERATE_RECORDED_SESSION=1 to regenerate";
  fs::remove_all(session_dir());
  std::vector<std::string> args = kSimulateArgs;
  args.insert(args.end(), {"--out", session_dir().string()});
  ASSERT_EQ(run_cli(args), 0);
  json doc;
  doc["session"] = "sessions/delta_quick";
  doc["recorded_with"] = kSimulateArgs;
  doc["image_sha256"] = image_hashes(session_dir());
  doc["results"] = measure_and_identify("regenerate");
  std::ofstream(expected_file()) << doc.dump(2) << "\n";
}

}  // namespace
