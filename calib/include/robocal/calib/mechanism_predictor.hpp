#pragma once
// Adapter from the closed-loop mechanism model (mechanism.hpp, closure.hpp, kinematics.hpp) to the
// identification engine's FramePredictor: closure solved per pose (warm-started from that pose's
// previous solution), frame pose and its exact parameter Jacobian by the implicit-function
// theorem (parameter_jacobian). Plus the defaults identification takes from a robot file: which
// parameters are free, their prior tolerances, and which of a confounded group to keep.
#include "robocal/calib/closure.hpp"
#include "robocal/calib/identification.hpp"
#include "robocal/calib/mechanism.hpp"

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
  bool predict(const Eigen::VectorXd& params, const Eigen::VectorXd& actuators, int slot,
               bool with_jacobian, FramePrediction& out, std::string& why) const override;

  const Mechanism& model() const { return model_; }
  int frame() const { return frame_; }

 private:
  const Mechanism& model_;
  int frame_;
  ClosureOptions options_;
  // Caches (single-threaded use): the closure solver for the last parameter vector, and the last
  // passive solution per pose slot (warm start keeps each pose on its assembly mode).
  mutable std::optional<ClosureSolver> solver_;
  mutable Eigen::VectorXd solver_params_;
  mutable std::vector<Eigen::VectorXd> seeds_;
};

// Candidates = the robot file's free parameters; prior_sigma = their tolerances when
// `use_priors`; preference: joint geometry and rod lengths first, then encoder parameters and
// attachment/cut frames, then the base frame (bodies hanging from the world), then the tool
// frame — so a tool offset confounded with the base translation is the one held fixed.
SolveOptions solve_options_from_model(const Mechanism& model, bool use_priors);

}  // namespace robocal::calib
