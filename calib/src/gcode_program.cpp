#include "robocal/calib/gcode_program.hpp"

#include "robocal/calib/closure.hpp"
#include "robocal/core/input_error.hpp"

#include <fmt/core.h>

#include <algorithm>
#include <array>
#include <cctype>
#include <charconv>
#include <cmath>
#include <limits>
#include <memory>
#include <numbers>
#include <sstream>

namespace robocal::calib {

const GcodeWord* GcodeLine::word(char letter) const {
  for (const auto& w : words)
    if (w.letter == letter) return &w;
  return nullptr;
}

std::vector<GcodeActuatorAxis> gcode_actuator_axes(const Mechanism& model,
                                                   const Eigen::VectorXd& nominal) {
  static const std::string kLetters = "XYZUVWABC";
  if (model.actuated.size() > kLetters.size())
    throw core::InputError(
        fmt::format("{}: {} actuators; a G-code controller has at most 9 axes (X Y Z U V W A B C)",
                    model.source, model.actuated.size()));
  // As robocal's G-code link: readings in counts reach the axes through the nominal scale.
  const Eigen::VectorXd scale = encoder_scales(model, nominal);
  std::vector<GcodeActuatorAxis> axes;
  for (std::size_t i = 0; i < model.actuated.size(); ++i) {
    const Body& b = model.bodies[static_cast<std::size_t>(model.actuated[i])];
    const bool revolute = b.joint == JointType::kRevolute;
    axes.push_back(
        {kLetters[i], b.name, revolute,
         (revolute ? 180.0 / std::numbers::pi : 1000.0) * scale[static_cast<Eigen::Index>(i)]});
  }
  return axes;
}

namespace {

[[noreturn]] void fail(const std::string& source, int line, const std::string& what) {
  throw core::InputError(fmt::format("{}:{}: {}", source, line, what));
}

// Commands whose argument is free text (messages, file names), not words.
bool takes_text(const std::string& command) {
  return command == "M23" || command == "M28" || command == "M30" || command == "M32" ||
         command == "M117" || command == "M118";
}

std::string command_name(char letter, const std::string& number_text, double value) {
  if (value == std::floor(value) && std::abs(value) < 1e6)
    return fmt::format("{}{}", letter, static_cast<long>(value));
  return std::string(1, letter) + number_text;
}

GcodeLine parse_line(const std::string& raw, int number, const std::string& source) {
  GcodeLine line;
  line.number = number;
  line.text = raw;
  if (!line.text.empty() && line.text.back() == '\r') line.text.pop_back();
  const std::string& s = line.text;
  std::vector<std::string> comments;
  std::size_t i = 0;
  const auto trimmed = [&]() {
    std::size_t a = s.find_first_not_of(" \t");
    return a == std::string::npos ? std::string() : s.substr(a);
  };
  if (trimmed() == "%") return line;  // program delimiter of some senders
  while (i < s.size()) {
    const char c = s[i];
    if (c == ' ' || c == '\t') {
      ++i;
      continue;
    }
    if (c == ';') {
      comments.push_back(s.substr(i));
      break;
    }
    if (c == '(') {
      const std::size_t close = s.find(')', i);
      if (close == std::string::npos)
        fail(source, number, fmt::format("comment '(' at column {} is not closed with ')'", i + 1));
      comments.push_back(s.substr(i, close - i + 1));
      i = close + 1;
      continue;
    }
    if (c == '*' || ((c == 'N' || c == 'n') && line.command.empty() && line.words.empty()))
      fail(source, number,
           "line numbers (N...) and checksums (*...) belong to a host's serial protocol, not to a "
           "program file; remove them");
    if (std::isalpha(static_cast<unsigned char>(c)) == 0)
      fail(source, number, fmt::format("unexpected character '{}' at column {}", c, i + 1));
    const char letter = static_cast<char>(std::toupper(static_cast<unsigned char>(c)));
    std::size_t j = i + 1;
    while (j < s.size() && (std::isdigit(static_cast<unsigned char>(s[j])) != 0 || s[j] == '.' ||
                            s[j] == '-' || s[j] == '+'))
      ++j;
    const std::string text = s.substr(i + 1, j - i - 1);
    double value = 0.0;
    const char* first = text.data();
    if (!text.empty() && text[0] == '+') ++first;
    const auto [end, ec] = std::from_chars(first, text.data() + text.size(), value);
    if (text.empty() || ec != std::errc() || end != text.data() + text.size() ||
        !std::isfinite(value))
      fail(source, number,
           text.empty() ? fmt::format("'{}' at column {} has no number", letter, i + 1)
                        : fmt::format("'{}{}' at column {} is not a number", letter, text, i + 1));
    if (letter == 'G' || letter == 'M' || letter == 'T') {
      if (!line.command.empty())
        fail(source, number,
             fmt::format("two commands on one line ({} and {}{}); write one per line", line.command,
                         letter, text));
      if (!line.words.empty())
        fail(source, number,
             fmt::format("the command {}{} must come first on the line", letter, text));
      line.command = command_name(letter, text, value);
      i = j;
      if (takes_text(line.command)) break;  // the rest is the command's text
      continue;
    }
    if (line.word(letter) != nullptr)
      fail(source, number, fmt::format("'{}' is given twice", letter));
    line.words.push_back({letter, value, s.substr(i, j - i)});
    i = j;
  }
  if (line.command.empty() && !line.words.empty())
    fail(source, number,
         fmt::format("'{}' without a command (G0/G1/...) before it", line.words.front().text));
  for (std::size_t k = 0; k < comments.size(); ++k)
    line.comment += (k > 0 ? " " : "") + comments[k];
  return line;
}

// ---- the interpreter both the rewrite and gcode_path run --------------------------------------

constexpr double kMm = 1e-3;   // m per mm
constexpr int kEDecimals = 5;  // of the emitted extrusion (mm of filament)

enum class MoveKind : std::uint8_t { kNone, kLinear, kArc };

// A move the program means, in machine coordinates (m): the logical position plus the G92 offset.
struct MeantMove {
  MoveKind kind = MoveKind::kNone;
  bool rapid = false;       // G0
  bool from_known = false;  // the start position is known
  Eigen::Vector3d from = Eigen::Vector3d::Zero();
  Eigen::Vector3d to = Eigen::Vector3d::Zero();
  // Arcs (XY plane): centre (z ignored), signed sweep (rad, + = counter-clockwise), radius.
  Eigen::Vector3d centre = Eigen::Vector3d::Zero();
  double sweep = 0.0;
  double radius = 0.0;
  [[nodiscard]] Eigen::Vector3d at(double f) const {
    if (kind == MoveKind::kLinear) return from + f * (to - from);
    const double a0 = std::atan2(from.y() - centre.y(), from.x() - centre.x());
    const double a = a0 + f * sweep;
    return {centre.x() + radius * std::cos(a), centre.y() + radius * std::sin(a),
            from.z() + f * (to.z() - from.z())};
  }
};

struct Interpreter {
  explicit Interpreter(const std::string& program_source) : source(program_source) {}
  const std::string& source;
  bool absolute = true;
  bool e_absolute = true;
  int plane = 17;
  std::array<std::optional<double>, 3> machine;  // m, per axis
  std::array<double, 3> offset{};                // machine = logical + offset (m)

  [[nodiscard]] bool known() const {
    return machine[0].has_value() && machine[1].has_value() && machine[2].has_value();
  }
  [[nodiscard]] Eigen::Vector3d position() const { return {*machine[0], *machine[1], *machine[2]}; }

  // Updates the modal state; returns the move the line means (kind kNone: no XYZ motion).
  MeantMove step(const GcodeLine& line) {
    MeantMove move;
    const std::string& c = line.command;
    if (c == "G20")
      fail(source, line.number,
           "inch units (G20) are not supported: write the program in millimetres (G21)");
    if (c == "G90") absolute = e_absolute = true;
    if (c == "G91") absolute = e_absolute = false;
    if (c == "M82") e_absolute = true;
    if (c == "M83") e_absolute = false;
    if (c == "G17" || c == "G18" || c == "G19") plane = std::stoi(c.substr(1));
    if (c == "G28") machine = {};  // homed: where the real tool is, no program position says
    if (c == "G92") set_position(line);
    if (c != "G0" && c != "G1" && c != "G2" && c != "G3") return move;
    const bool arc = c == "G2" || c == "G3";
    static constexpr std::array<char, 3> kAxes = {'X', 'Y', 'Z'};
    bool any = false;
    std::array<std::optional<double>, 3> target;
    for (std::size_t a = 0; a < 3; ++a) {
      const GcodeWord* w = line.word(kAxes[a]);
      target[a] = machine[a];
      if (w == nullptr) continue;
      any = true;
      if (absolute) {
        target[a] = w->value * kMm + offset[a];
      } else {
        if (!machine[a])
          fail(source, line.number,
               fmt::format("relative move of {} from an unknown position (the program starts or "
                           "homes (G28) without an absolute position for it)",
                           kAxes[a]));
        target[a] = *machine[a] + w->value * kMm;
      }
    }
    // An arc without an end point ends where it starts: a full circle (Marlin, RepRapFirmware).
    if (!any && !arc) return move;
    const bool was_known = known();
    const Eigen::Vector3d from = was_known ? position() : Eigen::Vector3d::Zero();
    for (std::size_t a = 0; a < 3; ++a)
      if (!target[a])
        fail(source, line.number,
             fmt::format("{} is unknown here (the program starts or homes (G28) without giving "
                         "it): give X, Y and Z in the first move",
                         kAxes[a]));
    move.to = {*target[0], *target[1], *target[2]};
    move.from = from;
    move.from_known = was_known;
    move.rapid = c == "G0";
    move.kind = MoveKind::kLinear;
    if (arc) make_arc(line, c == "G3", move);
    machine = target;
    return move;
  }

  void set_position(const GcodeLine& line) {
    static constexpr std::array<char, 3> kAxes = {'X', 'Y', 'Z'};
    const bool all = line.words.empty();
    for (std::size_t a = 0; a < 3; ++a) {
      const GcodeWord* w = line.word(kAxes[a]);
      if (w == nullptr && !all) continue;
      if (!machine[a])
        fail(source, line.number,
             fmt::format("G92 sets {} where the tool's position is unknown (before the first "
                         "absolute move, or after G28)",
                         kAxes[a]));
      offset[a] = *machine[a] - (w != nullptr ? w->value : 0.0) * kMm;
    }
  }

  void make_arc(const GcodeLine& line, bool ccw, MeantMove& move) const {
    if (plane != 17)
      fail(source, line.number,
           fmt::format("arcs are supported in the XY plane (G17) only; G{} is active", plane));
    if (!move.from_known)
      fail(source, line.number, "an arc from an unknown position (no absolute move before it)");
    const GcodeWord* i = line.word('I');
    const GcodeWord* j = line.word('J');
    const GcodeWord* r = line.word('R');
    const Eigen::Vector2d p0 = move.from.head<2>();
    const Eigen::Vector2d p1 = move.to.head<2>();
    Eigen::Vector2d centre;
    if (r != nullptr) {
      if (i != nullptr || j != nullptr)
        fail(source, line.number, "an arc gives both R and I/J; give one");
      const double radius = std::abs(r->value) * kMm;
      const Eigen::Vector2d chord = p1 - p0;
      const double d = chord.norm();
      if (d == 0.0) fail(source, line.number, "an R arc cannot be a full circle (use I/J)");
      if (d > 2.0 * radius * (1.0 + 1e-9))
        fail(source, line.number,
             fmt::format("arc radius R{} is shorter than half the distance to its end ({:.4f} mm)",
                         r->text.substr(1), d / kMm / 2.0));
      const double h = std::sqrt(std::max(0.0, radius * radius - d * d / 4.0));
      const Eigen::Vector2d mid = 0.5 * (p0 + p1);
      const Eigen::Vector2d left(-chord.y() / d, chord.x() / d);
      // Positive R: the shorter arc; the centre lies to the left of the chord for a
      // counter-clockwise short arc and to the right for a clockwise one.
      const double side = (ccw ? 1.0 : -1.0) * (r->value >= 0.0 ? 1.0 : -1.0);
      centre = mid + side * h * left;
    } else {
      if (i == nullptr && j == nullptr)
        fail(source, line.number,
             fmt::format("{} needs a centre (I/J) or a radius (R)", line.command));
      centre =
          p0 + Eigen::Vector2d(i != nullptr ? i->value : 0.0, j != nullptr ? j->value : 0.0) * kMm;
    }
    const double r0 = (p0 - centre).norm();
    const double r1 = (p1 - centre).norm();
    // The firmwares' own check (Marlin and LinuxCNC accept a few µm of rounding).
    if (std::abs(r1 - r0) > 0.01 * kMm + 1e-3 * r0)
      fail(source, line.number,
           fmt::format("the arc's end is {:.4f} mm from its centre but its start {:.4f} mm: not "
                       "a circle",
                       r1 / kMm, r0 / kMm));
    if (r0 <= 0.0) fail(source, line.number, "an arc of radius 0");
    const double a0 = std::atan2(p0.y() - centre.y(), p0.x() - centre.x());
    const double a1 = std::atan2(p1.y() - centre.y(), p1.x() - centre.x());
    double sweep = a1 - a0;
    if (ccw) {
      while (sweep <= 1e-12) sweep += 2.0 * M_PI;
    } else {
      while (sweep >= -1e-12) sweep -= 2.0 * M_PI;
    }
    move.kind = MoveKind::kArc;
    move.centre = {centre.x(), centre.y(), 0.0};
    move.radius = r0;
    move.sweep = sweep;
  }
};

// Chords of an arc whose sagitta stays within `sagitta` (m).
int arc_chords(const MeantMove& move, double sagitta) {
  const double ratio = std::clamp(1.0 - sagitta / move.radius, -1.0, 1.0);
  const double max_angle = std::max(2.0 * std::acos(ratio), 1e-4);
  return std::max(1, static_cast<int>(std::ceil(std::abs(move.sweep) / max_angle)));
}

double rounded(double v, int decimals) {
  const double scale = std::pow(10.0, decimals);
  return std::round(v * scale) / scale;
}

// Writes the rewritten program line by line.
struct Writer {
  Writer(const GcodeRewriteOptions& rewrite_options, const CompensationModels& compensation)
      : options(rewrite_options), models(compensation) {}
  const GcodeRewriteOptions& options;
  const CompensationModels& models;
  std::ostringstream out;
  GcodeRewriteStats stats;
  bool absolute = true;
  bool e_absolute = true;
  std::array<double, 3> out_offset{};  // controller's logical = commanded - out_offset (m)
  IkSeed seed;  // the calibrated IK answer at `commanded` (warm start of the next move)
  std::optional<Eigen::Vector3d> commanded;  // last commanded machine position (m)
  std::array<double, 3> last_emitted{};      // last emitted logical values (mm, rounded)
  double e = 0.0;                            // the program's absolute E

  void keep(const GcodeLine& line) { out << line.text << '\n'; }

  // ---- a controller whose axes are the actuators (GcodeAxes::kActuators) ----
  std::unique_ptr<Compensator> compensator;  // calibrated IK (and the nominal FK, for the stats)
  std::vector<GcodeActuatorAxis> axes;
  struct Node {
    double f = 0.0;              // fraction of the meant move
    Eigen::VectorXd readings;    // calibrated IK answer
    Eigen::VectorXd actuator_q;  // joint values (IK seed)
    Eigen::VectorXd passive;     // passive joints (IK and FK seed)
  };
  std::optional<Node> at;                // where the controller's axes were last sent
  std::vector<double> last_axis_values;  // last emitted axis values (rounded, absolute)
  double feed = std::numeric_limits<double>::quiet_NaN();  // the program's F (mm/min)

  [[nodiscard]] bool actuator_axes() const { return options.axes == GcodeAxes::kActuators; }

  int axis_decimals(const GcodeActuatorAxis& axis) const {
    return options.decimals + (axis.revolute ? 1 : 0);
  }

  Node solve(const GcodeLine& line, const Eigen::Vector3d& p, double f, const Node* near,
             const std::string& source) {
    TaskTarget t;
    t.pose.translation() = p;
    IkSeed warm;
    if (near != nullptr) warm = {near->actuator_q, near->passive};
    CompensatedTarget c = compensator->compensate(t, warm);
    if (!c.usable() && near != nullptr) c = compensator->compensate(t);  // again, cold
    if (!c.usable())
      fail(source, line.number,
           fmt::format("the point ({:.4f}, {:.4f}, {:.4f}) mm: {}", p.x() / kMm, p.y() / kMm,
                       p.z() / kMm, c.problem));
    stats.max_correction = std::max(stats.max_correction, (c.commanded.translation() - p).norm());
    return {f, c.ik.actuator_readings, c.ik.actuator_q, c.ik.passive};
  }

  // Largest distance, at 1/4, 1/2 and 3/4 of the piece a -> b, between the calibrated tool driven
  // along the linearly interpolated readings and the meant point there (infinite when the robot
  // does not assemble).
  double piece_deviation(const MeantMove& meant, const Node& a, const Node& b) const {
    const Mechanism& model = *models.model;
    double worst = 0.0;
    for (const double t : {0.25, 0.5, 0.75}) {
      const Eigen::VectorXd r = a.readings + t * (b.readings - a.readings);
      const Eigen::VectorXd passive = a.passive.size() == b.passive.size() && a.passive.size() > 0
                                          ? Eigen::VectorXd(a.passive + t * (b.passive - a.passive))
                                          : Eigen::VectorXd();
      const ForwardResult fk =
          forward_kinematics(model, models.calibrated, r, model.task.frame, passive);
      if (!fk.closure.ok()) return std::numeric_limits<double>::infinity();
      worst = std::max(worst, (fk.pose.translation() - meant.at(a.f + t * (b.f - a.f))).norm());
    }
    return worst;
  }

  // Appends the pieces that end after `a` up to `b` (bisected until each deviates less than the
  // tolerance), `b` last.
  void bisect(const GcodeLine& line, const MeantMove& meant, const Node& a, const Node& b,
              int depth, std::vector<Node>& pieces, const std::string& source) {
    const double deviation = piece_deviation(meant, a, b);
    if (deviation <= options.tolerance) {
      stats.max_deviation = std::max(stats.max_deviation, deviation);
      pieces.push_back(b);
      return;
    }
    if (depth >= 16)
      fail(source, line.number,
           fmt::format("cannot be compensated: the actuators' straight interpolation stays "
                       "{:.1f} um from the meant path even in 2^16 pieces (a singular "
                       "configuration near the path?)",
                       deviation * 1e6));
    const double f = 0.5 * (a.f + b.f);
    const Node mid = solve(line, meant.at(f), f, &a, source);
    bisect(line, meant, a, mid, depth + 1, pieces, source);
    bisect(line, meant, mid, b, depth + 1, pieces, source);
  }

  void emit_axes(const GcodeLine& line, const char* command, const Eigen::VectorXd& readings,
                 bool first, std::optional<double> e_value, std::optional<double> f_value) {
    out << command;
    for (std::size_t a = 0; a < axes.size(); ++a) {
      const int decimals = axis_decimals(axes[a]);
      const double v =
          rounded(readings[static_cast<Eigen::Index>(a)] * axes[a].unit_factor, decimals);
      const double value = absolute ? v : v - last_axis_values[a];
      out << fmt::format(" {}{:.{}f}", axes[a].letter, value == 0.0 ? 0.0 : value, decimals);
      last_axis_values[a] = v;
    }
    if (e_value) out << fmt::format(" E{:.{}f}", *e_value, kEDecimals);
    if (f_value) out << fmt::format(" F{:.3f}", *f_value);
    if (first)
      for (const auto& w : line.words) {
        bool axis = false;
        for (const auto& ax : axes) axis = axis || ax.letter == w.letter;
        if (!axis && std::string("XYZEIJRF").find(w.letter) == std::string::npos)
          out << ' ' << w.text;
      }
    if (first && !line.comment.empty()) out << ' ' << line.comment;
    out << '\n';
    ++stats.emitted_moves;
  }

  // The line's extrusion split over the pieces it is cut into. Relative pieces are differences of
  // rounded running sums, so they add up to the line's E exactly as written (no rounding drift
  // over hundreds of pieces).
  struct ExtrusionSplit {
    bool given = false;  // the line has an E word
    bool absolute = false;
    double start = 0.0;
    double end = 0.0;
    [[nodiscard]] std::optional<double> between(double f0, double f1) const {
      if (!given) return std::nullopt;
      const double de = end - start;
      return absolute ? start + f1 * de
                      : rounded(f1 * de, kEDecimals) - rounded(f0 * de, kEDecimals);
    }
  };

  [[nodiscard]] ExtrusionSplit split_extrusion(const GcodeLine& line) const {
    const GcodeWord* ew = line.word('E');
    if (ew == nullptr) return {false, e_absolute, e, e};
    return {true, e_absolute, e, e_absolute ? ew->value : e + ew->value};
  }

  void move_actuators(const GcodeLine& line, const MeantMove& meant, const std::string& source) {
    ++stats.moves;
    if (const GcodeWord* fw = line.word('F')) feed = fw->value;
    const ExtrusionSplit extrusion = split_extrusion(line);
    const char* command = meant.rapid ? "G0" : "G1";
    if (!meant.from_known || !at) {
      // Nothing to interpolate from: one point, and no feed (its distance is unknown).
      at = solve(line, meant.to, 1.0, nullptr, source);
      emit_axes(line, command, at->readings, true, extrusion.between(0.0, 1.0), std::nullopt);
      e = extrusion.end;
      return;
    }
    Node start = *at;
    start.f = 0.0;
    const Node end = solve(line, meant.to, 1.0, &start, source);
    std::vector<Node> pieces;
    bisect(line, meant, start, end, 0, pieces, source);
    Node previous = start;
    bool first = true;
    for (const Node& piece : pieces) {
      // The piece takes the time the program meant for it: its meant length at the program's
      // feed. The controller's F is the axes' rate over their combined (Euclidean) change.
      std::optional<double> f_value;
      if (std::isfinite(feed) && feed > 0.0) {
        const double tool_mm = (meant.at(piece.f) - meant.at(previous.f)).norm() / kMm;
        double axes_units = 0.0;
        for (std::size_t a = 0; a < axes.size(); ++a) {
          const double d = (piece.readings[static_cast<Eigen::Index>(a)] -
                            previous.readings[static_cast<Eigen::Index>(a)]) *
                           axes[a].unit_factor;
          axes_units += d * d;
        }
        if (tool_mm > 1e-9) f_value = feed * std::sqrt(axes_units) / tool_mm;
      }
      emit_axes(line, command, piece.readings, first, extrusion.between(previous.f, piece.f),
                f_value);
      first = false;
      previous = piece;
    }
    at = end;
    e = extrusion.end;
  }

  void emit(const GcodeLine& line, const char* command, const Eigen::Vector3d& c, bool first,
            std::optional<double> e_value) {
    out << command;
    static constexpr std::array<char, 3> kAxes = {'X', 'Y', 'Z'};
    for (std::size_t a = 0; a < 3; ++a) {
      const double logical =
          rounded(c[static_cast<Eigen::Index>(a)] / kMm - out_offset[a] / kMm, options.decimals);
      const double value = absolute ? logical : logical - last_emitted[a];
      out << fmt::format(" {}{:.{}f}", kAxes[a], value == 0.0 ? 0.0 : value, options.decimals);
      last_emitted[a] = logical;
    }
    if (e_value) out << fmt::format(" E{:.{}f}", *e_value, kEDecimals);
    if (first)
      for (const auto& w : line.words)
        if (std::string("XYZEIJR").find(w.letter) == std::string::npos) out << ' ' << w.text;
    if (first && !line.comment.empty()) out << ' ' << line.comment;
    out << '\n';
    ++stats.emitted_moves;
  }

  void move(const GcodeLine& line, const MeantMove& meant, const std::string& source) {
    ++stats.moves;
    const ExtrusionSplit extrusion = split_extrusion(line);
    const char* command = meant.rapid ? "G0" : "G1";
    if (!meant.from_known || !commanded) {
      // The first known position: nothing to interpolate from, one compensated point.
      const CompensatedTarget t = target(line, meant.to, source);
      commanded = t.commanded.translation();
      seed = {t.ik.actuator_q, t.ik.passive};
      emit(line, command, *commanded, true, extrusion.between(0.0, 1.0));
      e = extrusion.end;
      return;
    }
    const int chords =
        meant.kind == MoveKind::kArc ? arc_chords(meant, 0.5 * options.tolerance) : 1;
    SegmentOptions seg;
    seg.tolerance = meant.kind == MoveKind::kArc ? 0.5 * options.tolerance : options.tolerance;
    Eigen::Vector3d from = meant.from;
    bool first = true;
    double f_done = 0.0;
    for (int k = 1; k <= chords; ++k) {
      const double f_chord0 = static_cast<double>(k - 1) / chords;
      const double f_chord1 = static_cast<double>(k) / chords;
      const Eigen::Vector3d to = k == chords ? meant.to : meant.at(f_chord1);
      const CompensatedSegment piece = compensate_segment(models, from, *commanded, to, seg, seed);
      if (!piece.ok) fail(source, line.number, "cannot be compensated: " + piece.problem);
      stats.max_deviation = std::max(stats.max_deviation, piece.max_deviation);
      for (std::size_t p = 0; p < piece.commanded.size(); ++p) {
        const double f = f_chord0 + piece.fractions[p] * (f_chord1 - f_chord0);
        emit(line, command, piece.commanded[p], first, extrusion.between(f_done, f));
        first = false;
        f_done = f;
      }
      stats.max_correction = std::max(stats.max_correction, (piece.commanded.back() - to).norm());
      commanded = piece.commanded.back();
      seed = piece.end_seed;
      from = to;
    }
    e = extrusion.end;
  }

  CompensatedTarget target(const GcodeLine& line, const Eigen::Vector3d& p,
                           const std::string& source) {
    TaskTarget t;
    t.pose.translation() = p;
    CompensatedTarget c = compensate_target(models, t);
    if (!c.usable())
      fail(source, line.number,
           fmt::format("the point ({:.4f}, {:.4f}, {:.4f}) mm: {}", p.x() / kMm, p.y() / kMm,
                       p.z() / kMm, c.problem));
    stats.max_correction = std::max(stats.max_correction, (c.commanded.translation() - p).norm());
    return c;
  }

  // Modal lines the output keeps, mirrored in the writer's own state.
  void modal(const GcodeLine& line, const Interpreter& state) {
    const std::string& c = line.command;
    if (c == "G90" || c == "G91" || c == "M82" || c == "M83") {
      absolute = state.absolute;
      e_absolute = state.e_absolute;
    }
    if (c == "G28") {
      commanded.reset();
      seed = {};
      at.reset();
    }
    if (c == "G92" && actuator_axes()) {
      // The program's coordinate shift is in the meant positions already; the controller's axes
      // (actuators) keep their own positions. E is still reset as written.
      const GcodeWord* ew = line.word('E');
      if (ew != nullptr || line.words.empty()) e = ew != nullptr ? ew->value : 0.0;
      return;
    }
    if (c == "G92") {
      static constexpr std::array<char, 3> kAxes = {'X', 'Y', 'Z'};
      const bool all = line.words.empty();
      for (std::size_t a = 0; a < 3; ++a) {
        const GcodeWord* w = line.word(kAxes[a]);
        if (w == nullptr && !all) continue;
        const double v = (w != nullptr ? w->value : 0.0) * kMm;
        // The controller is at `commanded`; G92 makes its logical position v there.
        out_offset[a] = (*commanded)[static_cast<Eigen::Index>(a)] - v;
        last_emitted[a] = rounded(v / kMm, options.decimals);
      }
      const GcodeWord* ew = line.word('E');
      if (ew != nullptr || all) e = ew != nullptr ? ew->value : 0.0;
    }
  }
};

}  // namespace

GcodeProgram parse_gcode(const std::string& text, const std::string& source) {
  GcodeProgram program;
  program.source = source;
  std::size_t start = 0;
  int number = 0;
  while (start < text.size()) {
    std::size_t end = text.find('\n', start);
    if (end == std::string::npos) end = text.size();
    program.lines.push_back(parse_line(text.substr(start, end - start), ++number, source));
    start = end + 1;
  }
  return program;
}

GcodeRewrite rewrite_gcode(const GcodeProgram& program, const CompensationModels& models,
                           const GcodeRewriteOptions& options) {
  if (models.model == nullptr || models.model->task.type != TaskType::kPosition)
    throw core::InputError(fmt::format(
        "{}: G-code rewriting needs a robot whose task is a position (a printer-style robot); "
        "{} has another task type",
        program.source, models.model != nullptr ? models.model->name : "the robot"));
  if (options.axes == GcodeAxes::kUnknown)
    throw core::InputError(fmt::format(
        "{}: it is not known whether the controller of {} reads G-code X Y Z as the tool's "
        "position or as its actuators' positions",
        program.source, models.model->name));
  Interpreter state(program.source);
  Writer writer(options, models);
  if (writer.actuator_axes()) {
    writer.axes = gcode_actuator_axes(*models.model, models.nominal);
    writer.last_axis_values.assign(writer.axes.size(), 0.0);
    writer.compensator = std::make_unique<Compensator>(models);
  }
  for (const GcodeLine& line : program.lines) {
    const MeantMove meant = state.step(line);
    if (meant.kind == MoveKind::kNone) {
      if (const GcodeWord* fw = line.word('F');
          fw != nullptr && (line.command == "G0" || line.command == "G1"))
        writer.feed = fw->value;
      if (writer.actuator_axes() && line.command == "G92") {
        writer.modal(line, state);
        // Only E survives: the axes' G92 would redefine where the actuators are.
        const GcodeWord* ew = line.word('E');
        writer.out << (ew != nullptr        ? "G92 " + ew->text
                       : line.words.empty() ? std::string("G92 E0")
                                            : std::string("; G92"))
                   << " ; robocal: G92 X/Y/Z applied to the program's coordinates (the "
                      "controller's axes are the actuators)"
                   << (line.comment.empty() ? "" : " " + line.comment) << '\n';
        continue;
      }
      writer.modal(line, state);
      // E-only moves still advance the program's extrusion.
      const GcodeWord* ew = line.word('E');
      if ((line.command == "G0" || line.command == "G1") && ew != nullptr)
        writer.e = writer.e_absolute ? ew->value : writer.e + ew->value;
      writer.keep(line);
      continue;
    }
    if (writer.actuator_axes())
      writer.move_actuators(line, meant, program.source);
    else
      writer.move(line, meant, program.source);
  }
  return {writer.out.str(), writer.stats};
}

std::vector<GcodePathPoint> gcode_path(const GcodeProgram& program, double step) {
  Interpreter state(program.source);
  std::vector<GcodePathPoint> path;
  for (const GcodeLine& line : program.lines) {
    const MeantMove meant = state.step(line);
    if (meant.kind == MoveKind::kNone) continue;
    if (!meant.from_known) {
      path.push_back({meant.to, line.number});
      continue;
    }
    const double length =
        meant.kind == MoveKind::kArc
            ? std::hypot(std::abs(meant.sweep) * meant.radius, meant.to.z() - meant.from.z())
            : (meant.to - meant.from).norm();
    const int n = std::max(1, static_cast<int>(std::ceil(length / step)));
    for (int k = 1; k <= n; ++k)
      path.push_back({k == n ? meant.to : meant.at(static_cast<double>(k) / n), line.number});
  }
  return path;
}

}  // namespace robocal::calib
