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

std::vector<std::string> MechanismPredictor::parameter_labels() const {
  std::vector<std::string> labels;
  for (const auto& p : model_.parameters) labels.push_back(display_name(p));
  return labels;
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
  const Eigen::VectorXd seed = seed_for(actuators, slot);
  std::unique_ptr<Solver> lease;
  {
    const std::lock_guard lock(pool_mutex_);
    // The solver set up for these parameters, if one is idle; else any.
    for (auto it = idle_solvers_.begin(); it != idle_solvers_.end(); ++it)
      if ((*it)->params.size() == params.size() && (*it)->params == params) {
        lease = std::move(*it);
        idle_solvers_.erase(it);
        break;
      }
    if (!lease && !idle_solvers_.empty()) {
      lease = std::move(idle_solvers_.back());
      idle_solvers_.pop_back();
    }
  }
  if (!lease) lease = std::make_unique<Solver>();
  if (!lease->solver || lease->params.size() != params.size() || lease->params != params) {
    lease->solver.emplace(model_, params, options_);
    lease->params = params;
  }
  const auto give_back = [&] {
    const std::lock_guard lock(pool_mutex_);
    idle_solvers_.push_back(std::move(lease));
  };
  ClosureResult closure = lease->solver->solve(actuators, seed);
  if (!closure.ok() && seed.size() > 0) closure = lease->solver->solve(actuators);  // cold restart
  give_back();
  if (!closure.ok()) {
    why = closure.status == SolveStatus::kOtherMode
              ? fmt::format("closure {}: {}", to_string(closure.status), closure.mode.describe())
              : fmt::format("closure {} (residual {:.3g} after {} iterations)",
                            to_string(closure.status), closure.residual, closure.iterations);
    return false;
  }
  const JointState state = make_joint_state(model_, params, actuators, closure.passive);
  out.pose = frame_pose(model_, params, state, frame_);
  if (with_jacobian) out.jacobian = parameter_jacobian(model_, params, state, actuators, frame_);
  return true;
}

// Seed: this pose's solution at the NOMINAL parameters (cold start from the closed form, cached
// per slot). Seeding every parameter vector from the same nominal solution makes the prediction
// a deterministic function of the parameters on one assembly branch: warm-starting from the
// previous trial point instead lets a large trial step hop to a neighbouring branch (the plate
// ball joint modelled as three revolutes has two nearby branches once its offsets are nonzero),
// which the identification then cannot undo.
Eigen::VectorXd MechanismPredictor::seed_for(const Eigen::VectorXd& actuators, int slot) const {
  const std::lock_guard lock(seed_mutex_);
  if (slot >= 0 && static_cast<std::size_t>(slot) < seeds_.size() &&
      seeds_[static_cast<std::size_t>(slot)].size() > 0 &&
      seed_readings_[static_cast<std::size_t>(slot)] == actuators)
    return seeds_[static_cast<std::size_t>(slot)];
  Eigen::VectorXd seed;
  if (!nominal_solver_) nominal_solver_.emplace(model_, model_.nominal_parameters(), options_);
  const ClosureResult nominal = nominal_solver_->solve(actuators);
  if (nominal.ok()) seed = nominal.passive;
  if (slot >= 0) {
    const auto s = static_cast<std::size_t>(slot);
    if (s >= seeds_.size()) {
      seeds_.resize(s + 1);
      seed_readings_.resize(s + 1);
    }
    seeds_[s] = seed;
    seed_readings_[s] = actuators;
  }
  return seed;
}

SolveOptions solve_options_from_model(const Mechanism& model, bool use_priors) {
  SolveOptions opt;
  const auto P = model.parameters.size();
  opt.preference.assign(P, 0);
  if (use_priors) opt.prior_sigma.assign(P, 0.0);
  opt.gauge_sigma.assign(P, 0.0);
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
    if (prm.free) opt.gauge_sigma[i] = prm.sigma;
    // Base frame first: world <-> robot is always a real unknown and the natural carrier of a
    // combination it shares with the geometry or the tool.
    int pref = 1;
    if (prm.group == ParamGroup::kFrame && prm.body >= 0) {
      const auto body = static_cast<std::size_t>(prm.body);
      if (tool_chain[body])
        pref = 3;
      else if (model.bodies[body].parent < 0)
        pref = 0;
      else
        pref = 2;
    }
    // Within a class, lengths before angles: a cut or attachment point is then carried by its
    // translations, which represent any displaced point exactly (angles only to first order).
    // Then bodies nearer the root first. Parameters confounded at the nominal model are usually
    // so only to first order; the one kept must stand in for the others' true deviations. A
    // parameter upstream stands in for a downstream one benignly, whereas a downstream one (on the
    // Delta: an offset inside the plate ball joint, modelled as three revolutes, standing in for
    // the elbow's axis offset) adds behaviour the truth does not have (there: the 3R gimbal's lock
    // inside the working volume, millimetres off nearby). Measured in identify_bench "all".
    int depth = 0;
    for (int b = prm.body; b >= 0 && depth < 63;
         b = model.bodies[static_cast<std::size_t>(b)].parent)
      ++depth;
    opt.preference[i] = 64 * (2 * pref + (prm.unit == ParamUnit::kAngle ? 1 : 0)) + depth;
  }
  return opt;
}

}  // namespace robocal::calib

namespace robocal::calib {

Eigen::VectorXd tolerance_sigmas(const Mechanism& model, double length_sigma, double angle_sigma,
                                 double scale_sigma, bool include_fixed) {
  Eigen::VectorXd s = Eigen::VectorXd::Zero(static_cast<Eigen::Index>(model.parameters.size()));
  for (std::size_t i = 0; i < model.parameters.size(); ++i) {
    const Parameter& p = model.parameters[i];
    if ((!p.free && !include_fixed) || p.exact) continue;
    switch (p.unit) {
      case ParamUnit::kLength:
        s(static_cast<Eigen::Index>(i)) = length_sigma;
        break;
      case ParamUnit::kAngle:
        s(static_cast<Eigen::Index>(i)) = angle_sigma;
        break;
      case ParamUnit::kScale:
        s(static_cast<Eigen::Index>(i)) = scale_sigma;
        break;
    }
  }
  return s;
}

namespace {

// d(task position) / d(actuated joint values) at `readings` by central differences (readings ->
// joint values is affine per actuator, q = scale r + offset: step the reading by h / scale).
bool task_position_jacobian(const MechanismPredictor& predictor, const Eigen::VectorXd& params,
                            const Eigen::VectorXd& readings, Eigen::MatrixXd& J) {
  const Mechanism& m = predictor.model();
  const auto A = readings.size();
  J.resize(3, A);
  const double h = 1e-6;
  for (Eigen::Index i = 0; i < A; ++i) {
    const Body& b = m.bodies[static_cast<std::size_t>(m.actuated[static_cast<std::size_t>(i)])];
    const double scale = b.encoder_scale_param >= 0 ? params(b.encoder_scale_param) : 1.0;
    const double step = h / (std::abs(scale) > 1e-12 ? scale : 1.0);
    Eigen::Vector3d x[2];
    for (int s = 0; s < 2; ++s) {
      Eigen::VectorXd r = readings;
      r(i) += (s == 0 ? step : -step);
      FramePrediction fp;
      std::string why;
      if (!predictor.predict(params, r, -1, false, fp, why)) return false;
      x[s] = fp.pose.translation();
    }
    J.col(i) = (x[0] - x[1]) / (2.0 * h);
  }
  return true;
}

}  // namespace

double task_conditioning(const MechanismPredictor& predictor, const Eigen::VectorXd& params,
                         const Eigen::VectorXd& readings) {
  Eigen::MatrixXd J;
  if (!task_position_jacobian(predictor, params, readings, J)) return 0.0;
  const Eigen::JacobiSVD<Eigen::MatrixXd> svd(J);
  const Eigen::VectorXd& sv = svd.singularValues();
  if (sv.size() == 0 || sv(0) <= 0.0) return 0.0;
  return sv(sv.size() - 1) / sv(0);
}

bool tool_weight_loads(const MechanismPredictor& predictor, const Eigen::VectorXd& params,
                       const Eigen::VectorXd& readings, Eigen::VectorXd& loads) {
  Eigen::MatrixXd J;
  if (!task_position_jacobian(predictor, params, readings, J)) return false;
  // Virtual work: the actuator efforts tau balance the weight f = (0, 0, -1) N when
  // tau . dq = -f . dx for every motion, so tau = -J^T f = J's z row.
  loads = J.row(2).transpose();
  return true;
}

std::vector<Eigen::VectorXd> sample_actuators(const MechanismPredictor& predictor,
                                              const std::vector<Eigen::VectorXd>& must_solve,
                                              std::size_t count, std::mt19937& rng,
                                              double min_relative_sigma, bool within_workspace) {
  const Mechanism& m = predictor.model();
  const auto A = static_cast<Eigen::Index>(m.actuated.size());
  Eigen::VectorXd lo(A);
  Eigen::VectorXd hi(A);
  for (Eigen::Index i = 0; i < A; ++i) {
    const Body& b = m.bodies[static_cast<std::size_t>(m.actuated[static_cast<std::size_t>(i)])];
    lo(i) = b.limits.lower > -1e299 ? b.limits.lower : -1.0;
    hi(i) = b.limits.upper < 1e299 ? b.limits.upper : 1.0;
  }
  const Eigen::VectorXd nominal = m.nominal_parameters();
  std::uniform_real_distribution<double> u(0.0, 1.0);
  std::vector<Eigen::VectorXd> out;
  for (std::size_t tries = 0; out.size() < count && tries < 100 * count; ++tries) {
    Eigen::VectorXd q(A);
    for (Eigen::Index i = 0; i < A; ++i) q(i) = lo(i) + (hi(i) - lo(i)) * u(rng);
    // Limits are joint values; readings follow from the nominal encoder model.
    const Eigen::VectorXd readings = readings_from_joint_values(m, nominal, q);
    bool ok = true;
    for (const auto& params : must_solve) {
      FramePrediction pred;
      std::string why;
      ok = ok && predictor.predict(params, readings, -1, false, pred, why);
      if (!ok) break;
      ClosureOptions diag;
      diag.diagnose = true;
      const ClosureResult c = solve_closure(m, params, readings, {}, diag);
      // The assembly-mode check (assembly_mode.hpp): design and held-out poses lie on the
      // intended mode, clear of the boundaries where modes meet (ambiguous is refused too).
      ok = c.ok() && c.mode.verdict != ModeVerdict::kOther &&
           c.mode.verdict != ModeVerdict::kAmbiguous &&
           (c.unknowns == 0 ||
            (c.rank == c.unknowns && c.sigma_min >= min_relative_sigma * c.sigma_max));
      if (ok && within_workspace && m.workspace.min_task_conditioning > 0.0)
        ok = task_conditioning(predictor, params, readings) >= m.workspace.min_task_conditioning;
    }
    if (ok) out.push_back(readings);
  }
  return out;
}

}  // namespace robocal::calib
