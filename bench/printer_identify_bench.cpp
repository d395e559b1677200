// What printer users measure, against the Cramér–Rao bound, printed as JSON.
//
//   build/release/bench/printer_identify_bench [draws=20]
//
// On the library linear delta, per draw: a truth with the nine printer parameters perturbed
// (printer_scenario.hpp), then
//  - "heights": the firmwares' 7-point probe pattern (radius 80 mm, σ 10 µm), the nine printer
//    parameters as candidates; the rank analysis finds the identifiable subset and identify's
//    gauge choice (gauge_choice.hpp) which confounded ones are held at nominal. Held-out bed
//    heights on a 5 × 5 grid inside the probed circle: |predicted − true| against the Cramér–Rao
//    prediction sqrt(J_h Σ J_hᵀ) of the identified subset (Σ: the fit's covariance at the stated,
//    here true, noise; J_h by central differences at the estimate). The ratio of the mean-square
//    errors over all draws is the figure (1 = the estimator reaches the bound). The bound assumes
//    the parameters held at nominal are exact; the truth perturbs them too, so the same draws
//    without noise give the gauge's bias (gauge_bias_rms_um), and the error is also compared with
//    bound² + bias² (ratio_to_bound_and_gauge_bias).
//  - "heights_with_priors": the same 7 heights with the robot file's tolerances as priors (MAP,
//    identify --priors): all nine estimated; held-out error against the posterior's prediction.
//  - "heights_and_distances": the same plus twelve caliper distances on a printed part (σ 10 µm):
//    identified count and held-out 3-D error at the layer above the bed, before and after.
//  - "designed_probe_points": seven probe points chosen by calib's advice (advise_measurements
//    from no data over a 15 mm bed grid within 90 mm, at the nominal model; I-optimal for the bed
//    height over the printed square ±60 mm, the robot file's tolerances as the design's prior)
//    against the firmwares' fixed 7-point pattern, same draws and noise: held-out bed height error
//    of each, and the ratio; also the advice's rank/conditioning rule alone (design off).
//  - "firmware_baseline": the firmwares' own calibration routines
//    (firmware_routines.hpp: Klipper DELTA_CALIBRATE basic and extended, RepRapFirmware's least
//    squares with 4/6/7 factors, Marlin G33's 7) on the same simulated data as robocal's plain
//    `identify` (every free parameter of the robot file a candidate, its automatic choice): seven
//    heights, and heights plus the printed part's distances (against Klipper's extended routine).
//    Per draw over the 5 x 5 bed grid (±60 mm, z = 0): the height error (first layer) and the
//    3-D error after the best x/y shift and turn about z (what heights cannot see, removed for
//    every method alike), RMS; medians over the draws, robocal / firmware ratios of the medians,
//    and the same as root mean squares over the draws (what identify's choice minimises: a
//    variance-dominated fit such as the firmware's extended routine has a skewed spread, its
//    median well below its RMS).
#include "firmware_routines.hpp"
#include "printer_scenario.hpp"
#include "robocal/calib/measurement_advice.hpp"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <iostream>
#include <map>
#include <string>

namespace {

using namespace robocal;

std::vector<Eigen::Vector3d> heldout_grid(double z) {
  std::vector<Eigen::Vector3d> pts;
  for (double x = -0.06; x <= 0.061; x += 0.03)
    for (double y = -0.06; y <= 0.061; y += 0.03) pts.emplace_back(x, y, z);
  return pts;
}

Eigen::Vector3d nozzle(const calib::MechanismPredictor& pred, const Eigen::VectorXd& params,
                       const Eigen::VectorXd& readings) {
  calib::FramePrediction fp;
  std::string why;
  if (!pred.predict(params, readings, -1, false, fp, why)) throw std::runtime_error(why);
  return fp.pose.translation();
}

struct HeightFigures {
  double error_ms = 0.0;  // mean square of |predicted − true| height, m²
  double bound_ms = 0.0;  // mean square of the Cramér–Rao prediction, m²
  double before_ms = 0.0;
  int points = 0;
  std::size_t identified = 0;
};

// `noise` false: the same draw's truth measured without noise (σ still stated as 10 µm): what is
// left of the held-out error is the bias of the parameters held at nominal (the gauge).
// `priors`: the robot file's tolerances as priors (identify --priors, MAP): every parameter is
// estimated and Σ is the posterior covariance.
void heights_draw(const calib::Mechanism& model, unsigned seed, HeightFigures& f,
                  const std::vector<Eigen::Vector2d>& pattern, bool noise = true,
                  bool priors = false) {
  const calib::MechanismPredictor pred(model);
  const Eigen::VectorXd nominal = model.nominal_parameters();
  std::mt19937 rng(seed);
  const Eigen::VectorXd truth = test::printer_truth(model, rng);
  test::PrinterData data;
  test::add_probe_heights(model, truth, pattern, noise ? 10e-6 : 0.0, rng, data);
  if (!noise)
    for (auto& pose : data.measurements.poses)
      for (auto& o : pose.observations) std::get<calib::ProbeHeightObservation>(o).sigma = 10e-6;
  auto opt = calib::solve_options_from_model(model, priors);
  opt.candidates = test::printer_candidates(model);
  opt.keep_stated_noise = true;  // the stated σ is the true one: Σ is the bound itself
  // The rank-sized gauge estimator these figures and the probe design are about, not identify's
  // choice by predicted error (that one is in "firmware_baseline").
  opt.choose_estimator = false;
  const auto res = calib::identify(pred, nominal, data.measurements, opt);
  if (res.status != calib::IdentificationStatus::kConverged || !res.uncertainty.ok)
    throw std::runtime_error("draw " + std::to_string(seed) + ": " + res.message);
  f.identified = res.estimated.size();
  const auto n = static_cast<Eigen::Index>(res.estimated.size());
  for (const Eigen::Vector3d& target : heldout_grid(0.0)) {
    const Eigen::VectorXd r = test::commanded_readings(model, target);
    const double z_true = nozzle(pred, truth, r).z();
    const double z_est = nozzle(pred, res.estimate, r).z();
    Eigen::RowVectorXd J(n);
    for (Eigen::Index c = 0; c < n; ++c) {
      const auto i = static_cast<Eigen::Index>(res.estimated[static_cast<std::size_t>(c)]);
      const double h = 1e-7;
      Eigen::VectorXd plus = res.estimate;
      Eigen::VectorXd minus = res.estimate;
      plus(i) += h;
      minus(i) -= h;
      J(c) = (nozzle(pred, plus, r).z() - nozzle(pred, minus, r).z()) / (2.0 * h);
    }
    f.error_ms += std::pow(z_est - z_true, 2);
    f.bound_ms += (J * res.uncertainty.covariance * J.transpose())(0, 0);
    f.before_ms += std::pow(nozzle(pred, nominal, r).z() - z_true, 2);
    ++f.points;
  }
}

// Seven probe points by the advice: from no data, over a 15 mm bed grid within 90 mm of the
// centre, the points with the least expected height error over the printed square for identify's
// estimator (noise through the estimated parameters plus the bias of those it holds at nominal,
// at the robot file's tolerances); `design` false: the rank and conditioning rule alone.
std::vector<Eigen::Vector2d> designed_pattern(const calib::Mechanism& model, bool design) {
  const calib::MechanismPredictor pred(model);
  std::vector<Eigen::VectorXd> bed;
  for (double x = -0.09; x <= 0.0901; x += 0.015)
    for (double y = -0.09; y <= 0.0901; y += 0.015)
      if (std::hypot(x, y) <= 0.09) bed.push_back(test::commanded_readings(model, {x, y, 0.0}));
  calib::AdviceOptions o;
  o.distances = false;
  o.redundancy = 0;
  o.max_suggestions = 7;
  o.design = design;
  // The working area: the printed square (±60 mm) on a 10 mm grid (the held-out grid is every
  // third of these); the design's prior: the robot file's tolerances.
  for (double x = -0.06; x <= 0.0601; x += 0.01)
    for (double y = -0.06; y <= 0.0601; y += 0.01)
      o.working_area.push_back(test::commanded_readings(model, {x, y, 0.0}));
  for (const auto& prm : model.parameters) o.prior_sigma.push_back(prm.sigma);
  o.preference = calib::solve_options_from_model(model, false).preference;
  const auto advice = calib::advise_measurements(pred, model.nominal_parameters(), {},
                                                 test::printer_candidates(model), bed, {}, o);
  std::vector<Eigen::Vector2d> out;
  for (const auto& s : advice.suggestions) out.emplace_back(s.position.x(), s.position.y());
  return out;
}

struct DistanceFigures {
  double before_ms = 0.0;
  double after_ms = 0.0;
  int points = 0;
  int nine_identified = 0;
};

void distances_draw(const calib::Mechanism& model, unsigned seed, DistanceFigures& f) {
  const calib::MechanismPredictor pred(model);
  const Eigen::VectorXd nominal = model.nominal_parameters();
  std::mt19937 rng(seed);
  const Eigen::VectorXd truth = test::printer_truth(model, rng);
  test::PrinterData data;
  test::add_probe_heights(model, truth, test::probe_pattern(0.08), 10e-6, rng, data);
  test::add_printed_distances(model, truth, test::printed_points(), test::printed_pairs(), 10e-6,
                              rng, data);
  auto opt = calib::solve_options_from_model(model, false);
  opt.candidates = test::printer_candidates(model);
  const auto res = calib::identify(pred, nominal, data.measurements, opt);
  if (res.status != calib::IdentificationStatus::kConverged)
    throw std::runtime_error("draw " + std::to_string(seed) + ": " + res.message);
  if (res.estimated.size() == 9) ++f.nine_identified;
  for (const Eigen::Vector3d& target : heldout_grid(0.002)) {
    const Eigen::VectorXd r = test::commanded_readings(model, target);
    const Eigen::Vector3d t = nozzle(pred, truth, r);
    f.before_ms += (nozzle(pred, nominal, r) - t).squaredNorm();
    f.after_ms += (nozzle(pred, res.estimate, r) - t).squaredNorm();
    ++f.points;
  }
}

// Bed errors of one calibrated model: predicted minus true nozzle position at the readings the
// nominal model commands for each grid target. `height`: RMS of the z error; `aligned`: RMS of
// the 3-D error after removing the best x/y translation and turn about z.
struct BedError {
  double height = 0.0;
  double aligned = 0.0;
};

BedError bed_error(const std::vector<Eigen::Vector3d>& targets,
                   const std::vector<Eigen::Vector3d>& predicted,
                   const std::vector<Eigen::Vector3d>& truth) {
  const auto n = static_cast<Eigen::Index>(targets.size());
  Eigen::MatrixXd A(2 * n, 3);
  Eigen::VectorXd b(2 * n);
  BedError e;
  for (Eigen::Index k = 0; k < n; ++k) {
    const auto i = static_cast<std::size_t>(k);
    const Eigen::Vector3d d = predicted[i] - truth[i];
    e.height += d.z() * d.z();
    A.row(2 * k) << 1.0, 0.0, -truth[i].y();
    A.row(2 * k + 1) << 0.0, 1.0, truth[i].x();
    b(2 * k) = d.x();
    b(2 * k + 1) = d.y();
  }
  const Eigen::VectorXd rest = b - A * A.colPivHouseholderQr().solve(b);
  e.aligned = std::sqrt((rest.squaredNorm() + e.height) / static_cast<double>(n));
  e.height = std::sqrt(e.height / static_cast<double>(n));
  return e;
}

// Root mean square over the draws: the statistic identify's choice minimises (an expected
// squared error), beside the median the figures are read by.
double rms(const std::vector<double>& v) {
  double sum = 0.0;
  for (const double x : v) sum += x * x;
  return v.empty() ? 0.0 : std::sqrt(sum / static_cast<double>(v.size()));
}

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  const std::size_t n = v.size();
  return n % 2 == 1 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

// Per method: the per-draw height and aligned RMS errors (m).
using MethodErrors = std::map<std::string, std::pair<std::vector<double>, std::vector<double>>>;

void firmware_draw(const calib::Mechanism& model, unsigned seed, bool distances,
                   MethodErrors& errors, std::map<std::string, int>& chosen) {
  const calib::MechanismPredictor pred(model);
  const Eigen::VectorXd nominal = model.nominal_parameters();
  std::mt19937 rng(seed);
  const Eigen::VectorXd truth = test::printer_truth(model, rng);
  test::PrinterData data;
  test::add_probe_heights(model, truth, test::probe_pattern(0.08), 10e-6, rng, data);
  if (distances)
    test::add_printed_distances(model, truth, test::printed_points(), test::printed_pairs(), 10e-6,
                                rng, data);
  std::vector<Eigen::Vector3d> targets;
  std::vector<Eigen::VectorXd> readings;
  std::vector<Eigen::Vector3d> true_pos;
  for (const Eigen::Vector3d& t : heldout_grid(0.0)) {
    targets.push_back(t);
    readings.push_back(test::commanded_readings(model, t));
    true_pos.push_back(nozzle(pred, truth, readings.back()));
  }
  auto record = [&](const std::string& name, const BedError& e) {
    errors[name].first.push_back(e.height);
    errors[name].second.push_back(e.aligned);
  };
  // robocal's plain identify: every free parameter a candidate, its automatic choice.
  const auto res = calib::identify(pred, nominal, data.measurements,
                                   calib::solve_options_from_model(model, false));
  if (res.status != calib::IdentificationStatus::kConverged &&
      res.status != calib::IdentificationStatus::kNotConverged)
    throw std::runtime_error("draw " + std::to_string(seed) + ": " + res.message);
  std::vector<Eigen::Vector3d> p;
  p.reserve(readings.size());
  for (const auto& r : readings) p.push_back(nozzle(pred, res.estimate, r));
  record("robocal_identify", bed_error(targets, p, true_pos));
  ++chosen[res.estimator.made ? res.estimator.chosen.name
                              : std::to_string(res.estimated.size()) + " parameters (no choice)"];
  // The firmwares' routines on the same data.
  bench::FirmwareProbeData fd;
  for (const auto& pose : data.measurements.poses) {
    if (pose.observations.empty()) {
      fd.printed_readings.emplace_back(pose.actuators.head<3>());
      continue;
    }
    fd.probe_readings.emplace_back(pose.actuators.head<3>());
    fd.heights.push_back(
        std::get<calib::ProbeHeightObservation>(pose.observations[0]).measured_height);
  }
  for (const auto& d : data.measurements.distances) {
    fd.pairs.emplace_back(std::stoi(d.first.substr(5)), std::stoi(d.second.substr(5)));
    fd.distances.push_back(d.observation.measured_distance);
  }
  const calib::FirmwareDeltaModel shipped = bench::nominal_firmware_model(model);
  for (const auto& routine : bench::firmware_routines(distances)) {
    const calib::FirmwareDeltaModel fw = bench::run_firmware_routine(shipped, routine, fd);
    std::vector<Eigen::Vector3d> q;
    q.reserve(readings.size());
    for (const auto& r : readings) {
      Eigen::Vector3d x;
      if (!calib::firmware_delta_position(fw, r.head<3>(), x))
        throw std::runtime_error(routine.name + ": outside the firmware model");
      q.push_back(x);
    }
    record(routine.name, bed_error(targets, q, true_pos));
  }
}

nlohmann::json firmware_json(const MethodErrors& errors, const std::string& reference,
                             const std::map<std::string, int>& chosen_counts) {
  nlohmann::json j;
  const auto& ours = errors.at("robocal_identify");
  for (const auto& [name, e] : errors) {
    j["median_height_rms_um"][name] = 1e6 * median(e.first);
    j["median_aligned_3d_rms_um"][name] = 1e6 * median(e.second);
    j["rms_over_draws_height_um"][name] = 1e6 * rms(e.first);
    j["rms_over_draws_aligned_3d_um"][name] = 1e6 * rms(e.second);
    if (name == "robocal_identify") continue;
    std::vector<double> rh, ra;
    for (std::size_t k = 0; k < e.first.size(); ++k) {
      rh.push_back(ours.first[k] / e.first[k]);
      ra.push_back(ours.second[k] / e.second[k]);
    }
    j["ratio_robocal_to"][name] = {
        {"height_of_medians", median(ours.first) / median(e.first)},
        {"aligned_3d_of_medians", median(ours.second) / median(e.second)},
        {"height_of_rms_over_draws", rms(ours.first) / rms(e.first)},
        {"aligned_3d_of_rms_over_draws", rms(ours.second) / rms(e.second)},
        {"height_median_per_draw", median(rh)},
        {"aligned_3d_median_per_draw", median(ra)},
        {"height_per_draw_min_max",
         {*std::min_element(rh.begin(), rh.end()), *std::max_element(rh.begin(), rh.end())}},
        {"aligned_3d_per_draw_min_max",
         {*std::min_element(ra.begin(), ra.end()), *std::max_element(ra.begin(), ra.end())}}};
  }
  j["reference_routine"] = reference;
  j["robocal_chosen"] = chosen_counts;
  return j;
}

}  // namespace

int main(int argc, char** argv) {
  const int draws = argc > 1 ? std::atoi(argv[1]) : 20;
  if (draws < 1) {
    std::cerr << "usage: printer_identify_bench [draws >= 1]\n";
    return 2;
  }
  try {
    const calib::Mechanism model =
        calib::load_robot_file(std::string(ROBOCAL_TESTDATA_DIR) + "/robots/linear_delta.yaml");
    HeightFigures h;
    HeightFigures designed;
    HeightFigures ranked;
    HeightFigures h_bias;
    HeightFigures designed_bias;
    HeightFigures map;
    DistanceFigures d;
    MethodErrors fw_heights;
    MethodErrors fw_distances;
    std::map<std::string, int> chosen_heights;
    std::map<std::string, int> chosen_distances;
    const auto pattern = designed_pattern(model, true);
    const auto rank_pattern = designed_pattern(model, false);
    for (int k = 0; k < draws; ++k) {
      heights_draw(model, static_cast<unsigned>(100 + k), h, test::probe_pattern(0.08));
      heights_draw(model, static_cast<unsigned>(100 + k), designed, pattern);
      heights_draw(model, static_cast<unsigned>(100 + k), ranked, rank_pattern);
      heights_draw(model, static_cast<unsigned>(100 + k), h_bias, test::probe_pattern(0.08), false);
      heights_draw(model, static_cast<unsigned>(100 + k), designed_bias, pattern, false);
      heights_draw(model, static_cast<unsigned>(100 + k), map, test::probe_pattern(0.08), true,
                   true);
      distances_draw(model, static_cast<unsigned>(200 + k), d);
      firmware_draw(model, static_cast<unsigned>(100 + k), false, fw_heights, chosen_heights);
      firmware_draw(model, static_cast<unsigned>(200 + k), true, fw_distances, chosen_distances);
    }
    nlohmann::json out;
    out["robot"] = "linear_delta";
    out["draws"] = draws;
    out["heights"] = {
        {"probe_points", 7},
        {"sigma_um", 10},
        {"identified_parameters", h.identified},
        {"heldout_points", h.points},
        {"heldout_height_rms_before_um", 1e6 * std::sqrt(h.before_ms / h.points)},
        {"heldout_height_rms_um", 1e6 * std::sqrt(h.error_ms / h.points)},
        {"cramer_rao_rms_um", 1e6 * std::sqrt(h.bound_ms / h.points)},
        {"ratio_to_bound", std::sqrt(h.error_ms / h.bound_ms)},
        {"gauge_bias_rms_um", 1e6 * std::sqrt(h_bias.error_ms / h_bias.points)},
        {"ratio_to_bound_and_gauge_bias", std::sqrt(h.error_ms / (h.bound_ms + h_bias.error_ms))}};
    out["heights_with_priors"] = {
        {"identified_parameters", map.identified},
        {"heldout_height_rms_um", 1e6 * std::sqrt(map.error_ms / map.points)},
        {"posterior_rms_um", 1e6 * std::sqrt(map.bound_ms / map.points)},
        {"ratio_to_bound", std::sqrt(map.error_ms / map.bound_ms)}};
    out["heights_and_distances"] = {
        {"distances", 12},
        {"draws_with_all_nine_identified", d.nine_identified},
        {"heldout_3d_rms_before_um", 1e6 * std::sqrt(d.before_ms / d.points)},
        {"heldout_3d_rms_after_um", 1e6 * std::sqrt(d.after_ms / d.points)}};
    auto mm = [](const std::vector<Eigen::Vector2d>& pts) {
      nlohmann::json a = nlohmann::json::array();
      for (const auto& p : pts)
        a.push_back({std::round(1e4 * p.x()) / 10.0, std::round(1e4 * p.y()) / 10.0});
      return a;
    };
    out["designed_probe_points"] = {
        {"points_mm", mm(pattern)},
        {"identified_parameters", designed.identified},
        {"heldout_height_rms_um", 1e6 * std::sqrt(designed.error_ms / designed.points)},
        {"fixed_pattern_heldout_height_rms_um", 1e6 * std::sqrt(h.error_ms / h.points)},
        {"ratio_designed_to_fixed", std::sqrt(designed.error_ms / h.error_ms)},
        {"cramer_rao_rms_um", 1e6 * std::sqrt(designed.bound_ms / designed.points)},
        {"ratio_to_bound", std::sqrt(designed.error_ms / designed.bound_ms)},
        {"gauge_bias_rms_um", 1e6 * std::sqrt(designed_bias.error_ms / designed_bias.points)},
        {"rank_rule_points_mm", mm(rank_pattern)},
        {"rank_rule_heldout_height_rms_um", 1e6 * std::sqrt(ranked.error_ms / ranked.points)},
        {"ratio_rank_rule_to_fixed", std::sqrt(ranked.error_ms / h.error_ms)}};
    out["firmware_baseline"] = {
        {"seven_heights", firmware_json(fw_heights, "klipper_basic", chosen_heights)},
        {"heights_and_distances",
         firmware_json(fw_distances, "klipper_extended", chosen_distances)}};
    std::cout << out.dump(2) << "\n";
  } catch (const std::exception& e) {
    std::cerr << "printer_identify_bench: " << e.what() << "\n";
    return 1;
  }
  return 0;
}
