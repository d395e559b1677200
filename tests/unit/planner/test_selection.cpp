// Selection: the indices against closed forms written here, the rank-6 update against a direct
// computation, sequential mode, early stop.
#include "robocal/calib/mechanism_predictor.hpp"
#include "robocal/calib/robot_file.hpp"
#include "robocal/planner/selection.hpp"

#include <gtest/gtest.h>
#include <Eigen/SVD>

#include <algorithm>
#include <cmath>
#include <numeric>
#include <random>

namespace robocal::planner {
namespace {

// A synthetic observability model: random 6 x L pose blocks.
ObservabilityModel random_model(std::size_t poses, int columns, unsigned seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> n(0, 1);
  ObservabilityModel m;
  m.rows.resize(static_cast<Eigen::Index>(6 * poses), columns);
  for (Eigen::Index i = 0; i < m.rows.rows(); ++i)
    for (Eigen::Index j = 0; j < columns; ++j) m.rows(i, j) = n(rng);
  // Some poses far more informative in a few columns, so a design choice matters.
  for (std::size_t p = 0; p < poses; p += 7)
    m.rows.middleRows(static_cast<Eigen::Index>(6 * p), 6) *= 3.0;
  m.column_scale = Eigen::VectorXd::Ones(columns);
  for (int j = 0; j < columns; ++j) m.names.push_back(std::string("p").append(std::to_string(j)));
  return m;
}

Eigen::VectorXd singular_values(const ObservabilityModel& m, const std::vector<std::size_t>& set) {
  Eigen::MatrixXd J(static_cast<Eigen::Index>(6 * set.size()), m.rows.cols());
  for (std::size_t k = 0; k < set.size(); ++k)
    J.middleRows(static_cast<Eigen::Index>(6 * k), 6) =
        m.rows.middleRows(static_cast<Eigen::Index>(6 * set[k]), 6);
  return Eigen::JacobiSVD<Eigen::MatrixXd>(J).singularValues();
}

TEST(Selection, IndicesMatchTheirDefinitions) {
  const ObservabilityModel m = random_model(50, 8, 1);
  const std::vector<std::size_t> set = {0, 3, 5, 9, 11, 20, 30};
  const Eigen::VectorXd s = singular_values(m, set);
  const double L = static_cast<double>(s.size());
  double prod = 1, inv = 0;
  for (Eigen::Index i = 0; i < s.size(); ++i) {
    prod *= s(i);
    inv += 1 / s(i);
  }
  const IndexValues v = evaluate_set(m, set);
  EXPECT_NEAR(v.o[0], std::pow(prod, 1 / L) / std::sqrt(7.0), 1e-9 * v.o[0]);
  EXPECT_NEAR(v.o[1], s(s.size() - 1) / s(0), 1e-9);
  EXPECT_NEAR(v.o[2], s(s.size() - 1), 1e-9 * s(0));
  EXPECT_NEAR(v.o[3], s(s.size() - 1) * s(s.size() - 1) / s(0), 1e-9 * s(0));
  EXPECT_NEAR(v.o[4], 1 / inv, 1e-9 * s(0));
  EXPECT_EQ(v.rank, 8u);
}

TEST(Selection, GreedyDetmaxBeatsRandomAndEveryIndexRuns) {
  const ObservabilityModel m = random_model(300, 10, 2);
  std::vector<std::size_t> random_set(12);
  std::iota(random_set.begin(), random_set.end(), 100);
  for (const ObservabilityIndex idx :
       {ObservabilityIndex::kO1, ObservabilityIndex::kO2, ObservabilityIndex::kO3,
        ObservabilityIndex::kO4, ObservabilityIndex::kO5}) {
    SelectionOptions o;
    o.index = idx;
    o.count = 12;
    const Selection s = select_poses(m, o);
    ASSERT_EQ(s.chosen.size(), 12u) << to_string(idx);
    const auto i = static_cast<std::size_t>(idx);
    EXPECT_GT(s.values.o[i], evaluate_set(m, random_set).o[i]) << to_string(idx);
  }
  // DETMAX never lowers the D-optimal index of the greedy pass.
  SelectionOptions greedy;
  greedy.count = 12;
  greedy.exchange = false;
  SelectionOptions detmax = greedy;
  detmax.exchange = true;
  EXPECT_GE(select_poses(m, detmax).values.o[0], select_poses(m, greedy).values.o[0] * (1 - 1e-12));
}

// Mean position variance over the pool from the set's normal matrix, computed directly:
// mean_i tr(Jp_i (J^T J)^-1 Jp_i^T), Jp_i = the pose's first three rows.
double mean_position_variance(const ObservabilityModel& m, const std::vector<std::size_t>& set) {
  const Eigen::Index L = m.rows.cols();
  Eigen::MatrixXd N = Eigen::MatrixXd::Zero(L, L);
  for (const std::size_t i : set) {
    const Eigen::MatrixXd Ji = m.rows.middleRows(static_cast<Eigen::Index>(6 * i), 6);
    N += Ji.transpose() * Ji;
  }
  const Eigen::MatrixXd Ninv = N.inverse();
  double sum = 0;
  for (std::size_t i = 0; i < m.poses(); ++i) {
    const Eigen::MatrixXd Jp = m.rows.middleRows(static_cast<Eigen::Index>(6 * i), 3);
    sum += (Jp * Ninv * Jp.transpose()).trace();
  }
  return sum / static_cast<double>(m.poses());
}

TEST(Selection, TaskCriterionMinimisesTheMeanPredictedPositionVariance) {
  const ObservabilityModel m = random_model(300, 10, 5);
  SelectionOptions o;
  o.count = 12;
  o.index = ObservabilityIndex::kTask;
  const Selection task = select_poses(m, o);
  ASSERT_EQ(task.chosen.size(), 12u);
  const double v_task = mean_position_variance(m, task.chosen);
  // Better than every O1-O5 design and than random sets of the same size.
  for (const ObservabilityIndex idx :
       {ObservabilityIndex::kO1, ObservabilityIndex::kO2, ObservabilityIndex::kO3,
        ObservabilityIndex::kO4, ObservabilityIndex::kO5}) {
    SelectionOptions oi = o;
    oi.index = idx;
    EXPECT_LE(v_task, mean_position_variance(m, select_poses(m, oi).chosen)) << to_string(idx);
  }
  std::mt19937 rng(6);
  std::vector<std::size_t> all(m.poses());
  std::iota(all.begin(), all.end(), 0);
  for (int t = 0; t < 20; ++t) {
    std::shuffle(all.begin(), all.end(), rng);
    const std::vector<std::size_t> random_set(all.begin(), all.begin() + 12);
    EXPECT_LT(v_task, mean_position_variance(m, random_set));
  }
  // The prediction the selection reports is that variance (sigma scaling).
  EXPECT_NEAR(task.predicted_rms, m.position_sigma * std::sqrt(v_task), 1e-6 * task.predicted_rms);
}

TEST(Selection, SequentialModeProposesNewPosesAndCountsTheMeasured) {
  const ObservabilityModel m = random_model(200, 8, 3);
  const std::vector<std::size_t> measured = {1, 2, 3, 4};
  SelectionOptions o;
  o.count = 5;
  const Selection s = select_poses(m, o, measured);
  ASSERT_EQ(s.chosen.size(), 5u);
  for (const std::size_t c : s.chosen)
    EXPECT_EQ(std::count(measured.begin(), measured.end(), c), 0);
  std::vector<std::size_t> all = measured;
  all.insert(all.end(), s.chosen.begin(), s.chosen.end());
  EXPECT_NEAR(s.values.o[0], evaluate_set(m, all).o[0], 1e-12);
}

TEST(Selection, StopsEarlyAtTheTargetAccuracy) {
  const calib::Mechanism model =
      calib::load_robot_file(std::string(ROBOCAL_TESTDATA_DIR) + "/robots/linear_delta.yaml");
  const calib::MechanismPredictor pred(model);
  std::mt19937 rng(4);
  const std::vector<Eigen::VectorXd> pool =
      calib::sample_actuators(pred, {model.nominal_parameters()}, 300, rng);
  const ObservabilityModel obs = build_observability_model(pred, model.nominal_parameters(), pool);
  SelectionOptions o;
  o.count = 80;
  const Selection full = select_poses(obs, o);
  o.target_accuracy = 2.0 * full.predicted_rms;
  const Selection early = select_poses(obs, o);
  EXPECT_TRUE(early.stopped_early);
  EXPECT_LT(early.chosen.size(), full.chosen.size());
  EXPECT_LE(early.predicted_rms, o.target_accuracy);
  // The predicted accuracy matches the covariance computed directly: J_pos (J^T J)^-1 J_pos^T.
  double rms = 0, mx = 0;
  predicted_accuracy(obs, full.chosen, &rms, &mx);
  Eigen::MatrixXd N = Eigen::MatrixXd::Zero(obs.rows.cols(), obs.rows.cols());
  for (const std::size_t i : full.chosen) {
    const Eigen::MatrixXd Ji = obs.rows.middleRows(static_cast<Eigen::Index>(6 * i), 6);
    N += Ji.transpose() * Ji;
  }
  const Eigen::MatrixXd C = N.inverse();
  double sum = 0;
  for (std::size_t i = 0; i < obs.poses(); ++i) {
    const Eigen::MatrixXd Jp = obs.rows.middleRows(static_cast<Eigen::Index>(6 * i), 3);
    sum += (Jp * C * Jp.transpose()).trace() * obs.position_sigma * obs.position_sigma;
  }
  EXPECT_NEAR(rms, std::sqrt(sum / static_cast<double>(obs.poses())), 1e-3 * rms);
}

}  // namespace
}  // namespace robocal::planner
