// Feasibility of candidate poses (see feasibility.hpp).
#include "robocal/planner/feasibility.hpp"

#include "robocal/calib/kinematics.hpp"

#include <algorithm>
#include <cmath>
#include <random>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

namespace robocal::planner {

const char* to_string(Rejection r) {
  switch (r) {
    case Rejection::kNone:
      return "feasible";
    case Rejection::kActuatorLimit:
      return "outside the actuator limits (with margin)";
    case Rejection::kNoAssembly:
      return "cannot assemble (closure does not close)";
    case Rejection::kModeChange:
      return "only on another assembly mode";
    case Rejection::kSingular:
      return "too close to a singular configuration";
    case Rejection::kPassiveLimit:
      return "outside a passive joint's limits";
    case Rejection::kConeLimit:
      return "beyond a ball-joint cone";
    case Rejection::kOutsideWorkspace:
      return "outside the declared safe workspace";
    case Rejection::kObstacleCollision:
      return "collide with an obstacle (or lack clearance)";
    case Rejection::kSelfCollision:
      return "collide with the robot itself";
    case Rejection::kFacingAway:
      return "target turned away from a required camera (incidence)";
    case Rejection::kOutsideImage:
      return "target corners outside a required camera's image (border margin)";
    case Rejection::kTooSmall:
      return "target too small in a required camera's image";
    case Rejection::kOccluded:
      return "line of sight blocked (obstacle or robot link)";
    case Rejection::kTolerance:
      return "reachable by the nominal robot only, not by one within its tolerances";
  }
  return "?";
}

Rejection rejection_of(ReachVerdict v) {
  switch (v) {
    case ReachVerdict::kReachable:
      return Rejection::kNone;
    case ReachVerdict::kActuatorLimit:
      return Rejection::kActuatorLimit;
    case ReachVerdict::kNoAssembly:
      return Rejection::kNoAssembly;
    case ReachVerdict::kModeChange:
      return Rejection::kModeChange;
    case ReachVerdict::kSingular:
      return Rejection::kSingular;
    case ReachVerdict::kPassiveLimit:
      return Rejection::kPassiveLimit;
    case ReachVerdict::kConeLimit:
      return Rejection::kConeLimit;
  }
  return Rejection::kNoAssembly;
}

void FeasibilityCounts::add(const Candidate& c) {
  ++evaluated;
  if (c.feasible()) {
    ++feasible;
    return;
  }
  ++removed[c.rejection];
  if (example.find(c.rejection) == example.end()) example[c.rejection] = c.detail;
}

std::string FeasibilityCounts::summary(bool examples) const {
  std::ostringstream s;
  s << "of " << evaluated << " candidates " << feasible << " are feasible";
  if (!removed.empty()) {
    s << "; removed:";
    bool first = true;
    for (const auto& [why, n] : removed) {
      s << (first ? " " : "; ") << n << " " << to_string(why);
      const auto ex = example.find(why);
      if (examples && ex != example.end() && !ex->second.empty())
        s << " (e.g. " << ex->second << ")";
      first = false;
    }
  }
  return s.str();
}

FeasibilityOptions feasibility_options_from_cell(const Cell& cell) {
  FeasibilityOptions o;
  o.reach.joint_margin_angle = cell.margins.joint_limit_angle;
  o.reach.joint_margin_length = cell.margins.joint_limit_length;
  o.collision.clearance = cell.margins.clearance;
  o.collision.self_clearance = cell.margins.self_clearance;
  return o;
}

namespace {

// Reach checkers of robots drawn within the tolerances (FeasibilityOptions::tolerance_draws): each
// draw and its mirror image, so a reach edge is tested on both sides of the nominal model.
std::vector<ReachChecker> tolerance_checkers(const ReachChecker& nominal,
                                             const FeasibilityOptions& options) {
  const calib::Mechanism& model = nominal.model();
  const Eigen::VectorXd& params = nominal.params();
  std::vector<ReachChecker> out;
  if (options.tolerance_draws <= 0 || options.tolerance_scale <= 0) return out;
  Eigen::VectorXd sigma = Eigen::VectorXd::Zero(params.size());
  if (options.tolerance_sigma.size() > 0) {
    if (options.tolerance_sigma.size() != params.size())
      throw std::invalid_argument(
          "tolerance sigmas: " + std::to_string(options.tolerance_sigma.size()) + " for " +
          std::to_string(params.size()) + " parameters");
    sigma = options.tolerance_scale * options.tolerance_sigma.cwiseAbs();
  } else {
    for (std::size_t i = 0;
         i < model.parameters.size() && i < static_cast<std::size_t>(sigma.size()); ++i) {
      const calib::Parameter& p = model.parameters[i];
      if (p.free && !p.exact)
        sigma(static_cast<Eigen::Index>(i)) = options.tolerance_scale * p.sigma;
    }
  }
  if (sigma.isZero()) return out;
  // What a drawn robot must do is assemble on the intended mode. The singular band and the
  // joint margins are the nominal check's soft keep-outs: applied again to every drawn robot they
  // would widen by the tolerances for no gain (a real robot 0.007 from singular still moves).
  ReachOptions reach = options.reach;
  reach.min_relative_sigma = 0.0;
  std::mt19937 rng(20261128);
  std::normal_distribution<double> n(0.0, 1.0);
  out.reserve(static_cast<std::size_t>(2 * options.tolerance_draws));
  for (int d = 0; d < options.tolerance_draws; ++d) {
    Eigen::VectorXd delta(sigma.size());
    for (Eigen::Index i = 0; i < sigma.size(); ++i) delta(i) = sigma(i) * n(rng);
    out.push_back(nominal.with_parameters(params + delta, reach));
    out.push_back(nominal.with_parameters(params - delta, reach));
  }
  return out;
}

}  // namespace

FeasibilityChecker::FeasibilityChecker(const calib::Mechanism& model, const Eigen::VectorXd& params,
                                       const Cell& cell, int frame,
                                       const FeasibilityOptions& options)
    : cell_(&cell),
      frame_(frame),
      options_(options),
      reach_(model, params, options.reach),
      within_tolerance_(tolerance_checkers(reach_, options)),
      scene_(model, cell, options.collision),
      corners_(required_corner_points(cell.target.board, cell.visibility.corners)),
      outline_(board_outline(cell.target.board)),
      required_(cell.required_cameras()),
      needed_(cell.cameras_needed()) {}

namespace {

// Shortest side of a projected quadrilateral.
double shortest_side(const std::array<Eigen::Vector2d, 4>& q) {
  double s = 1e300;
  for (std::size_t i = 0; i < 4; ++i) s = std::min(s, (q[(i + 1) % 4] - q[i]).norm());
  return s;
}

}  // namespace

Candidate FeasibilityChecker::evaluate(const Eigen::VectorXd& readings) const {
  Candidate c;
  c.readings = readings;
  const ReachResult r = reach_.reach_check(readings);
  if (!r.ok()) {
    c.rejection = rejection_of(r.verdict);
    c.detail = r.detail;
    return c;
  }
  c.passive = r.passive;
  c.world_T_frame = r.body_poses[static_cast<std::size_t>(frame_)];
  c.world_T_board = c.world_T_frame * cell_->target.frame_T_board;
  std::vector<Eigen::Vector3d> outline_world;
  for (const Eigen::Vector3d& p : outline_) outline_world.push_back(c.world_T_board * p);

  const SafeWorkspace& ws = cell_->workspace;
  if (ws.declared) {
    bool inside = ws.contains(c.world_T_frame.translation());
    for (const Eigen::Vector3d& p : outline_world) inside = inside && ws.contains(p);
    if (!inside) {
      c.rejection = Rejection::kOutsideWorkspace;
      std::ostringstream s;
      s << "measured frame at (" << c.world_T_frame.translation().transpose() << ")";
      c.detail = s.str();
      return c;
    }
  }
  const CollisionReport col = scene_.check_robot(r.body_poses);
  if (!col.free) {
    c.rejection = col.self ? Rejection::kSelfCollision : Rejection::kObstacleCollision;
    c.detail = col.what;
    return c;
  }

  const Eigen::Vector3d face_normal = -c.world_T_board.linear().col(2);  // printed face, outwards
  Eigen::Vector3d board_centre = Eigen::Vector3d::Zero();
  for (const Eigen::Vector3d& p : outline_world) board_centre += p / 4.0;
  c.views.resize(cell_->cameras.size());
  int seen = 0;
  Rejection first_problem = Rejection::kNone;
  std::string first_detail;
  for (std::size_t ci = 0; ci < cell_->cameras.size(); ++ci) {
    const CellCamera& cam = cell_->cameras[ci];
    CameraView& v = c.views[ci];
    const Eigen::Isometry3d camera_T_world = cam.world_T_camera.inverse();
    const Eigen::Vector3d eye = cam.world_T_camera.translation();
    const Eigen::Vector3d to_eye = eye - board_centre;
    v.incidence = std::acos(std::clamp(face_normal.dot(to_eye.normalized()), -1.0, 1.0));
    // A camera whose pose is only roughly known: widen the border by the image shift the pose
    // uncertainty can cause at this distance.
    const double fx = cam.model.params.empty() ? 0.0 : cam.model.params[0];
    const double margin =
        cell_->margins.image_border +
        (cam.pose_known ? 0.0 : fx * cam.pose_uncertainty / std::max(to_eye.norm(), 1e-3));
    v.problem = Rejection::kNone;
    if (v.incidence > cell_->visibility.max_incidence) v.problem = Rejection::kFacingAway;
    for (std::size_t k = 0; k < 4 && v.problem == Rejection::kNone; ++k) {
      const auto px = vision::project(cam.model, camera_T_world * outline_world[k]);
      if (!px) {
        v.problem = Rejection::kOutsideImage;
        break;
      }
      v.outline[k] = *px;
    }
    if (v.problem == Rejection::kNone) {
      const auto pc = vision::project(cam.model, camera_T_world * board_centre);
      if (pc) v.centre = *pc;
      v.image_size = shortest_side(v.outline);
      for (const Eigen::Vector3d& p : corners_) {
        const auto px = vision::project(cam.model, camera_T_world * (c.world_T_board * p));
        if (!px || !vision::in_image(cam.model, *px, margin)) {
          v.problem = Rejection::kOutsideImage;
          break;
        }
      }
    }
    if (v.problem == Rejection::kNone && v.image_size < cell_->visibility.min_image_size)
      v.problem = Rejection::kTooSmall;
    std::string blocker;
    if (v.problem == Rejection::kNone &&
        !scene_.sight_clear(eye, outline_world, r.body_poses, &blocker))
      v.problem = Rejection::kOccluded;
    v.visible = v.problem == Rejection::kNone;
    const bool required =
        std::find(required_.begin(), required_.end(), static_cast<int>(ci)) != required_.end();
    seen += required && v.visible ? 1 : 0;
    if (required && !v.visible && first_problem == Rejection::kNone) {
      first_problem = v.problem;
      std::ostringstream s;
      s << "camera '" << cam.name << "'";
      if (v.problem == Rejection::kOccluded) s << " blocked by " << blocker;
      if (v.problem == Rejection::kFacingAway)
        s << " at " << v.incidence * 180 / M_PI << " deg incidence";
      if (v.problem == Rejection::kTooSmall) s << ": " << v.image_size << " px";
      if (needed_ < static_cast<int>(required_.size()))
        s << " (" << needed_ << " of " << required_.size() << " cameras must see it)";
      first_detail = s.str();
    }
  }
  // Too few of the required cameras see it: the first one that does not says why.
  if (options_.check_visibility && seen < needed_) {
    c.rejection = first_problem;
    c.detail = first_detail;
    return c;
  }
  // Last, being the dearest: the same reach for robots within the tolerances, warm-started from
  // the nominal assembly (so the branch test compares against the intended mode's answer).
  for (std::size_t k = 0; k < within_tolerance_.size(); ++k) {
    const ReachResult rk = within_tolerance_[k].reach_check(readings, r.passive);
    if (rk.verdict == ReachVerdict::kNoAssembly || rk.verdict == ReachVerdict::kModeChange) {
      c.rejection = Rejection::kTolerance;
      c.detail = std::string("robot drawn within its tolerances #") + std::to_string(k + 1) + ": " +
                 to_string(rk.verdict) + (rk.detail.empty() ? "" : " (" + rk.detail + ")");
      return c;
    }
  }
  return c;
}

bool FeasibilityChecker::segment_free(const Eigen::VectorXd& from, const Eigen::VectorXd& to,
                                      double step, std::string* why) const {
  const calib::Mechanism& model = reach_.model();
  // Joint-unit size of the move per actuator (readings may be counts).
  const Eigen::VectorXd qa =
      calib::make_joint_state(model, reach_.params(), from, model.home_passive()).q;
  const Eigen::VectorXd qb =
      calib::make_joint_state(model, reach_.params(), to, model.home_passive()).q;
  double largest = 0.0;
  for (const int bi : model.actuated) largest = std::max(largest, std::abs(qb(bi) - qa(bi)));
  const int steps = std::max(1, static_cast<int>(std::ceil(largest / std::max(step, 1e-9))));
  Eigen::VectorXd seed;
  {
    const ReachResult start = reach_.reach_check(from);
    if (!start.ok()) {
      if (why != nullptr) *why = std::string("start pose: ") + to_string(start.verdict);
      return false;
    }
    seed = start.passive;
  }
  const ReachResult end_ref = reach_.reach_check(to);
  for (int k = 1; k <= steps; ++k) {
    const double t = static_cast<double>(k) / steps;
    const Eigen::VectorXd x = (1 - t) * from + t * to;
    const ReachResult r = reach_.reach_check(x, seed);
    if (!r.ok()) {
      if (why != nullptr)
        *why = std::string("at ") + std::to_string(t) + " of the motion: " + to_string(r.verdict) +
               " " + r.detail;
      return false;
    }
    const CollisionReport col = scene_.check_robot(r.body_poses);
    if (!col.free) {
      if (why != nullptr)
        *why = std::string("at ") + std::to_string(t) + " of the motion: " + col.what;
      return false;
    }
    seed = r.passive;
  }
  // The motion must arrive on the same mode as the pose itself (a serial arm has no passive
  // joints to compare).
  if (end_ref.ok() && seed.size() > 0 && seed.size() == end_ref.passive.size() &&
      (seed - end_ref.passive).cwiseAbs().maxCoeff() > 1e-6) {
    if (why != nullptr) *why = "the motion arrives on another assembly mode";
    return false;
  }
  return true;
}

std::vector<Candidate> FeasibilityChecker::sample(std::size_t count, std::mt19937& rng,
                                                  FeasibilityCounts* counts) const {
  Eigen::VectorXd lo, hi;
  reach_.reading_limits(lo, hi);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  std::vector<Candidate> out;
  out.reserve(count);
  for (std::size_t i = 0; i < count; ++i) {
    Eigen::VectorXd x(lo.size());
    for (Eigen::Index k = 0; k < lo.size(); ++k) x(k) = lo(k) + u(rng) * (hi(k) - lo(k));
    Candidate c = evaluate(reach_.nearest_turn_to_home(x));
    if (counts != nullptr) counts->add(c);
    out.push_back(std::move(c));
  }
  return out;
}

}  // namespace robocal::planner
