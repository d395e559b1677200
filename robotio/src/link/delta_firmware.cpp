#include "robocal/robotio/delta_firmware.hpp"

#include <fmt/core.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdlib>
#include <numbers>
#include <stdexcept>
#include <string_view>
#include <utility>

namespace robocal::robotio {
namespace {

constexpr std::array<double, 3> kTowerBaseAngle = {210.0, 330.0, 90.0};
constexpr std::array<char, 3> kTowerName = {'A', 'B', 'C'};

double radians(double degrees) {
  return degrees * std::numbers::pi / 180.0;
}

// Number at the start of `s`; nullopt when there is none.
std::optional<double> number_at(std::string_view s, std::size_t* used = nullptr) {
  const std::string text(s.substr(0, 40));
  char* end = nullptr;
  const double v = std::strtod(text.c_str(), &end);
  if (end == text.c_str() || !std::isfinite(v)) return std::nullopt;
  if (used != nullptr) *used = static_cast<std::size_t>(end - text.c_str());
  return v;
}

// The value of word `letter` in a G-code line's words after `command` ("M665 L250.00 R124.00"):
// a space-separated token starting with the letter.
std::optional<double> word_value(std::string_view line, std::string_view command, char letter) {
  const std::size_t at = line.find(command);
  if (at == std::string_view::npos) return std::nullopt;
  std::string_view rest = line.substr(at + command.size());
  while (!rest.empty()) {
    const std::size_t start = rest.find_first_not_of(' ');
    if (start == std::string_view::npos) break;
    rest.remove_prefix(start);
    const std::size_t end = rest.find(' ');
    const std::string_view token = rest.substr(0, end);
    if (token.size() > 1 && token[0] == letter) return number_at(token.substr(1));
    if (end == std::string_view::npos) break;
    rest.remove_prefix(end);
  }
  return std::nullopt;
}

// The number after `key` in `line` ("delta radius 105.000" -> 105).
std::optional<double> number_after(std::string_view line, std::string_view key) {
  const std::size_t at = line.find(key);
  if (at == std::string_view::npos) return std::nullopt;
  std::string_view rest = line.substr(at + key.size());
  while (!rest.empty() && rest.front() == ' ') rest.remove_prefix(1);
  return number_at(rest);
}

const std::string* line_with(const std::vector<std::string>& lines, std::string_view what) {
  for (const std::string& l : lines)
    if (l.find(what) != std::string::npos) return &l;
  return nullptr;
}

// "Diagonals 215.000:215.000:215.000" (or one value for all towers).
bool parse_rrf_diagonals(std::string_view line, DeltaGeometry& g) {
  const std::size_t at = line.find("Diagonal");
  if (at == std::string_view::npos) return false;
  std::string_view rest = line.substr(at);
  rest.remove_prefix(rest.find(' ') == std::string_view::npos ? rest.size() : rest.find(' ') + 1);
  for (std::size_t i = 0; i < 3; ++i) {
    std::size_t used = 0;
    const auto v = number_at(rest, &used);
    if (!v) {
      if (i == 0) return false;
      g.diagonal_rod[i] = g.diagonal_rod[i - 1];  // one value given for every tower
      continue;
    }
    g.diagonal_rod[i] = *v;
    rest.remove_prefix(used);
    if (rest.empty() || rest.front() != ':') {
      for (std::size_t k = i + 1; k < 3; ++k) g.diagonal_rod[k] = *v;
      break;
    }
    rest.remove_prefix(1);
  }
  return true;
}

std::string fixed(double v, int decimals) {
  return fmt::format("{:.{}f}", v, decimals);
}

}  // namespace

std::optional<DeltaGeometry> parse_marlin_delta_settings(const std::vector<std::string>& lines) {
  const std::string* m665 = line_with(lines, "M665 ");
  if (m665 == nullptr) return std::nullopt;
  DeltaGeometry g;
  g.firmware = Firmware::kMarlin;
  const auto l = word_value(*m665, "M665", 'L');
  const auto r = word_value(*m665, "M665", 'R');
  const auto h = word_value(*m665, "M665", 'H');
  if (!l || !r || !h) return std::nullopt;
  g.radius = *r;
  g.height = *h;
  g.segments_per_second = word_value(*m665, "M665", 'S').value_or(g.segments_per_second);
  for (std::size_t i = 0; i < 3; ++i) {
    // Rod trims A B C are newer than the rest; a firmware without them has one rod length.
    g.diagonal_rod[i] = *l + word_value(*m665, "M665", "ABC"[i]).value_or(0.0);
    g.angle_trim[i] = word_value(*m665, "M665", "XYZ"[i]).value_or(0.0);
  }
  if (const std::string* m666 = line_with(lines, "M666 ")) {
    for (std::size_t i = 0; i < 3; ++i) {
      const auto adj = word_value(*m666, "M666", "XYZ"[i]);
      if (!adj) return std::nullopt;
      g.endstop_adjustment[i] = *adj;
    }
  }
  return g;
}

std::optional<DeltaGeometry> parse_rrf_delta_settings(const std::vector<std::string>& m665_lines,
                                                      const std::vector<std::string>& m666_lines) {
  const std::string* m665 = line_with(m665_lines, "Diagonal");
  const std::string* m666 = line_with(m666_lines, "Endstop adjustments");
  if (m665 == nullptr || m666 == nullptr) return std::nullopt;
  DeltaGeometry g;
  g.firmware = Firmware::kRepRapFirmware;
  if (!parse_rrf_diagonals(*m665, g)) return std::nullopt;
  const auto r = number_after(*m665, "delta radius");
  const auto h = number_after(*m665, "homed height");
  if (!r || !h) return std::nullopt;
  g.radius = *r;
  g.height = *h;
  g.bed_radius = number_after(*m665, "bed radius").value_or(g.bed_radius);
  for (std::size_t i = 0; i < 3; ++i) {
    const std::string key = fmt::format(", {} ", "XYZ"[i]);
    g.angle_trim[i] = number_after(*m665, key).value_or(0.0);
    const std::string adj_key = fmt::format(" {}", "XYZ"[i]);
    const std::size_t adjustments = m666->find("adjustments");
    const auto adj = number_after(std::string_view(*m666).substr(adjustments), adj_key);
    if (!adj) return std::nullopt;
    g.endstop_adjustment[i] = *adj;
  }
  const std::size_t tilt = m666->find("tilt");
  if (tilt != std::string::npos) {
    g.tilt_x = number_after(std::string_view(*m666).substr(tilt), "X").value_or(0.0) / 100.0;
    g.tilt_y = number_after(std::string_view(*m666).substr(tilt), "Y").value_or(0.0) / 100.0;
  }
  return g;
}

std::vector<std::string> marlin_m503_lines(const std::optional<DeltaGeometry>& delta,
                                           double steps_per_mm) {
  std::vector<std::string> out = {
      "echo:; Linear Units:", "echo:  G21 ; (mm)", "echo:; Steps per unit:",
      fmt::format("echo:  M92 X{0:.2f} Y{0:.2f} Z{0:.2f} E93.00", steps_per_mm)};
  if (!delta) return out;
  const DeltaGeometry& g = *delta;
  out.emplace_back("echo:; Endstop adjustment:");
  out.push_back(fmt::format("echo:  M666 X{:.2f} Y{:.2f} Z{:.2f}", g.endstop_adjustment[0],
                            g.endstop_adjustment[1], g.endstop_adjustment[2]));
  out.emplace_back(
      "echo:; Delta (L<diagonal rod> R<radius> H<height> S<segments per sec> XYZ<tower angle "
      "trim> ABC<rod trim>):");
  const double l = g.diagonal_rod[0];
  out.push_back(fmt::format(
      "echo:  M665 L{:.2f} R{:.2f} H{:.2f} S{:.2f} X{:.2f} Y{:.2f} Z{:.2f} A{:.2f} B{:.2f} C{:.2f}",
      l, g.radius, g.height, g.segments_per_second, g.angle_trim[0], g.angle_trim[1],
      g.angle_trim[2], 0.0, g.diagonal_rod[1] - l, g.diagonal_rod[2] - l));
  return out;
}

std::string rrf_m665_reply(const DeltaGeometry& g) {
  return fmt::format(
      "Diagonals {:.3f}:{:.3f}:{:.3f}, delta radius {:.3f}, homed height {:.3f}, bed radius "
      "{:.1f}, X {:.3f}\u00b0, Y {:.3f}\u00b0, Z {:.3f}\u00b0",
      g.diagonal_rod[0], g.diagonal_rod[1], g.diagonal_rod[2], g.radius, g.height, g.bed_radius,
      g.angle_trim[0], g.angle_trim[1], g.angle_trim[2]);
}

std::string rrf_m666_reply(const DeltaGeometry& g) {
  return fmt::format("Endstop adjustments X{:.2f} Y{:.2f} Z{:.2f}, tilt X{:.2f}% Y{:.2f}%",
                     g.endstop_adjustment[0], g.endstop_adjustment[1], g.endstop_adjustment[2],
                     g.tilt_x * 100.0, g.tilt_y * 100.0);
}

Eigen::Vector2d tower_xy(const DeltaGeometry& g, int tower) {
  const auto k = static_cast<std::size_t>(tower);
  const double a = radians(kTowerBaseAngle[k] + g.angle_trim[k]);
  return {g.radius * std::cos(a), g.radius * std::sin(a)};
}

std::optional<Eigen::Vector3d> carriage_coordinates(const DeltaGeometry& g,
                                                    const Eigen::Vector3d& xyz) {
  Eigen::Vector3d out;
  for (int i = 0; i < 3; ++i) {
    const double l = g.diagonal_rod[static_cast<std::size_t>(i)];
    const double h2 = l * l - (xyz.head<2>() - tower_xy(g, i)).squaredNorm();
    if (!(h2 >= 0.0)) return std::nullopt;
    out[i] = xyz.z() + std::sqrt(h2) + xyz.x() * g.tilt_x + xyz.y() * g.tilt_y;
  }
  return out;
}

std::optional<Eigen::Vector3d> nozzle_position(const DeltaGeometry& g,
                                               const Eigen::Vector3d& carriages) {
  // Trilateration on the carriage joints (tower point at the carriage coordinate), the nozzle
  // below them. The tilt terms depend on x and y only, so they are taken off the heights after
  // x and y are known: a fixed point of two passes (the tilt is a fraction of a percent).
  Eigen::Vector3d nozzle = Eigen::Vector3d::Zero();
  for (int pass = 0; pass < 3; ++pass) {
    const double tilt = nozzle.x() * g.tilt_x + nozzle.y() * g.tilt_y;
    std::array<Eigen::Vector3d, 3> p;
    for (int i = 0; i < 3; ++i) {
      const Eigen::Vector2d t = tower_xy(g, i);
      p[static_cast<std::size_t>(i)] = {t.x(), t.y(), carriages[i] - tilt};
    }
    const Eigen::Vector3d p12 = p[1] - p[0], p13 = p[2] - p[0];
    const double d = p12.norm();
    if (!(d > 0.0)) return std::nullopt;
    const Eigen::Vector3d ex = p12 / d;
    const double i = ex.dot(p13);
    Eigen::Vector3d ey = p13 - i * ex;
    const double j = ey.norm();
    if (!(j > 0.0)) return std::nullopt;
    ey /= j;
    Eigen::Vector3d ez = ex.cross(ey);
    if (ez.z() > 0) ez = -ez;
    const double l1 = g.diagonal_rod[0] * g.diagonal_rod[0];
    const double l2 = g.diagonal_rod[1] * g.diagonal_rod[1];
    const double l3 = g.diagonal_rod[2] * g.diagonal_rod[2];
    const double x = (l1 - l2 + d * d) / (2.0 * d);
    const double y = (l1 - l3 + i * i + j * j) / (2.0 * j) - i * x / j;
    const double z2 = l1 - x * x - y * y;
    if (!(z2 >= 0.0)) return std::nullopt;
    nozzle = p[0] + x * ex + y * ey + std::sqrt(z2) * ez;
    if (g.tilt_x == 0.0 && g.tilt_y == 0.0) break;
  }
  return nozzle;
}

double endstop_coordinate(const DeltaGeometry& g, int tower) {
  const auto k = static_cast<std::size_t>(tower);
  const double l = g.diagonal_rod[k];
  const double rise = std::sqrt(l * l - g.radius * g.radius);
  // Marlin calls the backed-off position (0, 0, H), so the endstop is |M666| above it; RRF puts
  // the endstop itself at H + rise + M666; Klipper at position_endstop + rise, which is H + rise +
  // adjustment with H = stepper_a's position_endstop (klipper.hpp).
  if (g.firmware == Firmware::kMarlin) return g.height + rise + std::abs(g.endstop_adjustment[k]);
  return g.height + rise + g.endstop_adjustment[k];
}

double homing_backoff(const DeltaGeometry& g, int tower) {
  return g.firmware == Firmware::kMarlin
             ? std::abs(g.endstop_adjustment[static_cast<std::size_t>(tower)])
             : 0.0;
}

long endstop_count(const CarriageFrame& f, int tower) {
  return std::lround(endstop_coordinate(f.geometry, tower) * f.steps_per_mm);
}

double carriage_coordinate_of_reading(const CarriageFrame& f, int tower, double reading) {
  return static_cast<double>(endstop_count(f, tower)) / f.steps_per_mm +
         (reading - f.endstop_reading[static_cast<std::size_t>(tower)]) * 1000.0;
}

double reading_of_carriage_coordinate(const CarriageFrame& f, int tower, double coordinate) {
  return f.endstop_reading[static_cast<std::size_t>(tower)] +
         (coordinate - static_cast<double>(endstop_count(f, tower)) / f.steps_per_mm) / 1000.0;
}

std::vector<long> delta_counts(const CarriageFrame& f, const Eigen::VectorXd& readings) {
  std::vector<long> c(3);
  for (int i = 0; i < 3; ++i)
    c[static_cast<std::size_t>(i)] =
        endstop_count(f, i) +
        std::lround((readings[i] - f.endstop_reading[static_cast<std::size_t>(i)]) * 1000.0 *
                    f.steps_per_mm);
  return c;
}

Eigen::VectorXd delta_readings(const CarriageFrame& f, const std::vector<long>& counts) {
  Eigen::VectorXd r(3);
  for (int i = 0; i < 3; ++i)
    r[i] = f.endstop_reading[static_cast<std::size_t>(i)] +
           static_cast<double>(counts[static_cast<std::size_t>(i)] - endstop_count(f, i)) /
               f.steps_per_mm / 1000.0;
  return r;
}

double coordinate_of_count(const CarriageFrame& f, int tower, long count) {
  if (f.geometry.firmware == Firmware::kKlipper)
    return endstop_coordinate(f.geometry, tower) +
           static_cast<double>(count - endstop_count(f, tower)) / f.steps_per_mm;
  return static_cast<double>(count) / f.steps_per_mm;
}

long count_of_coordinate(const CarriageFrame& f, int tower, double coordinate) {
  if (f.geometry.firmware == Firmware::kKlipper)
    return endstop_count(f, tower) +
           std::lround((coordinate - endstop_coordinate(f.geometry, tower)) * f.steps_per_mm);
  return std::lround(coordinate * f.steps_per_mm);
}

std::optional<Eigen::Vector3d> cartesian_for_counts(const CarriageFrame& f,
                                                    const std::vector<long>& counts) {
  Eigen::Vector3d coordinates;
  for (int i = 0; i < 3; ++i)
    coordinates[i] = coordinate_of_count(f, i, counts[static_cast<std::size_t>(i)]);
  return nozzle_position(f.geometry, coordinates);
}

std::optional<std::vector<long>> counts_for_cartesian(const CarriageFrame& f,
                                                      const Eigen::Vector3d& xyz) {
  const auto coordinates = carriage_coordinates(f.geometry, xyz);
  if (!coordinates) return std::nullopt;
  std::vector<long> c(3);
  for (int i = 0; i < 3; ++i)
    c[static_cast<std::size_t>(i)] = count_of_coordinate(f, i, (*coordinates)[i]);
  return c;
}

bool firmware_can_command(const CarriageFrame& f, const std::vector<long>& counts) {
  const auto xyz = cartesian_for_counts(f, counts);
  if (!xyz) return false;
  const auto back = counts_for_cartesian(f, *xyz);
  return back && *back == counts;
}

RobotFileDelta robot_file_delta(const calib::Mechanism& model) {
  RobotFileDelta out;
  const calib::ClosedFormSpec& s = model.closed_form;
  if (s.kind != calib::ClosedFormKind::kLinearDelta || model.actuated.size() != 3 ||
      s.rail_origin.size() != 3 || s.link_length.size() != 3) {
    out.problem = fmt::format(
        "robot '{}' is not a linear delta (three carriages on towers, the robot file's "
        "closed_form: rails): a delta firmware's kinematics cannot drive it",
        model.name);
    return out;
  }
  auto sigma_of = [&](const std::string& name, double fallback) {
    for (const calib::Parameter& p : model.parameters)
      if (p.name == name && p.sigma > 0.0) return p.sigma;
    return fallback;
  };
  double radius = 0.0;
  for (std::size_t i = 0; i < 3; ++i) {
    const Eigen::Vector3d joint = s.rail_origin[i] - s.platform_offset[i];
    radius += joint.head<2>().norm() / 3.0;
    out.diagonal_rod[i] = s.link_length[i] * 1000.0;
    out.tower_angle[i] = std::atan2(joint.y(), joint.x()) * 180.0 / std::numbers::pi;
  }
  out.radius = radius * 1000.0;
  // The endstops sit at the top of the towers: each carriage's upper limit, as a reading through
  // the robot file's nominal encoder model.
  Eigen::VectorXd top(3);
  for (int i = 0; i < 3; ++i)
    top[i] = model.bodies[static_cast<std::size_t>(model.actuated[static_cast<std::size_t>(i)])]
                 .limits.upper;
  const Eigen::VectorXd top_readings =
      calib::readings_from_joint_values(model, model.nominal_parameters(), top);
  for (int i = 0; i < 3; ++i) out.endstop_reading[static_cast<std::size_t>(i)] = top_readings[i];
  // Three sigma of the file's own tolerances: a firmware inside them is the same printer.
  out.rod_tolerance = 3.0 * sigma_of("rod_a.length", 5e-4) * 1000.0;
  out.radius_tolerance = 3.0 * sigma_of("tower_a.x", 5e-4) * 1000.0;
  out.angle_tolerance = std::atan2(out.radius_tolerance, out.radius) * 180.0 / std::numbers::pi;
  return out;
}

DeltaGeometry drawing_geometry(const RobotFileDelta& file, Firmware firmware) {
  DeltaGeometry g;
  g.firmware = firmware;
  g.diagonal_rod = file.diagonal_rod;
  g.radius = file.radius;
  for (std::size_t i = 0; i < 3; ++i)
    g.angle_trim[i] = std::remainder(file.tower_angle[i] - kTowerBaseAngle[i], 360.0);
  const double l = g.diagonal_rod[0];
  g.height = file.endstop_reading[0] * 1000.0 - std::sqrt(l * l - g.radius * g.radius);
  return g;
}

void apply_delta_setting(DeltaGeometry& g, const std::string& item) {
  const std::size_t eq = item.find('=');
  const std::string name = item.substr(0, eq);
  const auto value =
      eq == std::string::npos ? std::nullopt : number_at(std::string_view(item).substr(eq + 1));
  if (!value)
    throw std::invalid_argument("delta setting '" + item + "': expected NAME=VALUE (mm, deg)");
  const std::array<std::pair<const char*, double*>, 12> fields = {{
      {"L_A", &g.diagonal_rod[0]},
      {"L_B", &g.diagonal_rod[1]},
      {"L_C", &g.diagonal_rod[2]},
      {"R", &g.radius},
      {"H", &g.height},
      {"X", &g.angle_trim[0]},
      {"Y", &g.angle_trim[1]},
      {"Z", &g.angle_trim[2]},
      {"M666_X", &g.endstop_adjustment[0]},
      {"M666_Y", &g.endstop_adjustment[1]},
      {"M666_Z", &g.endstop_adjustment[2]},
      {"L", nullptr},
  }};
  for (const auto& [key, target] : fields) {
    if (name != key) continue;
    if (target == nullptr) {
      g.diagonal_rod = {*value, *value, *value};
    } else {
      *target = *value;
    }
    return;
  }
  throw std::invalid_argument("delta setting '" + item +
                              "': unknown name (L, L_A, L_B, L_C, R, H, X, Y, Z, M666_X, M666_Y, "
                              "M666_Z)");
}

std::vector<std::string> geometry_disagreements(const DeltaGeometry& firmware,
                                                const RobotFileDelta& file) {
  std::vector<std::string> out;
  for (std::size_t i = 0; i < 3; ++i)
    if (std::abs(firmware.diagonal_rod[i] - file.diagonal_rod[i]) > file.rod_tolerance)
      out.push_back(fmt::format(
          "tower {} diagonal rod: the firmware says {} mm, the robot file {} mm (tolerance {} mm)",
          kTowerName[i], fixed(firmware.diagonal_rod[i], 2), fixed(file.diagonal_rod[i], 2),
          fixed(file.rod_tolerance, 2)));
  if (std::abs(firmware.radius - file.radius) > file.radius_tolerance)
    out.push_back(fmt::format(
        "delta radius: the firmware says {} mm, the robot file {} mm (tolerance {} mm)",
        fixed(firmware.radius, 2), fixed(file.radius, 2), fixed(file.radius_tolerance, 2)));
  for (std::size_t i = 0; i < 3; ++i) {
    const double fw = kTowerBaseAngle[i] + firmware.angle_trim[i];
    const double diff = std::remainder(fw - file.tower_angle[i], 360.0);
    if (std::abs(diff) > file.angle_tolerance)
      out.push_back(fmt::format(
          "tower {} angle: the firmware says {} deg, the robot file {} deg (tolerance {} deg)",
          kTowerName[i], fixed(fw, 2), fixed(std::remainder(file.tower_angle[i], 360.0), 2),
          fixed(file.angle_tolerance, 2)));
  }
  return out;
}

namespace {

std::string frame_triple_text(const std::array<double, 3>& v) {
  return fmt::format("{},{},{}", v[0], v[1], v[2]);
}

// "A,B,..." into exactly `values.size()` numbers; false when the text holds another count or a
// word that is not a finite number.
bool read_frame_numbers(const std::string& text, std::vector<double*> values) {
  std::size_t at = 0;
  for (std::size_t k = 0; k < values.size(); ++k) {
    const std::size_t end = k + 1 == values.size() ? text.size() : text.find(',', at);
    if (end == std::string::npos) return false;
    const std::string word = text.substr(at, end - at);
    char* stop = nullptr;
    const double v = std::strtod(word.c_str(), &stop);
    if (word.empty() || *stop != '\0' || !std::isfinite(v)) return false;
    *values[k] = v;
    at = end + 1;
  }
  return true;
}

}  // namespace

std::string carriage_frame_text(const CarriageFrame& f) {
  const DeltaGeometry& g = f.geometry;
  return fmt::format(
      "firmware={} rods={} radius={} height={} angle_trim={} endstops={} tilt={},{} "
      "steps_per_mm={} endstop_reading={}",
      to_string(g.firmware), frame_triple_text(g.diagonal_rod), g.radius, g.height,
      frame_triple_text(g.angle_trim), frame_triple_text(g.endstop_adjustment), g.tilt_x, g.tilt_y,
      f.steps_per_mm, frame_triple_text(f.endstop_reading));
}

std::optional<CarriageFrame> carriage_frame_from_text(const std::string& text) {
  CarriageFrame f;
  DeltaGeometry& g = f.geometry;
  const auto triple = [](std::array<double, 3>& v) {
    return std::vector<double*>{v.data(), v.data() + 1, v.data() + 2};
  };
  const std::vector<std::pair<std::string, std::vector<double*>>> fields = {
      {"rods", triple(g.diagonal_rod)},
      {"radius", {&g.radius}},
      {"height", {&g.height}},
      {"angle_trim", triple(g.angle_trim)},
      {"endstops", triple(g.endstop_adjustment)},
      {"tilt", {&g.tilt_x, &g.tilt_y}},
      {"steps_per_mm", {&f.steps_per_mm}},
      {"endstop_reading", triple(f.endstop_reading)}};
  std::vector<bool> found(fields.size(), false);
  bool firmware = false;
  std::size_t at = 0;
  while (at < text.size()) {
    const std::size_t end = std::min(text.find(' ', at), text.size());
    const std::string item = text.substr(at, end - at);
    at = end + 1;
    const std::size_t eq = item.find('=');
    if (eq == std::string::npos) return std::nullopt;
    const std::string name = item.substr(0, eq);
    const std::string value = item.substr(eq + 1);
    if (name == "firmware") {
      for (const Firmware kind : {Firmware::kMarlin, Firmware::kRepRapFirmware, Firmware::kKlipper})
        if (value == to_string(kind)) {
          g.firmware = kind;
          firmware = true;
        }
      continue;
    }
    const auto field = std::find_if(fields.begin(), fields.end(),
                                    [&](const auto& entry) { return entry.first == name; });
    if (field == fields.end() || !read_frame_numbers(value, field->second)) return std::nullopt;
    found[static_cast<std::size_t>(field - fields.begin())] = true;
  }
  const bool every = std::all_of(found.begin(), found.end(), [](bool seen) { return seen; });
  if (!firmware || !every || f.steps_per_mm <= 0.0) return std::nullopt;
  return f;
}

}  // namespace robocal::robotio
