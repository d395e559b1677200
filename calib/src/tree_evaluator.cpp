#include "tree_evaluator.hpp"

namespace robocal::calib::detail {

Eigen::Vector3d rotation_residual(const Eigen::Matrix3d& Ra, const Eigen::Matrix3d& Rb) {
  return 0.5 *
         (Rb.col(0).cross(Ra.col(0)) + Rb.col(1).cross(Ra.col(1)) + Rb.col(2).cross(Ra.col(2)));
}

Eigen::Vector3d rotation_residual_derivative(const Eigen::Matrix3d& Ra, const Eigen::Matrix3d& Rb,
                                             const Eigen::Vector3d& wA, const Eigen::Vector3d& wB) {
  Eigen::Vector3d d = Eigen::Vector3d::Zero();
  for (int k = 0; k < 3; ++k) {
    const Eigen::Vector3d a = Ra.col(k), b = Rb.col(k);
    d += wB.cross(b).cross(a) + b.cross(wA.cross(a));
  }
  return 0.5 * d;
}

void closure_value(const Closure& c, const Rigid& A, const Rigid& B, double length, double* out) {
  const Eigen::Vector3d d = A.p - B.p;
  switch (c.type) {
    case ClosureType::kDistance:
      out[0] = d.norm() - length;
      return;
    case ClosureType::kPosition:
      out[0] = d.x(), out[1] = d.y(), out[2] = d.z();
      return;
    case ClosureType::kPositionAxis:
      out[0] = d.x(), out[1] = d.y(), out[2] = d.z();
      out[3] = B.R.col(0).dot(A.R.col(2));
      out[4] = B.R.col(1).dot(A.R.col(2));
      return;
    case ClosureType::kPose: {
      out[0] = d.x(), out[1] = d.y(), out[2] = d.z();
      const Eigen::Vector3d e = rotation_residual(A.R, B.R);
      out[3] = e.x(), out[4] = e.y(), out[5] = e.z();
      return;
    }
  }
}

void closure_derivative(const Closure& c, const Rigid& A, const Rigid& B,
                        const Eigen::Vector3d& dpA, const Eigen::Vector3d& wA,
                        const Eigen::Vector3d& dpB, const Eigen::Vector3d& wB, double* out) {
  const Eigen::Vector3d dd = dpA - dpB;
  switch (c.type) {
    case ClosureType::kDistance: {
      const Eigen::Vector3d d = A.p - B.p;
      const double n = d.norm();
      out[0] = n > 0 ? d.dot(dd) / n : 0.0;
      return;
    }
    case ClosureType::kPosition:
      out[0] = dd.x(), out[1] = dd.y(), out[2] = dd.z();
      return;
    case ClosureType::kPositionAxis: {
      out[0] = dd.x(), out[1] = dd.y(), out[2] = dd.z();
      const Eigen::Vector3d za = A.R.col(2);
      // d(x_b . z_a) = (w_a - w_b) . (z_a x x_b), likewise for y_b.
      const Eigen::Vector3d dw = wA - wB;
      out[3] = dw.dot(za.cross(B.R.col(0)));
      out[4] = dw.dot(za.cross(B.R.col(1)));
      return;
    }
    case ClosureType::kPose: {
      out[0] = dd.x(), out[1] = dd.y(), out[2] = dd.z();
      const Eigen::Vector3d de = rotation_residual_derivative(A.R, B.R, wA, wB);
      out[3] = de.x(), out[4] = de.y(), out[5] = de.z();
      return;
    }
  }
}

TreeEvaluator::TreeEvaluator(const Mechanism& model, const Eigen::VectorXd& params)
    : model_(&model), params_(params) {
  const std::size_t nb = model.bodies.size();
  pre_.resize(nb);
  post_.resize(nb);
  poses_.resize(nb);
  joint_frames_.resize(nb);
  has_post_.assign(nb, 0);
  rows_ = model.constraint_rows();
  for (std::size_t b = 0; b < nb; ++b) {
    const Body& body = model.bodies[b];
    Rigid* target = &pre_[b];
    for (std::size_t k = 0; k < body.ops.size(); ++k) {
      if (static_cast<int>(k) == body.joint_op) {
        target = &post_[b];
        continue;
      }
      apply_op(target->R, target->p, body.ops[k].kind, op_value(body.ops[k], params, 0.0));
      if (target == &post_[b]) has_post_[b] = 1;
    }
  }
}

void TreeEvaluator::update(const Eigen::VectorXd& q) {
  const Mechanism& m = *model_;
  const std::size_t nb = m.bodies.size();
  for (std::size_t b = 0; b < nb; ++b) {
    const Body& body = m.bodies[b];
    Rigid& out = poses_[b];
    Rigid& jf = joint_frames_[b];
    if (body.parent >= 0) {
      const Rigid& par = poses_[body.parent];
      jf.R.noalias() = par.R * pre_[b].R;
      jf.p.noalias() = par.R * pre_[b].p;
      jf.p += par.p;
    } else {
      jf = pre_[b];
    }
    if (body.joint_op < 0) {
      out = jf;
      continue;
    }
    const ElementaryOp& op = body.ops[body.joint_op];
    if (!has_post_[b]) {
      out = jf;
      apply_op(out.R, out.p, op.kind, op_value(op, params_, q[static_cast<Eigen::Index>(b)]));
      continue;
    }
    Eigen::Matrix3d R = jf.R;
    Eigen::Vector3d p = jf.p;
    apply_op(R, p, op.kind, op_value(op, params_, q[static_cast<Eigen::Index>(b)]));
    out.R.noalias() = R * post_[b].R;
    out.p.noalias() = R * post_[b].p;
    out.p += p;
  }
}

void TreeEvaluator::joint_twist(int body, Eigen::Vector3d& w, Eigen::Vector3d& v) const {
  const Body& b = model_->bodies[body];
  const ElementaryOp& op = b.ops[b.joint_op];
  const Rigid& jf = joint_frames_[body];
  const Eigen::Vector3d axis = op.sign * jf.R.col(axis_of(op.kind));
  if (is_rotation(op.kind)) {
    w = axis;
    v = jf.p.cross(axis);
  } else {
    w.setZero();
    v = axis;
  }
}

void TreeEvaluator::closure_residual(double* out) const {
  const Mechanism& m = *model_;
  int row = 0;
  for (const Closure& c : m.closures) {
    closure_value(c, poses_[c.body_a], poses_[c.body_b],
                  c.length_param >= 0 ? params_[c.length_param] : 0.0, out + row);
    row += closure_rows(c.type);
  }
}

void TreeEvaluator::closure_column(int body, double scale, double* out) const {
  const Mechanism& m = *model_;
  Eigen::Vector3d w, v;
  joint_twist(body, w, v);
  w *= scale;
  v *= scale;
  int row = 0;
  const Eigen::Vector3d zero = Eigen::Vector3d::Zero();
  for (const Closure& c : m.closures) {
    const int nr = closure_rows(c.type);
    const bool a = in_subtree(m, body, c.body_a), bb = in_subtree(m, body, c.body_b);
    if (!a && !bb) {
      for (int k = 0; k < nr; ++k) out[row + k] = 0.0;
    } else {
      const Rigid& A = poses_[c.body_a];
      const Rigid& B = poses_[c.body_b];
      const Eigen::Vector3d dpA = a ? Eigen::Vector3d(w.cross(A.p) + v) : zero;
      const Eigen::Vector3d dpB = bb ? Eigen::Vector3d(w.cross(B.p) + v) : zero;
      closure_derivative(c, A, B, dpA, a ? w : zero, dpB, bb ? w : zero, out + row);
    }
    row += nr;
  }
}

}  // namespace robocal::calib::detail
