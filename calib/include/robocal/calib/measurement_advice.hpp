#pragma once
// What to measure next, and where.
//
// With little data the identification estimates only the combinations the data separate and
// holds the rest at nominal (the gauge). This says which further measurements, at which
// positions, would make the held parameters identifiable: candidates of the kinds the user can
// take (probe heights on the bed, 3-D points, distances between two positions), each added where
// it raises the rank of the identification Jacobian the most (ties: where it raises the weakest
// separated direction the most), until everything with an effect is identifiable with a few
// equations to spare (AdviceOptions::redundancy) or the budget is spent. Then, with as many
// suggestions, the points are chosen again for the predictions (AdviceOptions::design): an
// I-optimal design (probe_design.hpp) minimising the average variance, over the working area, of
// the quantity the user measures (the bed height where heights are probed, else the position),
// kept unless it separates fewer parameters than the rank rule. The same selection, started from
// no data, designs a probe pattern.
#include "robocal/calib/identification.hpp"

#include <Eigen/Core>

#include <string>
#include <vector>

namespace robocal::calib {

struct AdviceOptions {
  double height_sigma = 10e-6;          // m, a suggested probe height's noise
  double point_sigma = 20e-6;           // m, per coordinate
  double distance_sigma = 10e-6;        // m
  bool points = false;                  // suggest 3-D points (needs a tracker or cameras)
  bool distances = true;                // suggest distances between two positions of `pool`
  std::size_t distance_positions = 24;  // distances pair the first N positions of `pool`
  std::size_t max_suggestions = 12;
  // Equations beyond the identifiable count to aim for once the rank is reached: an exactly
  // determined fit has no check on its noise and is as ill-conditioned as the design allows.
  std::size_t redundancy = 6;
  // Choose the suggestions I-optimally for the predictions over `working_area` (false: by the rank
  // and weakest-direction rule alone).
  bool design = true;
  // Readings where the predictions matter (the printed area); empty = the height pool when there
  // is one, else the pool.
  std::vector<Eigen::VectorXd> working_area;
  // Per model parameter, how far the truth may be from nominal (the robot file's σ; 0 or empty =
  // unknown): the design weighs what stays undetermined (held at nominal, a bias over the working
  // area) against the noise with it. Without it a very weak prior stands in (probe_design.hpp).
  std::vector<double> prior_sigma;
  // How the fit will treat what the data do not separate (with prior_sigma on every candidate):
  // false = identify's default, held at nominal (the design then minimises noise plus the held
  // parameters' bias, that estimator's expected error); true = estimated with the priors (MAP:
  // the Bayesian criterion). `preference`: the fit's base-set preference per model parameter
  // (SolveOptions::preference), which decides what it holds.
  bool map_estimator = false;
  std::vector<int> preference;
};

struct SuggestedMeasurement {
  std::string kind;  // "probe height", "3-D point" or "distance"
  Eigen::VectorXd actuators;
  Eigen::Vector3d position = Eigen::Vector3d::Zero();  // of the measured frame, at `params`
  Eigen::VectorXd actuators_b;                         // distances: the second position
  Eigen::Vector3d position_b = Eigen::Vector3d::Zero();
  std::size_t rank_after = 0;  // identifiable parameters once this (and those before) are added
};

struct MeasurementAdvice {
  std::size_t rank_before = 0;     // identifiable candidate parameters with today's data
  std::size_t rank_reachable = 0;  // with every candidate measurement added
  std::size_t rank_after = 0;      // with the suggestions added
  std::vector<SuggestedMeasurement> suggestions;
  std::string text;  // plain words ("" when nothing would help)
};

// `candidates`: indices of the parameters to make identifiable (empty = all). `height_pool`:
// actuator readings with the measured frame on the bed (probe height candidates, may be empty);
// `pool`: readings for 3-D point and distance candidates (may be empty). Poses of either pool the
// model cannot predict are skipped.
MeasurementAdvice advise_measurements(const FramePredictor& model, const Eigen::VectorXd& params,
                                      const Measurements& current,
                                      const std::vector<std::size_t>& candidates,
                                      const std::vector<Eigen::VectorXd>& height_pool,
                                      const std::vector<Eigen::VectorXd>& pool,
                                      const AdviceOptions& options = {});

class MechanismPredictor;

// Advice with candidates like the user's own data, for the identify command: probe heights on a
// grid over the probed area (1.15 × its radius) at the probed height; distances between grid
// positions at the height of the distance measurements (or, with probe heights only, on a part
// printed 5 mm above the bed); 3-D points at sampled configurations when the data hold points or
// poses, or when nothing of the user's kinds would help. Grid positions are reached through the
// robot's inverse kinematics at `params` (the robot's own parameters: the head of `params` for a
// wrapping `model`). Empty advice when nothing would help.
MeasurementAdvice advise_like_the_data(const MechanismPredictor& robot, const FramePredictor& model,
                                       const Eigen::VectorXd& params, const Measurements& current,
                                       const std::vector<std::size_t>& candidates,
                                       AdviceOptions options = {});

}  // namespace robocal::calib
