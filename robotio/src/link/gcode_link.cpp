#include "robocal/robotio/gcode_link.hpp"

#include "robocal/robotio/link_error.hpp"
#include "robocal/robotio/motion_profile.hpp"
#include "robocal/robotio/native_delta.hpp"

#include <fmt/core.h>

#include <cmath>
#include <numbers>
#include <stdexcept>
#include <thread>
#include <utility>

namespace robocal::robotio {
namespace {

using std::chrono::milliseconds;

// A line a firmware would never send: control characters other than tab (noise on the wire,
// a wrong baud rate).
bool is_garbage(const std::string& line) {
  for (const char c : line) {
    const auto u = static_cast<unsigned char>(c);
    if ((u < 32 && c != '\t') || u == 127) return true;
  }
  return false;
}

}  // namespace

std::optional<GcodeMode> gcode_mode_from_string(const std::string& word) {
  if (word == "auto") return GcodeMode::kAuto;
  if (word == "native") return GcodeMode::kNativeDelta;
  if (word == "raw") return GcodeMode::kRawAxes;
  return std::nullopt;
}

std::optional<GeometryChoice> geometry_choice_from_string(const std::string& word) {
  if (word == "ask") return GeometryChoice::kAsk;
  if (word == "firmware") return GeometryChoice::kFirmware;
  if (word == "robot-file") return GeometryChoice::kRobotFile;
  return std::nullopt;
}

ActuatorAxes axes_for_robot(const calib::Mechanism& model, double steps_per_mm,
                            double steps_per_degree) {
  static const std::string kLetters = "XYZUVWABC";
  if (model.actuated.size() > kLetters.size())
    throw std::invalid_argument(model.name + ": more than 9 actuators cannot be G-code axes");
  // Readings in encoder counts (the wire robot's branch) reach G-code through the robot file's
  // nominal encoder scale: the firmware's axes are in millimetres and degrees of the joint.
  const Eigen::VectorXd scale = calib::encoder_scales(model, model.nominal_parameters());
  ActuatorAxes axes;
  for (std::size_t i = 0; i < model.actuated.size(); ++i) {
    axes.letters.push_back(kLetters[i]);
    const bool prismatic = model.bodies[model.actuated[i]].joint == calib::JointType::kPrismatic;
    axes.unit_factor.push_back((prismatic ? 1000.0 : 180.0 / std::numbers::pi) *
                               scale[static_cast<Eigen::Index>(i)]);
    axes.steps_per_unit.push_back(prismatic ? steps_per_mm : steps_per_degree);
  }
  return axes;
}

GcodeLink::GcodeLink(SafetyGuard& guard, const GcodeLinkOptions& options)
    : GcodeLink(guard, options, make_transport(options.address, options.baud)) {}

GcodeLink::GcodeLink(SafetyGuard& guard, GcodeLinkOptions options,
                     std::unique_ptr<Transport> transport)
    : RobotLink(guard), options_(std::move(options)), transport_(std::move(transport)) {
  if (options_.axes.size() != static_cast<int>(guard.model().actuated.size()))
    throw std::invalid_argument("GcodeLink: axis count differs from the robot's actuators");
  status_.device = transport_->device();
}

GcodeLink::~GcodeLink() = default;

std::vector<long> axis_counts(const ActuatorAxes& axes, const Eigen::VectorXd& readings) {
  std::vector<long> c(static_cast<std::size_t>(axes.size()));
  for (int i = 0; i < axes.size(); ++i) {
    const auto k = static_cast<std::size_t>(i);
    c[k] = std::lround(readings[i] * axes.unit_factor[k] * axes.steps_per_unit[k]);
  }
  return c;
}

std::vector<long> GcodeLink::counts_for(const Eigen::VectorXd& readings) const {
  if (native_) return delta_counts(*native_, readings);
  if (options_.mode == GcodeMode::kNativeDelta)
    throw LinkError(status_.device, "native delta mode: the firmware's geometry is not read yet");
  return axis_counts(options_.axes, readings);
}

// Marlin lists its delta settings in M503; RepRapFirmware answers M665 and M666 without
// parameters. A firmware that is not a delta says no such thing.
std::optional<DeltaGeometry> GcodeLink::query_delta_geometry(std::string& said) {
  const milliseconds total = options_.reply_timeout * (options_.attempts + 1);
  const Firmware fw = status_.firmware.firmware;
  std::vector<std::string> lines;
  std::optional<DeltaGeometry> g;
  try {
    if (fw == Firmware::kRepRapFirmware) {
      lines = exchange("M665", options_.reply_timeout, total, false);
      const std::vector<std::string> m666 = exchange("M666", options_.reply_timeout, total, false);
      g = parse_rrf_delta_settings(lines, m666);
    } else {
      lines = exchange("M503", options_.reply_timeout, total, false);
      g = parse_marlin_delta_settings(lines);
    }
  } catch (const LinkError& e) {
    // A firmware without delta kinematics may refuse the query outright.
    if (!transport_->is_open()) throw;
    lines = {status_.last_error.empty() ? e.controller_said() : status_.last_error};
  }
  said = lines.empty() ? last_line_ : lines.back();
  return g;
}

// The robot file must be a linear delta its firmware computes (raw axes otherwise, in kAuto);
// the firmware's geometry is compared with the file's before anything moves.
void GcodeLink::read_native_geometry() {
  const calib::Mechanism& model = guard().model();
  const RobotFileDelta file = robot_file_delta(model);
  const bool wanted = options_.mode == GcodeMode::kNativeDelta;
  if (!wanted && (!file.problem.empty() || model.controller.gcode_axes != calib::GcodeAxes::kTool))
    return;
  if (!file.problem.empty() || options_.axes.size() != 3) {
    status_.state = LinkState::kFault;
    throw LinkError(status_.device, file.problem);
  }
  std::string said;
  const std::optional<DeltaGeometry> geometry = query_delta_geometry(said);
  if (!geometry && !wanted) return;  // reconfigured to one axis per motor: raw-axis mode
  if (!geometry) {
    status_.state = LinkState::kFault;
    const bool rrf = status_.firmware.firmware == Firmware::kRepRapFirmware;
    throw LinkError(status_.device,
                    fmt::format("{} reports no delta geometry ({} names no M665 delta settings): "
                                "the printer is not a delta, so firmware-native delta mode cannot "
                                "drive it (raw-axis mode drives one G-code axis per motor)",
                                to_string(status_.firmware.firmware), rrf ? "M665" : "M503"),
                    said);
  }
  try {
    native_ = robotio::native_frame(*geometry, model, options_.axes.steps_per_unit[0],
                                    options_.geometry, status_.device, disagreements_);
  } catch (const LinkError&) {
    status_.state = LinkState::kFault;
    throw;
  }
}

FirmwareInfo GcodeLink::connect() {
  for (int round = 0;; ++round) {
    try {
      if (round > 0) std::this_thread::sleep_for(milliseconds(250));
      transport_->open();
      handshake();
      FirmwareInfo info = identify();
      if (options_.mode != GcodeMode::kRawAxes) read_native_geometry();
      status_.state = LinkState::kIdle;
      set_last_known(do_read().values);
      return info;
    } catch (const LinkError&) {
      // A connection lost while identifying is retried; anything the controller said is final.
      if (transport_->is_open() || round >= options_.reconnect_attempts) throw;
    }
  }
}

void GcodeLink::disconnect() {
  transport_->close();
  status_.state = LinkState::kDisconnected;
}

// Line numbers restart at 0 on every (re)connection: the firmware's count is unknown after a
// loss, and M110 is the documented way to set it.
void GcodeLink::handshake() {
  // A board that resets on open prints its banner first; let it finish (bounded) and drop it.
  const auto settle = Clock::now() + milliseconds(100);
  while (const auto line = transport_->read_line(settle)) {
    if (auto fw = parse_firmware_line(*line); fw && status_.firmware.firmware == Firmware::kUnknown)
      status_.firmware = *fw;
  }
  transport_->drain();
  stale_oks_ = 0;
  line_number_ = -1;  // exchange numbers "M110 N0" itself: the firmware expects N0 next
  exchange("M110 N0", options_.reply_timeout, options_.reply_timeout * (options_.attempts + 1),
           false);
  line_number_ = 0;
}

FirmwareInfo GcodeLink::identify() {
  const std::vector<std::string> lines =
      exchange("M115", options_.reply_timeout, options_.identify_timeout, false);
  std::optional<FirmwareInfo> found;
  for (const std::string& l : lines)
    if (auto fw = parse_firmware_line(l)) found = fw;
  if (!found) {
    status_.state = LinkState::kFault;
    throw LinkError(status_.device,
                    "M115 named no firmware (expected a FIRMWARE_NAME: report from Marlin or "
                    "RepRapFirmware)",
                    lines.empty() ? last_line_ : lines.back());
  }
  if (found->firmware == Firmware::kUnknown && !options_.accept_unknown_firmware) {
    status_.state = LinkState::kFault;
    throw LinkError(status_.device,
                    "unknown firmware \"" + found->name +
                        "\": only Marlin and RepRapFirmware dialects are supported",
                    found->raw);
  }
  status_.firmware = *found;
  if (sends_busy(found->firmware))
    exchange(fmt::format("M113 S{}", options_.keepalive.count()), options_.reply_timeout,
             options_.reply_timeout * (options_.attempts + 1), false);
  exchange("G90", options_.reply_timeout, options_.reply_timeout * (options_.attempts + 1), false);
  return *found;
}

void GcodeLink::reconnect() {
  std::string why;
  for (int attempt = 0; attempt < options_.reconnect_attempts; ++attempt) {
    if (attempt > 0) std::this_thread::sleep_for(milliseconds(250));
    try {
      transport_->open();
      handshake();
      ++status_.reconnects;
      status_.state = LinkState::kIdle;
      return;
    } catch (const LinkError& e) {
      why = e.what();
      transport_->close();
    }
  }
  status_.state = LinkState::kDisconnected;
  throw LinkError(status_.device, fmt::format("reconnect failed after {} attempts: {}",
                                              options_.reconnect_attempts, why));
}

std::vector<std::string> GcodeLink::command(const std::string& gcode, milliseconds silence_timeout,
                                            milliseconds total_timeout) {
  return exchange(gcode, silence_timeout, total_timeout, false);
}

// One command and its ok. See the header for the protocol rules; the numbered line is kept so a
// timeout re-sends exactly the same bytes (the firmware's line-number check then tells whether
// it had already executed them).
std::vector<std::string> GcodeLink::exchange(const std::string& gcode, milliseconds silence_timeout,
                                             milliseconds total_timeout, bool interruptible,
                                             Clock::time_point quiet_until) {
  long number = ++line_number_;
  std::string text = numbered_line(number, gcode);
  int attempts = 1;
  ++status_.commands;
  transport_->write_line(text);
  std::vector<std::string> lines;
  std::string error_text;
  const auto total_deadline = Clock::now() + total_timeout;
  // A blocking command's ok cannot come before the motion ends: silence is only suspicious
  // after `quiet_until`.
  auto silence_deadline = std::max(Clock::now(), quiet_until) + silence_timeout;
  auto give_up = [&](const std::string& problem) {
    status_.last_error = problem;
    throw LinkError(status_.device, problem, last_line_);
  };
  auto retry = [&](bool new_number) {
    if (++attempts > options_.attempts)
      give_up(fmt::format("'{}' failed {} times{}", gcode, options_.attempts,
                          error_text.empty() ? "" : ": " + error_text));
    if (new_number) {
      number = ++line_number_;
      text = numbered_line(number, gcode);
    }
    transport_->write_line(text);
    silence_deadline = Clock::now() + silence_timeout;
  };
  for (;;) {
    if (interruptible && guard().stop_requested()) {
      send_stop_during_wait();
      interrupted("'" + gcode + "'");
    }
    const auto now = Clock::now();
    const auto slice = std::min({silence_deadline, total_deadline, now + milliseconds(50)});
    const std::optional<std::string> line = transport_->read_line(slice);
    if (!line) {
      if (Clock::now() >= total_deadline)
        give_up(fmt::format("'{}' not finished within {:.1f} s", gcode,
                            static_cast<double>(total_timeout.count()) / 1000.0));
      if (Clock::now() >= silence_deadline) {
        ++status_.timeouts;
        retry(false);  // same number: a duplicate is detected by the firmware
      }
      continue;
    }
    last_line_ = *line;
    silence_deadline = std::max(silence_deadline, Clock::now() + silence_timeout);
    if (is_garbage(*line)) {
      ++status_.garbage;
      continue;
    }
    const Reply r = classify_reply(*line);
    switch (r.kind) {
      case ReplyKind::kOk:
        if (stale_oks_ > 0) {
          --stale_oks_;
          continue;
        }
        if (!error_text.empty()) {
          // "Error:..." then "ok" without a resend request: the command was received and not
          // executed. Transient refusals are retried as a new line.
          retry(true);
          error_text.clear();
          continue;
        }
        return lines;
      case ReplyKind::kBusy:
        ++status_.busy_lines;
        continue;
      case ReplyKind::kResend:
        ++status_.resends;
        error_text.clear();
        ++stale_oks_;  // the firmware follows a resend request with an ok of its own
        if (r.resend_line == number) {
          retry(false);
          continue;
        }
        if (r.resend_line == number + 1) return lines;  // it already had this line (lost ok)
        give_up(fmt::format("controller asks to resend line {} while line {} was the last sent",
                            r.resend_line, number));
        break;
      case ReplyKind::kError:
        ++status_.errors;
        error_text = r.text;
        status_.last_error = r.text;
        continue;
      case ReplyKind::kFatal:
        status_.state = LinkState::kFault;
        give_up("controller halted (reset it before reconnecting)");
        break;
      case ReplyKind::kEcho:
      case ReplyKind::kTemperature:
        ++status_.unsolicited;
        lines.push_back(r.text);
        continue;
      case ReplyKind::kPosition:
      case ReplyKind::kFirmware:
      case ReplyKind::kOther:
        lines.push_back(r.text);
        continue;
    }
  }
}

void GcodeLink::send_stop_during_wait() {
  // The command being waited for still owes its ok; the stop's own exchange must not take it.
  ++stale_oks_;
  try {
    do_stop(StopKind::kControlled);
  } catch (const LinkError&) {
    // The stop was written; its acknowledgement is not needed to stop the robot. The caller
    // reports the interruption either way.
  }
}

void GcodeLink::do_stop(StopKind kind) {
  const std::string quick = quick_stop_command(status_.firmware.firmware);
  if (kind == StopKind::kControlled && !quick.empty()) {
    exchange(quick, options_.reply_timeout, options_.reply_timeout * (options_.attempts + 1),
             false);
    status_.state = LinkState::kStopped;
    return;
  }
  // Emergency stop, or a firmware without a controlled stop (RRF): M112 unnumbered, which every
  // firmware's emergency parser acts on at once.
  transport_->write_line(emergency_stop_command());
  stale_oks_ = 0;
  status_.state = LinkState::kFault;
  if (kind == StopKind::kControlled) {
    // RRF restarts with M999; the line count starts again.
    transport_->write_line("M999");
    std::this_thread::sleep_for(milliseconds(200));
    handshake();
    status_.state = LinkState::kStopped;
  }
}

std::string GcodeLink::move_gcode(const Eigen::VectorXd& target, const MoveSpeed& speed,
                                  double gcode_per_joint) const {
  const std::vector<long> counts = counts_for(target);
  std::string cmd = "G1";
  for (int i = 0; i < options_.axes.size(); ++i) {
    const auto k = static_cast<std::size_t>(i);
    // The quantised target: the firmware rounds it back to exactly these counts.
    cmd += fmt::format(" {}{:.6f}", options_.axes.letters[k],
                       static_cast<double>(counts[k]) / options_.axes.steps_per_unit[k]);
  }
  cmd += fmt::format(" F{:.3f}", speed.speed * gcode_per_joint * 60.0);
  return cmd;
}

double GcodeLink::gcode_per_joint_unit(const Eigen::VectorXd& from,
                                       const Eigen::VectorXd& to) const {
  if (native_ && from.size() == to.size())
    return native_gcode_per_joint(*native_, from, to, guard().joint_per_reading());
  const std::vector<double>& f = options_.axes.unit_factor;
  const Eigen::VectorXd& j = guard().joint_per_reading();
  if (from.size() != to.size() || static_cast<std::size_t>(to.size()) != f.size())
    return std::abs(f[0]) / j[0];
  double joint = 0.0, gcode = 0.0;
  for (Eigen::Index i = 0; i < to.size(); ++i) {
    const double d = to[i] - from[i];
    joint += d * d * j[i] * j[i];
    gcode += d * d * f[static_cast<std::size_t>(i)] * f[static_cast<std::size_t>(i)];
  }
  return joint > 0.0 ? std::sqrt(gcode / joint) : std::abs(f[0]) / j[0];
}

void GcodeLink::do_home() {
  status_.state = LinkState::kMoving;
  exchange("G28", settle_silence(), milliseconds(120000), true);
  exchange("M400", settle_silence(), milliseconds(120000), true);
  status_.state = LinkState::kIdle;
}

void GcodeLink::do_move(const Eigen::VectorXd& target, const MoveSpeed& speed) {
  status_.state = LinkState::kMoving;
  // The firmware applies feed and acceleration to the G-code path's length; scaled by this move's
  // ratio of G-code to joint length, it takes as long as `speed` along the joints (axes in degrees
  // and millimetres together would otherwise take several times what the link waits).
  const double per_joint = gcode_per_joint_unit(last_known(), target);
  const double accel = speed.acceleration * per_joint;
  const milliseconds total = options_.reply_timeout * (options_.attempts + 1);
  for (int round = 0;; ++round) {
    try {
      Eigen::VectorXd from = last_known();
      if (round > 0) {
        // Connection lost mid-command: the move may or may not have reached the controller.
        // Look before re-issuing it, so it is neither lost nor executed twice.
        reconnect();
        acceleration_sent_ = -1.0;
        exchange("M400", settle_silence(), milliseconds(120000), true);
        const ActuatorReadings now = do_read();
        if (at_target(now, target)) return;
        // Native segments stop on the checked line: the rest of it starts where they stopped.
        from = now.values;
      }
      if (std::abs(accel - acceleration_sent_) > 1e-9 * accel) {
        exchange(fmt::format("M204 S{:.3f}", accel), options_.reply_timeout, total, true);
        acceleration_sent_ = accel;
      }
      if (native_) {
        for (const std::string& g :
             native_move_gcodes(*native_, from, target, speed, guard().joint_per_reading(),
                                options_.native_segment, status_.device))
          exchange(g, options_.reply_timeout, total, true);
        return;
      }
      exchange(move_gcode(target, speed, per_joint), options_.reply_timeout, total, true);
      return;
    } catch (const LinkError&) {
      // A refusal by a connected controller is final; a lost connection is recovered.
      if (transport_->is_open() || round >= options_.reconnect_attempts) throw;
    }
  }
}

// Silence allowed while waiting for M400: Marlin sends busy: every keep-alive interval, RRF
// says nothing until the motion ends.
milliseconds GcodeLink::settle_silence() const {
  return options_.reply_timeout + std::chrono::duration_cast<milliseconds>(options_.keepalive);
}

void GcodeLink::do_wait_settled(milliseconds timeout) {
  const milliseconds silence = settle_silence();
  const auto motion_end =
      Clock::now() + milliseconds(static_cast<long>(1000.0 * expected_move_seconds_));
  // The motion gets `timeout`; recovering a lost ok may add one silence period.
  const milliseconds total = timeout + silence;
  for (int round = 0;; ++round) {
    try {
      if (round > 0) reconnect();
      exchange("M400", silence, total, true, motion_end);
      break;
    } catch (const MotionInterrupted&) {
      throw;
    } catch (const LinkError& e) {
      if (!transport_->is_open() && round < options_.reconnect_attempts) continue;
      if (transport_->is_open() &&
          std::string(e.what()).find("not finished within") != std::string::npos) {
        // Stalled: stop the robot rather than leave a move running that nobody waits for.
        send_stop_during_wait();
        status_.state = LinkState::kStopped;
        throw LinkError(status_.device,
                        fmt::format("move did not settle within {:.1f} s (stalled?): sent the "
                                    "controller's stop",
                                    static_cast<double>(total.count()) / 1000.0),
                        last_line_);
      }
      throw;
    }
  }
  status_.state = LinkState::kIdle;
}

ActuatorReadings GcodeLink::parse_readings(const std::vector<std::string>& lines) const {
  const bool native = native_.has_value();
  // Marlin names a delta's counts by tower (A B C); RRF lists them in motor order.
  const std::string count_letters =
      native && native_->geometry.firmware == Firmware::kMarlin ? "ABC" : "";
  for (auto it = lines.rbegin(); it != lines.rend(); ++it) {
    const auto report = parse_position_report(*it, options_.axes.letters, count_letters);
    if (!report) continue;
    ActuatorReadings r;
    r.counts = report->counts;
    if (native) {
      r.values = delta_readings(*native_, r.counts);
      return r;
    }
    r.values.resize(options_.axes.size());
    for (int i = 0; i < options_.axes.size(); ++i) {
      const auto k = static_cast<std::size_t>(i);
      r.values[i] = static_cast<double>(r.counts[k]) / options_.axes.steps_per_unit[k] /
                    options_.axes.unit_factor[k];
    }
    return r;
  }
  return {};
}

ActuatorReadings GcodeLink::do_read() {
  const milliseconds total = options_.reply_timeout * (options_.attempts + 1);
  std::string said;
  for (int attempt = 0; attempt < options_.attempts; ++attempt) {
    std::vector<std::string> lines;
    try {
      lines = exchange("M114", options_.reply_timeout, total, false);
    } catch (const LinkError&) {
      if (transport_->is_open()) throw;
      reconnect();
      continue;  // a failed reconnect throws from reconnect() itself
    }
    ActuatorReadings r = parse_readings(lines);
    if (!r.counts.empty()) return r;
    // A corrupted or partial report: ask again rather than guess.
    said = lines.empty() ? last_line_ : lines.back();
  }
  throw LinkError(status_.device,
                  fmt::format("no readable M114 position with stepper counts for axes {} after "
                              "{} attempts",
                              options_.axes.letters, options_.attempts),
                  said);
}

bool GcodeLink::at_target(const ActuatorReadings& readings, const Eigen::VectorXd& target) const {
  return !readings.counts.empty() && readings.counts == counts_for(target);
}

double GcodeLink::expected_seconds(const Eigen::VectorXd& from, const Eigen::VectorXd& to,
                                   const MoveSpeed& speed) const {
  // The firmware's trapezoid in G-code units is this one scaled by gcode_per_joint_unit.
  double s = 0.0;
  if (native_) {
    s = native_expected_seconds(from, to, speed, guard().joint_per_reading(),
                                options_.native_segment);
  } else {
    const double length = (to - from).cwiseProduct(guard().joint_per_reading()).norm();
    s = trapezoid_seconds(length, speed.speed, speed.acceleration);
  }
  expected_move_seconds_ = s;
  return s;
}

}  // namespace robocal::robotio
