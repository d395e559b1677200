#include "stages/identify_setup.hpp"

#include "cli/cli_common.hpp"

#include "robocal/calib/calibrated_robot_file.hpp"
#include "robocal/calib/mechanism_predictor.hpp"
#include "robocal/core/files.hpp"

#include <fnmatch.h>

#include <set>

namespace robocal::app {

namespace {

bool matches(const std::string& name, const std::vector<std::string>& patterns) {
  for (const auto& p : patterns)
    if (fnmatch(p.c_str(), name.c_str(), 0) == 0) return true;
  return false;
}

// The parameters --free/--fix choose (empty when neither is given: the robot file's free ones).
std::vector<std::size_t> chosen_candidates(const calib::Mechanism& model,
                                           const IdentifyChoices& c) {
  std::vector<std::size_t> candidates;
  if (c.free_patterns.empty() && c.fix_patterns.empty()) return candidates;
  for (std::size_t i = 0; i < model.parameters.size(); ++i) {
    const std::string& n = model.parameters[i].name;
    const bool free =
        c.free_patterns.empty() ? model.parameters[i].free : matches(n, c.free_patterns);
    if (free && !matches(n, c.fix_patterns)) candidates.push_back(i);
  }
  if (candidates.empty()) throw UsageError("--free/--fix leave no parameter to estimate");
  return candidates;
}

}  // namespace

IdentifyProblem identify_problem(const calib::Mechanism& model, int frame,
                                 const Eigen::VectorXd& nominal,
                                 const calib::Measurements& measurements,
                                 const IdentifyChoices& choices) {
  IdentifyProblem problem;
  problem.start = nominal;
  problem.placed = calib::fit_base_frame(model, problem.start, frame, measurements.poses);
  calib::SolveOptions& opt = problem.options;
  opt = calib::solve_options_from_model(model, choices.priors);
  const std::vector<std::size_t> candidates = chosen_candidates(model, choices);
  if (!candidates.empty()) {
    opt.candidates = candidates;
    if (choices.priors) {
      opt.prior_sigma.assign(model.parameters.size(), 0.0);
      for (std::size_t i : candidates) opt.prior_sigma[i] = model.parameters[i].sigma;
    }
  }
  // The robot file's tolerances as priors (MAP). A cell's design (poses where the cameras see the
  // board) leaves weak directions; along them a maximum-likelihood estimate can trade, e.g., a
  // shoulder axis tilt of 1° against elbow offsets of 7 mm that fit the measured poses and are
  // millimetres off elsewhere (demo seed 1: 234 µm RMS, 5.1 mm max on held-out poses; with the
  // priors 46 µm, 0.26 mm). The base frame has no prior: world <-> robot is genuinely unknown
  // in the instrument's world.
  if (choices.priors)
    for (std::size_t i = 0; i < model.parameters.size(); ++i) {
      const int body = model.parameters[i].body;
      if (body >= 0 && model.bodies[static_cast<std::size_t>(body)].parent < 0)
        opt.prior_sigma[i] = 0.0;
    }
  if (choices.robust == "huber")
    opt.robust_loss = calib::RobustLoss::kHuber;
  else if (choices.robust == "cauchy")
    opt.robust_loss = calib::RobustLoss::kCauchy;
  else if (choices.robust != "none")
    throw UsageError("--robust must be none, huber or cauchy");
  opt.robust_scale = choices.robust_scale;
  opt.keep_stated_noise = choices.stated_noise;
  opt.multi_start = choices.multi_start;
  opt.seed = choices.seed;
  opt.threads = choices.threads;
  if (choices.multi_start > 0 && opt.prior_sigma.empty()) {
    opt.start_sigma.assign(model.parameters.size(), 0.0);
    for (std::size_t i = 0; i < model.parameters.size(); ++i)
      opt.start_sigma[i] = model.parameters[i].sigma;
  }
  return problem;
}

std::string calibrated_robot_text(const std::string& robot_file, const calib::Mechanism& model,
                                  const Eigen::VectorXd& estimate,
                                  const std::vector<std::size_t>& estimated,
                                  const std::vector<std::string>& provenance) {
  const Eigen::VectorXd values = estimate.head(static_cast<Eigen::Index>(model.parameters.size()));
  const Eigen::VectorXd file_values = model.nominal_parameters();
  std::set<std::size_t> changed;
  for (std::size_t i : estimated)
    if (i < model.parameters.size()) changed.insert(i);
  for (Eigen::Index i = 0; i < values.size(); ++i)
    if (values[i] != file_values[i]) changed.insert(static_cast<std::size_t>(i));
  return calib::calibrated_robot_yaml(core::read_text_file(robot_file), model, values,
                                      std::vector<std::size_t>(changed.begin(), changed.end()),
                                      provenance);
}

}  // namespace robocal::app
