// Residuals and noise of identify(): which observation type each residual row belongs to, the
// fit residuals per type, the outlier-proof scales for the robust loss, and plain-words warnings
// when the stated noise does not match the residuals.
#include "identification_detail.hpp"

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
  if (v.empty()) return 0.0;
  auto mid = v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2);
  std::nth_element(v.begin(), mid, v.end());
  return *mid;
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

}  // namespace robocal::calib::detail
