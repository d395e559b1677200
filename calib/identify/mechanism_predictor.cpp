#include "robocal/calib/mechanism_predictor.hpp"

#include "robocal/calib/kinematics.hpp"

#include <fmt/core.h>

namespace robocal::calib {

MechanismPredictor::MechanismPredictor(const Mechanism& model, int frame, ClosureOptions options)
    : model_(model), frame_(frame >= 0 ? frame : model.tool), options_(options) {
  if (frame_ < 0 || frame_ >= static_cast<int>(model.bodies.size()))
    throw std::invalid_argument(
        fmt::format("{}: no measured frame (the model has no tool frame)", model.source));
}

std::size_t MechanismPredictor::parameter_count() const {
  return model_.parameters.size();
}

std::vector<std::string> MechanismPredictor::parameter_names() const {
  std::vector<std::string> names;
  for (const auto& p : model_.parameters) names.push_back(p.name);
  return names;
}

bool MechanismPredictor::predict(const Eigen::VectorXd& params, const Eigen::VectorXd& actuators,
                                 int slot, bool with_jacobian, FramePrediction& out,
                                 std::string& why) const {
  if (actuators.size() != static_cast<Eigen::Index>(model_.actuated.size())) {
    why = fmt::format("{} actuator readings given, the robot has {} actuators", actuators.size(),
                      model_.actuated.size());
    return false;
  }
  if (!params.allFinite() || !actuators.allFinite()) {
    why = "non-finite parameters or readings";
    return false;
  }
  if (!solver_ || solver_params_.size() != params.size() || solver_params_ != params) {
    solver_.emplace(model_, params, options_);
    solver_params_ = params;
  }
  Eigen::VectorXd seed;
  if (slot >= 0 && static_cast<std::size_t>(slot) < seeds_.size()) seed = seeds_[slot];
  ClosureResult closure = solver_->solve(actuators, seed);
  if (!closure.ok() && seed.size() > 0) closure = solver_->solve(actuators);  // cold restart
  if (!closure.ok()) {
    why = fmt::format("closure {} (residual {:.3g} after {} iterations)", to_string(closure.status),
                      closure.residual, closure.iterations);
    return false;
  }
  if (slot >= 0) {
    if (static_cast<std::size_t>(slot) >= seeds_.size())
      seeds_.resize(static_cast<std::size_t>(slot) + 1);
    seeds_[static_cast<std::size_t>(slot)] = closure.passive;
  }
  const JointState state = make_joint_state(model_, params, actuators, closure.passive);
  out.pose = frame_pose(model_, params, state, frame_);
  if (with_jacobian) out.jacobian = parameter_jacobian(model_, params, state, actuators, frame_);
  return true;
}

SolveOptions solve_options_from_model(const Mechanism& model, bool use_priors) {
  SolveOptions opt;
  const auto P = model.parameters.size();
  opt.preference.assign(P, 0);
  if (use_priors) opt.prior_sigma.assign(P, 0.0);
  // Bodies on the chain from the tool up to the first moving joint form the tool frame.
  std::vector<bool> tool_chain(model.bodies.size(), false);
  for (int b = model.tool;
       b >= 0 && model.bodies[static_cast<std::size_t>(b)].joint == JointType::kFixed;
       b = model.bodies[static_cast<std::size_t>(b)].parent)
    tool_chain[static_cast<std::size_t>(b)] = true;
  for (std::size_t i = 0; i < P; ++i) {
    const Parameter& prm = model.parameters[i];
    if (prm.free) opt.candidates.push_back(i);
    if (use_priors && prm.free) opt.prior_sigma[i] = prm.sigma;
    int pref = 0;
    switch (prm.group) {
      case ParamGroup::kJointGeometry:
      case ParamGroup::kRodLength:
        pref = 0;
        break;
      case ParamGroup::kEncoderOffset:
      case ParamGroup::kEncoderScale:
        pref = 1;
        break;
      case ParamGroup::kFrame: {
        const auto body = static_cast<std::size_t>(prm.body);
        if (prm.body >= 0 && tool_chain[body])
          pref = 3;
        else if (prm.body >= 0 && model.bodies[body].parent < 0)
          pref = 2;
        else
          pref = 1;
        break;
      }
    }
    opt.preference[i] = pref;
  }
  return opt;
}

}  // namespace robocal::calib
