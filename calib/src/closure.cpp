#include "robocal/calib/closure.hpp"

#include "mode_check.hpp"
#include "robocal/calib/closed_form.hpp"
#include "robocal/calib/kinematics.hpp"
#include "tree_evaluator.hpp"

#include <Eigen/SVD>

#include <stdexcept>

namespace robocal::calib {

const char* to_string(SolveStatus status) {
  switch (status) {
    case SolveStatus::kConverged:
      return "converged";
    case SolveStatus::kSingular:
      return "singular";
    case SolveStatus::kNotConverged:
      return "not_converged";
    case SolveStatus::kNoSolution:
      return "no_solution";
    case SolveStatus::kInvalidInput:
      return "invalid_input";
    case SolveStatus::kOtherMode:
      return "other_assembly_mode";
  }
  return "unknown";
}

namespace {

// Status of one Levenberg-Marquardt run.
SolveStatus lm_status(const detail::LmOutcome& lm) {
  if (lm.converged) return SolveStatus::kConverged;
  if (!std::isfinite(lm.residual) || (lm.stalled && lm.residual > 1e-6))
    return SolveStatus::kNoSolution;
  return SolveStatus::kNotConverged;
}

// Closure rows (and optionally rows pinning the tool position) as a function of the passive
// joints; actuated joint values are already in q.
struct ClosureSystem {
  detail::TreeEvaluator* ev;
  Eigen::VectorXd* q;
  const Mechanism* m;
  int pin_frame = -1;  // >= 0: append 3 rows p_frame - pin_target
  Eigen::Vector3d pin_target = Eigen::Vector3d::Zero();

  Eigen::Index rows() const { return ev->rows() + (pin_frame >= 0 ? 3 : 0); }

  void evaluate(const Eigen::VectorXd& x, Eigen::VectorXd& r) {
    for (Eigen::Index j = 0; j < x.size(); ++j)
      (*q)[m->passive[static_cast<std::size_t>(j)]] = x[j];
    ev->update(*q);
    const int mc = ev->rows();
    ev->closure_residual(r.data());
    if (pin_frame >= 0) r.segment<3>(mc) = ev->pose(pin_frame).p - pin_target;
  }

  // At the last evaluated x.
  void jacobian(Eigen::MatrixXd& J) const {
    const int mc = ev->rows();
    for (Eigen::Index j = 0; j < J.cols(); ++j) {
      const int b = m->passive[static_cast<std::size_t>(j)];
      ev->closure_column(b, 1.0, J.col(j).data());
      if (pin_frame >= 0) {
        if (detail::in_subtree(*m, b, pin_frame)) {
          Eigen::Vector3d w, v;
          ev->joint_twist(b, w, v);
          J.col(j).segment<3>(mc) = w.cross(ev->pose(pin_frame).p) + v;
        } else {
          J.col(j).segment<3>(mc).setZero();
        }
      }
    }
  }
};

}  // namespace

struct ClosureSolver::Impl {
  const Mechanism* model;
  Eigen::VectorXd params;
  ClosureOptions options;
  detail::TreeEvaluator ev;
  // Evaluator for the closed-form seed: the base frames (fixed bodies hanging from the world) and
  // the task frame at the robot file's values, because a closed form describes the file's base
  // and tool. Neither enters a closure, so the passive joints it yields are the seed for any
  // base placement or tool offset (identification moves both far from the file's values).
  detail::TreeEvaluator seed_ev;
  detail::LmWorkspace ws, pin_ws;
  Eigen::VectorXd q;
  // The robot file's design parameters and their evaluator, and whether the loops of `params`
  // differ from them (base and task frames aside; -1 = not yet known): cold solves of such a model
  // follow the design's answer to `params` (from_design below). Set up on the first cold solve
  // that needs them (solve_closure() builds a solver per call).
  Eigen::VectorXd design;
  detail::TreeEvaluator design_ev;
  int differs_from_design = -1;

  Impl(const Mechanism& m, const Eigen::VectorXd& p, const ClosureOptions& o)
      : model(&m),
        params(p),
        options(o),
        ev(m, p),
        seed_ev(m, detail::loop_parameters(m, p)),
        q(Eigen::VectorXd::Zero(static_cast<Eigen::Index>(m.bodies.size()))) {
    ws.resize(m.constraint_rows(), static_cast<Eigen::Index>(m.passive.size()));
  }

  bool differs_from_design_loops() {
    if (differs_from_design < 0) {
      design = model->nominal_parameters();
      differs_from_design = detail::loops_differ_from_design(*model, params) ? 1 : 0;
      if (differs_from_design) design_ev = detail::TreeEvaluator(*model, design);
    }
    return differs_from_design == 1;
  }

  bool set_actuators(const Eigen::VectorXd& readings) { return set_actuators(readings, params); }
  bool set_actuators(const Eigen::VectorXd& readings, const Eigen::VectorXd& p) {
    if (readings.size() != static_cast<Eigen::Index>(model->actuated.size()) ||
        !readings.allFinite())
      return false;
    for (std::size_t i = 0; i < model->actuated.size(); ++i) {
      const Body& b = model->bodies[model->actuated[i]];
      q[model->actuated[i]] = p[b.encoder_scale_param] * readings[static_cast<Eigen::Index>(i)] +
                              p[b.encoder_offset_param];
    }
    return true;
  }

  Eigen::VectorXd seed() { return seed(seed_ev, params); }
  // Closed-form seed for the actuators in q, with the loops of `loop_ev` (whose parameters are p
  // but for the base and task frames).
  Eigen::VectorXd seed(detail::TreeEvaluator& loop_ev, const Eigen::VectorXd& p) {
    Eigen::VectorXd x = model->home_passive();
    if (model->closed_form.kind == ClosedFormKind::kNone || model->passive.empty()) return x;
    Eigen::VectorXd qa(static_cast<Eigen::Index>(model->actuated.size()));
    for (std::size_t i = 0; i < model->actuated.size(); ++i) {
      const Body& b = model->bodies[model->actuated[i]];
      // Closed forms use the total joint angle (joint op parameter + q).
      qa[static_cast<Eigen::Index>(i)] =
          detail::op_value(b.ops[b.joint_op], p, q[model->actuated[i]]);
    }
    const auto T = closed_form_forward(model->closed_form, qa);
    if (!T) return x;
    ClosureSystem pinned{&loop_ev, &q, model, model->task.frame, *T};
    pin_ws.resize(pinned.rows(), x.size());
    detail::levenberg_marquardt(pinned, x, pin_ws, 50, 1e-10, 0.5);
    return x;
  }

  // One Levenberg-Marquardt run from r.passive at the current actuators; fills status,
  // residual, iterations (added) and the mode verdict of a closed answer.
  template <class System>
  void attempt(System& sys, ClosureResult& r) {
    const detail::LmOutcome lm = detail::levenberg_marquardt(
        sys, r.passive, ws, options.max_iterations, options.tolerance, 0.5);
    r.residual = lm.residual;
    r.iterations += lm.iterations;
    r.status = lm_status(lm);
    r.mode = ModeCheck{};
    // On convergence the evaluator holds the poses of the returned state (the LM loop's last
    // evaluation is the accepted point).
    if (lm.converged)
      r.mode = detail::check_mode(
          *model, q, [&](int b) -> const Eigen::Vector3d& { return sys.ev->pose(b).p; },
          [&](int b) -> const Eigen::Matrix3d& { return sys.ev->pose(b).R; }, conditioning(sys));
  }

  // Estimate of sigma_min / sigma_max of the constraint Jacobian at a converged answer (the
  // evaluator holds its poses), for the ambiguous verdict near singular loops. Reuses the LU
  // factors of the last Newton step when there is one (the hot path: no new Jacobian).
  template <class System>
  double conditioning(System& sys) {
    const auto n = static_cast<Eigen::Index>(model->passive.size());
    if (n == 0 || model->assembly_mode.invariants.empty() || model->constraint_rows() != n)
      return -1.0;
    if (!ws.lu_current) {
      sys.jacobian(ws.J);
      ws.lu.factor(ws.J);
    }
    // The estimate only ever overstates the ratio (its power iterations approach sigma_max from
    // below and sigma_min from above), so a state just inside a threshold could pass as clear of
    // it: trusted from 4x the ambiguity gate; below that, the highest threshold the estimate
    // meets (the ambiguity gate, or the design check's for a model whose loops differ from the
    // design) is proved cleared or the exact ratio decides.
    const double gate = model->assembly_mode.min_conditioning;
    const double upper = differs_from_design_loops() ? detail::design_check_band(*model) : gate;
    return path_conditioning(&ws.lu, ws.J, ws.g, ws.dx, 4.0 * gate, gate, upper);
  }
  detail::PathConditioning path_conditioning;

  // Cold solve of a model whose loops differ from the robot file's design (closure.hpp, step 1):
  // the design's answer at these readings (closed-form seed, design loops), then continuation in
  // the parameters from the design to `params` at the same readings, so the answer is the one the
  // design's intended answer turns into (a perturbed loop closes in many configurations that
  // satisfy every declared invariant where the design is near a singularity of its loops: a
  // nearest-seed answer can be any of them). Where the design's own answer is not clearly
  // intended (ambiguous: near a singularity, where modes meet), the model's answer is reported
  // ambiguous too, whatever its own conditioning: a geometry error of the file's tolerances moves
  // the answer between those configurations. Returns false (r unspecified) when the design's
  // answer is not on an acceptable mode or a step does not close; the caller then seeds as before.
  static constexpr double kDesignStep = 1.0;  // largest step (fraction of the parameter path)
  // The seed's pinned solve starts from the home configuration, never from a warm answer: tried
  // (fewer steps), the design's answer then followed that answer's branch, and the compensation
  // test's perturbed Delta got a 4.6 mm different command at one target.
  bool from_design(const Eigen::VectorXd& readings, ClosureResult& r) {
    ClosureSystem dsys{&design_ev, &q, model};
    set_actuators(readings, design);
    r.passive = seed(design_ev, design);
    attempt(dsys, r);
    if (!r.ok() || !r.mode.acceptable()) return false;
    const ModeCheck design_mode = r.mode;
    // Steps in the parameters, the whole path at once when it closes (bench_assembly_modes: the
    // same answers as 2 or 4 steps, and as the reference's 8): a step that does not close, closes
    // on another mode, or moves a passive joint by more than 0.2 rad (a jump across a fold of the
    // branch) is halved.
    Eigen::VectorXd last = r.passive;
    double t = 0.0, h = kDesignStep;
    while (t < 1.0) {
      const double t_try = std::min(1.0, t + h);
      detail::TreeEvaluator step_ev;
      if (t_try < 1.0) {
        const Eigen::VectorXd p = design + t_try * (params - design);
        step_ev = detail::TreeEvaluator(*model, p);
        set_actuators(readings, p);
      } else {
        set_actuators(readings, params);
      }
      ClosureSystem ssys{t_try < 1.0 ? &step_ev : &ev, &q, model};
      r.passive = last;
      attempt(ssys, r);
      if (r.ok() && r.mode.verdict != ModeVerdict::kOther &&
          (r.passive - last).cwiseAbs().maxCoeff() <= 0.2) {
        t = t_try;
        last = r.passive;
        h = std::min(2.0 * h, kDesignStep);
      } else {
        h *= 0.5;
        if (h < 1.0 / 256) return false;
      }
    }
    if (design_mode.verdict == ModeVerdict::kAmbiguous &&
        r.mode.verdict == ModeVerdict::kIntended) {
      r.mode.verdict = ModeVerdict::kAmbiguous;
      r.mode.invariant = "design_" + design_mode.invariant;
      r.mode.conditioning = std::min(r.mode.conditioning, design_mode.conditioning);
    }
    return true;
  }

  // A warm answer of a model whose loops differ from the design, close to a singularity of its
  // loops (detail::kDesignCheckMargin): a warm seed may settle on any of the nearby configurations
  // that satisfy the declared invariants, and the answer that counts is the cold one (the
  // design's answer followed to `params`, from_design). So the warm answer is compared with it
  // and replaced when they differ; when they agree the cold verdict is kept (ambiguous where the
  // design is).
  // Also checked: a warm answer that took Newton more than kWarmNewtonSteps steps. From a seed
  // inside the basin where Newton converges quadratically, 1e-2 to the tolerance takes four or
  // five; more means the iterates travelled, and they can end on another configuration that
  // satisfies every declared sign, far from any singularity of its own (bench_assembly_modes
  // --warm: a perturbed Delta seeded with the design's answer took 7 steps to a configuration 45
  // mm from the sweep's reference, conditioning 0.066, and called it intended where the design is
  // near singular and the cold answer ambiguous). Warm solves along a path take one or two.
  static constexpr int kWarmNewtonSteps = detail::kWarmNewtonSteps;
  void check_warm_against_design(const Eigen::VectorXd& readings, ClosureResult& r) {
    const bool near_singular = detail::in_design_check_band(*model, r.mode.conditioning);
    const bool travelled = r.iterations > kWarmNewtonSteps;
    if (!options.enforce_mode || !r.ok() || !r.mode.acceptable() || !(near_singular || travelled) ||
        !differs_from_design_loops())
      return;
    ClosureResult cold = r;
    cold.iterations = 0;
    const bool found = from_design(readings, cold) && cold.mode.acceptable();
    set_actuators(readings);
    r.iterations += cold.iterations;
    if (!found) return;
    if ((cold.passive - r.passive).cwiseAbs().maxCoeff() > kSameAnswer) {
      cold.iterations = r.iterations;
      cold.seed_used = "design";
      r = cold;
    } else {
      r.mode = cold.mode;
    }
  }
  static constexpr double kSameAnswer = 1e-6;  // rad or m: the same configuration

  // Continuation from the home configuration to `readings` (closure.hpp, step 2).
  template <class System>
  bool continuation(System& sys, const Eigen::VectorXd& readings, ClosureResult& r) {
    const auto na = static_cast<Eigen::Index>(model->actuated.size());
    Eigen::VectorXd home_q(na);
    for (Eigen::Index i = 0; i < na; ++i)
      home_q[i] = model->bodies[model->actuated[static_cast<std::size_t>(i)]].home;
    const Eigen::VectorXd home = readings_from_joint_values(*model, params, home_q);
    r.passive = model->home_passive();
    set_actuators(home);
    attempt(sys, r);
    if (!r.ok()) return false;
    // Adaptive steps: a step that does not close, or closes on another mode, is halved (it jumped
    // branches); a step that succeeds lets the next one grow.
    Eigen::VectorXd last = r.passive;
    double t = 0.0, h = 1.0 / std::max(1, options.continuation_steps);
    while (t < 1.0) {
      const double t_try = std::min(1.0, t + h);
      set_actuators(home + t_try * (readings - home));
      r.passive = last;
      attempt(sys, r);
      if (r.ok() && r.mode.verdict != ModeVerdict::kOther) {
        t = t_try;
        last = r.passive;
        h = std::min(2.0 * h, 0.25);
      } else {
        h *= 0.5;
        if (h < 1.0 / 4096) return false;
      }
    }
    return true;
  }
};

ClosureSolver::ClosureSolver(const Mechanism& model, const Eigen::VectorXd& params,
                             ClosureOptions options)
    : impl_(params.size() != static_cast<Eigen::Index>(model.parameters.size())
                ? throw std::invalid_argument("ClosureSolver: parameter vector has the wrong size")
                : std::make_unique<Impl>(model, params, options)) {}
ClosureSolver::ClosureSolver(const ClosureSolver& other)
    : impl_(std::make_unique<Impl>(*other.impl_)) {}
ClosureSolver& ClosureSolver::operator=(const ClosureSolver& other) {
  if (this != &other) impl_ = std::make_unique<Impl>(*other.impl_);
  return *this;
}
ClosureSolver::ClosureSolver(ClosureSolver&&) noexcept = default;
ClosureSolver& ClosureSolver::operator=(ClosureSolver&&) noexcept = default;
ClosureSolver::~ClosureSolver() = default;

const Mechanism& ClosureSolver::model() const {
  return *impl_->model;
}
const Eigen::VectorXd& ClosureSolver::params() const {
  return impl_->params;
}
const ClosureOptions& ClosureSolver::options() const {
  return impl_->options;
}

Eigen::VectorXd ClosureSolver::closed_form_seed(const Eigen::VectorXd& actuator_readings) const {
  if (!impl_->set_actuators(actuator_readings)) return {};
  return impl_->seed();
}

ClosureResult ClosureSolver::solve(const Eigen::VectorXd& actuator_readings,
                                   const Eigen::VectorXd& seed) const {
  Impl& s = *impl_;
  const Mechanism& m = *s.model;
  ClosureResult result;
  const auto n = static_cast<Eigen::Index>(m.passive.size());
  result.unknowns = static_cast<int>(n);
  result.equations = m.constraint_rows();
  if (s.params.size() != static_cast<Eigen::Index>(m.parameters.size()) ||
      !s.set_actuators(actuator_readings) || (seed.size() != 0 && seed.size() != n) ||
      !seed.allFinite() || !s.params.allFinite()) {
    result.status = SolveStatus::kInvalidInput;
    return result;
  }
  ClosureSystem sys{&s.ev, &s.q, &m};
  const bool warm = seed.size() == n;
  bool done = false;
  if (!warm && s.options.enforce_mode && n > 0 && !m.assembly_mode.invariants.empty() &&
      s.differs_from_design_loops()) {
    result.seed_used = "design";
    done = s.from_design(actuator_readings, result);
    s.set_actuators(actuator_readings);
    if (!done) result.iterations = 0;
  }
  if (!done) {
    result.passive = warm ? seed : s.seed();
    result.seed_used =
        warm ? "warm" : (m.closed_form.kind != ClosedFormKind::kNone ? "closed_form" : "home");
    s.attempt(sys, result);
    if (warm) s.check_warm_against_design(actuator_readings, result);
  }
  // Serial chains (no passive joint) have one answer per reading: the verdict is reported, there is
  // nothing to re-seed.
  if (s.options.enforce_mode && n > 0 && !m.assembly_mode.invariants.empty() &&
      !(result.ok() && result.mode.acceptable())) {
    // Other seeds (closure.hpp): the closed form after a warm start, then continuation from home.
    ClosureResult retry = result;
    bool found = false;
    if (warm && m.closed_form.kind != ClosedFormKind::kNone) {
      s.set_actuators(actuator_readings);
      retry.passive = s.seed();
      retry.seed_used = "closed_form";
      s.attempt(sys, retry);
      found = retry.ok() && retry.mode.acceptable();
    }
    if (!found) {
      retry.seed_used = "continuation";
      found = s.continuation(sys, actuator_readings, retry) && retry.mode.acceptable();
    }
    if (found) {
      result = retry;
    } else if (result.ok() || result.status == SolveStatus::kOtherMode) {
      result.status = SolveStatus::kOtherMode;
    } else if (retry.ok()) {
      result = retry;
      result.status = SolveStatus::kOtherMode;
    }
    s.set_actuators(actuator_readings);
  }
  if (s.options.diagnose && n > 0 && result.equations > 0) {
    sys.evaluate(result.passive, s.ws.r);
    sys.jacobian(s.ws.J);
    const Eigen::JacobiSVD<Eigen::MatrixXd> svd(s.ws.J);
    const Eigen::VectorXd& sv = svd.singularValues();
    result.sigma_max = sv[0];
    result.sigma_min = sv.size() >= n ? sv[sv.size() - 1] : 0.0;
    result.rank = 0;
    for (Eigen::Index i = 0; i < sv.size(); ++i)
      if (sv[i] > s.options.rank_tolerance * std::max(sv[0], 1e-300)) ++result.rank;
    if (result.status == SolveStatus::kConverged && result.rank < n)
      result.status = SolveStatus::kSingular;
  }
  return result;
}

ClosureResult solve_closure(const Mechanism& model, const Eigen::VectorXd& params,
                            const Eigen::VectorXd& actuator_readings, const Eigen::VectorXd& seed,
                            const ClosureOptions& options) {
  if (params.size() != static_cast<Eigen::Index>(model.parameters.size())) {
    ClosureResult bad;
    bad.status = SolveStatus::kInvalidInput;
    return bad;
  }
  return ClosureSolver(model, params, options).solve(actuator_readings, seed);
}

ForwardResult forward_kinematics(const Mechanism& model, const Eigen::VectorXd& params,
                                 const Eigen::VectorXd& actuator_readings, int frame,
                                 const Eigen::VectorXd& seed, const ClosureOptions& options) {
  ForwardResult out;
  if (frame < 0 || frame >= static_cast<int>(model.bodies.size()) ||
      params.size() != static_cast<Eigen::Index>(model.parameters.size())) {
    out.closure.status = SolveStatus::kInvalidInput;
    return out;
  }
  out.closure = solve_closure(model, params, actuator_readings, seed, options);
  if (out.closure.status == SolveStatus::kInvalidInput) return out;
  out.state = make_joint_state(model, params, actuator_readings, out.closure.passive);
  out.pose = frame_pose(model, params, out.state, frame);
  return out;
}

}  // namespace robocal::calib
