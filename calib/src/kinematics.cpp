#include "robocal/calib/kinematics.hpp"

#include "tree_evaluator.hpp"

#include <Eigen/QR>

#include <cmath>
#include <stdexcept>
#include <string>

namespace robocal::calib {

using detail::Rigid;

namespace {

// Programming errors (bad indices, wrong vector sizes) throw instead of reading out of bounds.
void check_inputs(const Mechanism& model, const Eigen::VectorXd& params, const JointState& state,
                  int frame, const char* where) {
  if (frame < 0 || frame >= static_cast<int>(model.bodies.size()))
    throw std::invalid_argument(std::string(where) + ": frame index out of range");
  if (params.size() != static_cast<Eigen::Index>(model.parameters.size()))
    throw std::invalid_argument(std::string(where) + ": parameter vector has the wrong size");
  if (state.q.size() != static_cast<Eigen::Index>(model.bodies.size()))
    throw std::invalid_argument(std::string(where) + ": joint state has the wrong size");
}

}  // namespace

void body_poses(const Mechanism& model, const Eigen::VectorXd& params, const JointState& state,
                std::vector<Eigen::Isometry3d>& poses) {
  poses.resize(model.bodies.size());
  std::vector<Rigid> rigid(model.bodies.size());
  for (std::size_t b = 0; b < model.bodies.size(); ++b) {
    const Body& body = model.bodies[b];
    Rigid t = body.parent >= 0 ? rigid[body.parent] : Rigid{};
    for (const ElementaryOp& op : body.ops)
      detail::apply_op(t.R, t.p, op.kind,
                       detail::op_value(op, params, state.q[static_cast<Eigen::Index>(b)]));
    rigid[b] = t;
    poses[b].linear() = t.R;
    poses[b].translation() = t.p;
    poses[b].makeAffine();
  }
}

Eigen::Isometry3d frame_pose(const Mechanism& model, const Eigen::VectorXd& params,
                             const JointState& state, int body) {
  check_inputs(model, params, state, body, "frame_pose");
  // Walk the chain from the root to `body` only.
  std::vector<int> chain;
  for (int b = body; b >= 0; b = model.bodies[b].parent) chain.push_back(b);
  Rigid t;
  for (auto it = chain.rbegin(); it != chain.rend(); ++it)
    for (const ElementaryOp& op : model.bodies[*it].ops)
      detail::apply_op(t.R, t.p, op.kind, detail::op_value(op, params, state.q[*it]));
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  pose.linear() = t.R;
  pose.translation() = t.p;
  return pose;
}

Eigen::Vector3d rotation_log(const Eigen::Matrix3d& R) {
  const Eigen::AngleAxisd aa(R);
  return aa.angle() * aa.axis();
}

Eigen::Matrix3d rotation_exp(const Eigen::Vector3d& w) {
  const double angle = w.norm();
  if (angle < 1e-300) return Eigen::Matrix3d::Identity();
  return Eigen::AngleAxisd(angle, w / angle).toRotationMatrix();
}

Eigen::VectorXd closure_residual(const Mechanism& model, const Eigen::VectorXd& params,
                                 const JointState& state) {
  detail::TreeEvaluator ev(model, params);
  ev.update(state.q);
  Eigen::VectorXd v(ev.rows());
  ev.closure_residual(v.data());
  return v;
}

namespace {

struct Source {
  int body = -1;  // first body the motion moves (with its subtree)
  Eigen::Vector3d w = Eigen::Vector3d::Zero(), v = Eigen::Vector3d::Zero();
};

inline void motion_at(const Source& s, const Rigid& f, Eigen::Vector3d& dp, Eigen::Vector3d& w) {
  dp = s.w.cross(f.p) + s.v;
  w = s.w;
}

}  // namespace

FrameJacobians frame_jacobians(const Mechanism& model, const Eigen::VectorXd& params,
                               const JointState& state, const Eigen::VectorXd& actuator_readings,
                               int frame) {
  check_inputs(model, params, state, frame, "frame_jacobians");
  if (actuator_readings.size() != static_cast<Eigen::Index>(model.actuated.size()))
    throw std::invalid_argument("frame_jacobians: wrong number of actuator readings");
  const auto P = static_cast<Eigen::Index>(model.parameters.size());
  const auto n = static_cast<Eigen::Index>(model.passive.size());
  const auto na = static_cast<Eigen::Index>(model.actuated.size());
  const int m = model.constraint_rows();
  const std::size_t nb = model.bodies.size();

  // One walk over every op: world poses plus the unit twist of every parameter and joint.
  std::vector<Rigid> poses(nb);
  std::vector<Source> param_src(static_cast<std::size_t>(P));
  std::vector<Source> joint_src(nb);
  for (std::size_t b = 0; b < nb; ++b) {
    const Body& body = model.bodies[b];
    Rigid t = body.parent >= 0 ? poses[body.parent] : Rigid{};
    for (const ElementaryOp& op : body.ops) {
      const Eigen::Vector3d axis = t.R.col(detail::axis_of(op.kind));
      Source s;
      s.body = static_cast<int>(b);
      if (detail::is_rotation(op.kind)) {
        s.w = axis;
        s.v = t.p.cross(axis);
      } else {
        s.v = axis;
      }
      if (op.param >= 0) param_src[static_cast<std::size_t>(op.param)] = s;
      if (op.joint) {
        s.w *= op.sign;
        s.v *= op.sign;
        joint_src[b] = s;
      }
      detail::apply_op(t.R, t.p, op.kind,
                       detail::op_value(op, params, state.q[static_cast<Eigen::Index>(b)]));
    }
    poses[b] = t;
  }
  const Rigid& F = poses[static_cast<std::size_t>(frame)];
  const Eigen::Vector3d zero = Eigen::Vector3d::Zero();

  // Frame and closure rows of one motion source.
  auto frame_col = [&](const Source& s, double scale, auto&& col) {
    if (s.body < 0 || !detail::in_subtree(model, s.body, frame)) {
      col.setZero();
      return;
    }
    Eigen::Vector3d dp, w;
    motion_at(s, F, dp, w);
    col.template head<3>() = scale * dp;
    col.template tail<3>() = scale * w;
  };
  auto closure_col = [&](const Source& s, double scale, double* out) {
    int row = 0;
    for (const Closure& c : model.closures) {
      const int nr = closure_rows(c.type);
      const bool a = s.body >= 0 && detail::in_subtree(model, s.body, c.body_a);
      const bool b = s.body >= 0 && detail::in_subtree(model, s.body, c.body_b);
      if (!a && !b) {
        for (int k = 0; k < nr; ++k) out[row + k] = 0.0;
      } else {
        const Rigid& A = poses[static_cast<std::size_t>(c.body_a)];
        const Rigid& B = poses[static_cast<std::size_t>(c.body_b)];
        Eigen::Vector3d dpA = zero, wA = zero, dpB = zero, wB = zero;
        if (a) motion_at(s, A, dpA, wA);
        if (b) motion_at(s, B, dpB, wB);
        closure_derivative(c, A, B, scale * dpA, scale * wA, scale * dpB, scale * wB, out + row);
      }
      row += nr;
    }
  };

  FrameJacobians out;
  out.parameters.resize(6, P);
  out.actuators.resize(6, na);
  Eigen::MatrixXd Cv_a = Eigen::MatrixXd::Zero(m, P);
  Eigen::MatrixXd Cv_act = Eigen::MatrixXd::Zero(m, na);
  const bool closed = m > 0;
  for (Eigen::Index k = 0; k < P; ++k) {
    const Parameter& prm = model.parameters[static_cast<std::size_t>(k)];
    if (prm.group == ParamGroup::kRodLength) {
      out.parameters.col(k).setZero();
      int row = 0;
      for (int c = 0; c < prm.closure; ++c) row += closure_rows(model.closures[c].type);
      if (closed) Cv_a(row, k) = -1.0;
      continue;
    }
    if (prm.group == ParamGroup::kEncoderOffset || prm.group == ParamGroup::kEncoderScale) {
      const Body& body = model.bodies[static_cast<std::size_t>(prm.body)];
      const double scale =
          prm.group == ParamGroup::kEncoderOffset ? 1.0 : actuator_readings[body.actuator];
      const Source& s = joint_src[static_cast<std::size_t>(prm.body)];
      frame_col(s, scale, out.parameters.col(k));
      if (closed) closure_col(s, scale, Cv_a.col(k).data());
      continue;
    }
    frame_col(param_src[static_cast<std::size_t>(k)], 1.0, out.parameters.col(k));
    if (closed) closure_col(param_src[static_cast<std::size_t>(k)], 1.0, Cv_a.col(k).data());
  }
  for (Eigen::Index i = 0; i < na; ++i) {
    const int b = model.actuated[static_cast<std::size_t>(i)];
    const double scale = params[model.bodies[b].encoder_scale_param];
    frame_col(joint_src[b], scale, out.actuators.col(i));
    if (closed) closure_col(joint_src[b], scale, Cv_act.col(i).data());
  }
  if (!closed || n == 0) return out;

  // Implicit function theorem: subtract the passive joints' response, lambda = Jf_theta C^+.
  Eigen::MatrixXd C(m, n);
  Eigen::Matrix<double, 6, Eigen::Dynamic> Jf_theta(6, n);
  for (Eigen::Index j = 0; j < n; ++j) {
    const int b = model.passive[static_cast<std::size_t>(j)];
    closure_col(joint_src[b], 1.0, C.col(j).data());
    frame_col(joint_src[b], 1.0, Jf_theta.col(j));
  }
  Eigen::Matrix<double, 6, Eigen::Dynamic> lambda(6, m);
  if (m == n) {
    const Eigen::PartialPivLU<Eigen::MatrixXd> lu(C.transpose());
    lambda = lu.solve(Jf_theta.transpose()).transpose();
  } else {
    const Eigen::CompleteOrthogonalDecomposition<Eigen::MatrixXd> cod(C);
    lambda = Jf_theta * cod.pseudoInverse();
  }
  out.parameters.noalias() -= lambda * Cv_a;
  out.actuators.noalias() -= lambda * Cv_act;
  return out;
}

Eigen::Matrix<double, 6, Eigen::Dynamic> parameter_jacobian(
    const Mechanism& model, const Eigen::VectorXd& params, const JointState& state,
    const Eigen::VectorXd& actuator_readings, int frame) {
  return frame_jacobians(model, params, state, actuator_readings, frame).parameters;
}

}  // namespace robocal::calib
