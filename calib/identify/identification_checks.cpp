// The input checks of identify(): readings and observations that cannot enter the fit, pixel
// groups that do not fit their pose, corners that cannot be projected at the start, and
// measurements whose units are off by 1000.
#include "identification_detail.hpp"

#include <fmt/core.h>

#include <algorithm>
#include <cmath>
#include <optional>
#include <string>
#include <type_traits>
#include <variant>

namespace robocal::calib::detail {
namespace {

// RMS distance of the points from their centroid.
double spread(const std::vector<Eigen::Vector3d>& pts) {
  Eigen::Vector3d c = Eigen::Vector3d::Zero();
  for (const auto& p : pts) c += p;
  c /= static_cast<double>(pts.size());
  double s = 0.0;
  for (const auto& p : pts) s += (p - c).squaredNorm();
  return std::sqrt(s / static_cast<double>(pts.size()));
}

}  // namespace

bool finite_observation(const Observation& obs) {
  return std::visit(
      [](const auto& o) {
        using O = std::decay_t<decltype(o)>;
        if constexpr (std::is_same_v<O, PoseObservation>)
          return o.measured_position.allFinite() && o.measured_rotation.allFinite() &&
                 o.weight.allFinite();
        else if constexpr (std::is_same_v<O, PointObservation>)
          return o.measured.allFinite() && o.weight.allFinite();
        else if constexpr (std::is_same_v<O, PixelObservation>)
          return o.measured.allFinite() && o.point.allFinite() && o.weight.allFinite();
        else
          return std::isfinite(o.measured_height) && std::isfinite(o.offset) &&
                 o.normal.allFinite() && std::isfinite(o.sigma) && o.sigma > 0.0;
      },
      obs);
}

bool valid_pixel_groups(const PoseMeasurement& pose, std::string& why) {
  const auto n = static_cast<int>(pose.observations.size());
  std::vector<bool> grouped(pose.observations.size(), false);
  for (std::size_t k = 0; k < pose.pixel_groups.size(); ++k) {
    const PixelGroup& g = pose.pixel_groups[k];
    const auto size = static_cast<Eigen::Index>(2 * g.count);
    if (g.count < 1 || g.first < 0 || g.first + g.count > n || g.decorrelation.rows() != size ||
        g.decorrelation.cols() != size || !g.decorrelation.allFinite()) {
      why = fmt::format(
          "pixel group {} (observations {}..{}) does not fit the pose's {} "
          "observations or its decorrelation is not {}x{} and finite",
          k, g.first, g.first + g.count - 1, n, size, size);
      return false;
    }
    for (int i = g.first; i < g.first + g.count; ++i) {
      const auto at = static_cast<std::size_t>(i);
      if (!std::holds_alternative<PixelObservation>(pose.observations[at])) {
        why = fmt::format(
            "pixel group {} includes observation {}, which is not a pixel observation", k, i);
        return false;
      }
      if (grouped[at]) {
        why = fmt::format("pixel group {} includes observation {}, already in another group", k, i);
        return false;
      }
      grouped[at] = true;
    }
  }
  return true;
}

bool pixels_project(const FramePredictor& model, const Eigen::VectorXd& params,
                    const PoseMeasurement& pose, const FramePrediction& pred, std::string& why) {
  for (const auto& obs : pose.observations) {
    const auto* px = std::get_if<PixelObservation>(&obs);
    if (px == nullptr) continue;
    Eigen::Vector2d r;
    std::string reason;
    if (!model.pixel_residual(*px, params, pred, r, nullptr, reason)) {
      why = fmt::format("pixel observation of corner {} in camera {} unusable at the start: {}",
                        px->corner, px->camera, reason);
      return false;
    }
  }
  return true;
}

std::optional<std::string> position_units_mismatch(const MeasuredAndPredicted& positions) {
  if (positions.measured.size() >= 3) {
    const double ratio = spread(positions.measured) / std::max(spread(positions.predicted), 1e-300);
    if (ratio > 300.0 || ratio < 1.0 / 300.0)
      return fmt::format(
          "the measured positions spread {:.4g} times as far as the model predicts: units are "
          "probably mismatched by 1000 (millimetres vs metres); convert the measurements to metres",
          ratio);
  }
  return std::nullopt;
}

std::optional<std::string> probe_height_units_mismatch(const FramePredictor& model,
                                                       const Eigen::VectorXd& nominal,
                                                       const Assembly& as) {
  std::vector<double> misfit;
  std::vector<double> misfit_mm;
  const PoseMeasurement* worst = nullptr;
  double worst_misfit = 0.0;
  for (const auto* pose : as.poses) {
    FramePrediction pred;
    std::string why;
    if (!model.predict(nominal, pose->actuators, as.slot_of.at(pose->id), false, pred, why))
      continue;
    for (const auto& obs : pose->observations)
      if (const auto* ph = std::get_if<ProbeHeightObservation>(&obs)) {
        const double predicted = ph->normal.dot(pred.pose.translation()) - ph->offset;
        misfit.push_back(std::abs(ph->measured_height - predicted));
        misfit_mm.push_back(std::abs(1e-3 * ph->measured_height - predicted));
        if (misfit.back() > worst_misfit) {
          worst_misfit = misfit.back();
          worst = pose;
        }
      }
  }
  if (!misfit.empty() && median_of(misfit) > 0.05 && median_of(misfit_mm) < 0.01)
    return fmt::format(
        "probe heights are implausible in metres: median {:.3g} m from the nominal model, {:.3g} "
        "m if they were millimetres (largest at pose '{}'{}); declare units: {{length: mm}} or "
        "convert them",
        median_of(misfit), median_of(misfit_mm), worst->id,
        worst->line > 0 ? fmt::format(", line {}", worst->line) : "");
  return std::nullopt;
}

}  // namespace robocal::calib::detail
