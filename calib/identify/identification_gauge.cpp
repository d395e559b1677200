// With little data, which confounded candidates identify() holds at nominal (the gauge):
// gauge_choice.hpp weighed over the predictions across the measured area.
#include "identification_detail.hpp"

#include "robocal/calib/gauge_choice.hpp"

#include <fmt/core.h>

#include <algorithm>
#include <cmath>
#include <optional>
#include <variant>

namespace robocal::calib::detail {
namespace {

// Predicted quantities over the measured area, as whitened rows (candidate columns): every
// observation of each measured pose, at that pose and at the quarter points between every two of
// them in actuator space (at most 16 poses spread over the list; pixel poses are skipped). With
// `in_metres`, one observation with unit σ instead at every pose, those without observations
// too (a printed position measured only by distances): rows in metres per parameter unit.
Eigen::MatrixXd measured_area_rows(const FramePredictor& model, const Eigen::VectorXd& params,
                                   const std::vector<const PoseMeasurement*>& poses,
                                   const std::vector<std::size_t>& candidates,
                                   const std::optional<Observation>& in_metres = std::nullopt,
                                   std::vector<Eigen::Vector3d>* positions = nullptr) {
  std::vector<const PoseMeasurement*> used;
  for (const auto* pose : poses)
    if ((!pose->observations.empty() || in_metres) && pose->pixel_groups.empty())
      used.push_back(pose);
  constexpr std::size_t kMaxPoses = 16;
  if (used.size() > kMaxPoses) {
    std::vector<const PoseMeasurement*> spread_out;
    for (std::size_t k = 0; k < kMaxPoses; ++k)
      spread_out.push_back(used[k * (used.size() - 1) / (kMaxPoses - 1)]);
    used = std::move(spread_out);
  }
  Measurements area;
  for (std::size_t i = 0; i < used.size(); ++i) {
    const std::vector<Observation> obs =
        in_metres ? std::vector<Observation>{*in_metres} : used[i]->observations;
    area.poses.push_back({"area", used[i]->actuators, obs});
    for (std::size_t j = i + 1; j < used.size(); ++j)
      for (const double t : {0.25, 0.5, 0.75})
        area.poses.push_back(
            {"area", (1.0 - t) * used[i]->actuators + t * used[j]->actuators, obs});
  }
  // Each pose's rows kept, then copied once into the result (hundreds of poses: growing the
  // result pose by pose would copy it again for every one).
  std::vector<Eigen::MatrixXd> blocks;
  Eigen::Index total = 0;
  for (const auto& pose : area.poses) {
    Measurements one;
    one.poses.push_back(pose);
    Eigen::MatrixXd J;
    std::string why;
    if (!identification_jacobian(model, params, one, J, why)) continue;  // outside the workspace
    if (positions != nullptr) {
      FramePrediction fp;
      if (!model.predict(params, pose.actuators, -1, false, fp, why)) continue;
      positions->push_back(fp.pose.translation());
    }
    total += J.rows();
    blocks.push_back(std::move(J));
  }
  Eigen::MatrixXd rows(total, static_cast<Eigen::Index>(candidates.size()));
  Eigen::Index n = 0;
  for (const Eigen::MatrixXd& J : blocks) {
    for (std::size_t k = 0; k < candidates.size(); ++k)
      rows.col(static_cast<Eigen::Index>(k)).segment(n, J.rows()) =
          J.col(static_cast<Eigen::Index>(candidates[k]));
    n += J.rows();
  }
  return rows;
}

// 3-D rows (three per position) without what moves the whole measured area rigidly in the
// plane: a shift in x and y and a turn about z, which a printer's prints never see (they are
// placed on its bed, not in the frame the calibration chose).
Eigen::MatrixXd aligned_rows(const Eigen::MatrixXd& rows, const std::vector<Eigen::Vector3d>& at) {
  const auto n = static_cast<Eigen::Index>(at.size());
  if (rows.rows() != 3 * n || n == 0) return rows;
  Eigen::MatrixXd G = Eigen::MatrixXd::Zero(3 * n, 3);
  for (Eigen::Index k = 0; k < n; ++k) {
    const Eigen::Vector3d& p = at[static_cast<std::size_t>(k)];
    G(3 * k, 0) = 1.0;
    G(3 * k + 1, 1) = 1.0;
    G(3 * k, 2) = -p.y();
    G(3 * k + 1, 2) = p.x();
  }
  const Eigen::HouseholderQR<Eigen::MatrixXd> qr(G);
  const Eigen::MatrixXd Q = qr.householderQ() * Eigen::MatrixXd::Identity(3 * n, 3);
  return rows - Q * (Q.transpose() * rows);
}

// The printer firmwares' calibration sets in the parameter names of the library linear delta
// (testdata/robots/linear_delta.yaml): endstop offsets are the carriages' encoder offsets, the
// delta radius and two tower angles are the three towers' positions in the plane (each tower's
// coordinate across the centre: up to a shift and turn of the frame, which probe heights do not
// see, the same three degrees of freedom), the arm lengths the rods'. Firmware sets that need a
// single common radius or rod length (RepRapFirmware 4 and 7, Marlin G33's 4) have no parameter
// of their own here and are not candidates.
struct NamedSet {
  std::string name;
  std::vector<std::string> parameters;
};
std::vector<NamedSet> firmware_class_sets() {
  const std::vector<std::string> endstops = {
      "carriage_a.encoder_offset", "carriage_b.encoder_offset", "carriage_c.encoder_offset"};
  std::vector<std::string> basic = endstops;
  for (const char* t : {"tower_a.x", "tower_b.x", "tower_c.y"}) basic.emplace_back(t);
  std::vector<std::string> extended = basic;
  for (const char* r : {"rod_a.length", "rod_b.length", "rod_c.length"}) extended.emplace_back(r);
  std::vector<std::string> tilt = basic;
  for (const char* b : {"base.roll", "base.pitch"}) tilt.emplace_back(b);
  return {{"firmware-class: Klipper DELTA_CALIBRATE basic = RepRapFirmware 6-factor = Marlin G33 "
           "7-factor (endstops, delta radius, tower angles)",
           basic},
          {"firmware-class: Klipper DELTA_CALIBRATE extended (+ the three arm lengths)", extended},
          {"firmware-class: RepRapFirmware 3-factor (endstops)", endstops},
          {"firmware-class: RepRapFirmware 8-factor (6-factor + bed tilt)", tilt}};
}

// The columns (indices into the candidates) are separated by the data: after column scaling,
// every pivot of a column-pivoted QR above `tolerance`.
bool well_separated(const Eigen::MatrixXd& Jc, const std::vector<std::size_t>& cols,
                    double tolerance) {
  if (cols.empty() || static_cast<Eigen::Index>(cols.size()) > Jc.rows()) return false;
  Eigen::MatrixXd S(Jc.rows(), static_cast<Eigen::Index>(cols.size()));
  for (std::size_t k = 0; k < cols.size(); ++k) {
    S.col(static_cast<Eigen::Index>(k)) = Jc.col(static_cast<Eigen::Index>(cols[k]));
    const double n = S.col(static_cast<Eigen::Index>(k)).norm();
    if (!(n > 0.0)) return false;
    S.col(static_cast<Eigen::Index>(k)) /= n;
  }
  const Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(S);
  for (Eigen::Index k = 0; k < S.cols(); ++k)
    if (std::abs(qr.matrixQR()(k, k)) <= tolerance) return false;
  return true;
}

// Weighs the candidate sets and fills `out` (best first). `gauge_set`: the gauge choice's set.
void weigh_estimators(const Eigen::MatrixXd& Jc, const Eigen::MatrixXd& area,
                      const Eigen::MatrixXd& heights, const Eigen::VectorXd& sigma,
                      const std::vector<std::size_t>& gauge_set, const std::string& gauge_name,
                      const std::vector<std::size_t>& candidates,
                      const std::vector<std::string>& cand_names,
                      const IdentifiabilityReport& report, double tolerance, EstimatorChoice& out) {
  std::vector<std::pair<std::string, std::vector<std::size_t>>> sets = {{gauge_name, gauge_set}};
  const GaugeProblem over_area = gauge_problem(Jc, area);
  const GaugeProblem over_heights = gauge_problem(Jc, heights);
  auto value = [&](const std::vector<std::size_t>& cols) {
    return gauge_expected_error(over_area, sigma, cols);
  };
  auto admissible = [&](const std::vector<std::size_t>& cols) {
    for (std::size_t k : cols)
      if (std::binary_search(report.no_effect.begin(), report.no_effect.end(), k)) return false;
    return well_separated(Jc, cols, tolerance);
  };
  // Backward elimination from the gauge set: drop the parameter whose holding lowers the
  // prediction most, while one does.
  {
    std::vector<std::size_t> cur = gauge_set;
    double v = value(cur);
    bool dropped = false;
    while (cur.size() > 1) {
      std::vector<std::size_t> best_set;
      double best_v = v;
      for (std::size_t d = 0; d < cur.size(); ++d) {
        std::vector<std::size_t> s = cur;
        s.erase(s.begin() + static_cast<std::ptrdiff_t>(d));
        const double sv = value(s);
        if (gauge_criterion_less(sv, s, best_v, best_set.empty() ? cur : best_set))
          if (sv < v * (1.0 - 1e-6)) {
            best_v = sv;
            best_set = s;
          }
      }
      if (best_set.empty()) break;
      cur = best_set;
      v = best_v;
      dropped = true;
    }
    if (dropped) sets.emplace_back("smaller set (backward elimination from the gauge set)", cur);
  }
  for (const NamedSet& f : firmware_class_sets()) {
    std::vector<std::size_t> cols;
    for (const std::string& n : f.parameters) {
      const auto it = std::find(cand_names.begin(), cand_names.end(), n);
      if (it == cand_names.end()) break;
      cols.push_back(static_cast<std::size_t>(it - cand_names.begin()));
    }
    if (cols.size() != f.parameters.size()) continue;
    std::sort(cols.begin(), cols.end());
    sets.emplace_back(f.name, cols);
  }
  std::vector<EstimatorCandidate> weighed;
  std::vector<std::vector<std::size_t>> cols_of;
  for (const auto& [name, cols] : sets) {
    const auto same = std::find(cols_of.begin(), cols_of.end(), cols);
    if (same != cols_of.end()) {
      weighed[static_cast<std::size_t>(same - cols_of.begin())].name += " = " + name;
      continue;
    }
    if (!admissible(cols)) continue;
    const double v = value(cols);
    if (!std::isfinite(v)) continue;
    EstimatorCandidate c;
    c.name = name;
    for (std::size_t k : cols) c.estimated.push_back(candidates[k]);
    c.predicted_rms = std::sqrt(v);
    c.predicted_bias_rms =
        std::sqrt(std::max(0.0, gauge_expected_error(over_area, sigma, cols, true)));
    c.predicted_height_rms = std::sqrt(gauge_expected_error(over_heights, sigma, cols));
    weighed.push_back(c);
    cols_of.push_back(cols);
  }
  std::vector<std::size_t> order(weighed.size());
  for (std::size_t k = 0; k < order.size(); ++k) order[k] = k;
  std::sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) {
    return gauge_criterion_less(weighed[a].predicted_rms * weighed[a].predicted_rms, cols_of[a],
                                weighed[b].predicted_rms * weighed[b].predicted_rms, cols_of[b]);
  });
  for (std::size_t k : order) out.candidates.push_back(weighed[k]);
}

}  // namespace

std::string choose_little_data_gauge(const FramePredictor& model, const Eigen::VectorXd& params,
                                     const std::vector<const PoseMeasurement*>& poses,
                                     const Eigen::MatrixXd& Jc,
                                     const std::vector<std::size_t>& candidates,
                                     const std::vector<std::string>& cand_names,
                                     const SolveOptions& options, IdentifiabilityReport& report,
                                     EstimatorChoice& estimator) {
  const Eigen::MatrixXd targets = measured_area_rows(model, params, poses, candidates);
  if (targets.rows() == 0) return "";
  Eigen::VectorXd sigma(static_cast<Eigen::Index>(candidates.size()));
  for (std::size_t k = 0; k < candidates.size(); ++k) {
    const double s =
        candidates[k] < options.gauge_sigma.size() ? options.gauge_sigma[candidates[k]] : 0.0;
    if (!(s > 0.0)) return "";  // no tolerance for a candidate: nothing to weigh
    sigma(static_cast<Eigen::Index>(k)) = s;
  }
  GaugeOptions gauge_options;
  gauge_options.rank_tolerance = options.identifiability.ill_conditioning_ratio;
  const GaugeChoice choice =
      choose_gauge(Jc, targets, sigma, report.identifiable, {}, report.no_effect, gauge_options);
  if (!std::isfinite(choice.expected_error)) return "";

  // Which set to estimate, by what each predicts over the measured area: the 3-D
  // position error in metres — when every observation is a probe height (with or without
  // distances), without a shift and turn of the whole area in the plane, which such data never
  // see and a print placed on the bed never shows — and beside it the bed height (first layer). The
  // 3-D figure decides even for height-only data: the height error alone would not weigh the
  // x/y error each set leaves, which heights cannot check and prints' dimensions show (on the
  // library linear delta the exactly determined rank set predicts 16% less height error than
  // the firmware-class set but 16% more 3-D error).
  bool bed_data = true;
  for (const auto* pose : poses)
    for (const auto& o : pose->observations)
      bed_data = bed_data && std::holds_alternative<ProbeHeightObservation>(o);
  std::vector<std::size_t> chosen = choice.estimated;
  // Printer data only (probe heights, with or without distances between poses): that is where
  // the choice is measured against the firmwares' own routines (bench/printer_identify_bench.cpp).
  // On a camera session of a few poses (the wizard's 5-pose test session) it chose smaller sets
  // whose fits the held-out validation then refused; there the gauge choice stands.
  Eigen::MatrixXd heights;
  Eigen::MatrixXd area;
  if (options.choose_estimator && bed_data) {
    ProbeHeightObservation unit_height;
    unit_height.sigma = 1.0;
    heights = measured_area_rows(model, params, poses, candidates, Observation{unit_height});
    std::vector<Eigen::Vector3d> at;
    const Eigen::MatrixXd positions = measured_area_rows(
        model, params, poses, candidates,
        Observation{PointObservation::with_sigma(Eigen::Vector3d::Zero(), 1.0)}, &at);
    area = aligned_rows(positions, at);
  }
  if (options.choose_estimator && bed_data && heights.rows() > 0 && area.rows() > 0) {
    estimator.target = bed_data ? "3-D position (aligned on the bed)" : "3-D position";
    estimator.data_rank = report.rank;
    weigh_estimators(Jc, area, heights, sigma, choice.estimated,
                     choice.changed ? "gauge choice (the rank-sized set whose held parameters "
                                      "move the measured area least)"
                                    : "rank order (the analysis' base set)",
                     candidates, cand_names, report, gauge_options.rank_tolerance, estimator);
    if (!estimator.candidates.empty()) {
      estimator.made = true;
      estimator.chosen = estimator.candidates.front();
      if (estimator.candidates.size() > 1) estimator.next_best = estimator.candidates[1];
      chosen.clear();
      for (std::size_t i : estimator.chosen.estimated)
        chosen.push_back(static_cast<std::size_t>(
            std::find(candidates.begin(), candidates.end(), i) - candidates.begin()));
      std::sort(chosen.begin(), chosen.end());
      estimator.reason = fmt::format(
          "the least predicted {} error over the measured area: {:.3g} um RMS (of which the "
          "held parameters' bias {:.3g} um, at the robot file's tolerances; bed height {:.3g} "
          "um){}",
          estimator.target, 1e6 * estimator.chosen.predicted_rms,
          1e6 * estimator.chosen.predicted_bias_rms, 1e6 * estimator.chosen.predicted_height_rms,
          estimator.next_best.name.empty()
              ? std::string()
              : fmt::format("; next best: {}, {:.3g} um (bed height {:.3g} um)",
                            estimator.next_best.name, 1e6 * estimator.next_best.predicted_rms,
                            1e6 * estimator.next_best.predicted_height_rms));
    }
  }
  const bool smaller = chosen != choice.estimated;
  if (choice.changed || smaller) {
    // The analysis again with the chosen set visited first: it keeps exactly that set and
    // explains the others through it (a smaller set: what the analysis adds to it is held too).
    IdentifiabilityOptions strict = options.identifiability;
    strict.rank_tolerance = gauge_options.rank_tolerance;
    strict.stable_tie_break = true;
    std::vector<int> preference(candidates.size(), 1);
    for (std::size_t k : chosen) preference[k] = 0;
    IdentifiabilityReport redone = analyze_identifiability(Jc, cand_names, strict, preference);
    if (!std::includes(redone.identifiable.begin(), redone.identifiable.end(), chosen.begin(),
                       chosen.end()) ||
        (!smaller && redone.identifiable != chosen)) {
      estimator = EstimatorChoice{};
      return "";
    }
    if (smaller) {
      redone.identifiable = chosen;
      redone.rank = chosen.size();
      redone.redundant.clear();
      for (std::size_t k = 0; k < candidates.size(); ++k)
        if (!std::binary_search(chosen.begin(), chosen.end(), k)) redone.redundant.push_back(k);
      redone.messages.push_back(fmt::format(
          "the data determine {} combinations; {} parameters are estimated because that set "
          "predicts less error than estimating all {}",
          estimator.data_rank, chosen.size(), estimator.data_rank));
    }
    report = std::move(redone);
  }
  std::string why = fmt::format(
      "; they are the ones held because, off nominal by the robot file's tolerances, they move "
      "the predictions over the measured area least (expected prediction error {:.3g} x the "
      "measurement noise, of which their bias {:.3g}; the rank analysis' pivot order would hold "
      "{}: {:.3g}, bias {:.3g})",
      std::sqrt(choice.expected_error), std::sqrt(choice.bias),
      choice.changed ? "others" : "the same", std::sqrt(choice.initial_expected_error),
      std::sqrt(choice.initial_bias));
  if (estimator.made)
    why += fmt::format("; then, by what each candidate set predicts, the estimated set: {}, for {}",
                       estimator.chosen.name, estimator.reason);
  return why;
}

}  // namespace robocal::calib::detail
