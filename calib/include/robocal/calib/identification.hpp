#pragma once
// Kinematic identification: find the parameter values (geometry, base and tool frames, actuator
// offsets and scales — whatever the model exposes as named parameters) that best explain
// measurements of the robot's measured frame, say how sure we are, and validate on poses the fit
// did not see.
//
// The engine is written against FramePredictor (frame_predictor.hpp), the one thing it needs
// from a mechanism model; what it fits are Measurements (measurements.hpp). This header is the
// solve's API: options, result, identify() and its validation and simulation.
//
// Pipeline of identify():
//  1. validate input (duplicate ids → error; non-finite readings or observations, poses whose
//     closure cannot be solved at the nominal model → excluded with a reason; units off by 1000 →
//     error; too few equations → error naming how many poses are needed);
//  2. identifiability at the nominal model over the actual poses (identifiability.hpp): the free
//     set is reduced to an identifiable base set, the rest held at nominal and reported;
//  3. Ceres Levenberg–Marquardt on the whitened measurement residuals (maximum likelihood), with
//     optional robust loss, bounds, priors from tolerances (MAP) and multi-start; deliberately
//     tight tolerances (see SolveOptions);
//  4. a diverged or unusable solve keeps the nominal model and says so;
//  5. covariance, correlations, per-pose residuals with outlier flags, predicted accuracy.
#include "robocal/calib/frame_predictor.hpp"
#include "robocal/calib/identifiability.hpp"
#include "robocal/calib/measurements.hpp"
#include "robocal/calib/noise_estimate.hpp"
#include "robocal/calib/observations.hpp"
#include "robocal/calib/uncertainty.hpp"

#include <Eigen/Core>
#include <Eigen/Geometry>

#include <optional>
#include <random>
#include <string>
#include <variant>
#include <vector>

namespace robocal::calib {

enum class RobustLoss { kNone, kHuber, kCauchy };

struct SolveOptions {
  // Parameters the user allows to change (indices into the model's parameter vector). Empty =
  // every parameter. The identifiability step may hold some of them at nominal.
  std::vector<std::size_t> candidates;
  // Base-set preference per parameter (lower = kept first among confounded ones); empty = none.
  std::vector<int> preference;
  IdentifiabilityOptions identifiability;
  // Priors from tolerances: prior_sigma[i] > 0 adds (a_i − nominal_i)/σ_i (MAP). Empty = none.
  std::vector<double> prior_sigma;
  // How far each parameter's truth may be from nominal (the robot file's tolerances), used without
  // priors to choose the gauge with little data: which confounded parameters are held at nominal
  // (gauge_choice.hpp: those that move the predictions over the measured area least). Empty = the
  // rank analysis' own choice.
  std::vector<double> gauge_sigma;
  // With gauge_sigma, little data and printer observations (probe heights, with or without
  // distances), the estimated set is then chosen by what it predicts (EstimatorChoice);
  // false keeps the gauge choice's set of the data's rank.
  bool choose_estimator = true;
  // Estimate the redundant candidates too (all with an effect), regularised by the priors, instead
  // of holding them at nominal. Redundancies found at the nominal model are often only local
  // (first order): a truth perturbed in "redundant" parameters is then not exactly representable
  // by the base set. Requires prior_sigma on every candidate; covariance is then the MAP one.
  bool estimate_redundant = false;
  // Second, relinearised solve. Redundancies found at the nominal model often hold there only to
  // first order: the nominal geometry is special (on the rotary Delta the plate never rotates, so
  // a ball moved on the plate equals the rod's upper end moved in the world). A truth perturbed in
  // a held parameter is then carried by a stand-in from the base set, which leaves a model error
  // (Delta, all parameters perturbed: 37 µm RMS held-out from noise-free data, 0.6 µm after). The
  // analysis is therefore repeated at the first estimate with `relinearise_rank_tolerance`
  // (deliberately far above the first analysis' rank tolerance, at the ill-conditioning ratio:
  // only directions the design separates well are added; none is removed), and the solve
  // continues from the first estimate over the enlarged set. The model error is usually invisible
  // in the fit (0.3 σ on the Delta) but amplified on other poses, so no fit-improvement test can
  // decide; the guard is the predicted end-effector uncertainty: the second result is kept unless
  // it inflates it by more than `relinearise_max_uncertainty_growth` (a weak direction added).
  bool relinearise = true;
  double relinearise_rank_tolerance = 1e-3;
  double relinearise_max_uncertainty_growth = 2.0;
  int relinearise_max_iterations = 50;
  // Optional bounds per parameter (NaN = unbounded).
  std::vector<double> lower_bound;
  std::vector<double> upper_bound;
  RobustLoss robust_loss = RobustLoss::kNone;
  // The loss's threshold in σ. Unless keep_stated_noise is set, σ is the noise estimated from the
  // data (a first robust fit at the stated noise, then the outlier-proof scale of each observation
  // type's residuals, then the final fit): a stated noise 5× too large would otherwise hide
  // every outlier inside the loss's quadratic zone.
  double robust_scale = 3.0;
  // Multi-start: extra starts perturbed by N(0, start_sigma_i) around the start values (uses
  // prior_sigma when start_sigma is empty); the lowest final cost wins.
  int multi_start = 0;
  std::vector<double> start_sigma;
  unsigned seed = 1;
  // Start values (full vector); empty = nominal.
  Eigen::VectorXd start;
  // Tight by design: Ceres' defaults (function tolerance 1e-6) stop short of calibration-grade
  // estimates.
  double function_tolerance = 1e-15;
  double gradient_tolerance = 1e-14;
  double parameter_tolerance = 1e-13;
  int max_iterations = 200;
  // Workers that evaluate the poses' residuals and Jacobians (when the predictor is
  // thread_safe()); the estimate is the same to the bit for any number.
  int threads = 1;
  // The stated measurement noise (σ in the file, detector covariances) is only a guess unless
  // this is set: by default the noise scale of every observation type is estimated from the
  // residuals (noise_estimate.hpp) and the covariance, intervals and predicted accuracy are scaled
  // by it. Set it when the stated noise is known (e.g. the detector's covariance): then the
  // estimate is reported and compared (warnings both ways) but not applied.
  bool keep_stated_noise = false;
  CovarianceOptions covariance;
  OutlierOptions outliers;
};

enum class IdentificationStatus {
  kConverged,        // solved; result parameters updated
  kNotConverged,     // usable but hit the iteration limit; result parameters updated
  kDiverged,         // solve failed or worsened the fit: nominal kept
  kInvalidInput,     // nothing solved (message says why)
  kNotIdentifiable,  // valid data, but no free parameter changes the measurements: nothing to
                     // estimate (message says so; the front end adds what to measure next)
};
const char* to_string(IdentificationStatus status);

struct ExcludedPose {
  std::string id;
  std::string reason;
};

// What the second, relinearised solve did (SolveOptions::relinearise).
struct RelinearisationReport {
  bool attempted = false;
  bool accepted = false;
  std::vector<std::size_t> added;  // parameter indices estimated only after relinearising
  double cost_before = 0.0;        // ½‖r‖² of the first and the second solve
  double cost_after = 0.0;
  double predicted_before = 0.0;  // predicted end-effector σ (RMS over the measured poses), m
  double predicted_after = 0.0;
  std::string message;
};

// With little data: which estimated set identify chose by what it predicts. Every
// candidate set is weighed by the expected squared position error over the measured area (the
// bed height for height-only data, the 3-D position otherwise): the noise through the estimated
// parameters plus the bias of those held at nominal, off nominal by the robot file's tolerances
// (gauge_choice.hpp's criterion). Candidates: the rank analysis' set as the gauge choice leaves
// it, smaller sets from it by backward elimination (an exactly determined fit is avoided when a
// smaller set predicts less), and the printer firmwares' calibration sets in this model's
// parameter names when the robot has them. Errors are RMS, m.
struct EstimatorCandidate {
  std::string name;
  std::vector<std::size_t> estimated;  // parameter indices
  double predicted_rms = 0.0;          // over the measured area (height or 3-D, see `target`)
  double predicted_bias_rms = 0.0;     // the held parameters' part
  double predicted_height_rms = 0.0;   // the bed height (first layer) alone
};
struct EstimatorChoice {
  bool made = false;          // little data and every candidate has a tolerance
  std::string target;         // "bed height" or "3-D position"
  std::size_t data_rank = 0;  // combinations the data determine
  EstimatorCandidate chosen;
  EstimatorCandidate next_best;  // name empty when there was no other admissible candidate
  std::vector<EstimatorCandidate> candidates;  // every admissible one weighed, best first
  std::string reason;
};

struct IdentificationResult {
  IdentificationStatus status = IdentificationStatus::kInvalidInput;
  std::string message;
  std::vector<std::string> names;
  std::vector<std::string> labels;  // FramePredictor::parameter_labels, same order as names
  Eigen::VectorXd nominal;
  Eigen::VectorXd estimate;               // full parameter vector (nominal where not estimated)
  std::vector<std::size_t> estimated;     // indices actually estimated (identifiable candidates)
  IdentifiabilityReport identifiability;  // over the candidates (indices into `candidates`)
  std::vector<std::size_t> candidates;
  ParameterUncertainty uncertainty;  // over `estimated`, in that order
  ResidualDiagnostics residuals;     // per pose, at the estimate
  PredictedAccuracy predicted;       // at the measured poses, from the covariance
  std::vector<ExcludedPose> excluded;
  double initial_cost = 0.0;  // ½‖r‖² (whitened, without loss) at the start
  double final_cost = 0.0;
  double objective = 0.0;     // the minimised objective (robust loss and priors included)
  std::size_t equations = 0;  // measurement equations (whitened residual rows) used
  RelinearisationReport relinearisation;
  // Little data: fewer equations than free parameters with an effect. The data determine only
  // `identifiability.rank` combinations; the others are held at nominal (the gauge) and `gauge`
  // says so in words (which were held, and why: the redundancy explanations).
  bool limited_data = false;
  std::string gauge;
  EstimatorChoice estimator;
  // A posteriori noise per observation type (noise_estimate.hpp), beside the stated noise;
  // `noise_applied` when the covariance was scaled by it (SolveOptions::keep_stated_noise).
  NoiseEstimate noise;
  bool noise_applied = false;
  // Robust loss at the estimated noise: per observation type (NoiseEstimate's order), the scale
  // of the stated σ the loss threshold used (empty: the stated noise was used).
  std::vector<double> robust_loss_noise_scale;
  int iterations = 0;
  int starts_run = 1;
  double solve_seconds = 0.0;
  std::vector<std::string> warnings;
};

IdentificationResult identify(const FramePredictor& model, const Eigen::VectorXd& nominal,
                              const Measurements& measurements, const SolveOptions& options = {});

// The whitened identification Jacobian of `measurements` at `params` (rows: every observation's
// residual rows in order, then the distances; columns: every parameter), as identify builds it.
// Returns false and says why when a pose cannot be predicted or a distance names a missing pose.
bool identification_jacobian(const FramePredictor& model, const Eigen::VectorXd& params,
                             const Measurements& measurements, Eigen::MatrixXd& jacobian,
                             std::string& why);

// Errors of a parameter vector against measured poses: position from point/pose observations,
// orientation from pose observations.
struct ErrorStatistics {
  std::size_t poses = 0;
  double position_rms = 0.0;
  double position_max = 0.0;
  double orientation_rms = 0.0;
  double orientation_max = 0.0;
};
ErrorStatistics prediction_errors(const FramePredictor& model, const Eigen::VectorXd& params,
                                  const std::vector<PoseMeasurement>& poses);

struct ValidationReport {
  ErrorStatistics before;  // nominal
  ErrorStatistics after;   // estimate
};
ValidationReport validate(const FramePredictor& model, const Eigen::VectorXd& nominal,
                          const Eigen::VectorXd& estimate,
                          const std::vector<PoseMeasurement>& held_out);

// k-fold cross-validation: every fold is held out once and predicted by a model identified on the
// others. Poses are assigned to folds round-robin in the given order.
struct KFoldReport {
  int folds = 0;
  std::vector<ValidationReport> per_fold;
  ErrorStatistics before;  // pooled over all held-out poses
  ErrorStatistics after;
  std::vector<std::string> messages;
};
KFoldReport k_fold_validation(const FramePredictor& model, const Eigen::VectorXd& nominal,
                              const Measurements& measurements, int folds,
                              const SolveOptions& options = {});

// ---- simulation ----------------------------------------------------------------------------

// nominal + N(0, sigma_i) for each parameter (sigma 0 = unchanged).
Eigen::VectorXd perturb_parameters(const Eigen::VectorXd& nominal, const Eigen::VectorXd& sigma,
                                   std::mt19937& rng);

enum class SimulatedObservation { kPose, kPoint, kProbeHeight };

struct SimulationOptions {
  SimulatedObservation kind = SimulatedObservation::kPoint;
  double position_sigma = 20e-6;   // m
  double rotation_sigma = 1e-4;    // rad (pose observations)
  Eigen::VectorXd actuator_sigma;  // per actuator noise on the reported readings (empty = none)
  bool add_noise = true;
  // Probe plane for kProbeHeight: n·x = offset.
  Eigen::Vector3d plane_normal = Eigen::Vector3d::UnitZ();
  double plane_offset = 0.0;
};

// Measures the true robot at the true actuator values `actuators` and reports the (optionally
// noisy) readings plus observations. Poses the true model cannot solve are skipped.
Measurements simulate_measurements(const FramePredictor& model, const Eigen::VectorXd& truth,
                                   const std::vector<Eigen::VectorXd>& actuators,
                                   const SimulationOptions& options, std::mt19937& rng);

}  // namespace robocal::calib
