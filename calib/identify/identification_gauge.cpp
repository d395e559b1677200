// With little data, which confounded candidates identify() holds at nominal (the gauge):
// gauge_choice.hpp weighed over the predictions across the measured area.
#include "identification_detail.hpp"

#include "robocal/calib/gauge_choice.hpp"

#include <fmt/core.h>

#include <cmath>

namespace robocal::calib::detail {
namespace {

// Predicted quantities over the measured area, as whitened rows (candidate columns): every
// observation of each measured pose, at that pose and at the quarter points between every two of
// them in actuator space (at most 16 poses spread over the list; pixel poses are skipped).
Eigen::MatrixXd measured_area_rows(const FramePredictor& model, const Eigen::VectorXd& params,
                                   const std::vector<const PoseMeasurement*>& poses,
                                   const std::vector<std::size_t>& candidates) {
  std::vector<const PoseMeasurement*> used;
  for (const auto* pose : poses)
    if (!pose->observations.empty() && pose->pixel_groups.empty()) used.push_back(pose);
  constexpr std::size_t kMaxPoses = 16;
  if (used.size() > kMaxPoses) {
    std::vector<const PoseMeasurement*> spread_out;
    for (std::size_t k = 0; k < kMaxPoses; ++k)
      spread_out.push_back(used[k * (used.size() - 1) / (kMaxPoses - 1)]);
    used = std::move(spread_out);
  }
  Measurements area;
  for (std::size_t i = 0; i < used.size(); ++i) {
    area.poses.push_back({"area", used[i]->actuators, used[i]->observations});
    for (std::size_t j = i + 1; j < used.size(); ++j)
      for (const double t : {0.25, 0.5, 0.75})
        area.poses.push_back({"area", (1.0 - t) * used[i]->actuators + t * used[j]->actuators,
                              used[i]->observations});
  }
  Eigen::MatrixXd rows(0, static_cast<Eigen::Index>(candidates.size()));
  for (const auto& pose : area.poses) {
    Measurements one;
    one.poses.push_back(pose);
    Eigen::MatrixXd J;
    std::string why;
    if (!identification_jacobian(model, params, one, J, why)) continue;  // outside the workspace
    const Eigen::Index n = rows.rows();
    rows.conservativeResize(n + J.rows(), Eigen::NoChange);
    for (std::size_t k = 0; k < candidates.size(); ++k)
      rows.col(static_cast<Eigen::Index>(k)).segment(n, J.rows()) =
          J.col(static_cast<Eigen::Index>(candidates[k]));
  }
  return rows;
}

}  // namespace

std::string choose_little_data_gauge(const FramePredictor& model, const Eigen::VectorXd& params,
                                     const std::vector<const PoseMeasurement*>& poses,
                                     const Eigen::MatrixXd& Jc,
                                     const std::vector<std::size_t>& candidates,
                                     const std::vector<std::string>& cand_names,
                                     const SolveOptions& options, IdentifiabilityReport& report) {
  const Eigen::MatrixXd targets = measured_area_rows(model, params, poses, candidates);
  if (targets.rows() == 0) return "";
  Eigen::VectorXd sigma(static_cast<Eigen::Index>(candidates.size()));
  for (std::size_t k = 0; k < candidates.size(); ++k) {
    const double s =
        candidates[k] < options.gauge_sigma.size() ? options.gauge_sigma[candidates[k]] : 0.0;
    if (!(s > 0.0)) return "";  // no tolerance for a candidate: nothing to weigh
    sigma(static_cast<Eigen::Index>(k)) = s;
  }
  GaugeOptions gauge_options;
  gauge_options.rank_tolerance = options.identifiability.ill_conditioning_ratio;
  const GaugeChoice choice =
      choose_gauge(Jc, targets, sigma, report.identifiable, {}, report.no_effect, gauge_options);
  if (!std::isfinite(choice.expected_error)) return "";
  if (choice.changed) {
    // The analysis again with the chosen set visited first: it keeps exactly that set and
    // explains the others through it.
    IdentifiabilityOptions strict = options.identifiability;
    strict.rank_tolerance = gauge_options.rank_tolerance;
    strict.stable_tie_break = true;
    std::vector<int> preference(candidates.size(), 1);
    for (std::size_t k : choice.estimated) preference[k] = 0;
    IdentifiabilityReport redone = analyze_identifiability(Jc, cand_names, strict, preference);
    if (redone.identifiable != choice.estimated) return "";
    report = std::move(redone);
  }
  return fmt::format(
      "; they are the ones held because, off nominal by the robot file's tolerances, they move "
      "the predictions over the measured area least (expected prediction error {:.3g} x the "
      "measurement noise, of which their bias {:.3g}; the rank analysis' pivot order would hold "
      "{}: {:.3g}, bias {:.3g})",
      std::sqrt(choice.expected_error), std::sqrt(choice.bias),
      choice.changed ? "others" : "the same", std::sqrt(choice.initial_expected_error),
      std::sqrt(choice.initial_bias));
}

}  // namespace robocal::calib::detail
