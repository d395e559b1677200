#pragma once
// The Ceres cost functions of identify(): one block per measured pose, one per distance, the
// priors from tolerances, and a row scaling for the robust loss. Each evaluates the predictor
// exactly (closure included), so the Jacobians Ceres sees are the identification Jacobian's
// blocks. Internal to robocal_calib_identify.
#include "robocal/calib/frame_predictor.hpp"
#include "robocal/calib/measurements.hpp"

#include <ceres/ceres.h>

#include <Eigen/Core>

#include <cstddef>
#include <utility>
#include <vector>

namespace robocal::calib::detail {

// Whitened residuals of all observations of one pose; the model's frame Jacobian is chained with
// each observation's exact twist Jacobian, so the block Jacobian is exact (closure included).
class PoseCost final : public ceres::CostFunction {
 public:
  PoseCost(const FramePredictor& model, const PoseMeasurement& pose, int slot);

  bool Evaluate(double const* const* parameters, double* residuals,
                double** jacobians) const override;

  // Evaluates the block at `params` ahead of Ceres' call for it (EvaluateAhead: the poses on
  // several threads), unless that is done already.
  void evaluate_ahead(const double* params, bool with_jacobian) const;

 private:
  // Whether the block was evaluated ahead at exactly `params` (with its Jacobian if wanted).
  bool ahead_at(const double* params, bool with_jacobian) const;

  // The block's residuals and, when `jacobian` is not null, its row-major Jacobian.
  bool compute(const double* parameters, double* residuals, double* jacobian) const;

  const FramePredictor& model_;
  const PoseMeasurement& pose_;
  int slot_;
  struct Ahead {
    std::vector<double> params;  // where (empty: nowhere yet)
    bool with_jacobian = false;
    bool ok = false;
    std::vector<double> residuals;
    std::vector<double> jacobian;  // row-major, residuals x parameters
  };
  mutable Ahead ahead_;  // written by one worker at a time, read after it joined
};

// Evaluates every pose's block on `threads` workers before each of Ceres' evaluations, which
// then only copies them (Ceres' own threads would sum the cost and gradient in an order that
// changes from run to run; this keeps the solve the same to the bit for any number of threads).
class EvaluateAhead final : public ceres::EvaluationCallback {
 public:
  EvaluateAhead(std::vector<const PoseCost*> costs, const double* params, int threads)
      : costs_(std::move(costs)), params_(params), threads_(threads) {}
  void PrepareForEvaluation(bool evaluate_jacobians, bool /*new_evaluation_point*/) override;

 private:
  std::vector<const PoseCost*> costs_;
  const double* params_;  // the problem's parameter block, which Ceres updates before calling
  int threads_;
};

// The whitened distance between the measured frame at two poses.
class DistanceCost final : public ceres::CostFunction {
 public:
  DistanceCost(const FramePredictor& model, const PoseMeasurement& a, int slot_a,
               const PoseMeasurement& b, int slot_b, const DistanceObservation& obs);

  bool Evaluate(double const* const* parameters, double* residuals,
                double** jacobians) const override;

 private:
  const FramePredictor& model_;
  const PoseMeasurement& a_;
  const PoseMeasurement& b_;
  int slot_a_;
  int slot_b_;
  DistanceObservation obs_;
};

// (a_i − nominal_i)/σ_i for the estimated parameters that have a tolerance (MAP prior).
class PriorCost final : public ceres::CostFunction {
 public:
  PriorCost(Eigen::VectorXd nominal, std::vector<std::pair<std::size_t, double>> terms);
  bool Evaluate(double const* const* parameters, double* residuals,
                double** jacobians) const override;

 private:
  Eigen::VectorXd nominal_;
  std::vector<std::pair<std::size_t, double>> terms_;
};

// A cost whose whitened rows are divided by per-row scales (the robust loss's threshold then
// counts in estimated rather than stated σ). Does not own the wrapped cost.
class RowScaledCost final : public ceres::CostFunction {
 public:
  RowScaledCost(const ceres::CostFunction& inner, Eigen::VectorXd inverse_scale);
  bool Evaluate(double const* const* parameters, double* residuals,
                double** jacobians) const override;

 private:
  const ceres::CostFunction& inner_;
  Eigen::VectorXd inverse_scale_;
};

}  // namespace robocal::calib::detail
