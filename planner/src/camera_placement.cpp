// Camera placement for a working volume (see camera_placement.hpp).
#include "robocal/planner/camera_placement.hpp"

#include "robocal/planner/feasibility.hpp"
#include "robocal/planner/plan.hpp"

#include <algorithm>
#include <cmath>
#include <random>
#include <sstream>
#include <stdexcept>

namespace robocal::planner {
namespace {

// world_T_camera at `eye` looking at `at`, image up close to `up`.
Eigen::Isometry3d look_at(const Eigen::Vector3d& eye, const Eigen::Vector3d& at,
                          Eigen::Vector3d up) {
  const Eigen::Vector3d z = (at - eye).normalized();
  if (std::abs(z.dot(up.normalized())) > 0.99)
    up = std::abs(z.x()) < 0.9 ? Eigen::Vector3d::UnitX() : Eigen::Vector3d::UnitY();
  const Eigen::Vector3d x = (-up).cross(z).normalized();
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear().col(0) = x;
  T.linear().col(1) = z.cross(x);
  T.linear().col(2) = z;
  T.translation() = eye;
  return T;
}

}  // namespace

Cell with_cameras(const Cell& cell, const CameraPlacement& placement) {
  Cell out = cell;
  const CellCamera templ = cell.cameras.empty() ? CellCamera{} : cell.cameras.front();
  out.cameras.clear();
  for (std::size_t i = 0; i < placement.world_T_camera.size(); ++i) {
    CellCamera c = i < cell.cameras.size() ? cell.cameras[i] : templ;
    if (i >= cell.cameras.size()) c.name = "camera" + std::to_string(i + 1);
    c.world_T_camera = placement.world_T_camera[i];
    c.pose_known = true;
    c.pose_uncertainty = 0.0;
    out.cameras.push_back(c);
  }
  // Visibility requirements naming cameras that no longer exist fall back to "all".
  for (const std::string& n : out.visibility.cameras)
    if (out.camera_index(n) < 0) {
      out.visibility.cameras.clear();
      break;
    }
  return out;
}

CameraPlacement propose_cameras(const calib::Mechanism& model, const Eigen::VectorXd& params,
                                const Cell& cell, const PlacementOptions& options) {
  if (cell.cameras.empty())
    throw std::invalid_argument("camera placement needs one camera model (intrinsics)");
  const int frame = target_frame(model, cell);
  if (frame < 0) throw std::invalid_argument("the target's frame is not a body of the robot");
  FeasibilityOptions fo = feasibility_options_from_cell(cell);
  // Reachable, collision-free poses inside the workspace (visibility not yet asked).
  FeasibilityOptions no_sight = fo;
  no_sight.check_visibility = false;
  const FeasibilityChecker reach(model, params, cell, frame, no_sight);
  std::mt19937 rng(options.seed);
  const std::vector<Eigen::Vector3d> outline = board_outline(cell.target.board);
  Eigen::Vector3d board_mid = Eigen::Vector3d::Zero();
  for (const Eigen::Vector3d& p : outline) board_mid += p / 4.0;
  const double half_diag = 0.5 * (outline[2] - outline[0]).norm();
  const double short_side =
      std::min((outline[1] - outline[0]).norm(), (outline[3] - outline[0]).norm());
  std::vector<Eigen::VectorXd> configs;
  std::vector<Eigen::Vector3d> centres, normals;
  for (const Candidate& cand :
       reach.sample(static_cast<std::size_t>(10 * options.samples), rng, nullptr)) {
    if (!cand.feasible()) continue;
    if (static_cast<int>(configs.size()) >= options.samples) break;
    configs.push_back(cand.readings);
    centres.emplace_back(cand.world_T_board * board_mid);
    normals.emplace_back(-cand.world_T_board.linear().col(2));
  }
  if (configs.empty())
    throw std::invalid_argument("robot '" + model.name +
                                "' reaches no configuration inside the workspace");
  CameraPlacement out;
  Eigen::Vector3d c = Eigen::Vector3d::Zero(), n = Eigen::Vector3d::Zero();
  for (std::size_t i = 0; i < centres.size(); ++i) {
    c += centres[i];
    n += normals[i];
  }
  c /= static_cast<double>(centres.size());
  if (n.norm() < 1e-6) n = Eigen::Vector3d::UnitZ();  // faces every way: look from above
  n.normalize();
  double radius = 0.0;
  for (const Eigen::Vector3d& p : centres) radius = std::max(radius, (p - c).norm());
  radius += half_diag;
  out.look_at = c;
  out.view_direction = n;
  out.volume_radius = radius;
  const vision::CameraModel& cam = cell.cameras.front().model;
  const double fx = cam.params[0], fy = cam.params[1];
  const double half_fov =
      std::min(std::atan(0.5 * cam.width / fx), std::atan(0.5 * cam.height / fy));
  // Distance: the volume's sphere inside the narrower half field of view (15 % margin), but
  // no farther than keeps the target's image at min_image_size (10 % margin) on the far side.
  const double fov_distance = radius / std::sin(0.85 * half_fov);
  const double size_distance =
      cell.visibility.min_image_size > 0
          ? std::min(fx, fy) * short_side / (1.1 * cell.visibility.min_image_size) - radius
          : 1e300;
  // Two directions perpendicular to n for spreading the cameras around it.
  const Eigen::Vector3d e1 = n.unitOrthogonal();
  const Eigen::Vector3d e2 = n.cross(e1);
  const Eigen::Vector3d up = std::abs(n.z()) > 0.9 ? e2 : Eigen::Vector3d::UnitZ();
  const int ncam = std::max(1, options.cameras);
  auto place = [&](double distance) {
    CameraPlacement pl = out;
    const double tilt = ncam > 1 ? 0.5 * options.triangulation_angle : 0.0;
    for (int i = 0; i < ncam; ++i) {
      const double phi = 2 * M_PI * i / ncam;
      const Eigen::Vector3d dir =
          (std::cos(tilt) * n + std::sin(tilt) * (std::cos(phi) * e1 + std::sin(phi) * e2))
              .normalized();
      pl.world_T_camera.push_back(look_at(c + distance * dir, c, up));
    }
    pl.distance = distance;
    pl.baseline =
        ncam > 1 ? (pl.world_T_camera[0].translation() - pl.world_T_camera[1].translation()).norm()
                 : 0.0;
    const Cell placed = with_cameras(cell, pl);
    const FeasibilityChecker checker(model, params, placed, frame,
                                     feasibility_options_from_cell(placed));
    std::size_t seen = 0;
    for (const Eigen::VectorXd& x : configs) seen += checker.evaluate(x).feasible() ? 1 : 0;
    pl.coverage = static_cast<double>(seen) / static_cast<double>(configs.size());
    return pl;
  };
  // Try distances from 60 % to 160 % of the field-of-view distance (capped by the image-size
  // limit); keep the best coverage, the nearer on ties (bigger images).
  const double top = std::min(1.6 * fov_distance, std::max(size_distance, 0.3 * fov_distance));
  CameraPlacement best;
  best.coverage = -1;
  for (int k = 0; k <= 6; ++k) {
    const double distance = std::min(top, fov_distance * (0.6 + 0.1 * 1.67 * k));
    const CameraPlacement pl = place(distance);
    if (pl.coverage > best.coverage + 1e-9) best = pl;
    if (best.coverage >= 0.999) break;
  }
  out = best;
  std::ostringstream s;
  s << ncam << " camera(s) " << out.distance << " m from the working volume's centre ("
    << c.transpose() << "), looking along " << (-n).transpose() << ", baseline " << out.baseline
    << " m; they see the target at " << std::lround(100 * out.coverage) << " % of "
    << configs.size() << " reachable sampled poses";
  out.summary = s.str();
  return out;
}

}  // namespace robocal::planner
