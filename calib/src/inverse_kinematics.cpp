#include "robocal/calib/inverse_kinematics.hpp"

#include "robocal/calib/closed_form.hpp"
#include "tree_evaluator.hpp"

namespace robocal::calib {
namespace {

int task_rows(TaskType t) {
  switch (t) {
    case TaskType::kPosition:
      return 3;
    case TaskType::kPose:
      return 6;
    case TaskType::kJoint:
      return 1;
  }
  return 0;
}

// Closure rows + task rows as a function of [actuated q; passive].
struct IkSystem {
  detail::TreeEvaluator* ev;
  Eigen::VectorXd* q;
  const Mechanism* m;
  std::vector<int> unknown_bodies;
  TaskTarget target;

  Eigen::Index rows() const { return ev->rows() + task_rows(m->task.type); }

  void evaluate(const Eigen::VectorXd& x, Eigen::VectorXd& r) {
    for (std::size_t j = 0; j < unknown_bodies.size(); ++j)
      (*q)[unknown_bodies[j]] = x[static_cast<Eigen::Index>(j)];
    ev->update(*q);
    const int mc = ev->rows();
    ev->closure_residual(r.data());
    const int f = m->task.frame;
    const detail::Rigid& F = ev->pose(f);
    switch (m->task.type) {
      case TaskType::kPosition:
        r.segment<3>(mc) = F.p - target.pose.translation();
        break;
      case TaskType::kPose:
        r.segment<3>(mc) = F.p - target.pose.translation();
        r.segment<3>(mc + 3) = detail::rotation_residual(F.R, target.pose.linear());
        break;
      case TaskType::kJoint:
        r[mc] = (*q)[m->task.joint] - target.joint_value;
        break;
    }
  }

  // At the last evaluated x.
  void jacobian(Eigen::MatrixXd& Jm) const {
    Eigen::MatrixXd* J = &Jm;
    const int mc = ev->rows();
    const int f = m->task.frame;
    const detail::Rigid& F = ev->pose(f);
    for (std::size_t j = 0; j < unknown_bodies.size(); ++j) {
      const int b = unknown_bodies[j];
      auto col = J->col(static_cast<Eigen::Index>(j));
      ev->closure_column(b, 1.0, col.data());
      if (m->task.type == TaskType::kJoint) {
        col[mc] = b == m->task.joint ? 1.0 : 0.0;
        continue;
      }
      if (!detail::in_subtree(*m, b, f)) {
        col.segment(mc, task_rows(m->task.type)).setZero();
        continue;
      }
      Eigen::Vector3d w, v;
      ev->joint_twist(b, w, v);
      col.segment<3>(mc) = w.cross(F.p) + v;
      if (m->task.type == TaskType::kPose)
        col.segment<3>(mc + 3) = detail::rotation_residual_derivative(F.R, target.pose.linear(), w,
                                                                      Eigen::Vector3d::Zero());
    }
  }
};

}  // namespace

IkResult solve_ik(const Mechanism& model, const Eigen::VectorXd& params, const TaskTarget& target,
                  const IkSeed& seed, const IkOptions& options) {
  IkResult out;
  const auto na = static_cast<Eigen::Index>(model.actuated.size());
  const auto np = static_cast<Eigen::Index>(model.passive.size());
  if (!target.pose.matrix().allFinite() || !std::isfinite(target.joint_value) ||
      !params.allFinite() || (seed.actuator_q.size() != 0 && seed.actuator_q.size() != na) ||
      (seed.passive.size() != 0 && seed.passive.size() != np) || !seed.actuator_q.allFinite() ||
      !seed.passive.allFinite() ||
      params.size() != static_cast<Eigen::Index>(model.parameters.size()))
    return out;

  Eigen::VectorXd x(na + np);
  // Actuators: warm start, closed form (exact for nominal geometry), or home.
  bool have_act = seed.actuator_q.size() == na;
  if (have_act) {
    x.head(na) = seed.actuator_q;
  } else {
    for (Eigen::Index i = 0; i < na; ++i) x[i] = model.bodies[model.actuated[i]].home;
    if (model.closed_form.kind != ClosedFormKind::kNone && model.task.type == TaskType::kPosition) {
      if (const auto total = closed_form_inverse(model.closed_form, target.pose.translation())) {
        for (Eigen::Index i = 0; i < na; ++i) {
          const Body& b = model.bodies[model.actuated[i]];
          const ElementaryOp& op = b.ops[b.joint_op];
          x[i] = ((*total)[i] - (op.param >= 0 ? params[op.param] : 0.0)) / op.sign;
        }
      }
    }
  }
  // Passives: warm start, or close the loops at the seeded actuators.
  if (seed.passive.size() == np) {
    x.tail(np) = seed.passive;
  } else if (np > 0) {
    const Eigen::VectorXd readings = readings_from_joint_values(model, params, x.head(na));
    const ClosureResult c = solve_closure(model, params, readings);
    x.tail(np) = c.passive.size() == np ? c.passive : model.home_passive();
  }

  detail::TreeEvaluator ev(model, params);
  Eigen::VectorXd q = Eigen::VectorXd::Zero(static_cast<Eigen::Index>(model.bodies.size()));
  IkSystem sys{&ev, &q, &model, {}, target};
  for (int b : model.actuated) sys.unknown_bodies.push_back(b);
  for (int b : model.passive) sys.unknown_bodies.push_back(b);
  detail::LmWorkspace ws;
  const detail::LmOutcome lm =
      detail::levenberg_marquardt(sys, x, ws, options.max_iterations, options.tolerance, 0.5);
  out.iterations = lm.iterations;
  out.residual = lm.residual;
  out.actuator_q = x.head(na);
  out.passive = x.tail(np);
  out.actuator_readings = readings_from_joint_values(model, params, out.actuator_q);
  if (lm.converged) {
    out.status = SolveStatus::kConverged;
  } else if (!std::isfinite(lm.residual) || (lm.stalled && lm.residual > 1e-6)) {
    out.status = SolveStatus::kNoSolution;
  } else {
    out.status = SolveStatus::kNotConverged;
  }
  if (options.respect_limits && out.status == SolveStatus::kConverged) {
    for (Eigen::Index i = 0; i < na + np; ++i) {
      const Body& b = model.bodies[sys.unknown_bodies[static_cast<std::size_t>(i)]];
      if (x[i] < b.limits.lower || x[i] > b.limits.upper) out.status = SolveStatus::kNoSolution;
    }
  }
  return out;
}

}  // namespace robocal::calib
