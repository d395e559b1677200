#include "robocal/calib/assembly_mode.hpp"

#include "mode_check.hpp"
#include "robocal/calib/kinematics.hpp"
#include "tree_evaluator.hpp"

#include <sstream>

namespace robocal::calib {

const char* to_string(ModeVerdict verdict) {
  switch (verdict) {
    case ModeVerdict::kUndeclared:
      return "undeclared";
    case ModeVerdict::kIntended:
      return "intended";
    case ModeVerdict::kOther:
      return "other";
    case ModeVerdict::kAmbiguous:
      return "ambiguous";
  }
  return "unknown";
}

std::string ModeCheck::describe() const {
  std::ostringstream s;
  s.precision(3);
  switch (verdict) {
    case ModeVerdict::kUndeclared:
      return "the robot file declares no assembly mode";
    case ModeVerdict::kIntended:
      s << "intended assembly mode (distance to the nearest mode boundary " << distance << ")";
      break;
    case ModeVerdict::kOther:
      if (invariant == "design_branch") {
        s << "another configuration of the loops than the one forward kinematics gives for "
             "these joint values (near a singular configuration of the design, where the loops "
             "close in several configurations that all satisfy the declared invariants)";
        break;
      }
      s << "another assembly mode: invariant " << invariant
        << " has the opposite sign to the robot file's declaration (margin " << margin << ")";
      break;
    case ModeVerdict::kAmbiguous:
      if (invariant.rfind("design_", 0) == 0)
        s << "ambiguous assembly mode: the robot file's design geometry is near a singular "
             "configuration of the loops at these joint values ("
          << invariant.substr(7)
          << "), where assembly modes meet: the loops of this model close in several "
             "configurations nearby that all satisfy the declared invariants (constraint "
             "Jacobian sigma_min/sigma_max "
          << conditioning << ")";
      else if (invariant == "closure_conditioning")
        s << "ambiguous assembly mode: the loops are near a singular configuration (constraint "
             "Jacobian sigma_min/sigma_max "
          << conditioning << "), where assembly modes meet";
      else
        s << "ambiguous assembly mode: invariant " << invariant << " is " << distance
          << " from 0, at or near a singularity where modes meet";
      break;
  }
  return s.str();
}

double invariant_value(const ModeInvariant& invariant, const std::vector<Eigen::Isometry3d>& poses,
                       const JointState& state, const Mechanism& model) {
  return detail::invariant_value(
      invariant, model, state.q,
      [&](int b) { return Eigen::Vector3d(poses[static_cast<std::size_t>(b)].translation()); },
      [&](int b) { return Eigen::Matrix3d(poses[static_cast<std::size_t>(b)].linear()); });
}

ModeCheck check_assembly_mode(const Mechanism& model, const std::vector<Eigen::Isometry3d>& poses,
                              const JointState& state) {
  return detail::check_mode(
      model, state.q,
      [&](int b) { return Eigen::Vector3d(poses[static_cast<std::size_t>(b)].translation()); },
      [&](int b) { return Eigen::Matrix3d(poses[static_cast<std::size_t>(b)].linear()); });
}

ModeCheck check_assembly_mode(const Mechanism& model, const Eigen::VectorXd& params,
                              const JointState& state) {
  if (model.assembly_mode.invariants.empty()) return {};
  std::vector<Eigen::Isometry3d> poses;
  body_poses(model, params, state, poses);
  double conditioning = -1.0;
  const auto n = static_cast<Eigen::Index>(model.passive.size());
  if (n > 0 && model.constraint_rows() > 0) {
    detail::TreeEvaluator ev(model, params);
    ev.update(state.q);
    Eigen::MatrixXd J(ev.rows(), n);
    for (Eigen::Index j = 0; j < n; ++j)
      ev.closure_column(model.passive[static_cast<std::size_t>(j)], 1.0, J.col(j).data());
    conditioning = detail::sigma_ratio(J);
  }
  return detail::check_mode(
      model, state.q,
      [&](int b) { return Eigen::Vector3d(poses[static_cast<std::size_t>(b)].translation()); },
      [&](int b) { return Eigen::Matrix3d(poses[static_cast<std::size_t>(b)].linear()); },
      conditioning);
}

JointState home_joint_state(const Mechanism& model) {
  JointState s;
  s.q = Eigen::VectorXd::Zero(static_cast<Eigen::Index>(model.bodies.size()));
  for (std::size_t b = 0; b < model.bodies.size(); ++b)
    if (model.bodies[b].joint != JointType::kFixed)
      s.q[static_cast<Eigen::Index>(b)] = model.bodies[b].home;
  return s;
}

}  // namespace robocal::calib
