#include "identification_costs.hpp"

#include "robocal/core/parallel.hpp"

#include <algorithm>
#include <string>
#include <type_traits>
#include <variant>

namespace robocal::calib::detail {
namespace {

int residual_count(const Observation& obs) {
  return std::visit([](const auto& o) { return std::decay_t<decltype(o)>::kResiduals; }, obs);
}

}  // namespace

PoseCost::PoseCost(const FramePredictor& model, const PoseMeasurement& pose, int slot)
    : model_(model), pose_(pose), slot_(slot) {
  int rows = 0;
  for (const auto& obs : pose.observations) rows += residual_count(obs);
  set_num_residuals(rows);
  mutable_parameter_block_sizes()->push_back(static_cast<int>(model.parameter_count()));
}

bool PoseCost::Evaluate(double const* const* parameters, double* residuals,
                        double** jacobians) const {
  const bool want_jacobian = jacobians != nullptr && jacobians[0] != nullptr;
  if (ahead_at(parameters[0], want_jacobian)) {
    if (!ahead_.ok) return false;
    std::copy(ahead_.residuals.begin(), ahead_.residuals.end(), residuals);
    if (want_jacobian) std::copy(ahead_.jacobian.begin(), ahead_.jacobian.end(), jacobians[0]);
    return true;
  }
  return compute(parameters[0], residuals, want_jacobian ? jacobians[0] : nullptr);
}

void PoseCost::evaluate_ahead(const double* params, bool with_jacobian) const {
  if (ahead_at(params, with_jacobian)) return;
  const auto P = model_.parameter_count();
  ahead_.params.assign(params, params + P);
  ahead_.with_jacobian = with_jacobian;
  ahead_.residuals.resize(static_cast<std::size_t>(num_residuals()));
  ahead_.jacobian.resize(with_jacobian ? static_cast<std::size_t>(num_residuals()) * P : 0);
  ahead_.ok =
      compute(params, ahead_.residuals.data(), with_jacobian ? ahead_.jacobian.data() : nullptr);
}

bool PoseCost::ahead_at(const double* params, bool with_jacobian) const {
  return !ahead_.params.empty() && (ahead_.with_jacobian || !with_jacobian) &&
         std::equal(ahead_.params.begin(), ahead_.params.end(), params);
}

bool PoseCost::compute(const double* parameters, double* residuals, double* jacobian) const {
  const auto P = static_cast<Eigen::Index>(model_.parameter_count());
  const Eigen::VectorXd params = Eigen::Map<const Eigen::VectorXd>(parameters, P);
  const bool want_jacobian = jacobian != nullptr;
  double* jacobians[] = {jacobian};
  FramePrediction pred;
  std::string why;
  if (!model_.predict(params, pose_.actuators, slot_, want_jacobian, pred, why)) return false;
  int row = 0;
  bool ok = true;
  std::vector<int> first_row;  // residual row of each observation
  first_row.reserve(pose_.observations.size());
  for (const auto& obs : pose_.observations) {
    first_row.push_back(row);
    std::visit(
        [&](const auto& o) {
          using O = std::decay_t<decltype(o)>;
          Eigen::Map<Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>> J(
              want_jacobian ? jacobians[0] : nullptr, num_residuals(), P);
          if constexpr (std::is_same_v<O, PixelObservation>) {
            // Depends on camera parameters too: the predictor chains it (exact).
            Eigen::Vector2d r;
            Eigen::Matrix<double, 2, Eigen::Dynamic> Jp;
            if (!model_.pixel_residual(o, params, pred, r, want_jacobian ? &Jp : nullptr, why)) {
              ok = false;
              return;
            }
            residuals[row] = r(0);
            residuals[row + 1] = r(1);
            if (want_jacobian) J.middleRows(row, 2) = Jp;
          } else if constexpr (std::is_same_v<O, ProbeHeightObservation>) {
            // The bed plane may be estimated: the predictor evaluates it.
            Eigen::RowVectorXd Jh;
            if (!model_.probe_residual(o, params, pred, residuals[row],
                                       want_jacobian ? &Jh : nullptr, why)) {
              ok = false;
              return;
            }
            if (want_jacobian) J.row(row) = Jh;
          } else {
            Eigen::Matrix<double, O::kResiduals, 1> r;
            const auto Jo = residual_and_twist_jacobian(o, pred.pose, r);
            for (int i = 0; i < O::kResiduals; ++i) residuals[row + i] = r(i);
            if (want_jacobian) J.middleRows(row, O::kResiduals) = Jo * pred.jacobian;
          }
          row += O::kResiduals;
        },
        obs);
    if (!ok) return false;
  }
  // Jointly measured corners: decorrelate their (marginally whitened) rows together.
  for (const PixelGroup& g : pose_.pixel_groups) {
    const int r0 = first_row[static_cast<std::size_t>(g.first)];
    const auto n = static_cast<Eigen::Index>(2 * g.count);
    Eigen::Map<Eigen::VectorXd> r(residuals + r0, n);
    r = (g.decorrelation * r).eval();
    if (want_jacobian) {
      Eigen::Map<Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>> J(
          jacobians[0], num_residuals(), P);
      J.middleRows(r0, n) = (g.decorrelation * J.middleRows(r0, n)).eval();
    }
  }
  return true;
}

void EvaluateAhead::PrepareForEvaluation(bool evaluate_jacobians, bool /*new_evaluation_point*/) {
  core::parallel_for(static_cast<int>(costs_.size()), threads_, [&](int i) {
    costs_[static_cast<std::size_t>(i)]->evaluate_ahead(params_, evaluate_jacobians);
  });
}

DistanceCost::DistanceCost(const FramePredictor& model, const PoseMeasurement& a, int slot_a,
                           const PoseMeasurement& b, int slot_b, const DistanceObservation& obs)
    : model_(model), a_(a), b_(b), slot_a_(slot_a), slot_b_(slot_b), obs_(obs) {
  set_num_residuals(1);
  mutable_parameter_block_sizes()->push_back(static_cast<int>(model.parameter_count()));
}

bool DistanceCost::Evaluate(double const* const* parameters, double* residuals,
                            double** jacobians) const {
  const auto P = static_cast<Eigen::Index>(model_.parameter_count());
  const Eigen::VectorXd params = Eigen::Map<const Eigen::VectorXd>(parameters[0], P);
  const bool want_jacobian = jacobians != nullptr && jacobians[0] != nullptr;
  FramePrediction pa;
  FramePrediction pb;
  std::string why;
  if (!model_.predict(params, a_.actuators, slot_a_, want_jacobian, pa, why)) return false;
  if (!model_.predict(params, b_.actuators, slot_b_, want_jacobian, pb, why)) return false;
  Eigen::Matrix<double, 1, 1> r;
  const auto Jo = residual_and_twist_jacobian(obs_, pa.pose, pb.pose, r);
  residuals[0] = r(0);
  if (want_jacobian) {
    Eigen::Map<Eigen::Matrix<double, 1, Eigen::Dynamic>> J(jacobians[0], P);
    J = Jo.leftCols<6>() * pa.jacobian + Jo.rightCols<6>() * pb.jacobian;
  }
  return true;
}

PriorCost::PriorCost(Eigen::VectorXd nominal, std::vector<std::pair<std::size_t, double>> terms)
    : nominal_(std::move(nominal)), terms_(std::move(terms)) {
  set_num_residuals(static_cast<int>(terms_.size()));
  mutable_parameter_block_sizes()->push_back(static_cast<int>(nominal_.size()));
}

bool PriorCost::Evaluate(double const* const* parameters, double* residuals,
                         double** jacobians) const {
  const auto P = nominal_.size();
  for (std::size_t k = 0; k < terms_.size(); ++k) {
    const auto [i, s] = terms_[k];
    residuals[k] = (parameters[0][i] - nominal_(static_cast<Eigen::Index>(i))) / s;
  }
  if (jacobians != nullptr && jacobians[0] != nullptr) {
    Eigen::Map<Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>> J(
        jacobians[0], static_cast<Eigen::Index>(terms_.size()), P);
    J.setZero();
    for (std::size_t k = 0; k < terms_.size(); ++k)
      J(static_cast<Eigen::Index>(k), static_cast<Eigen::Index>(terms_[k].first)) =
          1.0 / terms_[k].second;
  }
  return true;
}

RowScaledCost::RowScaledCost(const ceres::CostFunction& inner, Eigen::VectorXd inverse_scale)
    : inner_(inner), inverse_scale_(std::move(inverse_scale)) {
  set_num_residuals(inner.num_residuals());
  *mutable_parameter_block_sizes() = inner.parameter_block_sizes();
}

bool RowScaledCost::Evaluate(double const* const* parameters, double* residuals,
                             double** jacobians) const {
  if (!inner_.Evaluate(parameters, residuals, jacobians)) return false;
  const Eigen::Index m = num_residuals();
  Eigen::Map<Eigen::VectorXd>(residuals, m).array() *= inverse_scale_.array();
  if (jacobians != nullptr && jacobians[0] != nullptr) {
    const Eigen::Index n = parameter_block_sizes()[0];
    Eigen::Map<Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>> J(
        jacobians[0], m, n);
    J = inverse_scale_.asDiagonal() * J;
  }
  return true;
}

}  // namespace robocal::calib::detail
