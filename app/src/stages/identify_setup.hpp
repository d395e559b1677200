#pragma once
// What both ways of identifying share — a session (`identify_session`) and a measurements file
// (`robocal identify --robot R --measurements F`): the identification problem built from the
// robot, its measurements and the caller's choices, and the calibrated robot file's text.
#include "robocal/calib/base_frame.hpp"
#include "robocal/calib/identification.hpp"
#include "robocal/calib/mechanism.hpp"

#include <Eigen/Core>

#include <cstddef>
#include <string>
#include <vector>

namespace robocal::app {

// What the caller chooses beside the robot and the measurements. The defaults are the session
// route's except for the priors (a session uses them unless --no-priors).
struct IdentifyChoices {
  bool priors = false;  // the robot file's tolerances as priors (MAP)
  // Parameters to estimate (globs on names; empty = the robot file's free ones) and to hold.
  std::vector<std::string> free_patterns;
  std::vector<std::string> fix_patterns;
  std::string robust = "none";  // none, huber or cauchy
  double robust_scale = 3.0;
  bool stated_noise = false;  // keep the stated noise for the covariance
  int multi_start = 0;
  unsigned seed = 1;
  int threads = 1;
};

// The identification problem of the robot alone (a caller that adds cameras or a bed wraps the
// predictor and these options).
struct IdentifyProblem {
  Eigen::VectorXd start;       // `nominal` with the base frame placed in the measurement world
  calib::BaseFrameFit placed;  // how the base frame was placed (placed == false: not moved)
  calib::SolveOptions options;
};

// The problem of identifying `model` (measured body `frame`, values `nominal`) from
// `measurements`. Both ways share two rules that follow from the data: the world is the frame the
// instrument reports in (the cameras' rig, a laser tracker), so where the robot stands in it is
// genuinely unknown. Its base frame therefore starts where the measured 6-D poses put it
// (calib::fit_base_frame; unchanged with fewer than three of them) and, with priors, carries no
// prior. UsageError for a --free/--fix that leaves nothing to estimate or an unknown --robust.
IdentifyProblem identify_problem(const calib::Mechanism& model, int frame,
                                 const Eigen::VectorXd& nominal,
                                 const calib::Measurements& measurements,
                                 const IdentifyChoices& choices);

// The calibrated robot file: the text of the robot file `robot_file` with the robot's values of
// `estimate` (parameters after the robot's — cameras, a bed — are not the robot's and are left
// out), marked calibrated where estimated (`estimated`) or moved from the robot file's values
// (the base frame placed before the fit), under the header `provenance`.
std::string calibrated_robot_text(const std::string& robot_file, const calib::Mechanism& model,
                                  const Eigen::VectorXd& estimate,
                                  const std::vector<std::size_t>& estimated,
                                  const std::vector<std::string>& provenance);

}  // namespace robocal::app
