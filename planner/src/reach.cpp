// reach_check: the planner's one path to the closure solver (see reach.hpp).
#include "robocal/planner/reach.hpp"

#include "robocal/calib/kinematics.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <sstream>
#include <stdexcept>

namespace robocal::planner {

const char* to_string(ReachVerdict verdict) {
  switch (verdict) {
    case ReachVerdict::kReachable:
      return "reachable";
    case ReachVerdict::kActuatorLimit:
      return "actuator limit";
    case ReachVerdict::kNoAssembly:
      return "cannot assemble (closure does not close)";
    case ReachVerdict::kModeChange:
      return "other assembly mode";
    case ReachVerdict::kSingular:
      return "near a singular configuration";
    case ReachVerdict::kPassiveLimit:
      return "passive joint limit";
    case ReachVerdict::kConeLimit:
      return "ball-joint cone";
  }
  return "?";
}

namespace {

calib::ClosureOptions solver_options() {
  calib::ClosureOptions o;
  o.diagnose = true;  // σ_min/σ_max for the singularity test
  return o;
}

double margin_for(const calib::Body& b, const ReachOptions& o) {
  return b.joint == calib::JointType::kPrismatic ? o.joint_margin_length : o.joint_margin_angle;
}

// Direction of the link that ends at `partner`, from the nearest ancestor whose origin differs.
bool link_direction(const calib::Mechanism& model, const std::vector<Eigen::Isometry3d>& poses,
                    int partner, Eigen::Vector3d& dir, int* base_out) {
  int base = model.bodies[static_cast<std::size_t>(partner)].parent;
  while (base >= 0) {
    const Eigen::Vector3d d = poses[static_cast<std::size_t>(partner)].translation() -
                              poses[static_cast<std::size_t>(base)].translation();
    if (d.norm() > 1e-6) {
      dir = d.normalized();
      if (base_out != nullptr) *base_out = base;
      return true;
    }
    base = model.bodies[static_cast<std::size_t>(base)].parent;
  }
  return false;
}

}  // namespace

ReachChecker::ReachChecker(const calib::Mechanism& model, const Eigen::VectorXd& params,
                           const ReachOptions& options)
    : model_(&model), params_(params), options_(options), solver_(model, params, solver_options()) {
  // Neutral directions of the ball-joint cones: the rod directions at the middle of the
  // actuators' ranges, in the cut body's frame.
  bool any_cone = false;
  for (const calib::Body& b : model.bodies) any_cone = any_cone || b.limits.cone > 0;
  if (!any_cone) return;
  const Eigen::VectorXd mid = middle_readings();
  const calib::ClosureResult solved = solver_.solve(mid);
  if (solved.status != calib::SolveStatus::kConverged &&
      solved.status != calib::SolveStatus::kSingular)
    throw std::invalid_argument(model.source +
                                ": the robot cannot assemble at the middle of its actuator ranges, "
                                "so its ball-joint cones have no neutral direction");
  std::vector<Eigen::Isometry3d> poses;
  calib::body_poses(model, params, calib::make_joint_state(model, params, mid, solved.passive),
                    poses);
  for (const calib::Closure& c : model.closures) {
    if (c.type != calib::ClosureType::kPosition) continue;
    for (int side = 0; side < 2; ++side) {
      const int cut = side == 0 ? c.body_a : c.body_b;
      const int partner = side == 0 ? c.body_b : c.body_a;
      const double cone = model.bodies[static_cast<std::size_t>(cut)].limits.cone;
      if (cone <= 0) continue;
      BallCone bc;
      bc.cut = cut;
      bc.partner = partner;
      bc.half_angle = cone;
      Eigen::Vector3d dir;
      if (!link_direction(model, poses, partner, dir, &bc.partner_base)) continue;
      bc.neutral = poses[static_cast<std::size_t>(cut)].linear().transpose() * dir;
      cones_.push_back(bc);
    }
  }
}

ReachChecker::ReachChecker(const calib::Mechanism& model, const Eigen::VectorXd& params,
                           const ReachOptions& options, SharedCones /*tag*/)
    : model_(&model),
      params_(params),
      options_(options),
      solver_(model, params, solver_options()) {}

ReachChecker ReachChecker::with_parameters(const Eigen::VectorXd& params,
                                           const ReachOptions& options) const {
  ReachChecker out(*model_, params, options, SharedCones{});
  out.cones_ = cones_;
  return out;
}

Eigen::VectorXd ReachChecker::middle_readings() const {
  Eigen::VectorXd lo, hi;
  reading_limits(lo, hi);
  return 0.5 * (lo + hi);
}

void ReachChecker::reading_limits(Eigen::VectorXd& lower, Eigen::VectorXd& upper) const {
  const auto n = static_cast<Eigen::Index>(model_->actuated.size());
  Eigen::VectorXd qlo(n), qhi(n);
  for (Eigen::Index i = 0; i < n; ++i) {
    const calib::Body& b =
        model_->bodies[static_cast<std::size_t>(model_->actuated[static_cast<std::size_t>(i)])];
    const double m = margin_for(b, options_);
    qlo(i) = (b.limits.lower > -1e299 ? b.limits.lower : -1.0) + m;
    qhi(i) = (b.limits.upper < 1e299 ? b.limits.upper : 1.0) - m;
  }
  const Eigen::VectorXd a = calib::readings_from_joint_values(*model_, params_, qlo);
  const Eigen::VectorXd c = calib::readings_from_joint_values(*model_, params_, qhi);
  lower = a.cwiseMin(c);
  upper = a.cwiseMax(c);
}

Eigen::VectorXd ReachChecker::nearest_turn_to_home(const Eigen::VectorXd& readings) const {
  const calib::Mechanism& model = *model_;
  const auto n = static_cast<Eigen::Index>(model.actuated.size());
  if (readings.size() != n) return readings;
  const Eigen::VectorXd home =
      calib::readings_from_joint_values(model, params_, model.home_actuated());
  // Readings per turn of each joint.
  const Eigen::VectorXd turn =
      (2.0 * std::numbers::pi) * calib::encoder_scales(model, params_).cwiseInverse();
  Eigen::VectorXd lo, hi;
  reading_limits(lo, hi);
  Eigen::VectorXd out = readings;
  for (Eigen::Index i = 0; i < n; ++i) {
    const calib::Body& b =
        model.bodies[static_cast<std::size_t>(model.actuated[static_cast<std::size_t>(i)])];
    if (b.joint != calib::JointType::kRevolute || !std::isfinite(turn(i))) continue;
    const double turned = readings(i) - std::round((readings(i) - home(i)) / turn(i)) * turn(i);
    if (turned >= lo(i) && turned <= hi(i)) out(i) = turned;
  }
  return out;
}

ReachResult ReachChecker::reach_check(const Eigen::VectorXd& readings,
                                      const Eigen::VectorXd& warm_seed) const {
  ReachResult out;
  const calib::Mechanism& model = *model_;
  if (readings.size() != static_cast<Eigen::Index>(model.actuated.size()) ||
      !readings.allFinite()) {
    out.verdict = ReachVerdict::kNoAssembly;
    out.detail = "wrong number of actuator readings or a non-finite reading";
    return out;
  }
  // Actuator limits (with margin), on joint values after the encoder model.
  const calib::JointState act_only =
      calib::make_joint_state(model, params_, readings, model.home_passive());
  for (const int bi : model.actuated) {
    const calib::Body& b = model.bodies[static_cast<std::size_t>(bi)];
    const double q = act_only.q(bi);
    const double m = margin_for(b, options_);
    if (q < b.limits.lower + m || q > b.limits.upper - m) {
      out.verdict = ReachVerdict::kActuatorLimit;
      std::ostringstream s;
      s << b.name << " at " << q << " outside [" << b.limits.lower + m << ", " << b.limits.upper - m
        << "]";
      out.detail = s.str();
      return out;
    }
  }
  // Closure from the intended-mode seed (closed form or home), or the warm seed.
  const Eigen::VectorXd seed =
      warm_seed.size() > 0 ? warm_seed : solver_.closed_form_seed(readings);
  const calib::ClosureResult solved = solver_.solve(readings, seed);
  if (solved.status == calib::SolveStatus::kOtherMode) {  // closes only on another mode
    out.verdict = ReachVerdict::kModeChange;
    out.detail = solved.mode.describe();
    return out;
  }
  if (solved.status != calib::SolveStatus::kConverged &&
      solved.status != calib::SolveStatus::kSingular) {
    out.verdict = ReachVerdict::kNoAssembly;
    out.detail = std::string("closure ") + calib::to_string(solved.status);
    return out;
  }
  if (solved.status == calib::SolveStatus::kSingular ||
      (solved.sigma_max > 0 && solved.sigma_min < options_.min_relative_sigma * solved.sigma_max)) {
    out.verdict = ReachVerdict::kSingular;
    std::ostringstream s;
    s << "constraint sigma_min/sigma_max = "
      << (solved.sigma_max > 0 ? solved.sigma_min / solved.sigma_max : 0.0);
    out.detail = s.str();
    return out;
  }
  // The robot file's assembly-mode invariants decide (calib's verdict): another mode
  // is refused naming the flipped invariant, an ambiguous answer (at a boundary where modes
  // meet) is treated as singular. Only robots that declare no invariants fall back to the
  // seed-continuity rule.
  if (solved.mode.verdict == calib::ModeVerdict::kOther) {
    out.verdict = ReachVerdict::kModeChange;
    out.detail = solved.mode.describe();
    return out;
  }
  if (solved.mode.verdict == calib::ModeVerdict::kAmbiguous) {
    out.verdict = ReachVerdict::kSingular;
    out.detail = solved.mode.describe();
    return out;
  }
  if (solved.mode.verdict == calib::ModeVerdict::kUndeclared &&
      seed.size() == solved.passive.size() && seed.size() > 0) {
    Eigen::Index worst = 0;
    const double jump = (solved.passive - seed).cwiseAbs().maxCoeff(&worst);
    if (jump > options_.max_branch_jump) {
      out.verdict = ReachVerdict::kModeChange;
      std::ostringstream s;
      s << model.bodies[static_cast<std::size_t>(model.passive[static_cast<std::size_t>(worst)])]
               .name
        << " moved " << jump << " from the intended-mode seed";
      out.detail = s.str();
      return out;
    }
  }
  out.passive = solved.passive;
  out.state = calib::make_joint_state(model, params_, readings, solved.passive);
  for (const int bi : model.passive) {
    const calib::Body& b = model.bodies[static_cast<std::size_t>(bi)];
    const double q = out.state.q(bi);
    const double m = margin_for(b, options_);
    if (q < b.limits.lower + m || q > b.limits.upper - m) {
      out.verdict = ReachVerdict::kPassiveLimit;
      out.detail = b.name + " outside its limits";
      return out;
    }
  }
  calib::body_poses(model, params_, out.state, out.body_poses);
  for (const BallCone& c : cones_) {
    Eigen::Vector3d dir;
    const Eigen::Vector3d d =
        out.body_poses[static_cast<std::size_t>(c.partner)].translation() -
        out.body_poses[static_cast<std::size_t>(c.partner_base)].translation();
    dir = out.body_poses[static_cast<std::size_t>(c.cut)].linear().transpose() * d.normalized();
    const double angle = std::acos(std::clamp(dir.dot(c.neutral), -1.0, 1.0));
    if (angle > c.half_angle - options_.joint_margin_angle) {
      out.verdict = ReachVerdict::kConeLimit;
      std::ostringstream s;
      s << "ball joint " << model.bodies[static_cast<std::size_t>(c.cut)].name << " at "
        << angle * 180 / M_PI << " deg of its " << c.half_angle * 180 / M_PI << " deg cone";
      out.detail = s.str();
      return out;
    }
  }
  out.verdict = ReachVerdict::kReachable;
  return out;
}

}  // namespace robocal::planner
