#pragma once
// Adapter from the closed-loop mechanism model (mechanism.hpp, closure.hpp, kinematics.hpp) to the
// identification engine's FramePredictor: closure solved per pose (seeded from that pose's
// solution at the nominal parameters), frame pose and its exact parameter Jacobian by the
// implicit-function theorem (parameter_jacobian). Plus the defaults identification takes from a
// robot file: which parameters are free, their prior tolerances, and which of a confounded group to
// keep.
#include "robocal/calib/closure.hpp"
#include "robocal/calib/identification.hpp"
#include "robocal/calib/mechanism.hpp"

#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

namespace robocal::calib {

class MechanismPredictor final : public FramePredictor {
 public:
  // `frame` = measured body (default: the model's tool frame). The model must outlive this.
  explicit MechanismPredictor(const Mechanism& model, int frame = -1, ClosureOptions options = {});

  std::size_t parameter_count() const override;
  std::vector<std::string> parameter_names() const override;
  std::vector<std::string> parameter_labels() const override;  // display_name of each
  bool predict(const Eigen::VectorXd& params, const Eigen::VectorXd& actuators, int slot,
               bool with_jacobian, FramePrediction& out, std::string& why) const override;

  // A solve's answer depends on its parameters, readings and seed alone (not on which solver
  // of the pool ran it, nor what it solved before).
  bool thread_safe() const override { return true; }

  const Mechanism& model() const { return model_; }
  int frame() const { return frame_; }

 private:
  // The seed of a pose slot: its solution at the nominal parameters (cached per slot).
  Eigen::VectorXd seed_for(const Eigen::VectorXd& actuators, int slot) const;

  const Mechanism& model_;
  int frame_;
  ClosureOptions options_;
  // Caches, shared by the threads that call predict: closure solvers, each set up for the
  // parameter vector it last solved at (one per thread at a time, from a pool, so that a thread
  // finds one set up for the parameters being evaluated), one for the nominal parameters, and each
  // pose slot's nominal solution (the seed for every parameter vector, see predict()).
  struct Solver {
    std::optional<ClosureSolver> solver;
    Eigen::VectorXd params;
  };
  mutable std::mutex pool_mutex_;
  mutable std::vector<std::unique_ptr<Solver>> idle_solvers_;
  mutable std::mutex seed_mutex_;
  mutable std::optional<ClosureSolver> nominal_solver_;
  mutable std::vector<Eigen::VectorXd> seeds_;
  mutable std::vector<Eigen::VectorXd> seed_readings_;
};

// Candidates = the robot file's free parameters; prior_sigma = their tolerances when
// `use_priors`; preference: the base frame (bodies hanging from the world) first, then joint
// geometry, rod lengths and encoder parameters, then attachment/cut frames, then the tool frame —
// so a tool offset confounded with the base translation is the one held fixed and explained;
// within each, lengths before angles, then bodies nearer the root first (an upstream parameter
// carries a downstream one's true deviation better than the reverse; identify/README.md).
SolveOptions solve_options_from_model(const Mechanism& model, bool use_priors);

}  // namespace robocal::calib

namespace robocal::calib {

// Realistic-tolerance perturbation sigmas per parameter: `length_sigma` for lengths,
// `angle_sigma` for angles, `scale_sigma` for encoder scales; parameters the robot file fixes are
// not perturbed unless `include_fixed`, and those it declares exact (Parameter::exact) never.
Eigen::VectorXd tolerance_sigmas(const Mechanism& model, double length_sigma, double angle_sigma,
                                 double scale_sigma = 0.0, bool include_fixed = false);

// `count` actuator reading vectors drawn uniformly within the actuated joints' limits (±1 joint
// unit where a limit is open) that every model in `must_solve` can assemble, away from
// singularities: closure converged with the assembly-mode verdict `intended` (assembly_mode.hpp;
// neither another mode nor ambiguous) and σ_min/σ_max of the constraint Jacobian ≥
// `min_relative_sigma` (0.01 keeps the Delta's plate clear of its stretched-arm and
// parallel-rod singularities). When the robot file declares a working volume (`workspace:`) and
// `within_workspace`, every model in `must_solve` must also have task_conditioning ≥ its
// min_task_conditioning there. Gives up after 100·count draws and returns what it has.
std::vector<Eigen::VectorXd> sample_actuators(const MechanismPredictor& predictor,
                                              const std::vector<Eigen::VectorXd>& must_solve,
                                              std::size_t count, std::mt19937& rng,
                                              double min_relative_sigma = 0.01,
                                              bool within_workspace = true);

// σ_min/σ_max of the Jacobian of the task frame's position w.r.t. the actuated joint values at
// `readings` (central differences through the closure; 1 / the velocity amplification spread);
// 0 where the closure cannot be solved.
double task_conditioning(const MechanismPredictor& predictor, const Eigen::VectorXd& params,
                         const Eigen::VectorXd& readings);

// The static load each actuator carries when a unit weight (1 N) hangs at the task frame, by
// virtual work: load_i = d z_task / d q_i, with z up in the robot file's frame (as every library
// robot declares it) and q_i the actuated joint value (N m per N for a revolute actuator, N per N
// for a prismatic one; the links' own weight is not included). Positive: the actuator pushes
// towards larger joint values to hold the weight up. Residuals that follow it point to
// compliance (joints, gears, belts) or a payload the model lacks. False where the closure cannot
// be solved (central differences through it, as task_conditioning).
bool tool_weight_loads(const MechanismPredictor& predictor, const Eigen::VectorXd& params,
                       const Eigen::VectorXd& readings, Eigen::VectorXd& loads);

}  // namespace robocal::calib
