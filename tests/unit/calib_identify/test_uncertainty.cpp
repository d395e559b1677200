#include "robocal/calib/noise_estimate.hpp"
#include "robocal/calib/observations.hpp"
#include "robocal/calib/uncertainty.hpp"
#include "robocal/core/random_draws.hpp"

#include "planar_fixture.hpp"

#include <ceres/ceres.h>
#include <gtest/gtest.h>

#include <Eigen/Eigenvalues>

#include <random>
#include <utility>

namespace {

using namespace robocal::calib;
using namespace robocal::calib::testing;

TEST(Quantiles, MatchTabulatedValues) {
  EXPECT_NEAR(normal_quantile(0.975), 1.959963985, 1e-8);
  EXPECT_NEAR(normal_quantile(0.5), 0.0, 1e-12);
  EXPECT_NEAR(normal_quantile(0.001), -3.090232306, 1e-8);
  // Tabulated chi-square quantiles.
  EXPECT_NEAR(chi_square_quantile(0.999, 3), 16.2662, 1e-4);
  EXPECT_NEAR(chi_square_quantile(0.999, 6), 22.4577, 1e-4);
  EXPECT_NEAR(chi_square_quantile(0.95, 1), 3.84146, 1e-5);
  EXPECT_NEAR(chi_square_quantile(0.5, 2), 2.0 * std::log(2.0), 1e-9);
  EXPECT_NEAR(chi_square_quantile(0.01, 10), 2.55821, 1e-5);
  EXPECT_THROW(normal_quantile(1.0), std::invalid_argument);
}

TEST(ParameterUncertainty, SingularNormalMatrixIsRefusedWithReason) {
  const auto a = planar_nominal();
  const Eigen::MatrixXd J = stacked_jacobian(a, planar_poses(20, -2, 2, 1));  // has redundancies
  const auto u = parameter_uncertainty(J, planar_names());
  EXPECT_FALSE(u.ok);
  EXPECT_NE(u.message.find("redundant"), std::string::npos) << u.message;
}

TEST(ParameterUncertainty, LinearModelClosedForm) {
  // y = a + b x, x = 0..3, unit noise: cov = (XᵀX)⁻¹ = [[7, -3], [-3, 2]] / 10.
  Eigen::MatrixXd X(4, 2);
  X << 1, 0, 1, 1, 1, 2, 1, 3;
  const auto u = parameter_uncertainty(X, {"a", "b"}, {.correlation_threshold = 0.8});
  ASSERT_TRUE(u.ok) << u.message;
  EXPECT_NEAR(u.covariance(0, 0), 0.7, 1e-12);
  EXPECT_NEAR(u.covariance(0, 1), -0.3, 1e-12);
  EXPECT_NEAR(u.covariance(1, 1), 0.2, 1e-12);
  EXPECT_NEAR(u.correlation(0, 1), -0.3 / std::sqrt(0.14), 1e-12);
  EXPECT_NEAR(u.ci_half_width(1), 1.959963985 * std::sqrt(0.2), 1e-8);
  ASSERT_EQ(u.strongly_correlated.size(), 1u);  // |ρ| = 0.80178
  EXPECT_EQ(u.strongly_correlated[0].first, 0u);
}

struct PlanarPointCost {
  JointSample q;
  PointObservation obs;
  template <typename T>
  bool operator()(const T* a, T* r) const {
    const Mat3<T> R = Mat3<T>::Identity();
    const Vec3<T> p = planar_position<T>(a, q.q1, q.q2);
    obs(R, p, r);
    return true;
  }
};

// Linearised covariance on the identifiable set matches the Monte-Carlo spread of full nonlinear
// re-solves (within 20 % on the diagonal), and the predicted end-effector accuracy matches the
// held-out error of the fitted models (within a factor 1.5).
TEST(ParameterUncertainty, MatchesMonteCarloOnIdentifiableSet) {
  const std::vector<int> held = {kYaw, kToolLen, kToolZ};  // redundant: held at nominal
  const std::vector<int> free_idx = {kBx, kBy, kBz, kO1, kO2, kL1, kL2};
  Eigen::VectorXd truth = planar_nominal();
  truth(kBx) += 2e-3;
  truth(kO1) += 0.01;
  truth(kL1) -= 1e-3;
  truth(kL2) += 5e-4;
  const double sigma = 1e-4;
  const auto poses = planar_poses(30, -2.0, 2.0, 11);
  const auto holdout = planar_poses(50, -2.0, 2.0, 12);

  Eigen::MatrixXd Jw(3 * 30, 7);
  const Eigen::MatrixXd Jfull = stacked_jacobian(truth, poses) / sigma;
  for (int k = 0; k < 7; ++k) Jw.col(k) = Jfull.col(free_idx[static_cast<std::size_t>(k)]);
  std::vector<std::string> names;
  for (int k : free_idx) names.push_back(planar_names()[static_cast<std::size_t>(k)]);
  const auto u = parameter_uncertainty(Jw, names);
  ASSERT_TRUE(u.ok) << u.message;

  std::mt19937 rng(2024);
  std::normal_distribution<double> noise(0.0, sigma);
  const int draws = 200;
  Eigen::MatrixXd estimates(draws, 7);
  double heldout_sq = 0.0;
  for (int d = 0; d < draws; ++d) {
    Eigen::VectorXd a = planar_nominal();
    ceres::Problem problem;
    for (const auto& q : poses) {
      Eigen::Vector3d m = planar_position<double>(truth.data(), q.q1, q.q2);
      for (int i = 0; i < 3; ++i) m(i) += noise(rng);
      problem.AddResidualBlock(new ceres::AutoDiffCostFunction<PlanarPointCost, 3, kPlanarCount>(
                                   new PlanarPointCost{q, PointObservation::with_sigma(m, sigma)}),
                               nullptr, a.data());
    }
    problem.SetManifold(a.data(), new ceres::SubsetManifold(kPlanarCount, held));
    ceres::Solver::Options opt;
    opt.function_tolerance = 1e-14;
    opt.gradient_tolerance = 1e-14;
    opt.parameter_tolerance = 1e-14;
    ceres::Solver::Summary summary;
    ceres::Solve(opt, &problem, &summary);
    ASSERT_TRUE(summary.IsSolutionUsable());
    for (int k = 0; k < 7; ++k) estimates(d, k) = a(free_idx[static_cast<std::size_t>(k)]);
    for (const auto& q : holdout)
      heldout_sq += (planar_position<double>(a.data(), q.q1, q.q2) -
                     planar_position<double>(truth.data(), q.q1, q.q2))
                        .squaredNorm();
  }
  const Eigen::RowVectorXd mean = estimates.colwise().mean();
  const Eigen::MatrixXd centred = estimates.rowwise() - mean;
  const Eigen::VectorXd mc_var = (centred.transpose() * centred).diagonal() / (draws - 1);
  for (int k = 0; k < 7; ++k) {
    const double ratio = mc_var(k) / u.covariance(k, k);
    EXPECT_GT(ratio, 0.8) << names[static_cast<std::size_t>(k)];
    EXPECT_LT(ratio, 1.2) << names[static_cast<std::size_t>(k)];
  }

  std::vector<Eigen::MatrixXd> pose_jacobians;
  for (const auto& q : holdout) {
    const auto Jq = planar_jacobian(truth, q.q1, q.q2);
    Eigen::MatrixXd Js(3, 7);
    for (int k = 0; k < 7; ++k) Js.col(k) = Jq.col(free_idx[static_cast<std::size_t>(k)]);
    pose_jacobians.push_back(Js);
  }
  const auto pred = predict_accuracy(pose_jacobians, u.covariance);
  const double actual = std::sqrt(heldout_sq / (draws * static_cast<double>(holdout.size())));
  EXPECT_GT(actual / pred.position_rms_overall, 1.0 / 1.5);
  EXPECT_LT(actual / pred.position_rms_overall, 1.5);
}

TEST(ResidualDiagnostics, FlagsGrossOutliersEvenWithWrongStatedNoise) {
  std::mt19937 rng(5);
  std::normal_distribution<double> n01(0.0, 1.0);
  std::vector<PoseResidual> res;
  for (int k = 0; k < 100; ++k) {
    PoseResidual r;
    r.id = "pose" + std::to_string(k);
    // Stated noise 10× too optimistic: whitened residuals have σ = 10.
    r.whitened = robocal::core::draw_vector3(n01, rng) * 10.0;
    if (k % 20 == 3) r.whitened(1) += 150.0;  // gross error (15 σ)
    r.position_error = r.whitened.norm() * 1e-5;
    res.push_back(r);
  }
  const auto diag = diagnose_residuals(res);
  EXPECT_NEAR(diag.scale, 10.0, 2.0);
  EXPECT_EQ(diag.outliers, 5u);
  for (int k = 0; k < 100; ++k)
    EXPECT_EQ(diag.poses[static_cast<std::size_t>(k)].outlier, k % 20 == 3) << k;
  EXPECT_GT(diag.position_max, diag.position_rms);
}

}  // namespace

namespace {

// rᵀ Q⁺ r and rank over eigenvalues above 1e-6 of a dense Q: the definition, written here.
std::pair<double, int> dense_test(const Eigen::VectorXd& r, const Eigen::MatrixXd& Q) {
  const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(Q);
  const Eigen::VectorXd proj = eig.eigenvectors().transpose() * r;
  double chi = 0.0;
  int dof = 0;
  for (Eigen::Index i = 0; i < proj.size(); ++i)
    if (eig.eigenvalues()(i) > 1e-6) {
      chi += proj(i) * proj(i) / eig.eigenvalues()(i);
      ++dof;
    }
  return {chi, dof};
}

}  // namespace

// The factored outlier test (a large pose block) gives the dense test's statistic and dof: rows
// in the fit and not, a block that absorbs some directions fully, a parameter the block does not
// see, and a noise-scale factor.
TEST(ResidualDiagnostics, FactoredTestEqualsTheDenseEigenDecomposition) {
  std::mt19937 rng(7);
  std::normal_distribution<double> g;
  struct Case {
    int rows_all, params, first, count;
    bool in_fit;
    double factor;
  };
  for (const Case c : {Case{100, 8, 20, 40, true, 1.3}, Case{100, 8, 20, 40, false, 0.7},
                       Case{8, 8, 0, 8, true, 1.0}, Case{30, 6, 0, 12, true, 2.0}}) {
    Eigen::MatrixXd J(c.rows_all, c.params);
    for (Eigen::Index i = 0; i < J.size(); ++i) J.data()[i] = g(rng);
    // Parameter 1 acts only outside the block: its column there is zero (unless the block is
    // all the data: every direction absorbed, nothing left to test).
    if (c.count < c.rows_all) J.block(c.first, 1, c.count, 1).setZero();
    const Eigen::MatrixXd C = (J.transpose() * J).inverse();
    const Eigen::MatrixXd Jb = J.middleRows(c.first, c.count);
    Eigen::VectorXd r(c.count);
    for (Eigen::Index i = 0; i < r.size(); ++i) r(i) = g(rng);
    // Residuals of rows in the fit lie in the range of Q (the fit removed the rest).
    const Eigen::MatrixXd G = pose_residual_covariance(Jb, C, c.in_fit);  // I ∓ J_b C J_bᵀ
    if (c.in_fit) r = G * r;
    const auto [chi, dof] = dense_test(r, c.factor * G);

    const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> ce(C);
    const Eigen::MatrixXd root = ce.eigenvectors() * ce.eigenvalues().cwiseSqrt().asDiagonal();
    const FactoredTest t = factored_residual_test(r, Jb * root, c.in_fit ? -1.0 : 1.0, c.factor);
    EXPECT_EQ(t.dof, dof) << c.rows_all << " " << c.count;
    EXPECT_NEAR(t.chi_square, chi, 1e-9 * std::max(1.0, chi)) << c.rows_all << " " << c.count;
  }
}
