// The closing summary of a validation in plain words (`robocal validate`, `robocal demo`).
#include "summary/validation_summary.hpp"

#include "session/results_layout.hpp"

#include "robocal/core/angles.hpp"

#include <fmt/core.h>

#include <algorithm>
#include <string>
#include <utility>

namespace robocal::app {

namespace {

std::string fmt_param_change(const std::string& unit, double delta) {
  if (unit == "length") return fmt::format("{:+8.3f} mm", delta * 1e3);
  if (unit == "angle") return fmt::format("{:+8.4f} deg", core::degrees(delta));
  return fmt::format("{:+8.2e}", delta);
}

ParameterSentence mentions(const std::string& text, const ParameterAccount& a) {
  return calib::parameter_mentions(text, a.names);
}

}  // namespace

ParameterWords parameter_words(const ParameterAccount& a) {
  const ParameterCounts& c = a.counts;
  ParameterWords w;
  const auto are = [](std::size_t n) { return n == 1 ? "is" : "are"; };
  w.identified = fmt::format(
      "{} of the {} free parameters were identified from the measurements; the other {} {} "
      "held at nominal (the robot file's value).",
      c.identified, c.free, c.held, are(c.held));
  if (c.fixed() > 0)
    w.identified += fmt::format(" {} more {} fixed in the robot file ({} parameters in all).",
                                c.fixed(), are(c.fixed()), c.total);
  w.held = fmt::format("{} of the {} free parameters {} held at nominal (the robot file's value)",
                       c.held, c.free, are(c.held));
  if (c.held > 0)
    w.held += c.no_effect == 0 ? std::string(": each moves the measurements like identified ones")
              : c.no_effect == c.held
                  ? std::string(": none has an effect on these measurements")
                  : fmt::format(
                        ": {} {} no effect on these measurements, {} move{} them like "
                        "identified ones",
                        c.no_effect, c.no_effect == 1 ? "has" : "have", c.held - c.no_effect,
                        c.held - c.no_effect == 1 ? "s" : "");
  w.held += ".";
  if (!a.no_effect.empty()) {
    ParameterSentence s{{"No effect on any measurement with these poses: ", -1}};
    for (std::size_t k = 0; k < a.no_effect.size(); ++k) {
      if (k > 0) s.push_back({", ", -1});
      const auto it = std::find(a.names.begin(), a.names.end(), a.no_effect[k]);
      s.push_back(
          {a.no_effect[k], it == a.names.end() ? -1 : static_cast<int>(it - a.names.begin())});
    }
    s.push_back({".", -1});
    w.reasons.push_back(std::move(s));
  }
  for (const auto& text : a.confounded) w.reasons.push_back(mentions(text, a));
  if (!a.relinearised.empty()) w.notes.push_back(mentions(a.relinearised, a));
  for (const auto& text : a.weak) w.notes.push_back(mentions(text, a));
  if (a.underdetermined)
    w.notes.push_back({{fmt::format("Only {} measurement equations for the {} free parameters: "
                                    "more poses would identify more.",
                                    a.equations, c.free),
                        -1}});
  return w;
}

std::string with_labels(const ParameterSentence& sentence, const ParameterAccount& a) {
  std::string out;
  for (const auto& part : sentence)
    out += part.parameter >= 0 ? a.labels.at(static_cast<std::size_t>(part.parameter)) : part.text;
  return out;
}

void print_validation_summary(std::FILE* out, const nlohmann::json& v,
                              const nlohmann::json& ident) {
  if (v.value("status", "") == "no_truth") {
    fmt::print(out, "\n=== No validation: {}\n", v.value("message", ""));
    return;
  }
  const double before = v.at("nominal").at("rms_m").get<double>();
  const double after = v.at("calibrated").at("rms_m").get<double>();
  fmt::print(out,
             "\n=== Result: end-effector position error on {} held-out poses, against the truth\n",
             v.at("held_out_poses").get<int>());
  fmt::print(out, "  nominal model (base frame fitted): {:8.1f} µm RMS, {:8.1f} µm max\n",
             before * 1e6, v.at("nominal").at("max_m").get<double>() * 1e6);
  fmt::print(
      out,
      "  calibrated model:                  {:8.1f} µm RMS, {:8.1f} µm max  ({:.0f}x better)\n",
      after * 1e6, v.at("calibrated").at("max_m").get<double>() * 1e6,
      after > 0 ? before / after : 0.0);
  if (v.contains("calibrated_pixels"))
    fmt::print(out,
               "  calibrated from pixels (camera-in-the-loop): {:5.1f} µm RMS, {:8.1f} µm max  "
               "(line above: from measured 6-D poses)\n",
               v["calibrated_pixels"].at("rms_m").get<double>() * 1e6,
               v["calibrated_pixels"].at("max_m").get<double>() * 1e6);
  if (v.contains("camera_frame") && v["camera_frame"].contains("held_out_in_true_frame")) {
    const auto& f = v["camera_frame"];
    const auto& in_true = f["held_out_in_true_frame"];
    fmt::print(
        out,
        "  (in camera 0's frame as its calibration placed it, {:.1f} µrad and {:.1f} µm from "
        "the true one; against the true frame, which no measurement sees: calibrated {:.1f} "
        "µm RMS{})\n",
        f.value("turn_rad", 0.0) * 1e6, f.value("shift_m", 0.0) * 1e6,
        in_true.at("calibrated").at("rms_m").get<double>() * 1e6,
        in_true.contains("calibrated_pixels")
            ? fmt::format(", from pixels {:.1f} µm",
                          in_true["calibrated_pixels"].at("rms_m").get<double>() * 1e6)
            : std::string());
  }
  // Configurations drawn from the truth where a model cannot answer: failures, never dropped
  // silently.
  if (v.contains("unanswered")) {
    int total = 0;
    std::string which;
    for (const auto& [model, count] : v["unanswered"].items()) {
      const int n = count.get<int>();
      if (n == 0) continue;
      total += n;
      which += fmt::format("{}{} {}", which.empty() ? "" : ", ", model, n);
    }
    const int drawn = v.value("held_out_drawn", v.at("held_out_poses").get<int>());
    if (total > 0)
      fmt::print(out,
                 "  FAILURES: of {} configurations drawn from the truth, a model could not answer "
                 "({}) at: {}. The figures above are over the {} every model answers.\n",
                 drawn, kNoAnswerMeaning, which, v.at("held_out_poses").get<int>());
    if (drawn < v.value("held_out_requested", drawn))
      fmt::print(out, "  only {} of the {} requested held-out configurations could be drawn\n",
                 drawn, v.value("held_out_requested", drawn));
  }
  if (v.contains("held_out_by_region") && v.contains("measured_region")) {
    const auto& by_region = v["held_out_by_region"];
    fmt::print(out,
               "  by region (measured region = convex hull of the {} measured board positions):\n",
               v["measured_region"].value("measured_poses", 0));
    for (const char* side : {"inside", "outside"}) {
      const auto& part = by_region.at(side);
      const int n = part.value("held_out_poses", 0);
      const bool in = std::string(side) == "inside";
      std::string line = fmt::format(
          "    {:<24} {:4} poses", in ? "inside (interpolation):" : "outside (extrapolation):", n);
      if (n > 0) {
        line += fmt::format(": calibrated {:.1f} µm RMS, {:.1f} µm max",
                            part.at("calibrated").at("rms_m").get<double>() * 1e6,
                            part.at("calibrated").at("max_m").get<double>() * 1e6);
        if (part.contains("calibrated_pixels"))
          line += fmt::format("; from pixels {:.1f} µm RMS, {:.1f} µm max",
                              part["calibrated_pixels"].at("rms_m").get<double>() * 1e6,
                              part["calibrated_pixels"].at("max_m").get<double>() * 1e6);
        if (!in)
          line += fmt::format(" (up to {:.0f} mm outside, median {:.0f} mm)",
                              part.value("distance_max_m", 0.0) * 1e3,
                              part.value("distance_median_m", 0.0) * 1e3);
      }
      fmt::print(out, "{}\n", line);
    }
  }
  fmt::print(out, "  robot accuracy in its own frame (after best-fit rigid registration):\n");
  fmt::print(out, "    nominal {:.1f} µm RMS, calibrated {:.1f} µm RMS ({:.1f} µm max)\n",
             v.at("nominal_registered").at("rms_m").get<double>() * 1e6,
             v.at("calibrated_registered").at("rms_m").get<double>() * 1e6,
             v.at("calibrated_registered").at("max_m").get<double>() * 1e6);
  if (v.contains("held_out_by_region")) {
    const auto& in = v["held_out_by_region"].at("inside");
    const auto& out_part = v["held_out_by_region"].at("outside");
    if (in.contains("calibrated_registered") && out_part.contains("calibrated_registered"))
      fmt::print(out,
                 "    calibrated inside the measured region {:.1f} µm RMS, outside {:.1f} µm "
                 "RMS\n",
                 in["calibrated_registered"].at("rms_m").get<double>() * 1e6,
                 out_part["calibrated_registered"].at("rms_m").get<double>() * 1e6);
  }
  fmt::print(
      out,
      "\n  robot dimensions that changed most (estimated change; true change in brackets;"
      "\n  the base frame, i.e. where the robot stands in the cameras' world, is left out):\n");
  int listed = 0;
  bool any_stand_in = false;
  for (const auto& p : v.at("parameters")) {
    if (listed == 8) break;
    if (p.value("base_frame", false)) continue;
    const auto unit = p.at("unit").get<std::string>();
    const int stands_in_for = p.value("stands_in_for", 0);
    any_stand_in = any_stand_in || stands_in_for > 0;
    fmt::print(out, "    {:<36} {}  ({}){}\n", p.value("label", p.at("name").get<std::string>()),
               fmt_param_change(unit, p.at("estimated_change").get<double>()),
               fmt_param_change(unit, p.at("true_change").get<double>()),
               stands_in_for > 0 ? fmt::format("  *{}", stands_in_for) : std::string());
    ++listed;
  }
  if (any_stand_in)
    fmt::print(out,
               "    *N: also carries N parameters it cannot be told apart from (held at nominal), "
               "so its change is\n       their combination, not comparable with its own true "
               "change\n");
  if (ident.value("status", "") == "ok") {
    const ParameterAccount account = parameter_account(ident, ResultsLayout::kIdentification);
    const ParameterWords words = parameter_words(account);
    fmt::print(out, "\n  {}\n", words.identified);
    if (account.counts.held > 0) {
      fmt::print(out, "  what could not be identified: {}\n", words.held);
      constexpr std::size_t kShown = 6;
      for (std::size_t k = 0; k < std::min(kShown, words.reasons.size()); ++k) {
        const std::string m = with_labels(words.reasons[k], account);
        fmt::print(out, "    - {}\n", m.size() > 240 ? m.substr(0, 237) + "..." : m);
      }
      if (words.reasons.size() > kShown)
        fmt::print(out, "    ... {} more in {}\n", words.reasons.size() - kShown,
                   ResultsLayout::kIdentification);
    }
  }
}

}  // namespace robocal::app
