// The realistic truth's elastic sag: the closed form, the simulated cell's true pose (forward
// kinematics of the true parameters, then the sag), and truth.json carrying it to validate.
#include "session/results_files.hpp"
#include "simcell/simulated_cell.hpp"

#include "robocal/calib/closure.hpp"
#include "robocal/calib/robot_file.hpp"
#include "robocal/core/files.hpp"

#include <gtest/gtest.h>

#include <filesystem>
#include <random>
#include <string>

namespace {

namespace fs = std::filesystem;
using namespace robocal;

TEST(ElasticSag, FrameSinksByTheSquareOfItsReachAndKeepsItsOrientation) {
  Eigen::Isometry3d pose(Eigen::AngleAxisd(0.3, Eigen::Vector3d(1, 2, 3).normalized()));
  pose.translation() = Eigen::Vector3d(0.3, -0.4, -0.9);
  const Eigen::Isometry3d sagged = app::elastic_deflection(pose, 1e-4);
  // 1e-4 /m * (0.3^2 + 0.4^2) m^2 = 25 µm down, nothing else.
  EXPECT_NEAR(sagged.translation().z(), -0.9 - 25e-6, 1e-15);
  EXPECT_EQ(sagged.translation().head<2>(), pose.translation().head<2>());
  EXPECT_EQ(sagged.linear(), pose.linear());
  EXPECT_TRUE(app::elastic_deflection(pose, 0.0).isApprox(pose, 0.0));
}

TEST(ElasticSag, SimulatedTruthIsTheTrueKinematicsPlusTheSag) {
  std::mt19937 rng(3);
  app::CellOptions options;
  options.elastic_sag = 1e-4;
  const app::SimulatedCell cell = app::make_simulated_cell(
      std::string(ROBOCAL_TESTDATA_DIR) + "/robots/rotary_delta.yaml", options, rng);
  for (const double a : {0.0, 0.3, 0.6}) {
    const Eigen::VectorXd q = Eigen::Vector3d(a, 0.2, 0.5 - a);
    const auto fk = calib::forward_kinematics(cell.model, cell.truth, q, cell.target_frame);
    ASSERT_TRUE(fk.closure.ok()) << a;
    Eigen::Isometry3d truth;
    ASSERT_TRUE(app::true_frame_pose(cell, q, &truth));
    const Eigen::Vector3d p = fk.pose.translation();
    const Eigen::Vector3d expected(p.x(), p.y(), p.z() - 1e-4 * (p.x() * p.x() + p.y() * p.y()));
    EXPECT_LT((truth.translation() - expected).norm(), 1e-12) << a;
    EXPECT_GT(p.head<2>().norm(), 0.05) << "a configuration off the axis, where the sag shows";
  }
}

TEST(ElasticSag, TruthFileCarriesItAndOlderFilesAreRigid) {
  const fs::path dir = fs::temp_directory_path() / "robocal_elastic_sag_truth";
  fs::remove_all(dir);
  fs::create_directories(dir / "truth");
  const calib::Mechanism model =
      calib::load_robot_file(std::string(ROBOCAL_TESTDATA_DIR) + "/robots/rotary_delta.yaml");
  app::TruthFile truth;
  truth.nominal = truth.truth = model.nominal_parameters();
  truth.elastic_sag = 1e-4;
  const app::ResultsLayout results{dir};
  app::write_truth(results, model, truth);
  EXPECT_EQ(app::read_truth(results, model).elastic_sag, 1e-4);

  // A truth.json written before the sag existed: a rigid truth.
  nlohmann::json doc = nlohmann::json::parse(core::read_text_file(results.truth()));
  doc.erase("elastic_sag");
  fs::remove(results.truth());
  core::write_file_atomic(results.truth(), doc.dump());
  EXPECT_EQ(app::read_truth(results, model).elastic_sag, 0.0);
}

}  // namespace
