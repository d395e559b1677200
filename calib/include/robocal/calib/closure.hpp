#pragma once
// Closure solver: forward kinematics of closed-loop mechanisms. Given actuator readings, find the
// passive joints that close every loop (damped Gauss-Newton / Levenberg-Marquardt with the exact
// analytic constraint Jacobian), warm-started from the previous solution, or cold-started from a
// closed-form seed (rotary Delta, linear delta, Gantry-Tau). Every answer carries the assembly-mode
// verdict (assembly_mode.hpp); an answer on another mode is never reported as converged.
//
// Seeding strategy (documented in testdata/robots/README.md, "Assembly mode"):
//  1. the caller's seed (warm start), else the closed-form seed, else the home configuration;
//  2. if that does not converge on an acceptable mode (intended or ambiguous) and the robot file
//     declares a mode: the closed-form seed (when 1 was a warm start), then continuation from the
//     home configuration (declared to be on the intended mode): the readings move from their home
//     values to the requested ones in steps, each step warm-started from the previous solution,
//     so the solution follows the intended branch unless the path crosses a singularity;
//  3. failing that, status kOtherMode (the answer found, with its verdict naming the flipped
//     invariant) or the first attempt's failure.
#include "robocal/calib/assembly_mode.hpp"
#include "robocal/calib/mechanism.hpp"

#include <Eigen/Core>
#include <Eigen/Geometry>

#include <memory>
#include <string>
#include <vector>

namespace robocal::calib {

enum class SolveStatus : std::uint8_t {
  kConverged,     // residual <= tolerance
  kSingular,      // converged (diagnose on) but dv/dtheta has rank < unknowns: singular pose or
                  // idle mobility (see rank)
  kNotConverged,  // iteration limit reached; residual reported
  kNoSolution,    // stalled with a residual far from zero (loop cannot close / unreachable)
  kInvalidInput,  // NaN/inf or wrong vector sizes
  kOtherMode,     // the loops close, but only on another assembly mode than the robot file's
                  // (every seed tried); ClosureResult::mode names the flipped invariant
};

const char* to_string(SolveStatus status);

struct ClosureOptions {
  int max_iterations = 50;
  double tolerance = 1e-12;  // max |residual| (m, rad) accepted as closed
  // Compute the SVD of the constraint Jacobian at the solution (rank, sigma_min/max). Costs
  // ~10-20 us on the Delta; off for the hot path.
  bool diagnose = false;
  double rank_tolerance = 1e-9;  // relative singular value below which a direction is lost
  // Retry other seeds (closed form, continuation from home) when the answer lies on another
  // assembly mode, and refuse it (kOtherMode) if none helps. Off: return the first answer with its
  // verdict (diagnostics, tests of the check itself).
  bool enforce_mode = true;
  int continuation_steps = 16;  // steps of the continuation from the home configuration
};

struct ClosureResult {
  SolveStatus status = SolveStatus::kInvalidInput;
  Eigen::VectorXd passive;  // passive joint values (Mechanism::passive order)
  double residual = 0.0;    // max |v| at the returned state
  int iterations = 0;
  // Diagnostics (filled when options.diagnose, else rank = -1).
  int rank = -1;      // numerical rank of dv/dtheta
  int unknowns = 0;   // number of passive joints
  int equations = 0;  // constraint rows
  double sigma_min = 0.0, sigma_max = 0.0;
  // Assembly-mode verdict of the returned state (kUndeclared when the file declares none or the
  // loops did not close).
  ModeCheck mode;
  // Which seed gave the answer: "warm", "closed_form", "home", "continuation".
  const char* seed_used = "";
  bool ok() const { return status == SolveStatus::kConverged; }
};

// Reusable solver: caches the parameter-dependent fixed transforms and a preallocated workspace,
// so the Newton iterations inside solve() do no heap allocation (only the returned vector is
// allocated). Keeps a pointer to `model`, which must outlive the solver. Throws
// std::invalid_argument when params has the wrong size.
class ClosureSolver {
 public:
  ClosureSolver(const Mechanism& model, const Eigen::VectorXd& params, ClosureOptions options = {});

  // Solve for the passive joints. `seed` = previous passive solution (warm start); empty ->
  // closed-form seed when the model has one, else the home configuration.
  ClosureResult solve(const Eigen::VectorXd& actuator_readings,
                      const Eigen::VectorXd& seed = Eigen::VectorXd()) const;

  // Passive seed from the closed form (or home) for these readings; empty if none applies.
  Eigen::VectorXd closed_form_seed(const Eigen::VectorXd& actuator_readings) const;

  const Mechanism& model() const;
  const Eigen::VectorXd& params() const;
  const ClosureOptions& options() const;

  ClosureSolver(const ClosureSolver& other);
  ClosureSolver& operator=(const ClosureSolver& other);
  ClosureSolver(ClosureSolver&&) noexcept;
  ClosureSolver& operator=(ClosureSolver&&) noexcept;
  ~ClosureSolver();

  // Implementation state (cached transforms + workspace); solve() reuses it, so one
  // ClosureSolver must not be used from two threads at once (copy it instead).
  struct Impl;

 private:
  std::unique_ptr<Impl> impl_;
};

// One-shot convenience: solve the closure at `params`.
ClosureResult solve_closure(const Mechanism& model, const Eigen::VectorXd& params,
                            const Eigen::VectorXd& actuator_readings,
                            const Eigen::VectorXd& seed = Eigen::VectorXd(),
                            const ClosureOptions& options = {});

// Forward kinematics in one call: solve the closure, then the frame pose.
struct ForwardResult {
  ClosureResult closure;
  JointState state;
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
};
ForwardResult forward_kinematics(const Mechanism& model, const Eigen::VectorXd& params,
                                 const Eigen::VectorXd& actuator_readings, int frame,
                                 const Eigen::VectorXd& seed = Eigen::VectorXd(),
                                 const ClosureOptions& options = {});

}  // namespace robocal::calib
