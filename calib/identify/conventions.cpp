#include "robocal/calib/conventions.hpp"

#include "robocal/core/median.hpp"

#include <fmt/core.h>

#include <algorithm>
#include <cmath>
#include <functional>
#include <vector>

namespace robocal::calib {
namespace {

struct Observed {
  std::size_t pose = 0;
  Eigen::Vector3d position;
  std::optional<Eigen::Matrix3d> rotation;
};

// Median over pose pairs of |measured − predicted| pairwise distance and relative-rotation angle:
// invariant to the unknown base and tool frames.
struct Misfit {
  double position = NAN;
  double angle = NAN;
};

Misfit misfit(const std::vector<Observed>& obs,
              const std::vector<std::optional<Eigen::Isometry3d>>& pred) {
  std::vector<double> dp;
  std::vector<double> da;
  const std::size_t n = obs.size();
  // Every pose with a few partners spread through the list: O(n) pairs, order-independent enough.
  for (std::size_t i = 0; i < n; ++i)
    for (std::size_t step : {std::size_t{1}, n / 3 + 1, n / 2 + 1}) {
      const std::size_t j = (i + step) % n;
      if (j == i || !pred[i] || !pred[j]) continue;
      const double dm = (obs[i].position - obs[j].position).norm();
      const double dq = (pred[i]->translation() - pred[j]->translation()).norm();
      dp.push_back(std::abs(dm - dq));
      if (obs[i].rotation && obs[j].rotation) {
        // The relative rotation's world axis against the displacement: both turn with the base
        // frame, so their angle does not depend on it (the rotation angle alone would not see a
        // quaternion order swap: it depends only on the 4-D dot product of the quaternions).
        const Eigen::AngleAxisd rm(*obs[i].rotation * obs[j].rotation->transpose());
        const Eigen::AngleAxisd rq(pred[i]->linear() * pred[j]->linear().transpose());
        const Eigen::Vector3d um = obs[i].position - obs[j].position;
        const Eigen::Vector3d uq = pred[i]->translation() - pred[j]->translation();
        if (rq.angle() > 0.1 && uq.norm() > 0.01 && um.norm() > 0.01 && rm.angle() > 1e-3) {
          const double am = std::acos(std::clamp(rm.axis().dot(um.normalized()), -1.0, 1.0));
          const double aq = std::acos(std::clamp(rq.axis().dot(uq.normalized()), -1.0, 1.0));
          da.push_back(std::abs(am - aq) + std::abs(rm.angle() - rq.angle()));
        }
      }
    }
  return {core::median(dp, NAN), core::median(da, NAN)};
}

}  // namespace

std::optional<ConventionMismatch> check_conventions(const FramePredictor& model,
                                                    const Eigen::VectorXd& nominal,
                                                    const Measurements& measurements, double ratio,
                                                    double min_misfit_position,
                                                    double min_misfit_angle) {
  std::vector<Observed> obs;
  for (std::size_t k = 0; k < measurements.poses.size() && obs.size() < 200; ++k) {
    const auto& pose = measurements.poses[k];
    if (!pose.actuators.allFinite()) continue;
    for (const auto& o : pose.observations) {
      if (const auto* po = std::get_if<PoseObservation>(&o)) {
        if (po->measured_position.allFinite() && po->measured_rotation.allFinite())
          obs.push_back({k, po->measured_position, po->measured_rotation});
        break;
      }
      if (const auto* pt = std::get_if<PointObservation>(&o)) {
        if (pt->measured.allFinite()) obs.push_back({k, pt->measured, std::nullopt});
        break;
      }
    }
  }
  if (obs.size() < 4) return std::nullopt;
  auto predict_all = [&](const std::function<Eigen::VectorXd(const Eigen::VectorXd&)>& readings) {
    std::vector<std::optional<Eigen::Isometry3d>> out;
    for (const auto& o : obs) {
      FramePrediction fp;
      std::string why;
      const Eigen::VectorXd q = readings(measurements.poses[o.pose].actuators);
      if (model.predict(nominal, q, -1, false, fp, why))
        out.emplace_back(fp.pose);
      else
        out.emplace_back(std::nullopt);
    }
    return out;
  };
  const auto identity = [](const Eigen::VectorXd& q) { return q; };
  const auto as_declared = predict_all(identity);
  const Misfit declared = misfit(obs, as_declared);

  auto decide = [&](const std::string& declared_text, const std::string& alt_text,
                    const Misfit& alt, bool use_angle,
                    const std::string& advice) -> std::optional<ConventionMismatch> {
    const double d = use_angle ? declared.angle : declared.position;
    const double a = use_angle ? alt.angle : alt.position;
    const double floor = use_angle ? min_misfit_angle : min_misfit_position;
    if (!std::isfinite(d) || !std::isfinite(a) || d < floor || a * ratio > d) return std::nullopt;
    ConventionMismatch m;
    m.declared = declared_text;
    m.alternative = alt_text;
    m.declared_misfit = d;
    m.alternative_misfit = a;
    const auto amount = [&](double v) {
      return use_angle ? fmt::format("{:.3g} deg", v * 180.0 / M_PI)
                       : fmt::format("{:.3g} mm", v * 1e3);
    };
    m.message = fmt::format(
        "the data fit the nominal model far better read as {} than as declared ({}): median "
        "mismatch of the pose-to-pose {} {} vs {}; {}",
        alt_text, declared_text, use_angle ? "rotation angles" : "distances", amount(a), amount(d),
        advice);
    return m;
  };

  // Quaternion order: numbers [x, y, z, w] read as [w, x, y, z].
  {
    std::vector<Observed> alt = obs;
    bool any = false;
    for (auto& o : alt)
      if (o.rotation) {
        const Eigen::Quaterniond q(*o.rotation);  // (w, x, y, z) as read = file (a, b, c, d)
        o.rotation = Eigen::Quaterniond(q.z(), q.w(), q.x(), q.y()).normalized().toRotationMatrix();
        any = true;
      }
    if (any)
      if (auto m = decide("quaternions [w, x, y, z]", "quaternions [x, y, z, w] (w last)",
                          misfit(alt, as_declared), true,
                          "write quaternions w first, or use 'quaternion_xyzw:' for w-last data"))
        return m;
  }
  // Readings in degrees where the model expects radians (and millimetres where it expects m).
  for (const auto& [factor, text, advice] :
       {std::tuple{M_PI / 180.0, "actuator readings in degrees",
                   "convert the readings to the robot file's encoder units (radians), or set the "
                   "encoder scale in the robot file"},
        std::tuple{1e-3, "actuator readings in millimetres",
                   "convert the readings to metres, or set the encoder scale in the robot file"}}) {
    const auto alt =
        predict_all([f = factor](const Eigen::VectorXd& q) { return Eigen::VectorXd(q * f); });
    const Misfit m_alt = misfit(obs, alt);
    if (auto m = decide("actuator readings in the robot file's units", text, m_alt, false, advice))
      return m;
  }
  // Poses given the other way round (target→camera instead of camera→target).
  {
    std::vector<Observed> alt = obs;
    bool all = true;
    for (auto& o : alt) {
      if (!o.rotation) {
        all = false;
        break;
      }
      Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
      T.linear() = *o.rotation;
      T.translation() = o.position;
      const Eigen::Isometry3d inv = T.inverse();
      o.position = inv.translation();
      o.rotation = inv.linear();
    }
    if (all)
      if (auto m = decide("poses of the measured frame in the world",
                          "inverted poses (the world in "
                          "the measured frame, e.g. target->camera for camera->target)",
                          misfit(alt, as_declared), false,
                          "invert the poses before writing them (position and rotation of the "
                          "measured frame in the instrument's frame)"))
        return m;
  }
  return std::nullopt;
}

}  // namespace robocal::calib
