#include "robocal/calib/compensation.hpp"

#include "mode_check.hpp"
#include "robocal/calib/assembly_mode.hpp"
#include "robocal/calib/closed_form.hpp"
#include "robocal/calib/closure.hpp"
#include "robocal/calib/frame_placement.hpp"
#include "robocal/calib/kinematics.hpp"
#include "small_lu.hpp"
#include "task_rows.hpp"
#include "tree_evaluator.hpp"

#include <fmt/core.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <memory>
#include <optional>
#include <stdexcept>
#include <utility>

namespace robocal::calib {

const char* to_string(TargetVerdict verdict) {
  switch (verdict) {
    case TargetVerdict::kOk:
      return "ok";
    case TargetVerdict::kAmbiguous:
      return "ambiguous";
    case TargetVerdict::kOtherMode:
      return "other_mode";
    case TargetVerdict::kUnreachable:
      return "unreachable";
  }
  return "?";
}

namespace {

void check_models(const CompensationModels& models) {
  if (models.model == nullptr) throw std::invalid_argument("compensation: no mechanism given");
  const auto n = static_cast<Eigen::Index>(models.model->parameters.size());
  if (models.nominal.size() != n || models.calibrated.size() != n)
    throw std::invalid_argument("compensation: parameter vectors do not match the mechanism");
}

TaskTarget position_target(const Eigen::Vector3d& p) {
  TaskTarget t;
  t.pose.translation() = p;
  return t;
}

}  // namespace

namespace {

using detail::SmallLu;

// Storage of the Newton iterations on one system (sized on first use).
struct NewtonWorkspace {
  Eigen::MatrixXd J;
  Eigen::VectorXd r, dx;
  SmallLu lu;
};

// A square system of closure rows (and, for inverse kinematics, task rows) in the joint values of
// `unknowns` (body indices), the other joint values fixed in q: the calibrated IK system (actuated
// and passive joints against the closures and the target) or a closure at given readings (passive
// joints only). Same residual rows and exact Jacobian columns as the general solvers'.
struct SquareSystem {
  const Mechanism* m = nullptr;
  detail::TreeEvaluator ev;
  Eigen::VectorXd q;          // per-body joint values
  std::vector<int> unknowns;  // bodies whose joint values are the unknowns
  bool with_task = false;     // append the task rows
  TaskTarget target;
  NewtonWorkspace ws;

  SquareSystem(const Mechanism& model, const Eigen::VectorXd& params, std::vector<int> bodies,
               bool task)
      : m(&model),
        ev(model, params),
        q(Eigen::VectorXd::Zero(static_cast<Eigen::Index>(model.bodies.size()))),
        unknowns(std::move(bodies)),
        with_task(task) {}

  [[nodiscard]] Eigen::Index rows() const {
    return ev.rows() + (with_task ? detail::task_rows(m->task.type) : 0);
  }
  [[nodiscard]] bool square() const { return rows() == static_cast<Eigen::Index>(unknowns.size()); }

  void evaluate(const Eigen::VectorXd& x, Eigen::VectorXd& r) {
    for (std::size_t j = 0; j < unknowns.size(); ++j)
      q[unknowns[j]] = x[static_cast<Eigen::Index>(j)];
    ev.update(q);
    ev.closure_residual(r.data());
    if (with_task) detail::task_residual(ev, *m, q, target, r.data() + ev.rows());
  }

  // At the last evaluated x.
  void jacobian(Eigen::MatrixXd& J) const {
    for (std::size_t j = 0; j < unknowns.size(); ++j) {
      const int b = unknowns[j];
      double* col = J.col(static_cast<Eigen::Index>(j)).data();
      ev.closure_column(b, 1.0, col);
      if (with_task) detail::task_column(ev, *m, b, target, col + ev.rows());
    }
  }

  [[nodiscard]] ModeCheck mode() const {
    return detail::check_mode(
        *m, q, [&](int b) -> const Eigen::Vector3d& { return ev.pose(b).p; },
        [&](int b) -> const Eigen::Matrix3d& { return ev.pose(b).R; });
  }
};

// Newton's method on a square system from x (steps limited to 0.5 per unknown, as the general
// solver's), in the system's preallocated storage. The factors of a Jacobian are kept while the
// contraction they gave (residual ratio of the last step) promises the tolerance within two more
// steps: such a chord step costs one evaluation, a new Jacobian and its factors several.
// `given_factors`: sys.ws.lu already holds factors of a nearby Jacobian (tried first). Converged:
// max |r| <= tolerance, and the system is left evaluated at the returned x. Gives up (false) when
// the Jacobian is singular, the residual is not finite or the iterations run out: the caller then
// uses the general solver.
bool newton(SquareSystem& sys, Eigen::VectorXd& x, double tolerance, int max_iterations,
            double& residual, int& iterations, bool given_factors = false) {
  NewtonWorkspace& ws = sys.ws;
  const Eigen::Index n = x.size();
  ws.J.resize(n, n);
  ws.r.resize(n);
  ws.dx.resize(n);
  sys.evaluate(x, ws.r);
  residual = detail::max_abs(ws.r);
  bool factored = given_factors;
  double rate = given_factors ? 0.0 : 1.0;  // residual ratio of the last step
  for (iterations = 0; iterations < max_iterations; ++iterations) {
    if (!std::isfinite(residual)) return false;
    if (residual <= tolerance) return true;
    if (!factored || rate > 0.1 || residual * rate * rate > tolerance) {
      sys.jacobian(ws.J);
      if (!ws.lu.factor(ws.J)) return false;
      factored = true;
    }
    const double previous = residual;
    ws.dx = ws.r;
    ws.lu.solve(ws.dx);
    const double step = detail::max_abs(ws.dx);
    if (!std::isfinite(step)) return false;
    if (step > 0.5) ws.dx *= 0.5 / step;
    x -= ws.dx;
    sys.evaluate(x, ws.r);
    residual = detail::max_abs(ws.r);
    rate = residual / previous;
  }
  return std::isfinite(residual) && residual <= tolerance;
}

}  // namespace

struct Compensator::Impl {
  CompensationModels models;
  const Mechanism* m;
  IkOptions ik_options;
  SquareSystem ik;           // calibrated: closures + task in [actuated; passive]
  SquareSystem closure;      // nominal: closures in the passive joints at given readings
  SquareSystem cal_closure;  // calibrated: the same
  bool fast_ik = false, fast_fk = false;
  // Cold starts: passive ~ home_passive + passive_slope * (qa - home_q), the calibrated
  // closure's first-order solution at the home configuration (empty when it does not close).
  Eigen::VectorXd home_q, home_passive;
  Eigen::MatrixXd passive_slope;
  bool predictor_tried = false;
  Counts counts;
  Eigen::VectorXd x;        // unknowns of the IK system
  Eigen::VectorXd passive;  // passive joints of a cold start, then of the nominal closure
  // The fast answer's verdict is solve_ik's: the closure conditioning (carried along a path of
  // targets as IkSolver carries it), and near a singularity of the design the general solver's
  // design-branch check, which the fast path leaves to it.
  bool differs_from_design = false;
  bool nominal_differs_from_design = false;  // (a controller's model other than the file's)
  detail::PathConditioning path_conditioning;
  Eigen::MatrixXd closure_jacobian;
  Eigen::VectorXd scratch_v, scratch_w;
  std::unique_ptr<IkSolver> general;        // the general solver, built on its first use
  std::unique_ptr<ClosureSolver> robot_fk;  // the calibrated FK of the design check, likewise

  static std::vector<int> ik_unknowns(const Mechanism& model) {
    std::vector<int> out(model.actuated);
    out.insert(out.end(), model.passive.begin(), model.passive.end());
    return out;
  }

  explicit Impl(const CompensationModels& mod)
      : models(mod),
        m(mod.model),
        ik(*mod.model, mod.calibrated, ik_unknowns(*mod.model), true),
        closure(*mod.model, mod.nominal, mod.model->passive, false),
        cal_closure(*mod.model, mod.calibrated, mod.model->passive, false) {
    // A command outside the joint limits is not a command the robot can execute.
    ik_options.respect_limits = true;
    differs_from_design = detail::loops_differ_from_design(*m, mod.calibrated);
    nominal_differs_from_design = detail::loops_differ_from_design(*m, mod.nominal);
    fast_ik = ik.square() && !ik.unknowns.empty();
    fast_fk = closure.square();
    const auto na = static_cast<Eigen::Index>(m->actuated.size());
    const auto np = static_cast<Eigen::Index>(m->passive.size());
    home_q.resize(na);
    for (Eigen::Index i = 0; i < na; ++i)
      home_q[i] =
          m->bodies[static_cast<std::size_t>(m->actuated[static_cast<std::size_t>(i)])].home;
    x.resize(na + np);
  }

  // The passive-joint prediction for cold starts, made on the first cold start (warm-started
  // uses never pay for it). false when there is none (the general solver takes cold starts).
  bool passive_predictor() {
    const auto np = static_cast<Eigen::Index>(m->passive.size());
    if (predictor_tried) return home_passive.size() == np;
    predictor_tried = true;
    make_passive_predictor();
    return home_passive.size() == np;
  }

  void make_passive_predictor() {
    const auto na = static_cast<Eigen::Index>(m->actuated.size());
    const auto np = static_cast<Eigen::Index>(m->passive.size());
    if (np == 0) {
      home_passive.resize(0);
      passive_slope.resize(0, na);
      return;
    }
    if (m->constraint_rows() != np) return;
    const ClosureResult home = solve_closure(
        *m, models.calibrated, readings_from_joint_values(*m, models.calibrated, home_q));
    if (!home.ok()) return;
    // d(passive)/d(qa) = -Jp^-1 Ja at the home configuration.
    SquareSystem at_home(*m, models.calibrated, m->passive, false);
    for (Eigen::Index i = 0; i < na; ++i)
      at_home.q[m->actuated[static_cast<std::size_t>(i)]] = home_q[i];
    Eigen::VectorXd r(np);
    at_home.evaluate(home.passive, r);
    Eigen::MatrixXd jp(np, np);
    at_home.jacobian(jp);
    SmallLu lu;
    if (!lu.factor(jp)) return;
    passive_slope.resize(np, na);
    Eigen::VectorXd col(np);
    for (Eigen::Index i = 0; i < na; ++i) {
      at_home.ev.closure_column(m->actuated[static_cast<std::size_t>(i)], -1.0, col.data());
      lu.solve(col);
      passive_slope.col(i) = col;
    }
    home_passive = home.passive;
  }

  // The calibrated IK: the fast path, else the general solver; true when the fast path answered
  // (its last Jacobian is then at hand for the nominal closure).
  bool calibrated_ik(const TaskTarget& target, const IkSeed& seed, IkResult& out) {
    if (fast_solve_ik(target, seed, out)) {
      ++counts.fast_ik;
      return true;
    }
    ++counts.general_ik;
    if (!general) general = std::make_unique<IkSolver>(*m, models.calibrated, ik_options);
    out = general->solve(target, seed);
    return false;
  }

  // sigma_min / sigma_max of the closure Jacobian in the passive joints at the IK system's last
  // evaluated state (-1 where the closure is not square), gated as IkSolver gates it.
  double closure_conditioning() {
    if (!passive_closure_jacobian(ik.ev)) return -1.0;
    return detail::inverse_answer_conditioning(path_conditioning, closure_jacobian, scratch_v,
                                               scratch_w, *m, differs_from_design);
  }

  // solve_ik's design-branch check (inverse_kinematics.cpp): near a singularity of the design a
  // perturbed model's loops close in several configurations that keep every invariant, and
  // Newton may have settled on one that the robot's forward kinematics (the design's answer
  // followed to these parameters) does not give for the answer's readings: a controller sent
  // them would put the tool elsewhere. True when FK puts the task frame where the IK system's
  // last state (x) has it; `mode` then becomes FK's verdict. False: the general solver decides
  // (Newton again from FK's configuration, or a refusal).
  bool forward_kinematics_agrees(ModeCheck& mode) {
    const auto na = static_cast<Eigen::Index>(m->actuated.size());
    const auto np = static_cast<Eigen::Index>(m->passive.size());
    if (!robot_fk) robot_fk = std::make_unique<ClosureSolver>(*m, models.calibrated);
    const ClosureResult fk =
        robot_fk->solve(readings_from_joint_values(*m, models.calibrated, x.head(na)), x.tail(np));
    if (!fk.ok() || !fk.mode.acceptable() || fk.passive.size() != np) return false;
    for (Eigen::Index i = 0; i < na; ++i)
      cal_closure.q[m->actuated[static_cast<std::size_t>(i)]] = x[i];
    Eigen::VectorXd r(np);
    cal_closure.evaluate(fk.passive, r);
    const detail::Rigid& by_fk = cal_closure.ev.pose(m->task.frame);
    const detail::Rigid& by_ik = ik.ev.pose(m->task.frame);
    if (!detail::same_task_pose(by_fk.p, by_fk.R, by_ik.p, by_ik.R)) return false;
    mode = fk.mode;
    return true;
  }

  // The nominal closure's state (last evaluated) is within the design check's band.
  bool nominal_near_singular() {
    if (!passive_closure_jacobian(closure.ev)) return false;
    const double band = detail::design_check_band(*m);
    return detail::gated_sigma_ratio(nullptr, closure_jacobian, scratch_v, scratch_w, 2.0 * band,
                                     band, band)
               .ratio < band;
  }

  // closure_jacobian <- d(closure rows)/d(passive joints) at ev's poses; false where not square.
  bool passive_closure_jacobian(const detail::TreeEvaluator& ev) {
    const auto np = static_cast<Eigen::Index>(m->passive.size());
    if (np == 0 || ev.rows() != np) return false;
    closure_jacobian.resize(np, np);
    for (Eigen::Index j = 0; j < np; ++j)
      ev.closure_column(m->passive[static_cast<std::size_t>(j)], 1.0,
                        closure_jacobian.col(j).data());
    scratch_v.resize(np);
    scratch_w.resize(np);
    return true;
  }

  // The calibrated IK by Newton from the caller's seed, or (none given, or it fails) from the
  // closed-form / predicted cold seed; false when the general solver must decide.
  bool fast_solve_ik(const TaskTarget& target, const IkSeed& seed, IkResult& out) {
    if (!fast_ik || !target.pose.matrix().allFinite() || !std::isfinite(target.joint_value))
      return false;
    ik.target = target;
    int iterations = 0;
    const bool warm = seed.actuator_q.size() == static_cast<Eigen::Index>(m->actuated.size());
    if (warm && solve_from(&seed, iterations, out)) return true;
    return solve_from(nullptr, iterations, out);
  }

  // One attempt (seed == nullptr: cold); `iterations` accumulates the Newton steps.
  bool solve_from(const IkSeed* seed, int& iterations, IkResult& out) {
    const auto na = static_cast<Eigen::Index>(m->actuated.size());
    const auto np = static_cast<Eigen::Index>(m->passive.size());
    const Eigen::VectorXd& params = models.calibrated;
    if (seed != nullptr) {
      if (!seed->actuator_q.allFinite()) return false;
      x.head(na) = seed->actuator_q;
    } else {
      // As solve_ik's cold start: the closed form of the file's geometry, else home.
      x.head(na) = home_q;
      const auto total =
          m->closed_form.kind != ClosedFormKind::kNone && m->task.type == TaskType::kPosition
              ? closed_form_inverse(m->closed_form, ik.target.pose.translation())
              : std::nullopt;
      for (Eigen::Index i = 0; total && i < na; ++i) {
        const Body& b =
            m->bodies[static_cast<std::size_t>(m->actuated[static_cast<std::size_t>(i)])];
        const ElementaryOp& op = b.ops[static_cast<std::size_t>(b.joint_op)];
        x[i] = ((*total)[i] - (op.param >= 0 ? params[op.param] : 0.0)) / op.sign;
      }
    }
    if (seed != nullptr && seed->passive.size() == np) {
      if (!seed->passive.allFinite()) return false;
      x.tail(np) = seed->passive;
    } else if (np > 0) {
      // Predicted passive joints, then the loops closed at the seeded actuators (roughly, to
      // 1e-2: the IK finishes), so that its first steps do not carry the actuators to another
      // branch (from the prediction alone they do, on a Delta, for ~2 % of the targets).
      if (!passive_predictor()) return false;
      passive = home_passive + passive_slope * (x.head(na) - home_q);
      for (Eigen::Index i = 0; i < na; ++i)
        cal_closure.q[m->actuated[static_cast<std::size_t>(i)]] = x[i];
      double residual = 0.0;
      int steps = 0;
      const bool closed = newton(cal_closure, passive, 1e-2, 12, residual, steps);
      iterations += steps;
      if (!closed) return false;
      x.tail(np) = passive;
    }
    double residual = 0.0;
    int steps = 0;
    const bool converged = newton(ik, x, ik_options.tolerance, 12, residual, steps);
    iterations += steps;
    if (!converged) return false;
    for (Eigen::Index i = 0; i < na + np; ++i) {
      const Body& b = m->bodies[static_cast<std::size_t>(ik.unknowns[static_cast<std::size_t>(i)])];
      if (x[i] < b.limits.lower || x[i] > b.limits.upper) return false;
    }
    ModeCheck mode = ik.mode();
    if (!m->assembly_mode.invariants.empty()) {
      if (!mode.acceptable()) return false;
      if (np > 0) {
        const double conditioning = closure_conditioning();
        if (conditioning >= 0.0) {
          mode = detail::check_mode(
              *m, ik.q, [&](int b) -> const Eigen::Vector3d& { return ik.ev.pose(b).p; },
              [&](int b) -> const Eigen::Matrix3d& { return ik.ev.pose(b).R; }, conditioning);
          if (differs_from_design && detail::in_design_check_band(*m, conditioning) &&
              !forward_kinematics_agrees(mode))
            return false;
        }
      }
    }
    out.status = SolveStatus::kConverged;
    out.residual = residual;
    out.iterations = iterations;
    out.mode = mode;
    out.actuator_q = x.head(na);
    out.passive = x.tail(np);
    out.actuator_readings = readings_from_joint_values(*m, params, out.actuator_q);
    return true;
  }

  // The nominal model's closure at the calibrated readings, from the calibrated passive joints:
  // the commanded pose, or false when the general solver must decide.
  bool fast_nominal_pose(const IkResult& ik_answer, bool from_fast_ik, Eigen::Isometry3d& pose) {
    if (!fast_fk) return false;
    const Eigen::VectorXd& params = models.nominal;
    for (std::size_t i = 0; i < m->actuated.size(); ++i) {
      const Body& b = m->bodies[static_cast<std::size_t>(m->actuated[i])];
      closure.q[m->actuated[i]] = params[b.encoder_scale_param] *
                                      ik_answer.actuator_readings[static_cast<Eigen::Index>(i)] +
                                  params[b.encoder_offset_param];
    }
    passive = ik_answer.passive;
    // First step with the factors of the calibrated closure's Jacobian in the passive joints (a
    // block of the IK's last Jacobian, taken close to this state) instead of a new Jacobian: it
    // costs one small factorisation, and the chord rule decides when a new Jacobian is due.
    const auto na = static_cast<Eigen::Index>(m->actuated.size());
    const auto np = static_cast<Eigen::Index>(m->passive.size());
    const bool given = from_fast_ik && np > 0 && closure.ws.lu.factor(ik.ws.J.block(0, na, np, np));
    double residual = 0.0;
    int iterations = 0;
    if (!newton(closure, passive, ClosureOptions{}.tolerance, 12, residual, iterations, given))
      return false;
    if (closure.mode().verdict == ModeVerdict::kOther) return false;
    // As a warm closure solve of such a model (closure.cpp, check_warm_against_design): an answer
    // near a singularity of its loops, or one Newton travelled to, is the general solver's to
    // check against the design's answer.
    if (nominal_differs_from_design &&
        (iterations > detail::kWarmNewtonSteps || nominal_near_singular()))
      return false;
    const detail::Rigid& F = closure.ev.pose(m->task.frame);
    pose = Eigen::Isometry3d::Identity();
    pose.linear() = F.R;
    pose.translation() = F.p;
    return true;
  }
};

Compensator::Compensator(const CompensationModels& models)
    : impl_((check_models(models), std::make_unique<Impl>(models))) {}
Compensator::Compensator(Compensator&&) noexcept = default;
Compensator& Compensator::operator=(Compensator&&) noexcept = default;
Compensator::~Compensator() = default;

const CompensationModels& Compensator::models() const {
  return impl_->models;
}
const Compensator::Counts& Compensator::counts() const {
  return impl_->counts;
}

IkResult Compensator::calibrated_ik(const TaskTarget& target, const IkSeed& seed) {
  IkResult out;
  impl_->calibrated_ik(target, seed, out);
  return out;
}

CompensatedTarget Compensator::compensate(const TaskTarget& target, const IkSeed& seed) {
  Impl& s = *impl_;
  const CompensationModels& models = s.models;
  const Mechanism& model = *s.m;
  CompensatedTarget out;
  const bool fast = s.calibrated_ik(target, seed, out.ik);
  if (out.ik.status == SolveStatus::kOtherMode) {
    out.verdict = TargetVerdict::kOtherMode;
    out.problem = "the calibrated robot reaches it only on " + out.ik.mode.describe();
    return out;
  }
  if (!out.ik.ok()) {
    out.verdict = TargetVerdict::kUnreachable;
    out.problem = fmt::format(
        "the calibrated robot cannot reach it within its joint limits (inverse kinematics: {}, "
        "residual {:.3g} m)",
        to_string(out.ik.status), out.ik.residual);
    return out;
  }
  if (out.ik.mode.verdict == ModeVerdict::kOther) {
    out.verdict = TargetVerdict::kOtherMode;
    out.problem = "the calibrated robot reaches it only on " + out.ik.mode.describe();
    return out;
  }
  // What a controller running the nominal model believes these readings do.
  if (s.fast_nominal_pose(out.ik, fast, out.commanded)) {
    ++s.counts.fast_fk;
  } else {
    ++s.counts.general_fk;
    const ForwardResult fk = forward_kinematics(model, models.nominal, out.ik.actuator_readings,
                                                model.task.frame, out.ik.passive);
    if (!fk.closure.ok() || fk.closure.mode.verdict == ModeVerdict::kOther) {
      out.verdict = TargetVerdict::kUnreachable;
      out.problem = fmt::format(
          "the nominal model cannot assemble at the calibrated readings (closure: {}{}), so no "
          "task-space command for the nominal controller produces them",
          to_string(fk.closure.status),
          fk.closure.mode.verdict == ModeVerdict::kOther ? "; " + fk.closure.mode.describe() : "");
      return out;
    }
    out.commanded = fk.pose;
  }
  if (out.ik.mode.verdict == ModeVerdict::kAmbiguous) {
    out.verdict = TargetVerdict::kAmbiguous;
    out.problem = "near a configuration where assembly modes meet: " + out.ik.mode.describe();
  } else {
    out.verdict = TargetVerdict::kOk;
  }
  return out;
}

CompensatedTarget compensate_target(const CompensationModels& models, const TaskTarget& target,
                                    const IkSeed& seed) {
  return Compensator(models).compensate(target, seed);
}

std::vector<CompensatedTarget> compensate_targets(const CompensationModels& models,
                                                  const std::vector<TaskTarget>& targets) {
  Compensator compensator(models);
  std::vector<CompensatedTarget> out;
  out.reserve(targets.size());
  std::vector<std::size_t> solved;  // indices of usable answers (seed candidates)
  // Distance between two targets: position, plus the joint value for joint tasks and the
  // rotation (weighted as 0.1 m per rad) for pose tasks.
  const auto distance = [&](const TaskTarget& a, const TaskTarget& b) {
    double d = (a.pose.translation() - b.pose.translation()).squaredNorm() +
               (a.joint_value - b.joint_value) * (a.joint_value - b.joint_value);
    if (models.model != nullptr && models.model->task.type == TaskType::kPose)
      d += 0.01 * (a.pose.linear().transpose() * b.pose.linear() - Eigen::Matrix3d::Identity())
                      .squaredNorm();
    return d;
  };
  // Farther than this (1 cm, or its equivalent), a cold start (closed form, a few Newton steps)
  // costs less than a warm one from the nearest answer.
  constexpr double kWarmDistance2 = 1e-4;
  for (std::size_t k = 0; k < targets.size(); ++k) {
    IkSeed seed;
    double best = kWarmDistance2;
    for (const std::size_t j : solved) {
      const double d = distance(targets[k], targets[j]);
      if (d < best) {
        best = d;
        seed = {out[j].ik.actuator_q, out[j].ik.passive};
      }
    }
    out.push_back(compensator.compensate(targets[k], seed));
    // A warm start may land on another mode or fail where a cold start would not: retry cold.
    if (!out.back().usable() && !solved.empty()) out.back() = compensator.compensate(targets[k]);
    if (out.back().usable()) solved.push_back(k);
  }
  return out;
}

bool executed_position(const CompensationModels& models, const Eigen::VectorXd& params,
                       const Eigen::Vector3d& commanded, Eigen::Vector3d& reached, std::string& why,
                       const IkSeed& seed) {
  check_models(models);
  const Mechanism& model = *models.model;
  const IkResult ik = solve_ik(model, models.nominal, position_target(commanded), seed);
  if (!ik.ok()) {
    why = fmt::format("the nominal controller cannot reach ({:.6f}, {:.6f}, {:.6f}) m: {}",
                      commanded.x(), commanded.y(), commanded.z(), to_string(ik.status));
    return false;
  }
  const ForwardResult fk =
      forward_kinematics(model, params, ik.actuator_readings, model.task.frame, ik.passive);
  if (!fk.closure.ok()) {
    why = fmt::format(
        "the robot cannot assemble at the nominal controller's readings for "
        "({:.6f}, {:.6f}, {:.6f}) m: {}",
        commanded.x(), commanded.y(), commanded.z(), to_string(fk.closure.status));
    return false;
  }
  reached = fk.pose.translation();
  return true;
}

namespace {

struct SegmentRefiner {
  const CompensationModels& models;
  Compensator& compensator;
  const Eigen::Vector3d& from;
  const Eigen::Vector3d& to;
  const SegmentOptions& options;
  CompensatedSegment& out;

  [[nodiscard]] Eigen::Vector3d meant(double s) const { return from + s * (to - from); }

  // Largest distance between where the calibrated robot goes while the nominal controller runs
  // straight from c0 to c1, and where the meant line is at the same fraction.
  bool deviation(double s0, const Eigen::Vector3d& c0, double s1, const Eigen::Vector3d& c1,
                 const IkSeed& seed, double& worst) const {
    worst = 0.0;
    for (const double t : std::array<double, 3>{0.25, 0.5, 0.75}) {
      Eigen::Vector3d reached;
      std::string why;
      if (!executed_position(models, models.calibrated, c0 + t * (c1 - c0), reached, why, seed)) {
        out.problem = why;
        return false;
      }
      worst = std::max(worst, (reached - meant(s0 + t * (s1 - s0))).norm());
    }
    return true;
  }

  // Appends the pieces of [s0, s1] (c0, c1: their commanded ends; seed: the calibrated IK
  // answer at s0) after s0.
  bool refine(double s0, const Eigen::Vector3d& c0, double s1, const Eigen::Vector3d& c1,
              const IkSeed& seed, int depth) {
    double worst = 0.0;
    if (!deviation(s0, c0, s1, c1, seed, worst)) return false;
    if (worst <= options.tolerance) {
      out.fractions.push_back(s1);
      out.commanded.push_back(c1);
      out.max_deviation = std::max(out.max_deviation, worst);
      return true;
    }
    if (depth >= options.max_depth) {
      out.problem = fmt::format(
          "the move cannot be kept within {:.3g} m of the straight line after {} bisections "
          "(still {:.3g} m off near {:.0f} % of it)",
          options.tolerance, depth, worst, 100.0 * (s0 + s1) / 2.0);
      return false;
    }
    const double sm = 0.5 * (s0 + s1);
    const CompensatedTarget mid = compensator.compensate(position_target(meant(sm)), seed);
    if (!mid.usable()) {
      const Eigen::Vector3d p = meant(sm);
      out.problem = fmt::format("the point ({:.6f}, {:.6f}, {:.6f}) m on the move: {}", p.x(),
                                p.y(), p.z(), mid.problem);
      return false;
    }
    const Eigen::Vector3d cm = mid.commanded.translation();
    const IkSeed mid_seed{mid.ik.actuator_q, mid.ik.passive};
    return refine(s0, c0, sm, cm, seed, depth + 1) && refine(sm, cm, s1, c1, mid_seed, depth + 1);
  }
};

}  // namespace

CompensatedSegment compensate_segment(const CompensationModels& models, const Eigen::Vector3d& from,
                                      const Eigen::Vector3d& from_commanded,
                                      const Eigen::Vector3d& to, const SegmentOptions& options,
                                      const IkSeed& from_seed) {
  check_models(models);
  if (models.model->task.type != TaskType::kPosition)
    throw std::invalid_argument("compensate_segment: the robot's task is not a position");
  CompensatedSegment out;
  Compensator compensator(models);
  CompensatedTarget end = compensator.compensate(position_target(to), from_seed);
  // A warm start may fail where a cold one would not (a long move): retry cold.
  if (!end.usable() && from_seed.actuator_q.size() > 0)
    end = compensator.compensate(position_target(to));
  if (!end.usable()) {
    out.problem = fmt::format("the end point ({:.6f}, {:.6f}, {:.6f}) m: {}", to.x(), to.y(),
                              to.z(), end.problem);
    return out;
  }
  SegmentRefiner refiner{models, compensator, from, to, options, out};
  out.end_seed = {end.ik.actuator_q, end.ik.passive};
  out.ok = refiner.refine(0.0, from_commanded, 1.0, end.commanded.translation(), from_seed, 0);
  return out;
}

Eigen::VectorXd calibrated_in_robot_frame(const Mechanism& model, const Eigen::VectorXd& estimate,
                                          const Eigen::VectorXd& file_nominal, int mount_body) {
  const auto n = static_cast<Eigen::Index>(model.parameters.size());
  if (estimate.size() != n || file_nominal.size() != n)
    throw std::invalid_argument("calibrated_in_robot_frame: parameter vectors do not match");
  Eigen::VectorXd out = estimate;
  for (Eigen::Index i = 0; i < n; ++i) {
    const int body = model.parameters[static_cast<std::size_t>(i)].body;
    const bool base_frame = body >= 0 && model.bodies[static_cast<std::size_t>(body)].parent < 0;
    if (base_frame || (mount_body >= 0 && body == mount_body)) out[i] = file_nominal[i];
  }
  return out;
}

UserFrames user_frames(const Mechanism& model, const Eigen::VectorXd& estimate,
                       const Eigen::VectorXd& file_nominal, int measured_body,
                       bool mount_replaced) {
  const auto n = static_cast<Eigen::Index>(model.parameters.size());
  if (estimate.size() != n || file_nominal.size() != n)
    throw std::invalid_argument("user_frames: parameter vectors do not match the model");
  if (measured_body >= static_cast<int>(model.bodies.size()))
    throw std::invalid_argument("user_frames: measured body out of range");
  UserFrames out;
  out.params =
      calibrated_in_robot_frame(model, estimate, file_nominal, mount_replaced ? measured_body : -1);
  // Poses of fixed frames hanging from the world do not depend on the joints: any state does.
  const Eigen::VectorXd home = readings_from_joint_values(model, estimate, model.home_actuated());
  const JointState at_estimate = make_joint_state(model, estimate, home, model.home_passive());
  const JointState at_user = make_joint_state(model, out.params, home, model.home_passive());
  // The robot's first body is its base (fit_base_frame places it in the measurement world).
  const Eigen::Isometry3d measurement_T_base = frame_pose(model, estimate, at_estimate, 0);
  const Eigen::Isometry3d world_T_base = frame_pose(model, out.params, at_user, 0);
  out.world_T_measurement = world_T_base * measurement_T_base.inverse();
  // Other bodies hanging from the world are identified geometry relative to the base: they move
  // with it (calibrated_in_robot_frame took them to the file's values).
  for (std::size_t b = 1; b < model.bodies.size(); ++b) {
    if (model.bodies[b].parent >= 0) continue;
    bool has_params = false;
    for (const Parameter& p : model.parameters)
      has_params = has_params || p.body == static_cast<int>(b);
    if (!has_params) continue;
    const Eigen::Isometry3d wanted =
        out.world_T_measurement * frame_pose(model, estimate, at_estimate, static_cast<int>(b));
    set_fixed_frame_pose(model, out.params, static_cast<int>(b), home, wanted);
  }
  out.measured_body = measured_body;
  if (measured_body >= 0) {
    // The measured frame as identified, relative to its predecessor: the same in either world.
    out.measured_parent = model.bodies[static_cast<std::size_t>(measured_body)].parent;
    const Eigen::Isometry3d parent =
        out.measured_parent < 0 ? Eigen::Isometry3d::Identity()
                                : frame_pose(model, estimate, at_estimate, out.measured_parent);
    out.parent_T_measured =
        parent.inverse() * frame_pose(model, estimate, at_estimate, measured_body);
    if (out.measured_parent < 0)
      out.parent_T_measured = out.world_T_measurement * out.parent_T_measured;
  }
  return out;
}

}  // namespace robocal::calib
