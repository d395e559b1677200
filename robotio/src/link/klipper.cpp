#include "robocal/robotio/klipper.hpp"

#include <fmt/format.h>

#include <cmath>
#include <sstream>

namespace robocal::robotio {
namespace {

constexpr std::array<const char*, 3> kKlipperSteppers = {"stepper_a", "stepper_b", "stepper_c"};
constexpr std::array<double, 3> kKlipperTowerAngles = {210.0, 330.0, 90.0};
constexpr double kKlipperFullSteps = 200.0;
constexpr double kKlipperMicrosteps = 16.0;

// A number among the settings: section.option, else the fallback section's option, else the
// default; nullopt (with `problem` set) when absent without a default or not a number.
std::optional<double> setting(const nlohmann::json& settings, const std::string& section,
                              const std::string& option, const std::string& fallback_section,
                              std::optional<double> fallback, std::string& problem) {
  for (const std::string& name : {section, fallback_section}) {
    if (name.empty() || !settings.contains(name) || !settings[name].is_object()) continue;
    const nlohmann::json& s = settings[name];
    if (!s.contains(option)) continue;
    if (!s[option].is_number()) {
      problem = fmt::format("[{}] {}: {} is not a number", name, option, s[option].dump());
      return std::nullopt;
    }
    return s[option].get<double>();
  }
  if (!fallback)
    problem = fmt::format("the configuration has no [{}] {} (a delta needs it)", section, option);
  return fallback;
}

// gear_ratio is a list of "driven:driving" pairs; Klipper multiplies them.
std::optional<double> gear_ratio(const nlohmann::json& stepper, std::string& problem,
                                 const std::string& section) {
  if (!stepper.contains("gear_ratio")) return 1.0;
  double ratio = 1.0;
  const nlohmann::json& g = stepper["gear_ratio"];
  if (!g.is_array()) {
    problem = fmt::format("[{}] gear_ratio: {} is not a list of pairs", section, g.dump());
    return std::nullopt;
  }
  for (const nlohmann::json& pair : g) {
    if (!pair.is_array() || pair.size() != 2 || !pair[0].is_number() || !pair[1].is_number() ||
        pair[1].get<double>() == 0.0) {
      problem = fmt::format("[{}] gear_ratio: {} is not a list of pairs", section, g.dump());
      return std::nullopt;
    }
    ratio *= pair[0].get<double>() / pair[1].get<double>();
  }
  return ratio;
}

std::optional<double> steps_per_mm(const nlohmann::json& settings, const std::string& section,
                                   std::string& problem) {
  const auto rotation = setting(settings, section, "rotation_distance", "", std::nullopt, problem);
  const auto micro = setting(settings, section, "microsteps", "", std::nullopt, problem);
  const auto full = setting(settings, section, "full_steps_per_rotation", "", 200.0, problem);
  if (!rotation || !micro || !full) return std::nullopt;
  const auto ratio = gear_ratio(settings[section], problem, section);
  if (!ratio) return std::nullopt;
  if (!(*rotation > 0.0) || !(*micro > 0.0) || !(*full > 0.0) || !(*ratio > 0.0)) {
    problem = fmt::format(
        "[{}]: rotation_distance, microsteps and full_steps_per_rotation must "
        "be positive",
        section);
    return std::nullopt;
  }
  return *full * *micro * *ratio / *rotation;
}

// "name:value" words after a line's label ("mcu:", "stepper:").
std::optional<std::vector<std::string>> labelled_values(const std::string& line,
                                                        const std::string& label,
                                                        const std::vector<std::string>& names) {
  std::string text = line;
  if (text.rfind("// ", 0) == 0) text.erase(0, 3);
  if (text.rfind(label + " ", 0) != 0) return std::nullopt;
  std::stringstream ss(text.substr(label.size() + 1));
  std::vector<std::string> values(names.size());
  std::vector<bool> seen(names.size(), false);
  std::string word;
  while (ss >> word) {
    const auto colon = word.rfind(':');
    if (colon == std::string::npos) continue;
    for (std::size_t i = 0; i < names.size(); ++i)
      if (word.compare(0, colon, names[i]) == 0 && colon == names[i].size()) {
        values[i] = word.substr(colon + 1);
        seen[i] = true;
      }
  }
  for (const bool s : seen)
    if (!s) return std::nullopt;
  return values;
}

}  // namespace

KlipperPrinter klipper_printer_from_settings(const nlohmann::json& settings) {
  KlipperPrinter out;
  if (!settings.is_object() || !settings.contains("printer") || !settings["printer"].is_object() ||
      !settings["printer"].contains("kinematics") ||
      !settings["printer"]["kinematics"].is_string()) {
    out.problem = "the configuration has no [printer] kinematics";
    return out;
  }
  out.kinematics = settings["printer"]["kinematics"].get<std::string>();
  if (out.kinematics != "delta") {
    out.problem =
        fmt::format("the printer's kinematics is '{}' ([printer] kinematics), not a linear delta",
                    out.kinematics);
    return out;
  }
  DeltaGeometry g;
  g.firmware = Firmware::kKlipper;
  std::string& problem = out.problem;
  const auto radius = setting(settings, "printer", "delta_radius", "", std::nullopt, problem);
  if (!radius) return out;
  g.radius = *radius;
  std::array<double, 3> endstop{};
  for (std::size_t i = 0; i < 3; ++i) {
    const std::string section = kKlipperSteppers[i];
    if (!settings.contains(section) || !settings[section].is_object()) {
      problem =
          fmt::format("the configuration has no [{}] section (a delta has three towers)", section);
      return out;
    }
    const std::string first = i == 0 ? "" : kKlipperSteppers[0];
    const auto arm = setting(settings, section, "arm_length", first, std::nullopt, problem);
    const auto angle = setting(settings, section, "angle", "", kKlipperTowerAngles[i], problem);
    const auto position =
        setting(settings, section, "position_endstop", first, std::nullopt, problem);
    const auto steps = steps_per_mm(settings, section, problem);
    if (!arm || !angle || !position || !steps || !problem.empty()) return out;
    if (!(*arm > g.radius)) {
      problem = fmt::format("[{}] arm_length {:.3f} mm is not longer than delta_radius {:.3f} mm",
                            section, *arm, g.radius);
      return out;
    }
    g.diagonal_rod[i] = *arm;
    g.angle_trim[i] = *angle - kKlipperTowerAngles[i];
    endstop[i] = *position;
    if (i == 0) {
      out.steps_per_mm = *steps;
    } else if (std::abs(*steps - out.steps_per_mm) > 1e-9 * out.steps_per_mm) {
      problem = fmt::format(
          "[{}] moves {:.4f} steps/mm, [stepper_a] {:.4f}: towers with different "
          "step distances are not supported",
          section, *steps, out.steps_per_mm);
      return out;
    }
  }
  g.height = endstop[0];
  for (std::size_t i = 0; i < 3; ++i) g.endstop_adjustment[i] = endstop[i] - endstop[0];
  out.delta = g;
  return out;
}

nlohmann::json klipper_delta_settings(const DeltaGeometry& geometry, double steps_per_mm) {
  nlohmann::json s;
  s["printer"] = {{"kinematics", "delta"},
                  {"delta_radius", geometry.radius},
                  {"max_velocity", 300.0},
                  {"max_accel", 3000.0},
                  {"minimum_z_position", 0.0}};
  for (std::size_t i = 0; i < 3; ++i)
    s[kKlipperSteppers[i]] = {
        {"step_pin", fmt::format("PF{}", i)},
        {"rotation_distance", kKlipperFullSteps * kKlipperMicrosteps / steps_per_mm},
        {"microsteps", static_cast<int>(kKlipperMicrosteps)},
        {"full_steps_per_rotation", static_cast<int>(kKlipperFullSteps)},
        {"arm_length", geometry.diagonal_rod[i]},
        {"angle", kKlipperTowerAngles[i] + geometry.angle_trim[i]},
        {"position_endstop", geometry.height + geometry.endstop_adjustment[i]},
        {"homing_speed", 50.0}};
  s["delta_calibrate"] = {{"radius", geometry.radius * 0.8}, {"speed", 50.0}};
  return s;
}

std::optional<KlipperPosition> parse_get_position(const std::vector<std::string>& responses,
                                                  const std::vector<std::string>& steppers) {
  std::optional<std::vector<std::string>> mcu, stepper;
  for (const std::string& response : responses) {
    std::stringstream lines(response);
    std::string line;
    while (std::getline(lines, line)) {
      if (!line.empty() && line.back() == '\r') line.pop_back();
      if (auto v = labelled_values(line, "mcu:", steppers)) mcu = v;
      if (auto v = labelled_values(line, "stepper:", steppers)) stepper = v;
    }
  }
  if (!mcu || !stepper) return std::nullopt;
  KlipperPosition p;
  try {
    for (std::size_t i = 0; i < steppers.size(); ++i) {
      std::size_t used = 0;
      p.mcu.push_back(std::stol((*mcu)[i], &used));
      if (used != (*mcu)[i].size()) return std::nullopt;
      p.stepper.push_back(std::stod((*stepper)[i], &used));
      if (used != (*stepper)[i].size()) return std::nullopt;
    }
  } catch (const std::exception&) {
    return std::nullopt;
  }
  return p;
}

std::string get_position_text(const std::array<long, 3>& mcu, const std::array<double, 3>& stepper,
                              const Eigen::Vector3d& kinematic, const Eigen::Vector3d& toolhead) {
  std::string m, s;
  for (std::size_t i = 0; i < 3; ++i) {
    m += fmt::format("{}{}:{}", i == 0 ? "" : " ", kKlipperSteppers[i], mcu[i]);
    s += fmt::format("{}{}:{:.6f}", i == 0 ? "" : " ", kKlipperSteppers[i], stepper[i]);
  }
  const std::string xyz =
      fmt::format("X:{:.6f} Y:{:.6f} Z:{:.6f}", toolhead.x(), toolhead.y(), toolhead.z());
  return fmt::format(
      "// mcu: {}\n// stepper: {}\n// kinematic: X:{:.6f} Y:{:.6f} Z:{:.6f}\n// toolhead: {} "
      "E:0.000000\n// gcode: {} E:0.000000\n// gcode base: X:0.000000 Y:0.000000 Z:0.000000 "
      "E:0.000000\n// gcode homing: X:0.000000 Y:0.000000 Z:0.000000",
      m, s, kinematic.x(), kinematic.y(), kinematic.z(), xyz, xyz);
}

std::array<long, 3> klipper_mcu_at_endstop(const CarriageFrame& frame, const KlipperPosition& p) {
  std::array<long, 3> out{};
  for (int i = 0; i < 3; ++i) {
    const auto k = static_cast<std::size_t>(i);
    out[k] = p.mcu[k] - std::lround((p.stepper[k] - endstop_coordinate(frame.geometry, i)) *
                                    frame.steps_per_mm);
  }
  return out;
}

std::vector<long> klipper_frame_counts(const CarriageFrame& frame, const KlipperPosition& p,
                                       const std::array<long, 3>& mcu_at_endstop) {
  std::vector<long> c(3);
  for (int i = 0; i < 3; ++i) {
    const auto k = static_cast<std::size_t>(i);
    c[k] = endstop_count(frame, i) + (p.mcu[k] - mcu_at_endstop[k]);
  }
  return c;
}

}  // namespace robocal::robotio
