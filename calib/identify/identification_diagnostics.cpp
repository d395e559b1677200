// Residuals and noise of identify(): which observation type each residual row belongs to, the
// fit residuals per type, the outlier-proof scales for the robust loss, and plain-words warnings
// when the stated noise does not match the residuals.
#include "identification_detail.hpp"
#include "robocal/core/median.hpp"

#include <fmt/core.h>

#include <algorithm>
#include <cmath>
#include <type_traits>
#include <variant>

namespace robocal::calib::detail {
namespace {

std::string sigma_text(double sigma, const std::string& unit) {
  if (unit == "m")
    return sigma < 1e-3 ? fmt::format("{:.3g} µm", sigma * 1e6)
                        : fmt::format("{:.3g} mm", sigma * 1e3);
  if (unit == "rad") return fmt::format("{:.3g} mrad", sigma * 1e3);
  return fmt::format("{:.3g} {}", sigma, unit);
}

}  // namespace

std::optional<Eigen::Vector3d> observed_position(const Observation& obs) {
  if (const auto* p = std::get_if<PointObservation>(&obs)) return p->measured;
  if (const auto* p = std::get_if<PoseObservation>(&obs)) return p->measured_position;
  return std::nullopt;
}

std::vector<TypeResiduals> residuals_by_type(const FramePredictor& model,
                                             const Eigen::VectorXd& params,
                                             const std::vector<const PoseMeasurement*>& poses,
                                             const std::map<std::string, int>& slot_of,
                                             const std::vector<DistanceMeasurement>& distances) {
  std::vector<TypeResiduals> out = {{"point", "m"},
                                    {"pose position", "m"},
                                    {"pose rotation", "rad"},
                                    {"probe height", "m"},
                                    {"distance", "m"}};
  auto add = [&](std::size_t type, double e) {
    auto& t = out[type];
    ++t.count;
    t.rms += e * e;
    t.max = std::max(t.max, e);
  };
  std::map<std::string, Eigen::Vector3d> at;
  for (const auto* pose : poses) {
    FramePrediction pred;
    std::string why;
    const auto slot = slot_of.find(pose->id);
    if (!model.predict(params, pose->actuators, slot == slot_of.end() ? -1 : slot->second, false,
                       pred, why))
      continue;
    at[pose->id] = pred.pose.translation();
    for (const auto& obs : pose->observations) {
      if (const auto* p = std::get_if<PointObservation>(&obs))
        add(0, (pred.pose.translation() - p->measured).norm());
      if (const auto* p = std::get_if<PoseObservation>(&obs)) {
        add(1, (pred.pose.translation() - p->measured_position).norm());
        add(2, Eigen::AngleAxisd(pred.pose.linear() * p->measured_rotation.transpose()).angle());
      }
      if (const auto* h = std::get_if<ProbeHeightObservation>(&obs)) {
        double r = 0.0;  // whitened, against the estimated bed plane when there is one
        if (model.probe_residual(*h, params, pred, r, nullptr, why)) add(3, std::abs(r) * h->sigma);
      }
    }
  }
  for (const auto& d : distances) {
    const auto a = at.find(d.first);
    const auto b = at.find(d.second);
    if (a != at.end() && b != at.end())
      add(4, std::abs((a->second - b->second).norm() - d.observation.measured_distance));
  }
  std::vector<TypeResiduals> present;
  for (auto& t : out)
    if (t.count > 0) {
      t.rms = std::sqrt(t.rms / static_cast<double>(t.count));
      present.push_back(t);
    }
  return present;
}

std::vector<NoiseGroup> observation_groups() {
  std::vector<NoiseGroup> g(6);
  // Moved in rather than assigned from literals: GCC 12 inlines those assignments here and warns
  // (-Wrestrict) about a copy it cannot prove in bounds.
  const auto name = [&](Group group, std::string type, std::string unit) {
    g[group].type = std::move(type);
    g[group].unit = std::move(unit);
  };
  name(kPointRows, "point", "m");
  name(kPosePosition, "pose position", "m");
  name(kPoseRotation, "pose rotation", "rad");
  name(kProbeRows, "probe height", "m");
  name(kDistanceRows, "distance", "m");
  name(kPixelRows, "pixel", "px");
  return g;
}

std::vector<std::pair<int, double>> row_labels(const Observation& obs) {
  std::vector<std::pair<int, double>> out;
  auto diag_sigma = [](const auto& weight) {
    const auto info = (weight.transpose() * weight).eval();
    return info.inverse().diagonal().cwiseSqrt().eval();
  };
  std::visit(
      [&](const auto& o) {
        using O = std::decay_t<decltype(o)>;
        if constexpr (std::is_same_v<O, PoseObservation>) {
          const auto s = diag_sigma(o.weight);
          for (int i = 0; i < 6; ++i) out.emplace_back(i < 3 ? kPosePosition : kPoseRotation, s(i));
        } else if constexpr (std::is_same_v<O, PointObservation>) {
          const auto s = diag_sigma(o.weight);
          for (int i = 0; i < 3; ++i) out.emplace_back(kPointRows, s(i));
        } else if constexpr (std::is_same_v<O, PixelObservation>) {
          const auto s = diag_sigma(o.weight);
          for (int i = 0; i < 2; ++i) out.emplace_back(kPixelRows, s(i));
        } else {
          out.emplace_back(kProbeRows, o.sigma);
        }
      },
      obs);
  return out;
}

double median_of(std::vector<double> v) {
  return core::median(std::move(v), 0.0);
}

void add_noise_warnings(const NoiseEstimate& noise, bool applied,
                        std::vector<std::string>& warnings) {
  for (const auto& g : noise.groups) {
    if (!g.estimable || g.rows == 0) continue;
    const bool over = g.scale_high < 1.0 && g.scale < 1.0 / 1.5;
    const bool under = g.scale_low > 1.0 && g.scale > 1.5;
    if (!over && !under) continue;
    warnings.push_back(fmt::format(
        "{} noise {}: stated {}, the residuals show {} ({:.2g}x, 95 % interval {:.2g}-{:.2g}x "
        "from {:.0f} degrees of freedom); {}",
        g.type, over ? "overstated" : "understated", sigma_text(g.stated_sigma, g.unit),
        sigma_text(g.estimated_sigma(), g.unit), g.scale, g.scale_low, g.scale_high, g.redundancy,
        applied ? "uncertainties use the estimated noise (--stated-noise keeps the stated one)"
                : "uncertainties keep the stated noise as asked, so they are " +
                      std::string(over ? "pessimistic" : "optimistic")));
  }
}

std::vector<double> robust_row_scales(const Eigen::VectorXd& r, const std::vector<int>& row_group,
                                      std::size_t groups, int rows) {
  std::vector<std::vector<double>> by_group(groups);
  for (int i = 0; i < rows; ++i)
    by_group[static_cast<std::size_t>(row_group[static_cast<std::size_t>(i)])].push_back(
        std::abs(r(i)));
  std::vector<double> scale(groups, 1.0);
  for (std::size_t g = 0; g < groups; ++g) {
    auto& v = by_group[g];
    if (v.empty()) continue;
    auto mid = v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2);
    std::nth_element(v.begin(), mid, v.end());
    if (*mid > 0.0) scale[g] = 1.4826 * *mid;
  }
  return scale;
}

namespace {

// Each accepted pose's whitened residual block and its position and orientation errors at the
// estimate (PoseResidual), in the order of the pose blocks.
std::vector<PoseResidual> pose_residuals(const FramePredictor& model, const Assembly& as,
                                         const EstimateRows& at) {
  const Eigen::VectorXd& best = at.params;
  const Eigen::VectorXd& rb = at.residuals;
  const auto& pose_rows = at.pose_rows;
  std::vector<PoseResidual> per_pose;
  std::size_t cost_index = 0;
  for (const auto* pose : as.poses) {
    if (pose->observations.empty()) continue;
    const auto [start_row, count] = pose_rows[cost_index++];
    PoseResidual pr;
    pr.id = pose->id;
    pr.whitened = rb.segment(start_row, count);
    FramePrediction pred;
    std::string why;
    model.predict(best, pose->actuators, as.slot_of.at(pose->id), false, pred, why);
    for (const auto& obs : pose->observations) {
      if (auto p = observed_position(obs))
        pr.position_error = std::max(pr.position_error, (pred.pose.translation() - *p).norm());
      if (const auto* po = std::get_if<PoseObservation>(&obs))
        pr.orientation_error =
            Eigen::AngleAxisd(pred.pose.linear() * po->measured_rotation.transpose()).angle();
      if (const auto* ph = std::get_if<ProbeHeightObservation>(&obs))
        pr.position_error = std::max(
            pr.position_error,
            std::abs(ph->normal.dot(pred.pose.translation()) - ph->offset - ph->measured_height));
    }
    per_pose.push_back(std::move(pr));
  }
  return per_pose;
}

// The rows the covariance and the noise estimate are computed from: the estimated parameters'
// columns of the inlier rows (outliers flagged by the robust fit do not inform it), then one row
// per prior.
struct CovarianceRows {
  Eigen::MatrixXd Je;
  Eigen::VectorXd re;
  std::vector<int> je_group;      // observation type of each row (-1: a prior)
  std::vector<bool> pose_in_fit;  // per pose block: its rows are among them
};

CovarianceRows covariance_rows(const Eigen::VectorXd& nominal, const Assembly& as,
                               const EstimateRows& at, const SolveOptions& options,
                               const IdentificationResult& result) {
  const Eigen::VectorXd& best = at.params;
  const Eigen::VectorXd& rb = at.residuals;
  const Eigen::MatrixXd& Jb = at.jacobian;
  const auto& pose_rows = at.pose_rows;
  const auto& prior_terms = at.prior_terms;
  std::vector<Eigen::Index> keep_rows;
  std::vector<bool> pose_in_fit(pose_rows.size(), true);
  for (std::size_t k = 0; k < pose_rows.size(); ++k) {
    if (options.robust_loss != RobustLoss::kNone && result.residuals.poses[k].outlier) {
      pose_in_fit[k] = false;
      continue;
    }
    for (int i = 0; i < pose_rows[k].second; ++i) keep_rows.push_back(pose_rows[k].first + i);
  }
  for (Eigen::Index i = pose_rows.empty() ? 0 : pose_rows.back().first + pose_rows.back().second;
       i < Jb.rows(); ++i)
    keep_rows.push_back(i);
  const auto n_est = static_cast<Eigen::Index>(result.estimated.size());
  CovarianceRows rows;
  Eigen::MatrixXd& Je = rows.Je;
  Je.resize(
      static_cast<Eigen::Index>(keep_rows.size()) + static_cast<Eigen::Index>(prior_terms.size()),
      n_est);
  Eigen::VectorXd& re = rows.re;
  re.resize(Je.rows());
  std::vector<int>& je_group = rows.je_group;
  Je.setZero();
  for (std::size_t k = 0; k < keep_rows.size(); ++k) {
    for (Eigen::Index c = 0; c < n_est; ++c)
      Je(static_cast<Eigen::Index>(k), c) = Jb(
          keep_rows[k], static_cast<Eigen::Index>(result.estimated[static_cast<std::size_t>(c)]));
    re(static_cast<Eigen::Index>(k)) = rb(keep_rows[k]);
    je_group.push_back(as.row_group[static_cast<std::size_t>(keep_rows[k])]);
  }
  for (std::size_t t = 0; t < prior_terms.size(); ++t) {
    const auto row = static_cast<Eigen::Index>(keep_rows.size() + t);
    const auto it =
        std::find(result.estimated.begin(), result.estimated.end(), prior_terms[t].first);
    Je(row, it - result.estimated.begin()) = 1.0 / prior_terms[t].second;
    re(row) = (best(static_cast<Eigen::Index>(prior_terms[t].first)) -
               nominal(static_cast<Eigen::Index>(prior_terms[t].first))) /
              prior_terms[t].second;
    je_group.push_back(-1);  // a prior is information, not noise to estimate
  }
  rows.pose_in_fit = std::move(pose_in_fit);
  return rows;
}

// The noise per observation type estimated from the residuals (applied unless the stated noise
// is declared known) and the parameters' covariance with it.
void noise_and_covariance(const Assembly& as, const CovarianceRows& rows,
                          const SolveOptions& options, IdentificationResult& result) {
  const Eigen::MatrixXd& Je = rows.Je;
  const Eigen::VectorXd& re = rows.re;
  // A posteriori noise per observation type (noise_estimate.hpp); applied to the covariance
  // unless the stated noise is declared known.
  result.noise = estimate_noise(Je, re, rows.je_group, as.groups);
  Eigen::VectorXd row_scale = Eigen::VectorXd::Ones(Je.rows());
  if (result.noise.ok) {
    result.noise_applied = !options.keep_stated_noise &&
                           std::any_of(result.noise.groups.begin(), result.noise.groups.end(),
                                       [](const NoiseGroup& g) { return g.estimable; });
    if (result.noise_applied) row_scale = result.noise.row_scale;
    add_noise_warnings(result.noise, result.noise_applied, result.warnings);
  }
  std::vector<std::string> est_names;
  for (std::size_t i : result.estimated) est_names.push_back(result.names[i]);
  result.uncertainty = parameter_uncertainty(row_scale.cwiseInverse().asDiagonal() * Je, est_names,
                                             options.covariance, re.cwiseQuotient(row_scale));
  if (result.noise_applied && result.uncertainty.ok) {
    // One observation type: the classical variance factor; several: per-type, see `noise`.
    int estimable = 0;
    double factor = 1.0;
    for (const auto& g : result.noise.groups)
      if (g.estimable) {
        ++estimable;
        factor = g.scale * g.scale;
      }
    if (estimable == 1) result.uncertainty.variance_factor *= factor;
  }
}

// Final outlier test on normalised residuals: each pose's whitened residual divided by its
// type's noise scale (the robust one when asked), tested against its own covariance
// I ∓ J_b C J_bᵀ, so leverage and any mix of σ are accounted for.
void normalised_outlier_test(const Assembly& as, const EstimateRows& at,
                             const std::vector<bool>& pose_in_fit, const SolveOptions& options,
                             std::vector<PoseResidual>& per_pose, IdentificationResult& result) {
  const Eigen::MatrixXd& Jb = at.jacobian;
  const auto& pose_rows = at.pose_rows;
  const auto n_est = static_cast<Eigen::Index>(result.estimated.size());
  const auto& groups = result.noise.groups;  // same order as as.groups
  auto test_scale_of = [&](const NoiseGroup& g) {
    return options.outliers.robust_scale ? g.robust_scale : result.noise_applied ? g.scale : 1.0;
  };
  // normal_inverse is in the reweighted problem's units (rows / row_scale).
  // C = S Sᵀ for the factored form (PoseResidual::leverage_factor = J_b S).
  const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> c_eig(result.noise.normal_inverse);
  const Eigen::MatrixXd c_root =
      c_eig.eigenvectors() * c_eig.eigenvalues().cwiseMax(0.0).cwiseSqrt().asDiagonal();
  for (std::size_t k = 0; k < per_pose.size(); ++k) {
    const auto [start_row, count] = pose_rows[k];
    Eigen::MatrixXd Jp(count, n_est);
    Eigen::VectorXd fit_scale(count);
    Eigen::VectorXd test_scale(count);
    for (int i = 0; i < count; ++i) {
      const auto& g =
          groups[static_cast<std::size_t>(as.row_group[static_cast<std::size_t>(start_row + i)])];
      fit_scale(i) = g.scale;
      test_scale(i) = test_scale_of(g);
      for (Eigen::Index c = 0; c < n_est; ++c)
        Jp(i, c) = Jb(start_row + i,
                      static_cast<Eigen::Index>(result.estimated[static_cast<std::size_t>(c)])) /
                   fit_scale(i);
    }
    // Residual covariance in units of the fit scale, then re-expressed in the test scale.
    const Eigen::VectorXd ratio = fit_scale.cwiseQuotient(test_scale);
    const bool one_ratio =
        count > 0 && ratio.maxCoeff() - ratio.minCoeff() <= 1e-12 * ratio.cwiseAbs().maxCoeff();
    if (one_ratio) {
      // One noise scale in the block (e.g. all pixel rows): the factored form, exact and cheap.
      per_pose[k].leverage_factor = Jp * c_root;
      per_pose[k].leverage_sign = pose_in_fit[k] ? -1.0 : 1.0;
      per_pose[k].covariance_factor = ratio(0) * ratio(0);
    } else {
      per_pose[k].residual_covariance =
          ratio.asDiagonal() *
          pose_residual_covariance(Jp, result.noise.normal_inverse, pose_in_fit[k]) *
          ratio.asDiagonal();
    }
    per_pose[k].whitened = per_pose[k].whitened.cwiseQuotient(test_scale);
  }
  result.residuals = diagnose_residuals(per_pose, options.outliers);
}

// The end-effector accuracy predicted from the covariance at the measured poses.
void predicted_accuracy_at(const FramePredictor& model, const Assembly& as, const EstimateRows& at,
                           IdentificationResult& result) {
  const Eigen::VectorXd& best = at.params;
  const auto n_est = static_cast<Eigen::Index>(result.estimated.size());
  if (result.uncertainty.ok) {
    std::vector<Eigen::MatrixXd> frame_jacobians;
    for (const auto* pose : as.poses) {
      FramePrediction pred;
      std::string why;
      if (!model.predict(best, pose->actuators, as.slot_of.at(pose->id), true, pred, why)) continue;
      Eigen::MatrixXd Js(6, n_est);
      for (Eigen::Index c = 0; c < n_est; ++c)
        Js.col(c) = pred.jacobian.col(
            static_cast<Eigen::Index>(result.estimated[static_cast<std::size_t>(c)]));
      frame_jacobians.push_back(std::move(Js));
    }
    result.predicted = predict_accuracy(frame_jacobians, result.uncertainty.covariance);
  } else {
    result.warnings.push_back("no covariance: " + result.uncertainty.message);
  }
}

// Warnings on the fit as a whole: residuals far above the stated noise, no redundancy left,
// poses flagged as outliers.
void add_fit_warnings(const Assembly& as, const EstimateRows& at, IdentificationResult& result) {
  const auto& prior_terms = at.prior_terms;
  const auto n_est = static_cast<Eigen::Index>(result.estimated.size());
  {
    // Goodness of fit: ‖r‖² should be near the degrees of freedom when the model and the stated
    // noise are right. Far above it means a local minimum, a wrong model or optimistic noise.
    const double dof = std::max(1.0, static_cast<double>(as.rows) - static_cast<double>(n_est));
    const double ratio = 2.0 * result.final_cost / dof;
    if (ratio > 25.0)
      result.warnings.push_back(fmt::format(
          "the residuals are {:.3g} times larger than the stated measurement noise (reduced "
          "chi-square {:.3g}): a local minimum (try multi-start), an unmodelled error or "
          "optimistic noise",
          std::sqrt(ratio), ratio));
    if (prior_terms.empty() && static_cast<double>(as.rows) <= static_cast<double>(n_est))
      result.warnings.push_back(fmt::format(
          "no redundancy: {} equations for {} estimated parameters, so the fit passes through "
          "every measurement exactly; neither the noise nor outliers can be checked (measure a "
          "few more points)",
          as.rows, n_est));
  }
  if (result.residuals.outliers > 0)
    result.warnings.push_back(
        fmt::format("{} poses flagged as outliers", result.residuals.outliers));
}

}  // namespace

void diagnose_estimate(const FramePredictor& model, const Eigen::VectorXd& nominal,
                       const Assembly& as, const EstimateRows& at,
                       const std::vector<DistanceMeasurement>& distances,
                       const SolveOptions& options, IdentificationResult& result) {
  std::vector<PoseResidual> per_pose = pose_residuals(model, as, at);
  // Provisional flags (stated noise, robust scale): only used to leave the poses a robust loss
  // rejected out of the covariance; the final test below uses normalised residuals.
  result.residuals = diagnose_residuals(per_pose, options.outliers);
  const CovarianceRows rows = covariance_rows(nominal, as, at, options, result);
  noise_and_covariance(as, rows, options, result);
  if (result.noise.ok) normalised_outlier_test(as, at, rows.pose_in_fit, options, per_pose, result);
  result.residuals.by_type = residuals_by_type(model, at.params, as.poses, as.slot_of, distances);
  predicted_accuracy_at(model, as, at, result);
  add_fit_warnings(as, at, result);
}

}  // namespace robocal::calib::detail
