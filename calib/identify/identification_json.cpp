#include "robocal/calib/identification_json.hpp"

#include <cmath>

namespace robocal::calib {
namespace {
// JSON has no NaN/Inf: write null instead of producing an unreadable file.
nlohmann::json num(double v) {
  return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json();
}
}  // namespace

nlohmann::json to_json(const IdentifiabilityReport& r) {
  nlohmann::json j;
  j["equations"] = r.rows;
  j["rank"] = r.rank;
  j["condition_number"] = num(r.condition_number);
  j["underdetermined"] = r.underdetermined;
  auto names_of = [&](const std::vector<std::size_t>& idx) {
    nlohmann::json a = nlohmann::json::array();
    for (std::size_t i : idx) a.push_back(r.names[i]);
    return a;
  };
  j["identifiable"] = names_of(r.identifiable);
  j["held_at_nominal"] = names_of(r.redundant);
  j["no_effect"] = names_of(r.no_effect);
  j["redundancies"] = nlohmann::json::array();
  for (const auto& red : r.redundancies) {
    nlohmann::json e;
    e["parameter"] = r.names[red.parameter];
    e["partners"] = nlohmann::json::array();
    for (std::size_t k = 0; k < red.partners.size(); ++k)
      e["partners"].push_back(
          {{"name", r.names[red.partners[k]]}, {"coefficient", num(red.coefficients[k])}});
    e["explanation"] = red.explanation;
    j["redundancies"].push_back(e);
  }
  j["ill_conditioned"] = nlohmann::json::array();
  for (const auto& d : r.ill_conditioned)
    j["ill_conditioned"].push_back({{"first", r.names[d.first]},
                                    {"second", r.names[d.second]},
                                    {"relative_singular_value", num(d.relative_singular_value)},
                                    {"explanation", d.explanation}});
  j["messages"] = r.messages;
  return j;
}

nlohmann::json to_json(const ErrorStatistics& s) {
  return {{"poses", s.poses},
          {"position_rms_m", num(s.position_rms)},
          {"position_max_m", num(s.position_max)},
          {"orientation_rms_rad", num(s.orientation_rms)},
          {"orientation_max_rad", num(s.orientation_max)}};
}

nlohmann::json to_json(const ValidationReport& r) {
  return {{"before", to_json(r.before)}, {"after", to_json(r.after)}};
}

nlohmann::json to_json(const KFoldReport& r) {
  nlohmann::json j{{"folds", r.folds}, {"before", to_json(r.before)}, {"after", to_json(r.after)}};
  j["per_fold"] = nlohmann::json::array();
  for (const auto& f : r.per_fold) j["per_fold"].push_back(to_json(f));
  j["messages"] = r.messages;
  return j;
}

nlohmann::json to_json(const IdentificationResult& r) {
  nlohmann::json j;
  j["status"] = to_string(r.status);
  j["message"] = r.message;
  j["warnings"] = r.warnings;
  j["initial_cost"] = num(r.initial_cost);
  j["final_cost"] = num(r.final_cost);
  j["iterations"] = r.iterations;
  j["starts"] = r.starts_run;
  j["solve_seconds"] = num(r.solve_seconds);
  j["excluded_poses"] = nlohmann::json::array();
  for (const auto& e : r.excluded)
    j["excluded_poses"].push_back({{"id", e.id}, {"reason", e.reason}});
  j["identifiability"] = to_json(r.identifiability);
  {
    const RelinearisationReport& rl = r.relinearisation;
    nlohmann::json added = nlohmann::json::array();
    for (std::size_t i : rl.added) added.push_back(r.names[i]);
    j["relinearisation"] = {{"attempted", rl.attempted},
                            {"accepted", rl.accepted},
                            {"added", added},
                            {"cost_before", num(rl.cost_before)},
                            {"cost_after", num(rl.cost_after)},
                            {"predicted_position_rms_before_m", num(rl.predicted_before)},
                            {"predicted_position_rms_after_m", num(rl.predicted_after)},
                            {"message", rl.message}};
  }

  // Per parameter: nominal, estimate, change, and (when estimated) σ and confidence interval.
  j["parameters"] = nlohmann::json::array();
  std::vector<int> est_pos(r.names.size(), -1);
  for (std::size_t k = 0; k < r.estimated.size(); ++k)
    est_pos[r.estimated[k]] = static_cast<int>(k);
  for (std::size_t i = 0; i < r.names.size(); ++i) {
    const auto ii = static_cast<Eigen::Index>(i);
    nlohmann::json p{{"name", r.names[i]},
                     {"label", i < r.labels.size() ? r.labels[i] : r.names[i]},
                     {"nominal", num(r.nominal(ii))},
                     {"value", num(r.estimate(ii))},
                     {"change", num(r.estimate(ii) - r.nominal(ii))},
                     {"estimated", est_pos[i] >= 0}};
    if (est_pos[i] >= 0 && r.uncertainty.ok) {
      const auto k = static_cast<Eigen::Index>(est_pos[i]);
      p["sigma"] = num(r.uncertainty.sigma(k));
      p["ci_half_width"] = num(r.uncertainty.ci_half_width(k));
    }
    j["parameters"].push_back(p);
  }
  nlohmann::json u{{"ok", r.uncertainty.ok},
                   {"message", r.uncertainty.message},
                   {"confidence", r.uncertainty.confidence},
                   {"variance_factor", num(r.uncertainty.variance_factor)}};
  u["strongly_correlated"] = nlohmann::json::array();
  for (const auto& c : r.uncertainty.strongly_correlated)
    u["strongly_correlated"].push_back({{"first", r.uncertainty.names[c.first]},
                                        {"second", r.uncertainty.names[c.second]},
                                        {"correlation", num(c.correlation)}});
  j["uncertainty"] = u;
  j["predicted_accuracy"] = {{"position_rms_m", num(r.predicted.position_rms_overall)},
                             {"position_worst_m", num(r.predicted.position_worst)},
                             {"orientation_rms_rad", num(r.predicted.orientation_rms_overall)},
                             {"height_rms_m", num(r.predicted.height_rms_overall)}};
  nlohmann::json res{{"scale", num(r.residuals.scale)},
                     {"position_rms_m", num(r.residuals.position_rms)},
                     {"position_max_m", num(r.residuals.position_max)},
                     {"orientation_rms_rad", num(r.residuals.orientation_rms)},
                     {"orientation_max_rad", num(r.residuals.orientation_max)},
                     {"outliers", r.residuals.outliers}};
  res["by_type"] = nlohmann::json::array();
  for (const auto& t : r.residuals.by_type)
    res["by_type"].push_back({{"type", t.type},
                              {"unit", t.unit},
                              {"count", t.count},
                              {"rms", num(t.rms)},
                              {"max", num(t.max)}});
  res["poses"] = nlohmann::json::array();
  for (const auto& p : r.residuals.poses)
    res["poses"].push_back({{"id", p.id},
                            {"chi_square", num(p.chi_square)},
                            {"dof", p.dof},
                            {"threshold", num(p.threshold)},
                            {"position_error_m", num(p.position_error)},
                            {"orientation_error_rad", num(p.orientation_error)},
                            {"outlier", p.outlier}});
  j["residuals"] = res;
  j["limited_data"] = r.limited_data;
  if (r.limited_data) j["gauge"] = r.gauge;
  // With little data, the estimated set chosen by what it predicts, µm.
  if (r.estimator.made) {
    auto candidate = [&](const EstimatorCandidate& c) {
      nlohmann::json names = nlohmann::json::array();
      for (std::size_t i : c.estimated) names.push_back(r.names[i]);
      return nlohmann::json{{"name", c.name},
                            {"parameters", names},
                            {"predicted_rms_um", num(1e6 * c.predicted_rms)},
                            {"predicted_bias_rms_um", num(1e6 * c.predicted_bias_rms)},
                            {"predicted_bed_height_rms_um", num(1e6 * c.predicted_height_rms)}};
    };
    nlohmann::json all = nlohmann::json::array();
    for (const auto& c : r.estimator.candidates) all.push_back(candidate(c));
    j["estimator_choice"] = {{"target", r.estimator.target},
                             {"data_rank", r.estimator.data_rank},
                             {"chosen", candidate(r.estimator.chosen)},
                             {"reason", r.estimator.reason},
                             {"candidates", all}};
    if (!r.estimator.next_best.name.empty())
      j["estimator_choice"]["next_best"] = candidate(r.estimator.next_best);
    // The bed's flatness after calibration: the first-layer height error predicted over the
    // measured area beside the 3-D figure.
    j["predicted_bed_height_rms_um"] = num(1e6 * r.estimator.chosen.predicted_height_rms);
    j["predicted_3d_rms_um"] = num(1e6 * r.estimator.chosen.predicted_rms);
  } else if (r.uncertainty.ok && r.residuals.has_probe_heights()) {
    // Enough data to estimate every free parameter: the bed's flatness from the covariance at
    // the measured poses, beside the 3-D figure there.
    j["predicted_bed_height_rms_um"] = num(1e6 * r.predicted.height_rms_overall);
    j["predicted_3d_rms_um"] = num(1e6 * r.predicted.position_rms_overall);
  }
  // A posteriori noise per observation type beside the stated noise (noise_estimate.hpp).
  nlohmann::json noise = nlohmann::json::array();
  for (std::size_t k = 0; k < r.noise.groups.size(); ++k) {
    const auto& g = r.noise.groups[k];
    if (g.rows == 0) continue;
    noise.push_back({{"type", g.type},
                     {"unit", g.unit},
                     {"rows", g.rows},
                     {"stated_sigma", num(g.stated_sigma)},
                     {"estimable", g.estimable},
                     {"estimated_sigma", num(g.estimated_sigma())},
                     {"scale", num(g.scale)},
                     {"scale_95_low", num(g.scale_low)},
                     {"scale_95_high", num(g.scale_high)},
                     {"robust_scale", num(g.robust_scale)},
                     {"degrees_of_freedom", num(g.redundancy)}});
    // The robust loss's σ unit for this type, as a multiple of the stated σ (absent: stated).
    if (k < r.robust_loss_noise_scale.size())
      noise.back()["robust_loss_sigma_scale"] = num(r.robust_loss_noise_scale[k]);
  }
  j["noise"] = {{"applied", r.noise_applied}, {"types", noise}};
  return j;
}

}  // namespace robocal::calib
