#include "robocal/calib/inverse_kinematics.hpp"

#include "mode_check.hpp"
#include "robocal/calib/closed_form.hpp"
#include "robocal/calib/kinematics.hpp"
#include "task_rows.hpp"
#include "tree_evaluator.hpp"

#include <Eigen/LU>

#include <cmath>
#include <memory>
#include <random>

namespace robocal::calib {
namespace {

// Closure rows + task rows as a function of [actuated q; passive].
struct IkSystem {
  detail::TreeEvaluator* ev;
  Eigen::VectorXd* q;
  const Mechanism* m;
  std::vector<int> unknown_bodies;
  TaskTarget target;

  Eigen::Index rows() const { return ev->rows() + detail::task_rows(m->task.type); }

  void evaluate(const Eigen::VectorXd& x, Eigen::VectorXd& r) {
    for (std::size_t j = 0; j < unknown_bodies.size(); ++j)
      (*q)[unknown_bodies[j]] = x[static_cast<Eigen::Index>(j)];
    ev->update(*q);
    ev->closure_residual(r.data());
    detail::task_residual(*ev, *m, *q, target, r.data() + ev->rows());
  }

  // At the last evaluated x.
  void jacobian(Eigen::MatrixXd& J) const {
    for (std::size_t j = 0; j < unknown_bodies.size(); ++j) {
      const int b = unknown_bodies[j];
      double* col = J.col(static_cast<Eigen::Index>(j)).data();
      ev->closure_column(b, 1.0, col);
      detail::task_column(*ev, *m, b, target, col + ev->rows());
    }
  }
};

// Deterministic multi-start seeds: uniform within the actuated joints' limits (home +- pi where
// a limit is open).
Eigen::VectorXd spread_seed(const Mechanism& model, std::mt19937& rng) {
  const auto na = static_cast<Eigen::Index>(model.actuated.size());
  Eigen::VectorXd qa(na);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  for (Eigen::Index i = 0; i < na; ++i) {
    const Body& b = model.bodies[model.actuated[static_cast<std::size_t>(i)]];
    const double lo = b.limits.lower > -1e299 ? b.limits.lower : b.home - M_PI;
    const double hi = b.limits.upper < 1e299 ? b.limits.upper : b.home + M_PI;
    qa[i] = lo + (hi - lo) * u(rng);
  }
  return qa;
}

}  // namespace

// The solver's state across solves: the evaluator of the model (built once: its constant
// transforms cost a tenth of a solve), the workspace, the closure solver of the design-branch
// check, and the conditioning carried along a path of warm solves.
struct IkSolver::Impl {
  const Mechanism& model;
  Eigen::VectorXd params;
  IkOptions options;
  bool valid_params;
  detail::TreeEvaluator ev;
  Eigen::VectorXd q;
  IkSystem sys;
  detail::LmWorkspace ws;
  bool differs_from_design = false;
  std::unique_ptr<ClosureSolver> closure;  // built on first use
  detail::PathConditioning path_conditioning;

  Impl(const Mechanism& m, const Eigen::VectorXd& p, const IkOptions& o)
      : model(m),
        params(p),
        options(o),
        valid_params(p.size() == static_cast<Eigen::Index>(m.parameters.size()) && p.allFinite()),
        ev(valid_params ? detail::TreeEvaluator(m, p) : detail::TreeEvaluator()),
        q(Eigen::VectorXd::Zero(static_cast<Eigen::Index>(m.bodies.size()))),
        sys{&ev, &q, &m, {}, {}} {
    sys.unknown_bodies.reserve(m.actuated.size() + m.passive.size());
    for (int b : m.actuated) sys.unknown_bodies.push_back(b);
    for (int b : m.passive) sys.unknown_bodies.push_back(b);
    differs_from_design = valid_params && detail::loops_differ_from_design(m, p);
  }

  ClosureSolver& closure_solver() {
    if (!closure) closure = std::make_unique<ClosureSolver>(model, params);
    return *closure;
  }

  // Passive joints closing the loops at actuator joint values qa (any mode; the final IK solve
  // checks the mode of the whole state).
  Eigen::VectorXd passive_for(const Eigen::VectorXd& qa) {
    const auto np = static_cast<Eigen::Index>(model.passive.size());
    if (np == 0) return {};
    const ClosureResult c = closure_solver().solve(readings_from_joint_values(model, params, qa));
    return c.passive.size() == np ? c.passive : model.home_passive();
  }

  IkResult solve(const TaskTarget& target, const IkSeed& seed);
};

IkSolver::IkSolver(const Mechanism& model, const Eigen::VectorXd& params, IkOptions options)
    : impl_(std::make_unique<Impl>(model, params, options)) {}
IkSolver::~IkSolver() = default;
IkSolver::IkSolver(IkSolver&&) noexcept = default;
IkSolver& IkSolver::operator=(IkSolver&&) noexcept = default;

IkResult IkSolver::solve(const TaskTarget& target, const IkSeed& seed) {
  return impl_->solve(target, seed);
}

IkResult solve_ik(const Mechanism& model, const Eigen::VectorXd& params, const TaskTarget& target,
                  const IkSeed& seed, const IkOptions& options) {
  return IkSolver(model, params, options).solve(target, seed);
}

// Long on purpose: the start, the re-seeds and the design-branch check share one run (the
// solver's workspace, the evaluator's poses and the last converged step's Jacobian, which the
// conditioning reuses); apart, each would have to hand that state to the next.
IkResult IkSolver::Impl::solve(const TaskTarget& target, const IkSeed& seed) {
  IkResult out;
  const auto na = static_cast<Eigen::Index>(model.actuated.size());
  const auto np = static_cast<Eigen::Index>(model.passive.size());
  if (!valid_params || !target.pose.matrix().allFinite() || !std::isfinite(target.joint_value) ||
      (seed.actuator_q.size() != 0 && seed.actuator_q.size() != na) ||
      (seed.passive.size() != 0 && seed.passive.size() != np) || !seed.actuator_q.allFinite() ||
      !seed.passive.allFinite())
    return out;

  Eigen::VectorXd x(na + np);
  // Actuators: warm start, closed form (exact for nominal geometry), or home.
  Eigen::VectorXd home_q(na);
  for (Eigen::Index i = 0; i < na; ++i) home_q[i] = model.bodies[model.actuated[i]].home;
  bool from_home = false;
  if (seed.actuator_q.size() == na) {
    x.head(na) = seed.actuator_q;
  } else {
    x.head(na) = home_q;
    from_home = true;
    if (model.closed_form.kind != ClosedFormKind::kNone && model.task.type == TaskType::kPosition) {
      if (const auto total = closed_form_inverse(model.closed_form, target.pose.translation())) {
        from_home = false;
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
    x.tail(np) = passive_for(x.head(na));
  }

  sys.target = target;
  // The answer of the last run that converged in at least one step: ws.J then holds the system's
  // Jacobian at its last step (the answer's to within that step, as the closure solver's
  // conditioning uses it) and the evaluator holds the answer's poses.
  Eigen::VectorXd jacobian_near;
  // One damped Gauss-Newton run from x; status and verdict of its answer.
  auto run = [&](Eigen::VectorXd& xs, IkResult& r) {
    const detail::LmOutcome lm =
        detail::levenberg_marquardt(sys, xs, ws, options.max_iterations, options.tolerance, 0.5);
    jacobian_near = lm.converged && lm.iterations > 0 ? xs : Eigen::VectorXd();
    r.iterations += lm.iterations;
    r.residual = lm.residual;
    r.mode = ModeCheck{};
    // The pose residual (0.5 sum b_k x a_k) also vanishes at a half-turn error: a converged pose
    // task must have its true rotation error near zero too.
    const bool half_turn =
        lm.converged && model.task.type == TaskType::kPose &&
        (ev.pose(model.task.frame).R.transpose() * target.pose.linear()).trace() < 0.0;
    if (lm.converged && !half_turn) {
      r.status = SolveStatus::kConverged;
      // The evaluator holds the poses of the accepted (returned) state.
      r.mode = detail::check_mode(
          model, q, [&](int b) -> const Eigen::Vector3d& { return ev.pose(b).p; },
          [&](int b) -> const Eigen::Matrix3d& { return ev.pose(b).R; });
    } else if (half_turn || !std::isfinite(lm.residual) || (lm.stalled && lm.residual > 1e-6)) {
      r.status = SolveStatus::kNoSolution;
    } else {
      r.status = SolveStatus::kNotConverged;
    }
    if (options.respect_limits && r.status == SolveStatus::kConverged) {
      for (Eigen::Index i = 0; i < na + np; ++i) {
        const Body& b = model.bodies[sys.unknown_bodies[static_cast<std::size_t>(i)]];
        if (xs[i] < b.limits.lower || xs[i] > b.limits.upper) r.status = SolveStatus::kNoSolution;
      }
    }
  };
  run(x, out);
  const bool check = options.enforce_mode && !model.assembly_mode.invariants.empty();
  if (check && !(out.ok() && out.mode.acceptable())) {
    // Re-seed (inverse_kinematics.hpp): task-space continuation from home, then home and
    // deterministic spread seeds.
    bool found = false;
    ModeCheck other_mode = out.ok() ? out.mode : ModeCheck{};  // an answer seen on another mode
    const auto note_other = [&](const IkResult& r) {
      if (r.ok() && r.mode.verdict == ModeVerdict::kOther &&
          other_mode.verdict != ModeVerdict::kOther)
        other_mode = r.mode;
    };
    const auto accept = [&](const Eigen::VectorXd& xs, const IkResult& r) {
      found = true;
      x = xs;
      out.status = r.status;
      out.residual = r.residual;
      out.mode = r.mode;
    };
    {
      // The target moves from the task value at home (on the intended mode by the file's
      // declaration) to the requested one; each step is warm-started from the previous answer
      // and halved when it fails or lands on another mode.
      Eigen::VectorXd xs(na + np);
      xs.head(na) = home_q;
      if (np > 0) xs.tail(np) = passive_for(home_q);
      const JointState home_state = make_joint_state(
          model, params, readings_from_joint_values(model, params, home_q), xs.tail(np));
      const Eigen::Isometry3d from = frame_pose(model, params, home_state, model.task.frame);
      const double joint_from =
          model.task.type == TaskType::kJoint ? home_state.q[model.task.joint] : 0.0;
      const Eigen::Vector3d turn = rotation_log(from.linear().transpose() * target.pose.linear());
      const auto target_at = [&](double t) {
        TaskTarget g = target;
        g.pose.translation() =
            from.translation() + t * (target.pose.translation() - from.translation());
        g.pose.linear() = from.linear() * rotation_exp(t * turn);
        g.joint_value = joint_from + t * (target.joint_value - joint_from);
        return g;
      };
      Eigen::VectorXd last = xs;
      double t = 0.0, h = 1.0 / 16;
      IkResult r;
      while (t < 1.0) {
        const double t_try = std::min(1.0, t + h);
        sys.target = target_at(t_try);
        xs = last;
        r.iterations = out.iterations;
        run(xs, r);
        out.iterations = r.iterations;
        if (r.ok() && r.mode.verdict != ModeVerdict::kOther) {
          t = t_try;
          last = xs;
          h = std::min(2.0 * h, 0.25);
        } else {
          h *= 0.5;
          if (h < 1.0 / 4096) break;
        }
      }
      sys.target = target;
      if (t >= 1.0 && r.ok() && r.mode.acceptable()) accept(last, r);
    }
    std::mt19937 rng(12345);
    for (int k = from_home ? 1 : 0; k <= options.multi_start && !found; ++k) {
      Eigen::VectorXd xs(na + np);
      xs.head(na) = k == 0 ? home_q : spread_seed(model, rng);
      if (np > 0) xs.tail(np) = passive_for(xs.head(na));
      IkResult r;
      r.iterations = out.iterations;
      run(xs, r);
      out.iterations = r.iterations;
      if (r.ok() && r.mode.acceptable()) accept(xs, r);
      note_other(r);
    }
    // The target is reached, but only on another mode: refused as such (the last answer kept).
    if (!found && other_mode.verdict == ModeVerdict::kOther) {
      out.status = SolveStatus::kOtherMode;
      out.mode = other_mode;
    }
  }
  // sigma_min / sigma_max of the closure Jacobian (passive columns) at x, < 0 where not square.
  const auto closure_conditioning = [&](const Eigen::VectorXd& xs) {
    const int mc = ev.rows();
    if (mc != np) return -1.0;
    Eigen::MatrixXd J(mc, np);
    if (jacobian_near.size() == xs.size() && jacobian_near == xs) {
      J = ws.J.block(0, na, mc, np);  // the closure rows' passive columns
    } else {
      Eigen::VectorXd r(mc + detail::task_rows(model.task.type));
      sys.evaluate(xs, r);
      for (Eigen::Index j = 0; j < np; ++j)
        ev.closure_column(model.passive[static_cast<std::size_t>(j)], 1.0, J.col(j).data());
    }
    Eigen::VectorXd v(np), w(np);
    return detail::inverse_answer_conditioning(path_conditioning, J, v, w, model,
                                               differs_from_design);
  };
  // The verdict with the closure's conditioning, as forward kinematics reports it: an answer whose
  // loops are nearly singular is ambiguous even where every invariant keeps its sign.
  double conditioning = -1.0;
  if (check && np > 0 && out.ok() && out.mode.acceptable()) {
    conditioning = closure_conditioning(x);  // leaves the evaluator (and q) at x
    if (conditioning >= 0.0)
      out.mode = detail::check_mode(
          model, q, [&](int b) -> const Eigen::Vector3d& { return ev.pose(b).p; },
          [&](int b) -> const Eigen::Matrix3d& { return ev.pose(b).R; }, conditioning);
  }
  const bool near_design_singularity = detail::in_design_check_band(model, conditioning);
  if (near_design_singularity && differs_from_design) {
    // A perturbed model's loops can close in several configurations near a singularity of the
    // design (detail::kDesignCheckMargin), all satisfying the declared invariants, and the IK may
    // have settled on one that forward kinematics (the design's answer followed to these
    // parameters) does not give for its readings: a controller commanded these readings would put
    // the tool elsewhere. So the answer must be what FK gives for its readings; if not, Newton
    // again from FK's configuration, and failing that, refused as another mode.
    auto fk_agrees = [&](const Eigen::VectorXd& xs, ClosureResult& fk) {
      fk = closure_solver().solve(readings_from_joint_values(model, params, xs.head(na)),
                                  xs.tail(np));
      if (!fk.ok() || !fk.mode.acceptable()) return false;
      const Eigen::VectorXd readings = readings_from_joint_values(model, params, xs.head(na));
      const Eigen::Isometry3d by_fk = frame_pose(
          model, params, make_joint_state(model, params, readings, fk.passive), model.task.frame);
      const Eigen::Isometry3d by_ik = frame_pose(
          model, params, make_joint_state(model, params, readings, xs.tail(np)), model.task.frame);
      return detail::same_task_pose(by_fk.translation(), by_fk.linear(), by_ik.translation(),
                                    by_ik.linear());
    };
    ClosureResult fk;
    bool agrees = fk_agrees(x, fk);
    if (!agrees && fk.ok() && fk.mode.acceptable()) {
      Eigen::VectorXd xs = x;
      xs.tail(np) = fk.passive;
      IkResult r;
      r.iterations = out.iterations;
      run(xs, r);
      out.iterations = r.iterations;
      if (r.ok() && r.mode.acceptable() && fk_agrees(xs, fk)) {
        agrees = true;
        x = xs;
        out.residual = r.residual;
      }
    }
    if (agrees) {
      out.mode = fk.mode;  // with the closure's conditioning and the design's verdict
    } else {
      out.status = SolveStatus::kOtherMode;
      out.mode.verdict = ModeVerdict::kOther;
      out.mode.invariant = "design_branch";
    }
  }
  out.actuator_q = x.head(na);
  out.passive = x.tail(np);
  out.actuator_readings = readings_from_joint_values(model, params, out.actuator_q);
  return out;
}

}  // namespace robocal::calib
