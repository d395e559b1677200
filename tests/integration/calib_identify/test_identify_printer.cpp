// Issue 21: what printer and delta users measure, on the library linear delta with a known truth:
// the firmwares' 7-point probe pattern (σ 10 µm), a printed part measured with a caliper, a file
// mixing σ over six orders of magnitude.
#include "printer_scenario.hpp"
#include "robocal/calib/identification_summary.hpp"

#include <gtest/gtest.h>

namespace {

using namespace robocal::calib;
using namespace robocal::test;

struct Printer : ::testing::Test {
  Mechanism model = load_robot_file(std::string(ROBOCAL_TESTDATA_DIR) + "/robots/linear_delta.yaml");
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
};

TEST_F(Printer, SevenHeightsIdentifyTheIdentifiableSubsetWithAnExplainedGauge) {
  std::mt19937 rng(1);
  const Eigen::VectorXd truth = printer_truth(model, rng);
  PrinterData data;
  add_probe_heights(model, truth, probe_pattern(0.08), 10e-6, rng, data);
  // Every free parameter of the robot file (dozens): not refused.
  const auto all = identify(pred, nominal, data.measurements, solve_options_from_model(model, false));
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

}  // namespace
