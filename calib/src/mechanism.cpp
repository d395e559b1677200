#include "robocal/calib/mechanism.hpp"

namespace robocal::calib {

int closure_rows(ClosureType type) {
  switch (type) {
    case ClosureType::kPose:
      return 6;
    case ClosureType::kPosition:
      return 3;
    case ClosureType::kPositionAxis:
      return 5;
    case ClosureType::kDistance:
      return 1;
  }
  return 0;
}

int Mechanism::constraint_rows() const {
  int rows = 0;
  for (const Closure& c : closures) rows += closure_rows(c.type);
  return rows;
}

int Mechanism::body_index(const std::string& body_name) const {
  for (std::size_t i = 0; i < bodies.size(); ++i)
    if (bodies[i].name == body_name) return static_cast<int>(i);
  return -1;
}

int Mechanism::parameter_index(const std::string& param_name) const {
  for (std::size_t i = 0; i < parameters.size(); ++i)
    if (parameters[i].name == param_name) return static_cast<int>(i);
  return -1;
}

const std::string& display_name(const Parameter& parameter) {
  return parameter.label.empty() ? parameter.name : parameter.label;
}

const std::string& Mechanism::parameter_display_name(std::size_t index) const {
  return display_name(parameters.at(index));
}

Eigen::VectorXd Mechanism::nominal_parameters() const {
  Eigen::VectorXd v(static_cast<Eigen::Index>(parameters.size()));
  for (std::size_t i = 0; i < parameters.size(); ++i)
    v[static_cast<Eigen::Index>(i)] = parameters[i].value;
  return v;
}

Eigen::VectorXd Mechanism::home_passive() const {
  Eigen::VectorXd v(static_cast<Eigen::Index>(passive.size()));
  for (std::size_t i = 0; i < passive.size(); ++i)
    v[static_cast<Eigen::Index>(i)] = bodies[passive[i]].home;
  return v;
}

Eigen::VectorXd Mechanism::home_actuated() const {
  Eigen::VectorXd v(static_cast<Eigen::Index>(actuated.size()));
  for (std::size_t i = 0; i < actuated.size(); ++i)
    v[static_cast<Eigen::Index>(i)] = bodies[actuated[i]].home;
  return v;
}

Eigen::VectorXd encoder_scales(const Mechanism& model, const Eigen::VectorXd& params) {
  Eigen::VectorXd s(static_cast<Eigen::Index>(model.actuated.size()));
  for (std::size_t i = 0; i < model.actuated.size(); ++i)
    s[static_cast<Eigen::Index>(i)] = params[model.bodies[model.actuated[i]].encoder_scale_param];
  return s;
}

JointState make_joint_state(const Mechanism& model, const Eigen::VectorXd& params,
                            const Eigen::VectorXd& actuator_readings,
                            const Eigen::VectorXd& passive) {
  JointState s;
  s.q = Eigen::VectorXd::Zero(static_cast<Eigen::Index>(model.bodies.size()));
  for (std::size_t i = 0; i < model.actuated.size(); ++i) {
    const Body& b = model.bodies[model.actuated[i]];
    s.q[model.actuated[i]] =
        params[b.encoder_scale_param] * actuator_readings[static_cast<Eigen::Index>(i)] +
        params[b.encoder_offset_param];
  }
  for (std::size_t i = 0; i < model.passive.size(); ++i)
    s.q[model.passive[i]] = passive[static_cast<Eigen::Index>(i)];
  return s;
}

Eigen::VectorXd readings_from_joint_values(const Mechanism& model, const Eigen::VectorXd& params,
                                           const Eigen::VectorXd& actuator_q) {
  Eigen::VectorXd r(actuator_q.size());
  for (std::size_t i = 0; i < model.actuated.size(); ++i) {
    const Body& b = model.bodies[model.actuated[i]];
    const auto k = static_cast<Eigen::Index>(i);
    r[k] = (actuator_q[k] - params[b.encoder_offset_param]) / params[b.encoder_scale_param];
  }
  return r;
}

}  // namespace robocal::calib
