// Validation and simulation around identify(): errors of a parameter vector on held-out poses,
// k-fold cross-validation, and simulated measurements of a perturbed robot.
#include "identification_detail.hpp"

#include "robocal/core/random_draws.hpp"

#include <fmt/core.h>

#include <algorithm>
#include <cmath>
#include <set>
#include <stdexcept>

namespace robocal::calib {
namespace {

ErrorStatistics finish(const std::vector<double>& pos, const std::vector<double>& ori) {
  ErrorStatistics s;
  s.poses = pos.size();
  for (double e : pos) {
    s.position_rms += e * e;
    s.position_max = std::max(s.position_max, e);
  }
  for (double e : ori) {
    s.orientation_rms += e * e;
    s.orientation_max = std::max(s.orientation_max, e);
  }
  if (!pos.empty()) s.position_rms = std::sqrt(s.position_rms / static_cast<double>(pos.size()));
  if (!ori.empty())
    s.orientation_rms = std::sqrt(s.orientation_rms / static_cast<double>(ori.size()));
  return s;
}

}  // namespace

ErrorStatistics prediction_errors(const FramePredictor& model, const Eigen::VectorXd& params,
                                  const std::vector<PoseMeasurement>& poses) {
  std::vector<double> pos;
  std::vector<double> ori;
  for (std::size_t k = 0; k < poses.size(); ++k) {
    const auto& pose = poses[k];
    FramePrediction pred;
    std::string why;
    if (!pose.actuators.allFinite() ||
        !model.predict(params, pose.actuators, static_cast<int>(k), false, pred, why))
      continue;
    for (const auto& obs : pose.observations) {
      if (auto p = detail::observed_position(obs))
        pos.push_back((pred.pose.translation() - *p).norm());
      if (const auto* po = std::get_if<PoseObservation>(&obs))
        ori.push_back(
            Eigen::AngleAxisd(pred.pose.linear() * po->measured_rotation.transpose()).angle());
      if (const auto* ph = std::get_if<ProbeHeightObservation>(&obs))
        pos.push_back(
            std::abs(ph->normal.dot(pred.pose.translation()) - ph->offset - ph->measured_height));
    }
  }
  return finish(pos, ori);
}

ValidationReport validate(const FramePredictor& model, const Eigen::VectorXd& nominal,
                          const Eigen::VectorXd& estimate,
                          const std::vector<PoseMeasurement>& held_out) {
  return {prediction_errors(model, nominal, held_out),
          prediction_errors(model, estimate, held_out)};
}

KFoldReport k_fold_validation(const FramePredictor& model, const Eigen::VectorXd& nominal,
                              const Measurements& measurements, int folds,
                              const SolveOptions& options) {
  if (folds < 2) throw std::invalid_argument("k-fold validation needs at least 2 folds");
  KFoldReport report;
  report.folds = folds;
  std::vector<PoseMeasurement> all_held;
  std::vector<PoseMeasurement> pooled_after_dummy;
  std::vector<double> before_pos, before_ori, after_pos, after_ori;
  for (int f = 0; f < folds; ++f) {
    Measurements train;
    std::vector<PoseMeasurement> held;
    for (std::size_t k = 0; k < measurements.poses.size(); ++k)
      (static_cast<int>(k % static_cast<std::size_t>(folds)) == f ? held : train.poses)
          .push_back(measurements.poses[k]);
    std::set<std::string> train_ids;
    for (const auto& p : train.poses) train_ids.insert(p.id);
    for (const auto& d : measurements.distances)
      if (train_ids.count(d.first) && train_ids.count(d.second)) train.distances.push_back(d);
    const auto fit = identify(model, nominal, train, options);
    report.messages.push_back(
        fmt::format("fold {}: {} ({})", f + 1, to_string(fit.status), fit.message));
    report.per_fold.push_back(validate(model, nominal, fit.estimate, held));
    // Pool the squared errors: recompute per pose for exact pooled RMS.
    for (const auto& pose : held) {
      const auto b = prediction_errors(model, nominal, {pose});
      const auto a = prediction_errors(model, fit.estimate, {pose});
      if (b.poses > 0) before_pos.push_back(b.position_rms);
      if (a.poses > 0) after_pos.push_back(a.position_rms);
      if (b.orientation_rms > 0) before_ori.push_back(b.orientation_rms);
      if (a.orientation_rms > 0) after_ori.push_back(a.orientation_rms);
    }
  }
  report.before = finish(before_pos, before_ori);
  report.after = finish(after_pos, after_ori);
  return report;
}

Eigen::VectorXd perturb_parameters(const Eigen::VectorXd& nominal, const Eigen::VectorXd& sigma,
                                   std::mt19937& rng) {
  if (sigma.size() != nominal.size())
    throw std::invalid_argument("perturb_parameters: one sigma per parameter needed");
  std::normal_distribution<double> n01(0.0, 1.0);
  Eigen::VectorXd out = nominal;
  for (Eigen::Index i = 0; i < out.size(); ++i)
    if (sigma(i) > 0.0) out(i) += sigma(i) * n01(rng);
  return out;
}

Measurements simulate_measurements(const FramePredictor& model, const Eigen::VectorXd& truth,
                                   const std::vector<Eigen::VectorXd>& actuators,
                                   const SimulationOptions& options, std::mt19937& rng) {
  std::normal_distribution<double> n01(0.0, 1.0);
  const double noise = options.add_noise ? 1.0 : 0.0;
  Measurements out;
  for (std::size_t k = 0; k < actuators.size(); ++k) {
    FramePrediction pred;
    std::string why;
    if (!model.predict(truth, actuators[k], static_cast<int>(k), false, pred, why)) continue;
    PoseMeasurement m;
    m.id = fmt::format("p{:04d}", k);
    m.actuators = actuators[k];
    if (options.actuator_sigma.size() == actuators[k].size())
      for (Eigen::Index i = 0; i < m.actuators.size(); ++i)
        m.actuators(i) += noise * options.actuator_sigma(i) * n01(rng);
    const Eigen::Vector3d dp = core::draw_vector3(n01, rng);
    const Eigen::Vector3d p = pred.pose.translation() + noise * options.position_sigma * dp;
    switch (options.kind) {
      case SimulatedObservation::kPoint:
        m.observations.emplace_back(PointObservation::with_sigma(p, options.position_sigma));
        break;
      case SimulatedObservation::kPose: {
        const Eigen::Vector3d dphi = noise * options.rotation_sigma * core::draw_vector3(n01, rng);
        Eigen::Isometry3d T = pred.pose;
        T.translation() = p;
        if (dphi.norm() > 0)
          T.linear() = Eigen::AngleAxisd(dphi.norm(), dphi.normalized()).toRotationMatrix() *
                       pred.pose.linear();
        m.observations.emplace_back(
            PoseObservation::with_sigmas(T, options.position_sigma, options.rotation_sigma));
        break;
      }
      case SimulatedObservation::kProbeHeight: {
        ProbeHeightObservation ph;
        ph.normal = options.plane_normal.normalized();
        ph.offset = options.plane_offset;
        ph.sigma = options.position_sigma;
        ph.measured_height = ph.normal.dot(pred.pose.translation()) - ph.offset +
                             noise * options.position_sigma * n01(rng);
        m.observations.emplace_back(ph);
        break;
      }
    }
    out.poses.push_back(std::move(m));
  }
  return out;
}

}  // namespace robocal::calib
