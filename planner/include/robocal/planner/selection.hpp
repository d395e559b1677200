#pragma once
// Observability-driven selection of measurement poses from a feasible candidate pool
// (kinematics.md §5).
//
// The identification Jacobian of a pose is the 6 x P derivative of the measured frame's pose
// (position, world small-angle rotation) with respect to the model parameters, through the
// closures (calib::MechanismPredictor). Its rows are whitened by the measurement noise
// (position_sigma, rotation_sigma); its columns are restricted to the identifiable base set
// (calib::analyze_identifiability over a subsample of the pool, with the robot file's free
// parameters and preference) and scaled to unit RMS norm per pose over the pool, so lengths and
// angles compete on equal terms and singular values are unit-free.
//
// Indices of the scaled Jacobian of the m selected poses, singular values σ1 >= ... >= σL:
//   O1 = (σ1…σL)^(1/L)/√m  (D-optimal)        O2 = σL/σ1  (inverse condition number)
//   O3 = σL  (minimum singular value)          O4 = σL²/σ1 (noise amplification)
//   O5 = 1/Σ(1/σi)
// Selection: greedy (each step adds the candidate that increases the index most) then DETMAX
// exchange (add the best outsider, drop the least useful member, until the dropped pose is the
// one just added). O1 uses exact rank-6 determinant updates (Sherman–Morrison–Woodbury) over the
// whole pool; O2–O5 are not additive, so each step evaluates them exactly on the `shortlist`
// candidates with the largest D-optimal gain (until the set has full rank all of them are 0 and
// the D-optimal gain decides).
//
// Acceptance: the selected set passes when the condition number of its scaled base-set
// Jacobian (σ1/σL, columns scaled by their norms over the selected poses, as identifiability
// does) is at most `max_condition`. Default 1e4: the rotary Delta's well-spread 40-pose designs
// measure 1.5e3–2.5e3 with full-pose observations (planner_bench), a rank-deficient set
// (e.g. every pose in one plane) is infinite; beyond 1e4 the weakest identifiable direction is
// determined 10 000× worse than the best and its noise dominates the predicted accuracy.
//
// Predicted accuracy: the linearised covariance of the parameters from the selected poses
// propagated to the measured frame's position at every pool pose (the working volume): RMS and
// maximum of the 1-σ position error (m). Selection stops early once the RMS reaches
// `target_accuracy`.
#include "robocal/calib/identification.hpp"
#include "robocal/calib/mechanism.hpp"
#include "robocal/calib/mechanism_predictor.hpp"

#include <Eigen/Core>

#include <array>
#include <cstdint>
#include <string>
#include <vector>

namespace robocal::planner {

// kTask: not an index of the Jacobian's singular values but the quantity the calibration is
// judged by: the mean predicted position variance of the measured frame over the candidate pool
// (the working volume), tr(W M^-1) with W the pool's mean position information (I-optimality,
// "predicted accuracy"). Minimised by greedy + exchange with exact rank-6 updates.
enum class ObservabilityIndex : std::uint8_t { kO1, kO2, kO3, kO4, kO5, kTask };
const char* to_string(ObservabilityIndex index);
// "O1".."O5", "task" (case-insensitive) or "d-optimal"; false when unknown.
bool parse_index(const std::string& text, ObservabilityIndex* index);

// Whitened, column-scaled identification Jacobian of every pool pose (rows 6i..6i+5 = pose i).
struct ObservabilityModel {
  Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> rows;
  std::vector<std::string> names;       // base-set parameter names (columns)
  std::vector<std::size_t> parameters;  // their indices in the model's parameter vector
  Eigen::VectorXd column_scale;         // physical column = scaled column * scale
  double position_sigma = 20e-6;
  double rotation_sigma = 1e-4;
  std::vector<std::string> messages;  // identifiability in words
  std::size_t poses() const { return static_cast<std::size_t>(rows.rows() / 6); }
  std::size_t columns() const { return static_cast<std::size_t>(rows.cols()); }
};

struct ObservabilityOptions {
  double position_sigma = 20e-6;            // m, 1-σ of a measured position coordinate
  double rotation_sigma = 1e-4;             // rad
  std::size_t identifiability_poses = 300;  // pool subsample for the base set
};

// Builds the model over the pool's actuator readings at `params`. Poses the predictor cannot
// solve get zero rows. Throws std::invalid_argument when no parameter is identifiable.
ObservabilityModel build_observability_model(const calib::MechanismPredictor& predictor,
                                             const Eigen::VectorXd& params,
                                             const std::vector<Eigen::VectorXd>& pool,
                                             const ObservabilityOptions& options = {});

struct SelectionOptions {
  // O5 by default: lowest median held-out error of O1-O5 on planner_bench (Delta cell, 20 trials).
  ObservabilityIndex index = ObservabilityIndex::kO5;
  std::size_t count = 40;        // poses to select (in addition to `measured`)
  bool exchange = true;          // DETMAX after greedy
  int max_exchanges = 0;         // 0 = 4 × count
  std::size_t shortlist = 12;    // O2–O5: exact evaluations per step
  double max_condition = 1e4;    // acceptance test (see above)
  double target_accuracy = 0.0;  // m, RMS predicted position error; 0 = select `count`
};

struct IndexValues {
  std::array<double, 5> o{};      // O1..O5
  double condition_number = 0.0;  // σ1/σL of the selected, column-normalised Jacobian
  std::size_t rank = 0;
};

struct Selection {
  std::vector<std::size_t> chosen;  // pool indices, the new poses in selection order
  IndexValues values;
  bool accepted = false;
  double predicted_rms = 0.0;  // m
  double predicted_max = 0.0;  // m
  bool stopped_early = false;  // target accuracy reached before `count`
  int exchanges = 0;
  std::string message;
};

// Selects poses from the pool. `measured` (sequential mode): pool indices already measured; the
// selection proposes the next best ones given them (they count in the indices and predictions).
Selection select_poses(const ObservabilityModel& model, const SelectionOptions& options,
                       const std::vector<std::size_t>& measured = {});

// Indices and acceptance quantities of a set of pool poses (independent of how it was chosen).
IndexValues evaluate_set(const ObservabilityModel& model, const std::vector<std::size_t>& set);
// Predicted 1-σ position error (m) at every pool pose from the covariance of `set`; RMS and max.
void predicted_accuracy(const ObservabilityModel& model, const std::vector<std::size_t>& set,
                        double* rms, double* max);

}  // namespace robocal::planner
