#include "robocal/robotio/klipper_link.hpp"

#include "robocal/robotio/link_error.hpp"
#include "robocal/robotio/native_delta.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <thread>

namespace robocal::robotio {
namespace {

using std::chrono::milliseconds;

constexpr int kMoonrakerPort = 7125;
const std::vector<std::string> kSteppers = {"stepper_a", "stepper_b", "stepper_c"};

// "moonraker:HOST" or "moonraker:HOST:PORT".
bool split_address(const std::string& address, std::string& host, int& port) {
  const std::string prefix = "moonraker:";
  if (address.rfind(prefix, 0) != 0) return false;
  std::string rest = address.substr(prefix.size());
  port = kMoonrakerPort;
  const auto colon = rest.rfind(':');
  if (colon != std::string::npos) {
    try {
      std::size_t used = 0;
      port = std::stoi(rest.substr(colon + 1), &used);
      if (used != rest.size() - colon - 1 || port <= 0 || port > 65535) return false;
    } catch (const std::exception&) {
      return false;
    }
    rest.resize(colon);
  }
  host = rest;
  return !host.empty();
}

}  // namespace

bool is_moonraker_address(const std::string& address) {
  return address.rfind("moonraker:", 0) == 0;
}

KlipperLink::KlipperLink(SafetyGuard& guard, const GcodeLinkOptions& options)
    : RobotLink(guard), options_(options) {
  if (!split_address(options.address, host_, port_))
    throw LinkError(options.address,
                    "a Moonraker address is moonraker:HOST or moonraker:HOST:PORT");
  status_.device = fmt::format("Moonraker at {}:{}", host_, port_);
}

std::string KlipperLink::klippy_problem() {
  const auto deadline = Clock::now() + options_.identify_timeout;
  const nlohmann::json server = client_->call("server.info", nullptr, deadline);
  const std::string state = server.value("klippy_state", "");
  if (!server.value("klippy_connected", false) || state == "disconnected")
    return "Moonraker is not connected to Klipper (klippy_state: disconnected): is the klipper "
           "service running?";
  if (state == "ready") return "";
  // printer.info carries Klipper's own words on why it is not ready.
  std::string message;
  try {
    const nlohmann::json printer = client_->call("printer.info", nullptr, deadline);
    message = printer.value("state_message", "");
  } catch (const LinkError&) {
    message = "";
  }
  return fmt::format(
      "Klipper is not ready (state '{}'){}{}; nothing moved. Once the cause is "
      "fixed, FIRMWARE_RESTART brings it back",
      state, message.empty() ? "" : ": ", message.substr(0, message.find('\n')));
}

void KlipperLink::open_and_check() {
  client_ = std::make_unique<MoonrakerClient>(host_, port_);
  client_->open(Clock::now() + options_.identify_timeout);
  const std::string problem = klippy_problem();
  if (problem.empty()) klippy_said_.clear();  // ready again (after a FIRMWARE_RESTART)
  if (!problem.empty()) {
    status_.state = LinkState::kFault;
    status_.last_error = problem;
    throw LinkError(status_.device, problem);
  }
}

FirmwareInfo KlipperLink::connect() {
  for (int round = 0;; ++round) {
    try {
      if (round > 0) std::this_thread::sleep_for(milliseconds(250));
      open_and_check();
      break;
    } catch (const LinkError&) {
      // A connection that fails to open is retried; anything Klipper said is final.
      if ((client_ && client_->is_open()) || round >= options_.reconnect_attempts) throw;
    }
  }
  const auto deadline = Clock::now() + options_.identify_timeout;
  const nlohmann::json printer = client_->call("printer.info", nullptr, deadline);
  FirmwareInfo info;
  info.firmware = Firmware::kKlipper;
  info.version = printer.value("software_version", "");
  info.name = "Klipper " + info.version;
  info.raw = printer.dump();
  status_.firmware = info;

  const nlohmann::json query = client_->call(
      "printer.objects.query",
      {{"objects", {{"configfile", {"settings"}}, {"toolhead", {"homed_axes"}}}}}, deadline);
  const nlohmann::json status = query.value("status", nlohmann::json::object());
  const nlohmann::json settings = status.contains("configfile")
                                      ? status["configfile"].value("settings", nlohmann::json())
                                      : nlohmann::json();
  const KlipperPrinter p = klipper_printer_from_settings(settings);
  if (!p.problem.empty()) {
    status_.state = LinkState::kFault;
    throw LinkError(status_.device,
                    "the printer cannot be driven in Klipper's delta kinematics: " + p.problem);
  }
  try {
    frame_ = robotio::native_frame(*p.delta, guard().model(), p.steps_per_mm, options_.geometry,
                                   status_.device, disagreements_);
  } catch (const LinkError&) {
    status_.state = LinkState::kFault;
    throw;
  }
  status_.state = LinkState::kIdle;
  // Already homed: the microcontroller counts at the endstops follow from any position.
  const std::string homed = status.contains("toolhead")
                                ? status["toolhead"].value("homed_axes", std::string())
                                : std::string();
  if (homed == "xyz") {
    if (const auto position = get_position())
      mcu_at_endstop_ = klipper_mcu_at_endstop(*frame_, *position);
    set_last_known(do_read().values);
  }
  return info;
}

void KlipperLink::disconnect() {
  if (client_) client_->close();
  status_.state = LinkState::kDisconnected;
}

void KlipperLink::reconnect() {
  for (int round = 0;; ++round) {
    try {
      std::this_thread::sleep_for(milliseconds(250));
      open_and_check();
      ++status_.reconnects;
      return;
    } catch (const LinkError&) {
      if ((client_ && client_->is_open()) || round >= options_.reconnect_attempts) throw;
    }
  }
}

void KlipperLink::check_notifications(std::vector<std::string>* responses) {
  for (MoonrakerNotification& n : client_->take_notifications()) {
    if (n.method == "notify_gcode_response" && n.params.is_array() && !n.params.empty() &&
        n.params[0].is_string()) {
      if (responses) responses->push_back(n.params[0].get<std::string>());
    } else if (n.method == "notify_klippy_shutdown") {
      klippy_said_ = "Klippy shut down";
      mcu_at_endstop_.reset();
    } else if (n.method == "notify_klippy_disconnected") {
      klippy_said_ = "Moonraker lost its connection to Klippy";
      mcu_at_endstop_.reset();
    } else {
      ++status_.unsolicited;
    }
  }
}

std::vector<std::string> KlipperLink::script(const std::string& gcode, milliseconds timeout,
                                             bool interruptible) {
  if (!client_ || !client_->is_open()) reconnect();
  ++status_.commands;
  std::vector<std::string> responses;
  const auto deadline = Clock::now() + timeout;
  try {
    const long id = client_->send("printer.gcode.script", {{"script", gcode}});
    for (;;) {
      // Every 50 ms a stop request is looked at (RobotLink's contract for a move's wait).
      const auto slice = std::min(deadline, Clock::now() + milliseconds(50));
      if (client_->answer(id, "printer.gcode.script", slice)) break;
      if (interruptible && guard().stop_requested()) {
        do_stop(StopKind::kEmergency);
        interrupted("move");
      }
      if (Clock::now() >= deadline) {
        ++status_.timeouts;
        throw LinkError(status_.device, fmt::format("Klipper did not finish '{}' within {:.1f} s",
                                                    gcode.substr(0, gcode.find('\n')),
                                                    static_cast<double>(timeout.count()) / 1000.0));
      }
    }
  } catch (const MoonrakerError& e) {
    ++status_.errors;
    check_notifications(&responses);
    status_.last_error = e.controller_said();
    if (!klippy_said_.empty()) status_.state = LinkState::kFault;
    throw LinkError(status_.device,
                    fmt::format("Klipper refused '{}'{}", gcode.substr(0, gcode.find('\n')),
                                klippy_said_.empty() ? "" : " (" + klippy_said_ + ")"),
                    e.controller_said());
  }
  check_notifications(&responses);
  return responses;
}

std::optional<KlipperPosition> KlipperLink::get_position() {
  std::vector<std::string> responses = script("GET_POSITION", options_.reply_timeout * 4, false);
  // Klipper prints the position before its "ok": a response still on the way is waited for.
  const auto deadline = Clock::now() + options_.reply_timeout;
  while (!parse_get_position(responses, kSteppers) && client_->wait_notification(deadline))
    check_notifications(&responses);
  return parse_get_position(responses, kSteppers);
}

void KlipperLink::do_home() {
  status_.state = LinkState::kMoving;
  script("G28\nM400", milliseconds(120000), true);
  const auto position = get_position();
  if (!position)
    throw LinkError(status_.device, "GET_POSITION after homing gave no stepper counts");
  mcu_at_endstop_ = klipper_mcu_at_endstop(*frame_, *position);
  status_.state = LinkState::kIdle;
}

void KlipperLink::do_move(const Eigen::VectorXd& target, const MoveSpeed& speed) {
  if (!mcu_at_endstop_)
    throw MotionRefused(
        "move refused: Klipper has not homed the printer since it (re)started, so "
        "where the carriages are is unknown: home first");
  status_.state = LinkState::kMoving;
  const Eigen::VectorXd& j = guard().joint_per_reading();
  const double accel =
      speed.acceleration * native_gcode_per_joint(*frame_, last_known(), target, j);
  for (int round = 0;; ++round) {
    try {
      Eigen::VectorXd from = last_known();
      if (round > 0) {
        // The connection was lost mid-script: the move may or may not have run. Look first, so
        // it is neither lost nor done twice.
        reconnect();
        const ActuatorReadings now = do_read();
        if (at_target(now, target)) return;
        from = now.values;
      }
      std::string gcode = fmt::format("SET_VELOCITY_LIMIT ACCEL={:.3f}", accel);
      for (const std::string& g : native_move_gcodes(*frame_, from, target, speed, j,
                                                     options_.native_segment, status_.device))
        gcode += "\n" + g;
      // M400: the script's answer comes once the moves are done, not when they are queued.
      gcode += "\nM400";
      script(gcode,
             milliseconds(static_cast<long>(
                 1000.0 *
                 (2.0 * native_expected_seconds(from, target, speed, j, options_.native_segment) +
                  options_.reply_timeout.count() / 1000.0 + 2.0))),
             true);
      return;
    } catch (const MotionRefused&) {
      throw;
    } catch (const LinkError&) {
      // Klipper's refusal is final; a lost connection is recovered.
      if ((client_ && client_->is_open()) || round >= options_.reconnect_attempts) throw;
    }
  }
}

void KlipperLink::do_wait_settled(milliseconds /*timeout*/) {
  // The script's M400 already waited for the motion; a stop requested meanwhile is acted on.
  if (guard().stop_requested()) {
    do_stop(StopKind::kControlled);
    interrupted("move");
  }
  status_.state = LinkState::kIdle;
}

ActuatorReadings KlipperLink::do_read() {
  ActuatorReadings r;
  if (!mcu_at_endstop_) return r;  // not homed: the position is unknown
  std::optional<KlipperPosition> p;
  std::string last;
  for (int attempt = 0; attempt < options_.attempts && !p; ++attempt) {
    try {
      p = get_position();
    } catch (const LinkError& e) {
      // Reading moves nothing, so an error answer is asked again; Klippy shut down is final.
      if (!klippy_said_.empty()) throw;
      last = e.what();
      if (!client_ || !client_->is_open()) reconnect();
    }
  }
  if (!p)
    throw LinkError(
        status_.device,
        fmt::format("no readable GET_POSITION (mcu: stepper counts) after {} attempts{}",
                    options_.attempts, last.empty() ? "" : " (the last: " + last + ")"));
  r.counts = klipper_frame_counts(*frame_, *p, *mcu_at_endstop_);
  r.values = delta_readings(*frame_, r.counts);
  return r;
}

void KlipperLink::do_stop(StopKind /*kind*/) {
  // Klipper has no G-code that halts a running move and keeps going: M112 waits in the queue
  // behind it. Moonraker's emergency stop acts at once; Klipper then needs FIRMWARE_RESTART.
  if (!client_ || !client_->is_open()) return;
  try {
    client_->call("printer.emergency_stop", nullptr, Clock::now() + options_.reply_timeout);
  } catch (const LinkError&) {
    // Stopping is best effort here: the caller reports the stop it asked for.
  }
  mcu_at_endstop_.reset();
  status_.state = LinkState::kStopped;
}

bool KlipperLink::at_target(const ActuatorReadings& readings, const Eigen::VectorXd& target) const {
  return !readings.counts.empty() && frame_ && readings.counts == delta_counts(*frame_, target);
}

double KlipperLink::expected_seconds(const Eigen::VectorXd& from, const Eigen::VectorXd& to,
                                     const MoveSpeed& speed) const {
  return native_expected_seconds(from, to, speed, guard().joint_per_reading(),
                                 options_.native_segment);
}

}  // namespace robocal::robotio
