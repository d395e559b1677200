#include "robocal/vision/scale_check.hpp"

#include "fit/board_pose.hpp"

#include <fmt/format.h>
#include <Eigen/Dense>

#include <cmath>
#include <map>
#include <stdexcept>

namespace robocal::vision {

bool triangulate_point(const std::vector<RigCamera>& rig,
                       const std::vector<std::pair<int, CornerObservation>>& observations,
                       double default_sigma_px, Eigen::Vector3d* point,
                       Eigen::Matrix3d* covariance) {
  if (observations.size() < 2) return false;
  // Start: the point closest (least squares) to all viewing rays.
  Eigen::Matrix3d A = Eigen::Matrix3d::Zero();
  Eigen::Vector3d b = Eigen::Vector3d::Zero();
  for (const auto& [c, obs] : observations) {
    const RigCamera& cam = rig[static_cast<size_t>(c)];
    const auto ray = unproject(cam.model, obs.pixel);
    if (!ray) return false;
    const Eigen::Isometry3d world_T_camera = cam.camera_T_world.inverse();
    const Eigen::Vector3d d = (world_T_camera.linear() * *ray).normalized();
    const Eigen::Matrix3d P = Eigen::Matrix3d::Identity() - d * d.transpose();
    A += P;
    b += P * world_T_camera.translation();
  }
  const Eigen::FullPivLU<Eigen::Matrix3d> lu(A);
  if (lu.rank() < 3) return false;
  Eigen::Vector3d X = lu.solve(b);
  // Gauss-Newton on the whitened reprojection error.
  Eigen::Matrix3d H = Eigen::Matrix3d::Zero();
  for (int it = 0; it < 10; ++it) {
    H.setZero();
    Eigen::Vector3d g = Eigen::Vector3d::Zero();
    for (const auto& [c, obs] : observations) {
      const RigCamera& cam = rig[static_cast<size_t>(c)];
      Eigen::Vector2d px;
      Eigen::Matrix<double, 2, 3> J;
      if (!project_jacobians(cam.model, cam.camera_T_world * X, &px, &J, nullptr)) return false;
      const Eigen::Matrix<double, 2, 3> Jw = J * cam.camera_T_world.linear();
      const double s = detail::sigma_or(obs.sigma_px, default_sigma_px);
      H += Jw.transpose() * Jw / (s * s);
      g += Jw.transpose() * (px - obs.pixel) / (s * s);
    }
    const Eigen::Vector3d step = H.ldlt().solve(-g);
    X += step;
    if (step.norm() < 1e-12) break;
  }
  const Eigen::LDLT<Eigen::Matrix3d> ldlt(H);
  if (ldlt.info() != Eigen::Success || !ldlt.isPositive()) return false;
  *point = X;
  if (covariance) *covariance = ldlt.solve(Eigen::Matrix3d::Identity());
  return true;
}

ScaleCheck check_scale(const std::vector<RigCamera>& rig, const ScaleBar& bar,
                       const std::vector<std::vector<CameraFrame>>& frames,
                       const ScaleCheckOptions& options) {
  if (bar.corners_a.empty() || bar.corners_b.empty() || !(bar.certified_length_m > 0.0))
    throw std::invalid_argument(fmt::format(
        "scale bar '{}': needs corner ids for both ends and a positive certified length",
        bar.name));
  ScaleCheck out;
  double wsum = 0.0, wlen = 0.0;
  for (size_t f = 0; f < frames.size(); ++f) {
    if (frames[f].size() != rig.size())
      throw std::invalid_argument(
          fmt::format("scale check: frame {} has {} camera frames, the rig "
                      "has {} cameras",
                      f, frames[f].size(), rig.size()));
    ScaleBarFrame fr;
    // Observations of every corner by camera.
    std::map<int, std::vector<std::pair<int, CornerObservation>>> seen;
    for (size_t c = 0; c < rig.size(); ++c)
      for (const CornerObservation& o : frames[f][c].corners)
        if (o.pixel.allFinite()) seen[o.id].emplace_back(static_cast<int>(c), o);
    Eigen::Vector3d ends[2];
    Eigen::Matrix3d end_cov[2];
    bool ok = true;
    for (int e = 0; e < 2 && ok; ++e) {
      const std::vector<int>& ids = e == 0 ? bar.corners_a : bar.corners_b;
      ends[e].setZero();
      end_cov[e].setZero();
      for (int id : ids) {
        Eigen::Vector3d X;
        Eigen::Matrix3d C;
        const auto it = seen.find(id);
        if (it == seen.end() || it->second.size() < 2) {
          fr.message = fmt::format("corner {} seen by fewer than 2 cameras", id);
          ok = false;
          break;
        }
        if (!triangulate_point(rig, it->second, options.default_sigma_px, &X, &C)) {
          fr.message = fmt::format("corner {} cannot be triangulated", id);
          ok = false;
          break;
        }
        ends[e] += X / static_cast<double>(ids.size());
        end_cov[e] += C / static_cast<double>(ids.size() * ids.size());
      }
    }
    if (ok) {
      const Eigen::Vector3d d = ends[1] - ends[0];
      fr.length_m = d.norm();
      const Eigen::Vector3d u = d / fr.length_m;
      fr.sigma_m = std::sqrt(u.dot((end_cov[0] + end_cov[1]) * u));
      fr.ok = fr.sigma_m > 0.0;
      if (fr.ok) {
        const double w = 1.0 / (fr.sigma_m * fr.sigma_m);
        wsum += w;
        wlen += w * fr.length_m;
      }
    }
    out.frames.push_back(fr);
  }
  if (wsum <= 0.0) {
    out.message = fmt::format(
        "scale bar '{}' was not measured in any of the {} frames (both ends must be seen by at "
        "least two cameras){}",
        bar.name, frames.size(),
        out.frames.empty() ? std::string() : ": frame 0: " + out.frames[0].message);
    return out;
  }
  out.ok = true;
  out.measured_length_m = wlen / wsum;
  out.measured_sigma_m = std::sqrt(1.0 / wsum);
  const double L = bar.certified_length_m;
  out.scale_factor = L / out.measured_length_m;
  const double rel =
      std::hypot(out.measured_sigma_m / out.measured_length_m, bar.certified_sigma_m / L);
  out.scale_factor_sigma = out.scale_factor * rel;
  out.discrepancy = out.measured_length_m / L - 1.0;
  out.scale_error = std::abs(out.discrepancy) > options.significance * rel &&
                    std::abs(out.discrepancy) > options.tolerance;
  if (out.scale_error) {
    out.verdict = fmt::format(
        "SCALE ERROR: the rig measures scale bar '{}' as {:.4f} mm, certified {:.4f} mm: rig "
        "lengths are {:+.3f} % +- {:.3f} % off. The {} was probably printed at {:.2f} % of its "
        "nominal size; re-measure the board or correct the rig scale by x{:.6f}",
        bar.name, out.measured_length_m * 1e3, L * 1e3, 100.0 * out.discrepancy, 100.0 * rel,
        options.calibration_board_name, 100.0 * out.scale_factor, out.scale_factor);
  } else {
    out.verdict = fmt::format(
        "scale ok: the rig measures scale bar '{}' as {:.4f} mm, certified {:.4f} mm ({:+.4f} % "
        "+- {:.4f} %)",
        bar.name, out.measured_length_m * 1e3, L * 1e3, 100.0 * out.discrepancy, 100.0 * rel);
  }
  int bad = 0;
  for (const auto& fr : out.frames) bad += fr.ok ? 0 : 1;
  if (bad > 0) out.message = fmt::format("{} of {} frames not usable", bad, out.frames.size());
  return out;
}

}  // namespace robocal::vision
