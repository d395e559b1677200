// Issue 21: what printer and delta users measure, on the library linear delta with a known truth:
// the firmwares' 7-point probe pattern (σ 10 µm), a printed part measured with a caliper, a file
// mixing σ over six orders of magnitude.
#include "printer_scenario.hpp"
#include "robocal/calib/bed_plane.hpp"
#include "robocal/calib/identification_json.hpp"
#include "robocal/calib/identification_summary.hpp"
#include "robocal/calib/measurement_advice.hpp"
#include "robocal/core/random_draws.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <iostream>
#include <map>
#include <tuple>

namespace {

using namespace robocal::calib;
using namespace robocal::test;

struct Printer : ::testing::Test {
  Mechanism model =
      load_robot_file(std::string(ROBOCAL_TESTDATA_DIR) + "/robots/linear_delta.yaml");
  MechanismPredictor pred{model};
  Eigen::VectorXd nominal = model.nominal_parameters();

  // Held-out bed heights on a grid inside the probed circle: |height predicted − true|, RMS.
  double heldout_height_rms(const Eigen::VectorXd& truth, const Eigen::VectorXd& params) {
    double sum = 0.0;
    int n = 0;
    for (double x = -0.06; x <= 0.061; x += 0.03)
      for (double y = -0.06; y <= 0.061; y += 0.03) {
        const Eigen::VectorXd r = commanded_readings(model, Eigen::Vector3d(x, y, 0.0));
        FramePrediction a;
        FramePrediction b;
        std::string why;
        EXPECT_TRUE(pred.predict(truth, r, -1, false, a, why));
        EXPECT_TRUE(pred.predict(params, r, -1, false, b, why));
        sum += std::pow(a.pose.translation().z() - b.pose.translation().z(), 2);
        ++n;
      }
    return std::sqrt(sum / n);
  }
  // Held-out 3-D nozzle error on the same grid `z` above the bed, RMS.
  double heldout_3d_rms(const Eigen::VectorXd& truth, const Eigen::VectorXd& params, double z) {
    double sum = 0.0;
    int n = 0;
    for (double x = -0.06; x <= 0.061; x += 0.03)
      for (double y = -0.06; y <= 0.061; y += 0.03) {
        const Eigen::VectorXd r = commanded_readings(model, Eigen::Vector3d(x, y, z));
        FramePrediction t;
        FramePrediction a;
        std::string why;
        EXPECT_TRUE(pred.predict(truth, r, -1, false, t, why));
        EXPECT_TRUE(pred.predict(params, r, -1, false, a, why));
        sum += (t.pose.translation() - a.pose.translation()).squaredNorm();
        ++n;
      }
    return std::sqrt(sum / n);
  }
};

TEST_F(Printer, SevenHeightsIdentifyTheIdentifiableSubsetWithAnExplainedGauge) {
  std::mt19937 rng(1);
  const Eigen::VectorXd truth = printer_truth(model, rng);
  PrinterData data;
  add_probe_heights(model, truth, probe_pattern(0.08), 10e-6, rng, data);
  // Every free parameter of the robot file (dozens): not refused.
  const auto all =
      identify(pred, nominal, data.measurements, solve_options_from_model(model, false));
  std::cout << summary_text(all);
  ASSERT_EQ(all.status, IdentificationStatus::kConverged) << all.message;
  EXPECT_TRUE(all.limited_data);
  EXPECT_LE(all.estimated.size(), 7u);
  EXPECT_GE(all.estimated.size(), 1u);
  EXPECT_NE(all.gauge.find("held at their nominal values"), std::string::npos) << all.gauge;
  // --free naming the 9 printer parameters: the rank analysis decides, nothing is refused.
  auto opt = solve_options_from_model(model, false);
  opt.candidates = printer_candidates(model);
  const auto nine = identify(pred, nominal, data.measurements, opt);
  std::cout << summary_text(nine);
  ASSERT_EQ(nine.status, IdentificationStatus::kConverged) << nine.message;
  EXPECT_LT(nine.estimated.size(), 9u);
  const double before = heldout_height_rms(truth, nominal);
  const double after = heldout_height_rms(truth, nine.estimate);
  std::cout << "held-out height RMS " << before << " -> " << after << "\n";
  EXPECT_LT(after, before / 3.0);
}

// Issue 53: with seven heights, plain identify (every free parameter of the robot file a
// candidate) chooses the estimated set by its predicted error, and against the truth it is not
// worse than the firmware-class set (Klipper basic: endstops, delta radius, tower angles, here
// the towers' positions) fitted by robocal on the same data. Bound: over 20 seeds
// (printer_identify_bench 20, firmware_baseline) the per-draw ratio of plain identify to Klipper's
// own routine was 1.000 in height (range 1.000-1.000) and 1.000 in aligned 3-D (0.996-1.018), the
// firmware-class set being chosen on every draw; 10 seeds here, mean squares within 5%.
TEST_F(Printer, SevenHeightsAutomaticChoiceIsNotWorseThanTheFirmwareClassSet) {
  auto firmware_opt = solve_options_from_model(model, false);
  firmware_opt.candidates.clear();
  for (const char* name : {"carriage_a.encoder_offset", "carriage_b.encoder_offset",
                           "carriage_c.encoder_offset", "tower_a.x", "tower_b.x", "tower_c.y"})
    firmware_opt.candidates.push_back(static_cast<std::size_t>(model.parameter_index(name)));
  double auto_h = 0.0, fw_h = 0.0, auto_3d = 0.0, fw_3d = 0.0;
  for (unsigned seed = 0; seed < 10; ++seed) {
    std::mt19937 rng(400 + seed);
    const Eigen::VectorXd truth = printer_truth(model, rng);
    PrinterData data;
    add_probe_heights(model, truth, probe_pattern(0.08), 10e-6, rng, data);
    const auto automatic =
        identify(pred, nominal, data.measurements, solve_options_from_model(model, false));
    const auto firmware = identify(pred, nominal, data.measurements, firmware_opt);
    ASSERT_EQ(automatic.status, IdentificationStatus::kConverged) << automatic.message;
    ASSERT_EQ(firmware.status, IdentificationStatus::kConverged) << firmware.message;
    // The choice and why: named, with its predicted error beside the next best's.
    ASSERT_TRUE(automatic.estimator.made) << automatic.gauge;
    EXPECT_FALSE(automatic.estimator.next_best.name.empty());
    EXPECT_LE(automatic.estimator.chosen.predicted_rms,
              automatic.estimator.next_best.predicted_rms);
    EXPECT_GT(automatic.estimator.chosen.predicted_height_rms, 0.0);
    EXPECT_NE(automatic.gauge.find(automatic.estimator.chosen.name), std::string::npos);
    if (seed == 0) {
      std::cout << summary_text(automatic);
      EXPECT_NE(summary_text(automatic).find("Estimated set (chosen by predicted error)"),
                std::string::npos);
      // identification.json: the chosen set, why, the next best, the bed's predicted flatness.
      const nlohmann::json j = to_json(automatic);
      ASSERT_TRUE(j.contains("estimator_choice")) << j.dump(2);
      const auto& c = j["estimator_choice"];
      EXPECT_EQ(c["chosen"]["name"], automatic.estimator.chosen.name);
      EXPECT_FALSE(c["reason"].get<std::string>().empty());
      ASSERT_TRUE(c.contains("next_best"));
      EXPECT_LE(c["chosen"]["predicted_rms_um"].get<double>(),
                c["next_best"]["predicted_rms_um"].get<double>());
      EXPECT_GT(j["predicted_bed_height_rms_um"].get<double>(), 0.0);
      EXPECT_GT(j["predicted_3d_rms_um"].get<double>(), 0.0);
      std::size_t estimated = 0;
      for (const auto& p : j["parameters"]) estimated += p["estimated"].get<bool>() ? 1 : 0;
      EXPECT_EQ(estimated, c["chosen"]["parameters"].size());
    }
    auto_h += std::pow(heldout_height_rms(truth, automatic.estimate), 2);
    fw_h += std::pow(heldout_height_rms(truth, firmware.estimate), 2);
    auto_3d += std::pow(heldout_3d_rms(truth, automatic.estimate, 0.0), 2);
    fw_3d += std::pow(heldout_3d_rms(truth, firmware.estimate, 0.0), 2);
  }
  std::cout << "seven heights, RMS over 10 seeds: height automatic " << 1e6 * std::sqrt(auto_h / 10)
            << " um, firmware-class " << 1e6 * std::sqrt(fw_h / 10) << " um; 3-D automatic "
            << 1e6 * std::sqrt(auto_3d / 10) << " um, firmware-class "
            << 1e6 * std::sqrt(fw_3d / 10) << " um\n";
  EXPECT_LE(auto_h, 1.05 * 1.05 * fw_h);
  EXPECT_LE(auto_3d, 1.05 * 1.05 * fw_3d);
}

// Which confounded printer parameters the 7 heights leave at nominal is chosen for the robot's
// tolerances: the held ones move the heights over the probed area least. Noise-free heights (the
// held-out error is then the held parameters' bias alone), 30 truths: the chosen gauge's
// held-out error below the rank analysis' pivot-order gauge (no tolerances given), same count.
TEST_F(Printer, SevenHeightsGaugeHoldsWhatMovesTheProbedAreaLeast) {
  double chosen_ms = 0.0;
  double pivot_ms = 0.0;
  for (unsigned seed = 0; seed < 30; ++seed) {
    std::mt19937 rng(300 + seed);
    const Eigen::VectorXd truth = printer_truth(model, rng);
    PrinterData data;
    add_probe_heights(model, truth, probe_pattern(0.08), 0.0, rng, data);
    for (auto& pose : data.measurements.poses)
      for (auto& o : pose.observations) std::get<ProbeHeightObservation>(o).sigma = 10e-6;
    auto opt = solve_options_from_model(model, false);
    opt.candidates = printer_candidates(model);
    opt.choose_estimator = false;  // the gauge alone (the rank-sized set), not the smaller sets
    const auto chosen = identify(pred, nominal, data.measurements, opt);
    opt.gauge_sigma.clear();
    const auto pivot = identify(pred, nominal, data.measurements, opt);
    ASSERT_EQ(chosen.status, IdentificationStatus::kConverged) << chosen.message;
    ASSERT_EQ(pivot.status, IdentificationStatus::kConverged) << pivot.message;
    EXPECT_EQ(chosen.estimated.size(), pivot.estimated.size());
    if (seed == 0) {
      std::cout << chosen.gauge << "\n";
      EXPECT_NE(chosen.gauge.find("move the predictions over the measured area least"),
                std::string::npos)
          << chosen.gauge;
      EXPECT_EQ(pivot.gauge.find("measured area least"), std::string::npos) << pivot.gauge;
    }
    chosen_ms += std::pow(heldout_height_rms(truth, chosen.estimate), 2);
    pivot_ms += std::pow(heldout_height_rms(truth, pivot.estimate), 2);
  }
  std::cout << "held-out height bias RMS: chosen gauge " << 1e6 * std::sqrt(chosen_ms / 30)
            << " um, pivot order " << 1e6 * std::sqrt(pivot_ms / 30) << " um\n";
  EXPECT_LT(chosen_ms, pivot_ms);
}

// Priors are information: with the robot file's tolerances on the nine printer parameters, the 7
// heights estimate all of them (MAP), the gauge says the priors supply the rest, and the held-out
// heights beat the nominal model.
TEST_F(Printer, SevenHeightsWithPriorsEstimateEveryPrinterParameter) {
  std::mt19937 rng(1);
  const Eigen::VectorXd truth = printer_truth(model, rng);
  PrinterData data;
  add_probe_heights(model, truth, probe_pattern(0.08), 10e-6, rng, data);
  auto opt = solve_options_from_model(model, true);
  opt.candidates = printer_candidates(model);
  const auto res = identify(pred, nominal, data.measurements, opt);
  std::cout << summary_text(res);
  ASSERT_EQ(res.status, IdentificationStatus::kConverged) << res.message;
  EXPECT_EQ(res.estimated.size(), 9u);
  EXPECT_TRUE(res.limited_data);
  EXPECT_NE(res.gauge.find("priors"), std::string::npos) << res.gauge;
  EXPECT_LT(heldout_height_rms(truth, res.estimate), heldout_height_rms(truth, nominal) / 3.0);
}

TEST_F(Printer, HeightsPlusPrintedPartDistancesIdentifyTheNinePrinterParameters) {
  std::mt19937 rng(2);
  const Eigen::VectorXd truth = printer_truth(model, rng);
  PrinterData data;
  add_probe_heights(model, truth, probe_pattern(0.08), 10e-6, rng, data);
  add_printed_distances(model, truth, printed_points(), printed_pairs(), 10e-6, rng, data);
  auto opt = solve_options_from_model(model, false);
  opt.candidates = printer_candidates(model);
  const auto res = identify(pred, nominal, data.measurements, opt);
  std::cout << summary_text(res);
  ASSERT_EQ(res.status, IdentificationStatus::kConverged) << res.message;
  // Poses observed only through a distance are accepted and used.
  EXPECT_TRUE(res.excluded.empty());
  EXPECT_EQ(res.equations, 7u + 12u);
  EXPECT_EQ(res.estimated.size(), 9u);
  EXPECT_FALSE(res.limited_data);
  // Fit residuals per observation type, in metres: heights and distances, no position figure;
  // recomputed here from the estimate (|measured − predicted|).
  ASSERT_EQ(res.residuals.by_type.size(), 2u);
  EXPECT_EQ(res.residuals.by_type[0].type, "probe height");
  EXPECT_EQ(res.residuals.by_type[0].count, 7u);
  EXPECT_EQ(res.residuals.by_type[1].type, "distance");
  EXPECT_EQ(res.residuals.by_type[1].count, 12u);
  {
    std::map<std::string, Eigen::Vector3d> at;
    double h2 = 0.0;
    for (const auto& p : data.measurements.poses) {
      FramePrediction f;
      std::string why;
      ASSERT_TRUE(pred.predict(res.estimate, p.actuators, -1, false, f, why));
      at[p.id] = f.pose.translation();
      for (const auto& o : p.observations)
        h2 += std::pow(
            f.pose.translation().z() - std::get<ProbeHeightObservation>(o).measured_height, 2);
    }
    double d2 = 0.0;
    for (const auto& d : data.measurements.distances)
      d2 += std::pow((at[d.first] - at[d.second]).norm() - d.observation.measured_distance, 2);
    EXPECT_NEAR(res.residuals.by_type[0].rms, std::sqrt(h2 / 7.0), 1e-9);
    EXPECT_NEAR(res.residuals.by_type[1].rms, std::sqrt(d2 / 12.0), 1e-9);
  }
  const std::string summary = summary_text(res);
  EXPECT_NE(summary.find("probe height RMS"), std::string::npos) << summary;
  EXPECT_NE(summary.find("distance RMS"), std::string::npos) << summary;
  EXPECT_EQ(summary.find("Fit residuals: position"), std::string::npos) << summary;
  // The bed's flatness beside the 3-D figure: the predicted first-layer height error, the
  // vertical part of the predicted position error, in the summary and the JSON.
  EXPECT_NE(summary.find("bed height (first layer) RMS"), std::string::npos) << summary;
  EXPECT_GT(res.predicted.height_rms_overall, 0.0);
  EXPECT_LT(res.predicted.height_rms_overall, res.predicted.position_rms_overall);
  const nlohmann::json j = to_json(res);
  ASSERT_TRUE(j.contains("predicted_bed_height_rms_um")) << j.dump(2);
  EXPECT_NEAR(j["predicted_bed_height_rms_um"].get<double>(),
              1e6 * res.predicted.height_rms_overall, 1e-9);
  EXPECT_NEAR(j["predicted_3d_rms_um"].get<double>(), 1e6 * res.predicted.position_rms_overall,
              1e-9);
  EXPECT_GT(j["predicted_accuracy"]["height_rms_m"].get<double>(), 0.0);
  // Held-out 3-D error at the printed-part layer and on the bed, against the truth.
  double before = 0.0;
  double after = 0.0;
  int n = 0;
  for (double x = -0.06; x <= 0.061; x += 0.03)
    for (double y = -0.06; y <= 0.061; y += 0.03) {
      const Eigen::VectorXd r = commanded_readings(model, Eigen::Vector3d(x, y, 0.002));
      FramePrediction t, a, b;
      std::string why;
      ASSERT_TRUE(pred.predict(truth, r, -1, false, t, why));
      ASSERT_TRUE(pred.predict(nominal, r, -1, false, b, why));
      ASSERT_TRUE(pred.predict(res.estimate, r, -1, false, a, why));
      before += (t.pose.translation() - b.pose.translation()).squaredNorm();
      after += (t.pose.translation() - a.pose.translation()).squaredNorm();
      ++n;
    }
  std::cout << "held-out 3-D RMS " << std::sqrt(before / n) << " -> " << std::sqrt(after / n)
            << "\n";
  EXPECT_LT(std::sqrt(after / n), std::sqrt(before / n) / 5.0);
}

// A bed tilted by 2 and −1.5 mm/m: with the bed's slopes estimated beside the geometry (the
// printed part separates them from the endstops), the tilt is recovered within its σ and the
// printer's 3-D error is far below a fit that assumes a level bed; with heights alone the bed is
// held level and the endstops absorb the tilt, as a firmware's calibration does.
TEST_F(Printer, TiltedBedIsEstimatedWithTheGeometry) {
  std::mt19937 rng(3);
  const Eigen::VectorXd truth = printer_truth(model, rng);
  const double tx = 2e-3;
  const double ty = -1.5e-3;
  PrinterData data;
  add_probe_heights(model, truth, probe_pattern(0.08), 10e-6, rng, data, 0.0, tx, ty);
  add_printed_distances(model, truth, printed_points(), printed_pairs(), 10e-6, rng, data);
  auto opt = solve_options_from_model(model, false);
  opt.candidates = printer_candidates(model);

  const BedPlanePredictor bed(pred);
  const auto tilted =
      identify(bed, bed.initial_parameters(nominal), data.measurements, bed.solve_options(opt));
  std::cout << summary_text(tilted);
  ASSERT_EQ(tilted.status, IdentificationStatus::kConverged) << tilted.message;
  ASSERT_TRUE(tilted.uncertainty.ok);
  for (const auto& [name, truth_tilt, est] :
       {std::tuple{"bed.tilt_x", tx, bed.tilt_x(tilted.estimate)},
        std::tuple{"bed.tilt_y", ty, bed.tilt_y(tilted.estimate)}}) {
    const auto& names = tilted.uncertainty.names;
    const auto it = std::find(names.begin(), names.end(), name);
    ASSERT_NE(it, names.end()) << name << " not estimated";
    const double sigma = tilted.uncertainty.sigma(it - names.begin());
    EXPECT_LT(std::abs(est - truth_tilt), 4.0 * sigma) << name << " σ " << sigma;
    EXPECT_LT(sigma, 0.25 * std::abs(truth_tilt)) << name;  // the tilt is resolved
  }
  const auto level = identify(pred, nominal, data.measurements, opt);
  ASSERT_EQ(level.status, IdentificationStatus::kConverged) << level.message;
  const double with_bed = heldout_3d_rms(truth, tilted.estimate.head(nominal.size()), 0.002);
  const double assumed_level = heldout_3d_rms(truth, level.estimate, 0.002);
  std::cout << "held-out 3-D RMS: bed estimated " << with_bed << ", bed assumed level "
            << assumed_level << "\n";
  EXPECT_LT(with_bed, 0.5 * assumed_level);

  // Heights alone: the tilt is confounded with the endstops; the bed is held level.
  PrinterData heights;
  std::mt19937 rng2(4);
  add_probe_heights(model, truth, probe_pattern(0.08), 10e-6, rng2, heights, 0.0, tx, ty);
  const auto only =
      identify(bed, bed.initial_parameters(nominal), heights.measurements, bed.solve_options(opt));
  ASSERT_EQ(only.status, IdentificationStatus::kConverged) << only.message;
  for (std::size_t i : only.estimated) EXPECT_LT(i, static_cast<std::size_t>(nominal.size()));
}

// Seven heights leave two printer parameters held: the advice names further measurements, and
// where; simulated from the truth and added, they make all nine identifiable.
TEST_F(Printer, AdviceSaysWhatToMeasureNextAndWhereAndItWorks) {
  std::mt19937 rng(5);
  const Eigen::VectorXd truth = printer_truth(model, rng);
  PrinterData data;
  add_probe_heights(model, truth, probe_pattern(0.08), 10e-6, rng, data);
  auto opt = solve_options_from_model(model, false);
  opt.candidates = printer_candidates(model);
  const auto before = identify(pred, nominal, data.measurements, opt);
  ASSERT_EQ(before.status, IdentificationStatus::kConverged) << before.message;
  ASSERT_LT(before.estimated.size(), 9u);

  // Candidates: bed points (heights) and positions one layer up (distances on a printed part).
  std::vector<Eigen::VectorXd> bed;
  std::vector<Eigen::VectorXd> layer;
  for (double x = -0.09; x <= 0.091; x += 0.03)
    for (double y = -0.09; y <= 0.091; y += 0.03) {
      if (std::hypot(x, y) > 0.095) continue;
      bed.push_back(commanded_readings(model, Eigen::Vector3d(x, y, 0.0)));
      layer.push_back(commanded_readings(model, Eigen::Vector3d(x, y, 0.005)));
    }
  const auto advice =
      advise_measurements(pred, before.estimate, data.measurements, opt.candidates, bed, layer);
  std::cout << advice.text;
  // The data's rank (identify may estimate fewer, chosen by what they predict).
  EXPECT_EQ(advice.rank_before,
            before.estimator.made ? before.estimator.data_rank : before.estimated.size());
  EXPECT_EQ(advice.rank_reachable, 9u);
  EXPECT_EQ(advice.rank_after, 9u);
  ASSERT_FALSE(advice.suggestions.empty());
  EXPECT_NE(advice.text.find("measure next"), std::string::npos);

  // Take the advice on the true printer.
  PrinterData more = data;
  const MechanismPredictor truth_pred(model);
  std::normal_distribution<double> n01(0.0, 1.0);
  int k = 0;
  for (const auto& s : advice.suggestions) {
    auto true_position = [&](const Eigen::VectorXd& q) -> Eigen::Vector3d {
      FramePrediction f;
      std::string why;
      EXPECT_TRUE(truth_pred.predict(truth, q, -1, false, f, why));
      return f.pose.translation();
    };
    const std::string a = "advised" + std::to_string(k++);
    if (s.kind == "probe height") {
      ProbeHeightObservation h;
      h.sigma = 10e-6;
      h.measured_height = true_position(s.actuators).z() + 10e-6 * n01(rng);
      more.measurements.poses.push_back({a, s.actuators, {h}});
    } else {
      ASSERT_EQ(s.kind, "distance");
      const std::string b = "advised" + std::to_string(k++);
      more.measurements.poses.push_back({a, s.actuators, {}});
      more.measurements.poses.push_back({b, s.actuators_b, {}});
      DistanceMeasurement d;
      d.first = a;
      d.second = b;
      d.observation.sigma = 10e-6;
      d.observation.measured_distance =
          (true_position(s.actuators) - true_position(s.actuators_b)).norm() + 10e-6 * n01(rng);
      more.measurements.distances.push_back(d);
    }
  }
  const auto after = identify(pred, nominal, more.measurements, opt);
  std::cout << summary_text(after);
  ASSERT_EQ(after.status, IdentificationStatus::kConverged) << after.message;
  EXPECT_EQ(after.estimated.size(), 9u);
  EXPECT_FALSE(after.limited_data);
  const double e_before = heldout_3d_rms(truth, before.estimate, 0.002);
  const double e_after = heldout_3d_rms(truth, after.estimate, 0.002);
  std::cout << "held-out 3-D RMS: 7 heights " << e_before << ", with the advice " << e_after
            << "\n";
  EXPECT_LT(e_after, 0.5 * e_before);
}

// Probe-point design: seven points the advice designs from no data (I-optimal for the bed height
// over the printed square, for identify's estimator) against the firmwares' fixed 7-point pattern,
// same count, same truths and noise: the designed points predict held-out heights better. Over
// 100 draws (printer_identify_bench 100: 9.79 vs 10.43 µm, ratio 0.94) the margin is a few per
// cent, within the spread of a dozen draws, so the test takes 100 (about 2 s).
TEST_F(Printer, DesignedProbePointsBeatTheFixedPatternOnHeldOutHeights) {
  std::vector<Eigen::VectorXd> bed;
  for (double x = -0.09; x <= 0.0901; x += 0.015)
    for (double y = -0.09; y <= 0.0901; y += 0.015)
      if (std::hypot(x, y) <= 0.09) bed.push_back(commanded_readings(model, {x, y, 0.0}));
  AdviceOptions o;
  o.distances = false;
  o.redundancy = 0;
  o.max_suggestions = 7;
  for (double x = -0.06; x <= 0.0601; x += 0.01)
    for (double y = -0.06; y <= 0.0601; y += 0.01)
      o.working_area.push_back(commanded_readings(model, {x, y, 0.0}));
  for (const auto& prm : model.parameters) o.prior_sigma.push_back(prm.sigma);
  auto opt = solve_options_from_model(model, false);
  o.preference = opt.preference;
  opt.candidates = printer_candidates(model);
  // The design models identify's rank-sized gauge estimator, not the choice by predicted error
  //, which it does not weigh yet: with that choice on, the fixed pattern reached 9.41
  // µm and the designed points 9.57 µm over these 100 draws.
  opt.choose_estimator = false;
  const auto advice = advise_measurements(pred, nominal, {}, opt.candidates, bed, {}, o);
  ASSERT_EQ(advice.suggestions.size(), 7u);
  std::vector<Eigen::Vector2d> designed;
  for (const auto& s : advice.suggestions) {
    EXPECT_EQ(s.kind, "probe height");
    designed.emplace_back(s.position.x(), s.position.y());
  }
  double ms_fixed = 0.0;
  double ms_designed = 0.0;
  constexpr unsigned kDraws = 100;
  for (unsigned seed = 1; seed <= kDraws; ++seed) {
    for (int which = 0; which < 2; ++which) {
      std::mt19937 rng(seed);
      const Eigen::VectorXd truth = printer_truth(model, rng);
      PrinterData data;
      add_probe_heights(model, truth, which == 0 ? probe_pattern(0.08) : designed, 10e-6, rng,
                        data);
      const auto res = identify(pred, nominal, data.measurements, opt);
      ASSERT_EQ(res.status, IdentificationStatus::kConverged) << res.message;
      const double e = heldout_height_rms(truth, res.estimate);
      (which == 0 ? ms_fixed : ms_designed) += e * e;
    }
  }
  std::cout << "held-out height RMS: fixed pattern " << 1e6 * std::sqrt(ms_fixed / kDraws)
            << " um, designed " << 1e6 * std::sqrt(ms_designed / kDraws) << " um\n";
  EXPECT_LT(ms_designed, ms_fixed);
}

// σ spread over six orders of magnitude (0.1 µm .. 0.1 m) per pose, noise drawn with each pose's
// own σ: no genuine pose may be flagged. The old test (pooled robust scale of the raw whitened
// residuals, dof = rows) is run on the same residuals to show the symptom it had.
TEST_F(Printer, MixedSigmaOverSixOrdersGivesNoFalseOutlier) {
  std::mt19937 rng(4);
  const Eigen::VectorXd truth = printer_truth(model, rng);
  std::uniform_real_distribution<double> expo(-7.0, -1.0);
  std::normal_distribution<double> n01(0.0, 1.0);
  const auto qs = sample_actuators(pred, {nominal, truth}, 60, rng);
  Measurements meas;
  for (std::size_t k = 0; k < qs.size(); ++k) {
    FramePrediction fp;
    std::string why;
    ASSERT_TRUE(pred.predict(truth, qs[k], -1, false, fp, why));
    const double sigma = std::pow(10.0, expo(rng));
    const Eigen::Vector3d p = fp.pose.translation() + sigma * robocal::core::draw_vector3(n01, rng);
    PoseMeasurement m;
    m.id = fmt::format("m{}", k);
    m.actuators = qs[k];
    m.observations.emplace_back(PointObservation::with_sigma(p, sigma));
    meas.poses.push_back(std::move(m));
  }
  auto opt = solve_options_from_model(model, false);
  opt.candidates = printer_candidates(model);
  const auto res = identify(pred, nominal, meas, opt);
  ASSERT_EQ(res.status, IdentificationStatus::kConverged) << res.message;
  for (const auto& p : res.residuals.poses) EXPECT_FALSE(p.outlier) << p.id << " " << p.chi_square;
  EXPECT_EQ(res.residuals.outliers, 0u);
  // The noise was stated right: its estimate is within its own interval of 1.
  ASSERT_FALSE(res.noise.groups.empty());
  const auto& g = res.noise.groups[0];
  EXPECT_EQ(g.type, "point");
  EXPECT_LT(g.scale_low, 1.0);
  EXPECT_GT(g.scale_high, 1.0);
}

// A genuine outlier among mixed σ is still found (the test is not blind).
TEST_F(Printer, MixedSigmaStillFindsAGrossError) {
  std::mt19937 rng(5);
  const Eigen::VectorXd truth = printer_truth(model, rng);
  std::uniform_real_distribution<double> expo(-7.0, -1.0);
  std::normal_distribution<double> n01(0.0, 1.0);
  const auto qs = sample_actuators(pred, {nominal, truth}, 60, rng);
  Measurements meas;
  for (std::size_t k = 0; k < qs.size(); ++k) {
    FramePrediction fp;
    std::string why;
    ASSERT_TRUE(pred.predict(truth, qs[k], -1, false, fp, why));
    const double sigma = k == 7 ? 20e-6 : std::pow(10.0, expo(rng));
    Eigen::Vector3d p = fp.pose.translation() + sigma * robocal::core::draw_vector3(n01, rng);
    if (k == 7) p.x() += 2e-3;  // 100 σ
    PoseMeasurement m;
    m.id = fmt::format("m{}", k);
    m.actuators = qs[k];
    m.observations.emplace_back(PointObservation::with_sigma(p, sigma));
    meas.poses.push_back(std::move(m));
  }
  auto opt = solve_options_from_model(model, false);
  opt.candidates = printer_candidates(model);
  const auto res = identify(pred, nominal, meas, opt);
  ASSERT_EQ(res.status, IdentificationStatus::kConverged) << res.message;
  EXPECT_EQ(res.residuals.outliers, 1u);
  EXPECT_TRUE(res.residuals.poses[7].outlier);
}

}  // namespace
