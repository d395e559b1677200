#pragma once
// Internal: fast open-tree evaluation with parameter-dependent fixed transforms cached, exact
// joint twists, closure residual rows and their derivatives, and the damped Gauss-Newton loop
// shared by the closure solver and inverse kinematics. Not installed; not public API.
#include "robocal/calib/mechanism.hpp"

#include <Eigen/Cholesky>
#include <Eigen/Core>

#include <cmath>
#include <vector>

namespace robocal::calib::detail {

struct Rigid {
  Eigen::Matrix3d R = Eigen::Matrix3d::Identity();
  Eigen::Vector3d p = Eigen::Vector3d::Zero();
};

inline int axis_of(OpKind k) {
  return static_cast<int>(k) % 3;
}
inline bool is_rotation(OpKind k) {
  return static_cast<int>(k) < 3;
}

// Right-multiplies an elementary transform onto (R, p).
inline void apply_op(Eigen::Matrix3d& R, Eigen::Vector3d& p, OpKind kind, double value) {
  const int ax = axis_of(kind);
  if (!is_rotation(kind)) {
    p += value * R.col(ax);
    return;
  }
  const int i = (ax + 1) % 3, j = (ax + 2) % 3;
  const double c = std::cos(value), s = std::sin(value);
  const Eigen::Vector3d ci = R.col(i), cj = R.col(j);
  R.col(i) = c * ci + s * cj;
  R.col(j) = c * cj - s * ci;
}

inline double op_value(const ElementaryOp& op, const Eigen::VectorXd& params, double q) {
  return (op.param >= 0 ? params[op.param] : 0.0) + (op.joint ? op.sign * q : 0.0);
}

inline bool in_subtree(const Mechanism& m, int root, int body) {
  return body >= root && body < m.bodies[root].subtree_end;
}

// Value rows of one closure.
void closure_value(const Closure& c, const Rigid& A, const Rigid& B, double length, double* out);
// Derivative rows of one closure for frame motions (dp, w) of A and B (world frame).
void closure_derivative(const Closure& c, const Rigid& A, const Rigid& B,
                        const Eigen::Vector3d& dpA, const Eigen::Vector3d& wA,
                        const Eigen::Vector3d& dpB, const Eigen::Vector3d& wB, double* out);
// Rotation residual of pose closures / pose targets: 0.5 * sum_k b_k x a_k.
Eigen::Vector3d rotation_residual(const Eigen::Matrix3d& Ra, const Eigen::Matrix3d& Rb);
Eigen::Vector3d rotation_residual_derivative(const Eigen::Matrix3d& Ra, const Eigen::Matrix3d& Rb,
                                             const Eigen::Vector3d& wA, const Eigen::Vector3d& wB);

class TreeEvaluator {
 public:
  TreeEvaluator() = default;
  TreeEvaluator(const Mechanism& model, const Eigen::VectorXd& params);

  // World poses for per-body joint values q; also joint axes/origins in world.
  void update(const Eigen::VectorXd& q);
  const Rigid& pose(int body) const { return poses_[body]; }
  // Unit twist of body's joint: dp_f = w x p_f + v for descendants f.
  void joint_twist(int body, Eigen::Vector3d& w, Eigen::Vector3d& v) const;
  // Closure rows (model.constraint_rows()) at the current poses.
  void closure_residual(double* out) const;
  // d(closure rows)/dq of body's joint, times `scale`, written to `out` (constraint_rows()).
  void closure_column(int body, double scale, double* out) const;

  const Mechanism& model() const { return *model_; }
  const Eigen::VectorXd& params() const { return params_; }
  int rows() const { return rows_; }

 private:
  const Mechanism* model_ = nullptr;
  Eigen::VectorXd params_;
  std::vector<Rigid> pre_, post_;  // ops before / after the joint op
  std::vector<Rigid> poses_;
  std::vector<Rigid> joint_frames_;  // world frame just before the joint op
  int rows_ = 0;
};

// Damped Gauss-Newton (Levenberg) on a system with evaluate(x, r, J*) (J may be nullptr).
struct LmWorkspace {
  Eigen::MatrixXd J, A, J_trial;
  Eigen::VectorXd r, g, dx, x_trial, r_trial;
  Eigen::LLT<Eigen::MatrixXd> llt;
  void resize(Eigen::Index rows, Eigen::Index cols) {
    if (J.rows() != rows || J.cols() != cols) {
      J.resize(rows, cols);
      J_trial.resize(rows, cols);
      A.resize(cols, cols);
      llt = Eigen::LLT<Eigen::MatrixXd>(cols);
    }
    r.resize(rows);
    r_trial.resize(rows);
    g.resize(cols);
    dx.resize(cols);
    x_trial.resize(cols);
  }
};

struct LmOutcome {
  bool converged = false;
  bool stalled = false;
  double residual = 0.0;  // max |r|
  int iterations = 0;
};

template <class System>
LmOutcome levenberg_marquardt(System& sys, Eigen::VectorXd& x, LmWorkspace& ws, int max_iterations,
                              double tolerance, double max_step) {
  LmOutcome out;
  const Eigen::Index n = x.size();
  ws.resize(sys.rows(), n);
  sys.evaluate(x, ws.r, &ws.J);
  double cost = ws.r.squaredNorm();
  double lambda = 1e-12;
  for (out.iterations = 0; out.iterations < max_iterations; ++out.iterations) {
    out.residual = ws.r.size() ? ws.r.cwiseAbs().maxCoeff() : 0.0;
    if (!std::isfinite(out.residual)) return out;
    if (out.residual <= tolerance) {
      out.converged = true;
      return out;
    }
    if (n == 0) break;
    ws.A.noalias() = ws.J.transpose() * ws.J;
    ws.g.noalias() = ws.J.transpose() * ws.r;
    const double scale = std::max(ws.A.diagonal().maxCoeff(), 1e-300);
    bool accepted = false;
    for (int attempt = 0; attempt < 30 && !accepted; ++attempt) {
      for (Eigen::Index i = 0; i < n; ++i) ws.A(i, i) += lambda * scale;
      ws.llt.compute(ws.A);
      for (Eigen::Index i = 0; i < n; ++i) ws.A(i, i) -= lambda * scale;
      if (ws.llt.info() != Eigen::Success) {
        lambda *= 100.0;
        continue;
      }
      ws.dx = ws.llt.solve(ws.g);
      ws.dx = -ws.dx;
      const double step = ws.dx.cwiseAbs().maxCoeff();
      if (step > max_step) ws.dx *= max_step / step;
      ws.x_trial = x + ws.dx;
      sys.evaluate(ws.x_trial, ws.r_trial, nullptr);
      const double trial_cost = ws.r_trial.squaredNorm();
      if (std::isfinite(trial_cost) &&
          (trial_cost < cost || ws.r_trial.cwiseAbs().maxCoeff() <= tolerance)) {
        accepted = true;
        x = ws.x_trial;
        cost = trial_cost;
        lambda = std::max(lambda * 0.1, 1e-15);
      } else {
        if (step <= 1e-15 * (1.0 + x.cwiseAbs().maxCoeff())) break;
        lambda *= 10.0;
      }
    }
    if (!accepted) {
      out.stalled = true;
      break;
    }
    sys.evaluate(x, ws.r, &ws.J);
  }
  out.residual = ws.r.size() ? ws.r.cwiseAbs().maxCoeff() : 0.0;
  out.converged = out.residual <= tolerance;
  return out;
}

}  // namespace robocal::calib::detail
