#pragma once
// Internal: the task rows of inverse kinematics (task-frame value minus target) and their exact
// Jacobian columns, at a TreeEvaluator's last evaluated state. One definition for every solver
// that appends them to the closure rows (inverse_kinematics.cpp, compensation.cpp).
#include "robocal/calib/inverse_kinematics.hpp"
#include "tree_evaluator.hpp"

namespace robocal::calib::detail {

// Task rows (task_rows(m.task.type) values) into `r`; q = per-body joint values.
inline void task_residual(const TreeEvaluator& ev, const Mechanism& m, const Eigen::VectorXd& q,
                          const TaskTarget& target, double* r) {
  const Rigid& F = ev.pose(m.task.frame);
  Eigen::Map<Eigen::VectorXd> out(r, task_rows(m.task.type));
  switch (m.task.type) {
    case TaskType::kPosition:
      out.head<3>() = F.p - target.pose.translation();
      break;
    case TaskType::kPose:
      out.head<3>() = F.p - target.pose.translation();
      out.tail<3>() = rotation_residual(F.R, target.pose.linear());
      break;
    case TaskType::kJoint:
      out[0] = q[m.task.joint] - target.joint_value;
      break;
  }
}

// Task rows of the Jacobian column of body b's joint value into `col`.
inline void task_column(const TreeEvaluator& ev, const Mechanism& m, int b,
                        const TaskTarget& target, double* col) {
  const int f = m.task.frame;
  Eigen::Map<Eigen::VectorXd> out(col, task_rows(m.task.type));
  if (m.task.type == TaskType::kJoint) {
    out[0] = b == m.task.joint ? 1.0 : 0.0;
    return;
  }
  if (!in_subtree(m, b, f)) {
    out.setZero();
    return;
  }
  const Rigid& F = ev.pose(f);
  Eigen::Vector3d w, v;
  ev.joint_twist(b, w, v);
  out.head<3>() = w.cross(F.p) + v;
  if (m.task.type == TaskType::kPose)
    out.tail<3>() =
        rotation_residual_derivative(F.R, target.pose.linear(), w, Eigen::Vector3d::Zero());
}

}  // namespace robocal::calib::detail
