#include "robocal/calib/identification_summary.hpp"

#include <fmt/core.h>

#include <algorithm>
#include <cctype>
#include <cmath>

namespace robocal::calib {
namespace {

std::string length(double metres) {
  const double a = std::abs(metres);
  if (a < 1e-3) return fmt::format("{:.3g} µm", metres * 1e6);
  if (a < 1.0) return fmt::format("{:.4g} mm", metres * 1e3);
  return fmt::format("{:.5g} m", metres);
}

std::string noise_value(double sigma, const std::string& unit) {
  if (unit == "m") return length(sigma);
  if (unit == "rad") return fmt::format("{:.3g} mrad", sigma * 1e3);
  return fmt::format("{:.3g} {}", sigma, unit);
}

// Up to `limit` names, then "and N more".
std::string name_list(const std::vector<std::string>& names, std::size_t limit) {
  std::string out;
  for (std::size_t i = 0; i < names.size() && i < limit; ++i) out += (i ? ", " : "") + names[i];
  if (names.size() > limit) out += fmt::format(" and {} more", names.size() - limit);
  return out;
}

// The parameter's label when the robot file gives one, else its name.
const std::string& display_label(const IdentificationResult& r, std::size_t i) {
  return i < r.labels.size() && !r.labels[i].empty() ? r.labels[i] : r.names[i];
}

}  // namespace

std::vector<TextPart> parameter_mentions(const std::string& text,
                                         const std::vector<std::string>& names) {
  // Longest names first, so a name that is a prefix of another is not found inside it.
  std::vector<std::size_t> order;
  for (std::size_t i = 0; i < names.size(); ++i)
    if (!names[i].empty()) order.push_back(i);
  std::stable_sort(order.begin(), order.end(),
                   [&](std::size_t a, std::size_t b) { return names[a].size() > names[b].size(); });
  const auto name_char = [](char c) {
    return std::isalnum(static_cast<unsigned char>(c)) != 0 || c == '_' || c == '.';
  };
  // A whole name at `at`: not glued to a longer one (a trailing '.' ends a sentence, so allowed).
  const auto whole_at = [&](std::size_t at, const std::string& name) {
    if (text.compare(at, name.size(), name) != 0) return false;
    const std::size_t end = at + name.size();
    const bool starts = at == 0 || !name_char(text[at - 1]);
    const bool ends = end == text.size() || !name_char(text[end]) ||
                      (text[end] == '.' && (end + 1 == text.size() || text[end + 1] == ' '));
    return starts && ends;
  };
  std::vector<TextPart> parts;
  std::string plain;
  for (std::size_t at = 0; at < text.size();) {
    int found = -1;
    if (at == 0 || !name_char(text[at - 1]))
      for (std::size_t i : order)
        if (whole_at(at, names[i])) {
          found = static_cast<int>(i);
          break;
        }
    if (found < 0) {
      plain += text[at++];
      continue;
    }
    if (!plain.empty()) parts.push_back({std::move(plain), -1});
    plain.clear();
    parts.push_back({names[static_cast<std::size_t>(found)], found});
    at += names[static_cast<std::size_t>(found)].size();
  }
  if (!plain.empty()) parts.push_back({std::move(plain), -1});
  return parts;
}

std::string in_plain_words(const std::string& text, const IdentificationResult& r) {
  std::string out;
  for (const auto& part : parameter_mentions(text, r.names)) {
    const auto i = static_cast<std::size_t>(part.parameter);
    out += part.parameter >= 0 && i < r.labels.size() && !r.labels[i].empty() ? r.labels[i]
                                                                              : part.text;
  }
  return out;
}

std::string summary_text(const IdentificationResult& r) {
  std::string s = fmt::format("identify: {} - {}\n", to_string(r.status), r.message);
  if (r.status == IdentificationStatus::kInvalidInput) return s;
  for (const auto& e : r.excluded) s += fmt::format("  excluded pose {}: {}\n", e.id, e.reason);
  if (r.limited_data) s += fmt::format("Little data: {}.\n", r.gauge);
  if (r.estimator.made) {
    s += fmt::format(
        "Estimated set (chosen by predicted error): {}\n  predicted error over the measured "
        "area: {:.1f} um RMS {}, bed height (first layer) {:.1f} um RMS\n",
        r.estimator.chosen.name, 1e6 * r.estimator.chosen.predicted_rms, r.estimator.target,
        1e6 * r.estimator.chosen.predicted_height_rms);
    if (!r.estimator.next_best.name.empty())
      s += fmt::format("  next best: {}: {:.1f} um 3-D, bed height {:.1f} um\n",
                       r.estimator.next_best.name, 1e6 * r.estimator.next_best.predicted_rms,
                       1e6 * r.estimator.next_best.predicted_height_rms);
  }
  if (r.status == IdentificationStatus::kNotIdentifiable ||
      r.status == IdentificationStatus::kDiverged) {
    for (const auto& w : r.warnings) s += "  warning: " + w + "\n";
    return s;
  }
  // The counts every summary uses (the report page, the closing summary): of the free
  // parameters (the candidates), the identified ones and the rest, held at nominal.
  const std::size_t held_count = r.candidates.size() - r.estimated.size();
  // Identified parameters with σ (the covariance already carries the estimated noise when
  // applied).
  s += fmt::format("Identified {} of the {} free parameters:\n", r.estimated.size(),
                   r.candidates.size());
  for (std::size_t k = 0; k < r.estimated.size(); ++k) {
    const auto i = static_cast<Eigen::Index>(r.estimated[k]);
    std::string sigma;
    if (r.uncertainty.ok)
      sigma = fmt::format(" +- {:.3g}", r.uncertainty.sigma(static_cast<Eigen::Index>(k)));
    s += fmt::format("  {:<36} {:+.6g}{}  (nominal {:.6g}, change {:+.3g})\n",
                     display_label(r, r.estimated[k]), r.estimate(i), sigma, r.nominal(i),
                     r.estimate(i) - r.nominal(i));
  }
  const auto estimated = [&](std::size_t candidate) {
    return std::find(r.estimated.begin(), r.estimated.end(), r.candidates[candidate]) !=
           r.estimated.end();
  };
  // Held parameters: the redundancy explanations say what each moves like. A parameter the
  // relinearised solve went on to estimate is not held, whatever the first analysis said.
  std::vector<std::string> held;
  for (const auto& red : r.identifiability.redundancies)
    if (!estimated(red.parameter)) held.push_back(in_plain_words(red.explanation, r));
  std::vector<std::string> no_effect;
  for (std::size_t k : r.identifiability.no_effect)
    if (k >= r.candidates.size() || !estimated(k))
      no_effect.push_back(k < r.candidates.size() ? display_label(r, r.candidates[k])
                                                  : r.identifiability.names[k]);
  if (held_count > 0)
    s += fmt::format("Held at nominal: {} of the {} free parameters\n", held_count,
                     r.candidates.size());
  for (std::size_t k = 0; k < held.size() && k < 12; ++k) s += "  " + held[k] + "\n";
  if (held.size() > 12) s += fmt::format("  ... and {} more (see the JSON)\n", held.size() - 12);
  if (!no_effect.empty())
    s += fmt::format("  no effect on these measurements ({}): {}\n", no_effect.size(),
                     name_list(no_effect, 8));
  // Noise: stated vs what the residuals show.
  bool header = false;
  for (const auto& g : r.noise.groups) {
    if (g.rows == 0) continue;
    if (!header) {
      s += "Noise (stated -> estimated from the residuals):\n";
      header = true;
    }
    if (!g.estimable) {
      s += fmt::format("  {:<14} {} ({} rows; no redundancy left to estimate it)\n", g.type,
                       noise_value(g.stated_sigma, g.unit), g.rows);
      continue;
    }
    s += fmt::format("  {:<14} {} -> {} ({:.2g}x, 95 % {:.2g}-{:.2g}x, {:.0f} dof){}\n", g.type,
                     noise_value(g.stated_sigma, g.unit), noise_value(g.estimated_sigma(), g.unit),
                     g.scale, g.scale_low, g.scale_high, g.redundancy,
                     r.noise_applied ? "" : " [stated noise kept]");
  }
  if (!r.robust_loss_noise_scale.empty())
    s += "Robust loss: threshold counted in the noise estimated from the data, not the stated "
         "noise\n";
  // Per observation type, each in its own terms (a fit of heights and distances has no position
  // residual); the pose-level figures when the fit did not fill them (pixel observations only).
  std::string fit;
  for (const auto& t : r.residuals.by_type)
    fit += fmt::format("{}{} RMS {}, max {} ({})", fit.empty() ? "" : "; ", t.type,
                       t.unit == "rad" ? fmt::format("{:.3g} mrad", 1e3 * t.rms) : length(t.rms),
                       t.unit == "rad" ? fmt::format("{:.3g} mrad", 1e3 * t.max) : length(t.max),
                       t.count);
  if (fit.empty()) {
    fit = fmt::format("position RMS {}, max {}", length(r.residuals.position_rms),
                      length(r.residuals.position_max));
    if (r.residuals.orientation_max > 0)
      fit += fmt::format("; orientation RMS {:.3g} mrad", r.residuals.orientation_rms * 1e3);
  }
  s += fmt::format("Fit residuals: {}; {} outlier pose(s)\n", fit, r.residuals.outliers);
  for (const auto& p : r.residuals.poses)
    if (p.outlier)
      s += fmt::format("  outlier {}: chi-square {:.3g} > {:.3g} ({} dof), error {}\n", p.id,
                       p.chi_square, p.threshold, p.dof, length(p.position_error));
  if (r.uncertainty.ok)
    s += fmt::format("Predicted accuracy at the measured poses: position RMS {}, worst {}{}\n",
                     length(r.predicted.position_rms_overall), length(r.predicted.position_worst),
                     r.residuals.has_probe_heights()
                         ? fmt::format("; bed height (first layer) RMS {}",
                                       length(r.predicted.height_rms_overall))
                         : std::string());
  for (const auto& w : r.warnings) s += "  warning: " + w + "\n";
  return s;
}

std::string validation_line(const std::string& label, const ValidationReport& v) {
  return validation_line(label, v, "position");
}

std::string validation_line(const std::string& label, const ValidationReport& v,
                            const std::string& what) {
  std::string s = fmt::format("{}: {} poses, {} RMS {} -> {} (max {} -> {})", label, v.after.poses,
                              what, length(v.before.position_rms), length(v.after.position_rms),
                              length(v.before.position_max), length(v.after.position_max));
  if (v.after.orientation_max > 0)
    s += fmt::format(", orientation RMS {:.3g} -> {:.3g} mrad", v.before.orientation_rms * 1e3,
                     v.after.orientation_rms * 1e3);
  return s + "\n";
}

}  // namespace robocal::calib
