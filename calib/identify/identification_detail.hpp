#pragma once
// What the parts of identify() share (identification.cpp: the solve; identification_checks.cpp:
// the input checks; identification_diagnostics.cpp: residuals and noise; identification_gauge.cpp:
// the gauge with little data). Internal to robocal_calib_identify.
#include "identification_costs.hpp"

#include "robocal/calib/identification.hpp"

#include <Eigen/Core>

#include <map>
#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace robocal::calib::detail {

// ---- input checks (identification_checks.cpp) ----------------------------------------------

// Every reading of the observation is finite and its noise positive.
bool finite_observation(const Observation& obs);

// The pose's pixel groups name runs of its own pixel observations with a matching decorrelation;
// otherwise `why` says which group is malformed.
bool valid_pixel_groups(const PoseMeasurement& pose, std::string& why);

// Every pixel observation of a pose can be evaluated at the start (camera known, corner in front
// of it); otherwise `why` names the first that cannot.
bool pixels_project(const FramePredictor& model, const Eigen::VectorXd& params,
                    const PoseMeasurement& pose, const FramePrediction& pred, std::string& why);

// Measured positions beside the nominal model's prediction of them, pose by pose.
struct MeasuredAndPredicted {
  std::vector<Eigen::Vector3d> measured;
  std::vector<Eigen::Vector3d> predicted;
};

// Millimetres given as metres (or the reverse): the measured positions spread more than 300
// times as far as the predicted ones, or less than 1/300. The message says so, or nothing.
std::optional<std::string> position_units_mismatch(const MeasuredAndPredicted& positions);

// ---- observation types and residuals (identification_diagnostics.cpp) ----------------------

// Observation types whose noise is estimated separately (index = group id used below).
enum Group : int {
  kPointRows,
  kPosePosition,
  kPoseRotation,
  kProbeRows,
  kDistanceRows,
  kPixelRows
};
std::vector<NoiseGroup> observation_groups();

// Stated σ of each residual row of an observation (diagonal of the inverse information).
std::vector<std::pair<int, double>> row_labels(const Observation& obs);

// The middle element (the upper one of an even count); 0 for none.
double median_of(std::vector<double> v);

// The measured position of a point or pose observation.
std::optional<Eigen::Vector3d> observed_position(const Observation& obs);

// Fit residuals per observation type at `params` (ResidualDiagnostics::by_type), in the order
// point, pose position, pose rotation, probe height, distance; types without data left out.
std::vector<TypeResiduals> residuals_by_type(const FramePredictor& model,
                                             const Eigen::VectorXd& params,
                                             const std::vector<const PoseMeasurement*>& poses,
                                             const std::map<std::string, int>& slot_of,
                                             const std::vector<DistanceMeasurement>& distances);

// Plain-words warnings when the residuals say the stated noise was wrong, either way: the
// interval of the estimated scale excludes 1 and the scale is off by more than 1.5×.
void add_noise_warnings(const NoiseEstimate& noise, bool applied,
                        std::vector<std::string>& warnings);

// Outlier-proof noise scale of each observation type from whitened residual rows
// (1.4826 · median |r|; 1 where a type has no rows or zero spread).
std::vector<double> robust_row_scales(const Eigen::VectorXd& r, const std::vector<int>& row_group,
                                      std::size_t groups, int rows);

// ---- the assembled problem -------------------------------------------------------------------

// The assembled least-squares problem over the accepted poses (cost functions owned here so
// they can be evaluated outside Ceres for Jacobians and diagnostics).
struct Assembly {
  int threads = 1;  // workers for the pose blocks (evaluate_all, EvaluateAhead)
  std::vector<const PoseMeasurement*> poses;
  std::map<std::string, int> slot_of;  // pose id -> its slot (index in the measurements)
  std::vector<std::unique_ptr<PoseCost>> pose_costs;
  std::vector<std::unique_ptr<ceres::CostFunction>> distance_costs;
  std::vector<std::string> distance_labels;
  int rows = 0;
  // Observation type of every residual row (index into `groups`) for the noise estimate.
  std::vector<int> row_group;
  std::vector<NoiseGroup> groups = observation_groups();
  std::vector<std::vector<double>> stated =
      std::vector<std::vector<double>>(groups.size());  // per group: the stated σ of its rows
  void label(int group, double sigma) {
    row_group.push_back(group);
    stated[static_cast<std::size_t>(group)].push_back(sigma);
  }
};

// Probe heights in millimetres declared as metres: at the nominal model a height is off by at
// most millimetres; a value 1000x too large is off by decimetres to metres. The message names the
// worst pose, or nothing (identification_checks.cpp).
std::optional<std::string> probe_height_units_mismatch(const FramePredictor& model,
                                                       const Eigen::VectorXd& nominal,
                                                       const Assembly& as);

// ---- diagnostics at the estimate (identification_diagnostics.cpp) ------------------------

// Where the solve ended, as the diagnostics read it.
struct EstimateRows {
  const Eigen::VectorXd& params;     // the estimate (full parameter vector)
  const Eigen::VectorXd& residuals;  // whitened residual rows there (Assembly's order)
  const Eigen::MatrixXd& jacobian;   // their Jacobian, every parameter
  const std::vector<std::pair<int, int>>& pose_rows;  // first row and count of each pose block
  const std::vector<std::pair<std::size_t, double>>& prior_terms;  // (parameter, σ) of the priors
};

// Everything identify() reports about an accepted estimate: per-pose residuals with outlier
// flags, the noise per observation type, the covariance and the predicted accuracy, and the
// warnings on the fit's quality. Fills those parts of `result` (its estimated set and names are
// read).
void diagnose_estimate(const FramePredictor& model, const Eigen::VectorXd& nominal,
                       const Assembly& as, const EstimateRows& at,
                       const std::vector<DistanceMeasurement>& distances,
                       const SolveOptions& options, IdentificationResult& result);

// ---- the gauge with little data (identification_gauge.cpp) ---------------------------------

// Little data: which of the confounded candidates are held at nominal (gauge_choice.hpp). The
// rank analysis' pivot order gives one base set; among the sets of the same size the data
// separate as well, the one whose held parameters, off nominal by their tolerances, move the
// predictions over the measured area least. `report` is redone with that set first, so its
// redundancies explain the held parameters; returns the sentence for the gauge ("" = unchanged
// or not decidable).
std::string choose_little_data_gauge(const FramePredictor& model, const Eigen::VectorXd& params,
                                     const std::vector<const PoseMeasurement*>& poses,
                                     const Eigen::MatrixXd& Jc,
                                     const std::vector<std::size_t>& candidates,
                                     const std::vector<std::string>& cand_names,
                                     const SolveOptions& options, IdentifiabilityReport& report,
                                     EstimatorChoice& estimator);

}  // namespace robocal::calib::detail
