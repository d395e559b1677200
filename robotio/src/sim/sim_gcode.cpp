// The simulated controller's G-code firmware: Marlin or RepRapFirmware replies, line numbers and
// checksums as Marlin checks them, the emergency parser (M410/M112 act on receipt), blocking
// commands with busy: keep-alives, and the G-code faults.
#include "sim_internal.hpp"

#include <fmt/core.h>

#include <unistd.h>
#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <sstream>
#include <string>

namespace robocal::robotio {
namespace {

std::optional<double> word(const std::string& cmd, char letter) {
  std::stringstream ss(cmd);
  std::string tok;
  ss >> tok;  // the command itself
  while (ss >> tok)
    if (tok.size() > 1 && tok[0] == letter) {
      try {
        return std::stod(tok.substr(1));
      } catch (const std::exception&) {
        return std::nullopt;
      }
    }
  return std::nullopt;
}
}  // namespace

void SimController::Impl::greet(Channel& c) {
  ++counters.connections;
  write_log({{"ev", "connect"}, {"ch", c.name}});
  if (options.mute) return;
  // Marlin prints its boot banner when a host opens the port (the board resets on DTR).
  if (options.dialect == Firmware::kMarlin && options.firmware_name.empty()) {
    send(c, "start");
    send(c, "echo:Marlin 2.1.2.1");
  }
}

// A delta firmware reports the nozzle (its forward kinematics of the counts) and the tower
// counts: Marlin names them A B C, RRF lists them after "Count" and repeats the machine position.
std::string delta_position_report(Firmware dialect, const Eigen::Vector3d& p,
                                  const std::vector<long>& c) {
  if (dialect == Firmware::kRepRapFirmware) {
    const std::string pos = fmt::format("X:{:.3f} Y:{:.3f} Z:{:.3f} ", p.x(), p.y(), p.z());
    return fmt::format("{}E:0.000 Count {} {} {} Machine {}Bed comp 0.000", pos, c[0], c[1], c[2],
                       pos);
  }
  return fmt::format("X:{:.2f} Y:{:.2f} Z:{:.2f} E:0.00 Count A:{} B:{} C:{}", p.x(), p.y(), p.z(),
                     c[0], c[1], c[2]);
}

std::string SimController::Impl::position_report(bool partial) const {
  if (options.delta) {
    std::string line = delta_position_report(options.dialect, nozzle_of(counts), counts);
    if (partial) line.resize(line.find("Count") / 2);
    return line;
  }
  std::string pos, cnt;
  for (int i = 0; i < robot.axes.size(); ++i) {
    const auto k = static_cast<std::size_t>(i);
    const char letter = robot.axes.letters[k];
    const double v = units_of(counts[k], i);
    if (options.dialect == Firmware::kRepRapFirmware) {
      pos += fmt::format("{}:{:.3f} ", letter, v);
      cnt += fmt::format(" {}", counts[k]);
    } else {
      pos += fmt::format("{}:{:.2f} ", letter, v);
      cnt += fmt::format(" {}:{}", letter, counts[k]);
    }
  }
  std::string line = options.dialect == Firmware::kRepRapFirmware
                         ? pos + "E:0.000 Count" + cnt + " Machine " + pos + "Bed comp 0.000"
                         : pos + "E:0.00 Count" + cnt;
  if (partial) line.resize(line.find("Count") / 2);  // cut mid-report, as a lost USB packet
  return line;
}

std::string SimController::Impl::firmware_report() const {
  if (!options.firmware_name.empty()) return "FIRMWARE_NAME:" + options.firmware_name;
  if (options.dialect == Firmware::kRepRapFirmware)
    return "FIRMWARE_NAME: RepRapFirmware for Duet 3 MB6HC FIRMWARE_VERSION: 3.4.5 "
           "ELECTRONICS: Duet 3 MB6HC v1.01 FIRMWARE_DATE: 2022-11-30 (robocal simulator)";
  return "FIRMWARE_NAME:Marlin 2.1.2.1 (robocal simulator) SOURCE_CODE_URL:"
         "github.com/MarlinFirmware/Marlin PROTOCOL_VERSION:1.0 MACHINE_TYPE:" +
         robot.model.name + (options.delta ? " KINEMATICS:Delta" : " KINEMATICS:Cartesian") +
         " EXTRUDER_COUNT:0";
}

void SimController::Impl::reply_ok(Channel& c, bool lost) {
  if (lost) {
    write_log({{"ev", "ok_dropped"}, {"ch", c.name}});
    return;
  }
  send(c, "ok");
}

void SimController::Impl::block(Channel& c, bool lost_ok) {
  c.blocked = true;
  c.blocked_lost_ok = lost_ok;
  c.next_busy = now_seconds() + busy_interval;
}

std::optional<std::vector<long>> SimController::Impl::move_target(const std::string& cmd) const {
  const std::vector<long>& start = queue.empty() ? counts : queue.back().to;
  if (!options.delta) {
    std::vector<long> to = start;
    for (int i = 0; i < robot.axes.size(); ++i) {
      const auto k = static_cast<std::size_t>(i);
      if (const auto v = word(cmd, robot.axes.letters[k]))
        to[k] = std::lround(*v * robot.axes.steps_per_unit[k]);
    }
    return to;
  }
  // Delta kinematics: the Cartesian target (axes not given stay where they are), then the
  // firmware's own inverse kinematics, rounded to steps as it rounds them.
  Eigen::Vector3d xyz = nozzle_of(start);
  for (int i = 0; i < 3; ++i)
    if (const auto v = word(cmd, "XYZ"[i])) xyz[i] = *v;
  return counts_for_cartesian(*options.delta, xyz);
}

bool SimController::Impl::report_settings(Channel& c, const std::string& code, bool lost) {
  const bool rrf = options.dialect == Firmware::kRepRapFirmware;
  if (code == "M503" && !rrf) {
    const std::optional<DeltaGeometry> delta =
        options.delta ? std::optional<DeltaGeometry>(options.delta->geometry) : std::nullopt;
    for (const std::string& line : marlin_m503_lines(delta, robot.axes.steps_per_unit[0]))
      send(c, line);
  } else if ((code == "M665" || code == "M666") && rrf) {
    if (!options.delta) {
      send(c, fmt::format("Error: {} parameters do not apply to Cartesian kinematics", code));
    } else {
      send(c, code == "M665" ? rrf_m665_reply(options.delta->geometry)
                             : rrf_m666_reply(options.delta->geometry));
    }
  } else {
    return false;
  }
  reply_ok(c, lost);
  return true;
}

// Executes one accepted command; `fault` may alter the reply.
void SimController::Impl::execute(Channel& c, const std::string& cmd, long line,
                                  std::optional<FaultKind> fault) {
  const bool lost = fault == FaultKind::kLostOk;
  std::string code;
  std::stringstream(cmd) >> code;
  for (char& ch : code) ch = static_cast<char>(std::toupper(static_cast<unsigned char>(ch)));
  if (code == "G0" || code == "G1") {
    if (const auto f = word(cmd, 'F')) feed = *f / 60.0;
    Motion m;
    m.id = ++motion_ids;
    m.line = line;
    m.channel = c.name;
    const std::optional<std::vector<long>> to = move_target(cmd);
    if (!to) {
      // Out of the delta's reach: the firmware drops the move.
      write_log({{"ev", "unreachable"}, {"ch", c.name}, {"line", line}, {"cmd", cmd}});
      reply_ok(c, lost);
      return;
    }
    m.to = *to;
    m.feed = feed;
    m.acceleration = acceleration;
    m.stall = fault == FaultKind::kStall;
    queue.push_back(m);
    advance_motion(now_seconds());
    reply_ok(c, lost);
  } else if (code == "G28") {
    Motion m;
    m.id = ++motion_ids;
    m.line = line;
    m.channel = c.name;
    m.to = counts_of(robot.home_readings);
    m.feed = feed;
    m.acceleration = acceleration;
    m.homing = true;
    queue.push_back(m);
    advance_motion(now_seconds());
    block(c, lost);
  } else if (code == "M400") {
    block(c, lost);
  } else if (code == "M114") {
    send(c, position_report(fault == FaultKind::kPartial));
    reply_ok(c, lost);
  } else if (code == "M115") {
    send(c, firmware_report());
    if (options.dialect == Firmware::kMarlin && options.firmware_name.empty()) {
      send(c, "Cap:EMERGENCY_PARSER:1");
      send(c, "Cap:HOST_ACTION_COMMANDS:0");
    }
    reply_ok(c, lost);
  } else if (report_settings(c, code, lost)) {
    // reported
  } else if (code == "M204") {
    if (const auto s = word(cmd, 'S')) acceleration = *s;
    if (const auto p = word(cmd, 'P')) acceleration = *p;
    reply_ok(c, lost);
  } else if (code == "M113") {
    if (const auto s = word(cmd, 'S')) busy_interval = std::max(0.1, *s);
    reply_ok(c, lost);
  } else if (code == "M105") {
    send(c, "ok T:24.80 /0.00 B:25.10 /0.00 @:0 B@:0");
  } else if (code == "G91") {
    send(c, "Error:relative positioning (G91) is not simulated");
    reply_ok(c, lost);
  } else if (code == "M410" || code == "M112" || code == "G90" || code == "G21" || code == "M155" ||
             code == "M84" || code == "M110" || code == "M999") {
    reply_ok(c, lost);  // stops acted on when received (emergency parser)
  } else {
    send(c, "echo:Unknown command: \"" + cmd + "\"");
    reply_ok(c, lost);
  }
}

void SimController::Impl::handle_line(Channel& c, Pending& item) {
  ReceivedLine rl = split_received_line(item.text);
  if (item.fault == FaultKind::kCorrupt && rl.has_checksum) rl.valid = false;
  const std::optional<FaultKind> fault = item.fault;
  if (fault) {
    ++counters.faults[static_cast<std::size_t>(*fault)];
    write_log({{"ev", "fault"},
               {"kind", to_string(*fault)},
               {"ch", c.name},
               {"line", rl.number},
               {"cmd", rl.command}});
  }
  if (halted) {
    if (rl.command.rfind("M999", 0) == 0) {
      halted = false;
      c.last_n = 0;
      write_log({{"ev", "reset"}});
      send(c, "ok");
    }
    return;  // a killed firmware answers nothing
  }
  if (rl.command.empty() && !rl.has_number) return;
  if (fault == FaultKind::kGarbage) send(c, "\x02\x7f\x1b[0;~\x7f\x01");
  if (fault == FaultKind::kBusy)
    for (int i = 0; i < options.faults.busy_lines; ++i) send(c, "echo:busy: processing");
  if (rl.has_number) {
    const bool m110 = rl.command.rfind("M110", 0) == 0;
    if (!rl.valid || fault == FaultKind::kResend) {
      if (fault != FaultKind::kCorrupt && fault != FaultKind::kResend) void_fault(c, fault);
      send(c, fmt::format("Error:checksum mismatch, Last Line: {}", c.last_n));
      send(c, resend_request(options.dialect, c.last_n + 1));
      send(c, "ok");
      return;
    }
    if (m110) {
      const auto n = word(rl.command, 'N');
      c.last_n = n ? static_cast<long>(*n) : rl.number;
      send(c, "ok");
      return;
    }
    if (rl.number != c.last_n + 1) {
      void_fault(c, fault);
      send(c, fmt::format("Error:Line Number is not Last Line Number+1, Last Line: {}", c.last_n));
      send(c, resend_request(options.dialect, c.last_n + 1));
      send(c, "ok");
      return;
    }
    if (fault == FaultKind::kDrop) {
      // Half the drops lose the line on the wire, half happen after the firmware took it.
      std::uniform_int_distribution<int> coin(0, 1);
      if (coin(fault_rng) == 1) {
        c.last_n = rl.number;
        execute(c, rl.command, rl.number, std::nullopt);
        write_log({{"ev", "drop"}, {"ch", c.name}, {"executed", true}});
      } else {
        write_log({{"ev", "drop"}, {"ch", c.name}, {"executed", false}});
      }
      close_channel(c, true);
      return;
    }
    c.last_n = rl.number;
  }
  if (fault == FaultKind::kError) {
    send(c, fmt::format("Error:command rejected (injected fault), line {}", rl.number));
    send(c, "ok");
    return;
  }
  execute(c, rl.command, rl.number, fault);
}

// Bytes arrived on a channel: split lines, act on emergency commands at once.
void SimController::Impl::receive(Channel& c) {
  if (!read_input(c)) return;
  std::size_t eol;
  while ((eol = c.inbuf.find_first_of("\r\n")) != std::string::npos) {
    std::string line = c.inbuf.substr(0, eol);
    c.inbuf.erase(0, eol + 1);
    if (line.empty()) continue;
    ++counters.lines;
    write_log({{"ev", "rx"}, {"ch", c.name}, {"line", line}});
    if (options.mute) continue;
    const ReceivedLine rl = split_received_line(line);
    // Emergency parser: stops act on receipt, even while the firmware waits in M400.
    if (rl.valid && (rl.command.rfind("M410", 0) == 0 || rl.command.rfind("M112", 0) == 0)) {
      const bool kill = rl.command.rfind("M112", 0) == 0;
      quick_stop(kill ? "M112" : "M410");
      if (kill) {
        halted = true;
        for (Channel* ch : {&tcp, &pty}) {
          ch->pending.clear();
          ch->blocked = false;
        }
        send(c, "Error:Printer halted. kill() called!");
        continue;
      }
    }
    c.pending.push_back({line, false, std::nullopt});
  }
}

void SimController::Impl::process(Channel& c, double now) {
  if (!c.open()) return;
  if (c.blocked) {
    if (queue.empty()) {
      c.blocked = false;
      reply_ok(c, c.blocked_lost_ok);
    } else if (now >= c.next_busy) {
      if (options.dialect == Firmware::kMarlin) send(c, "echo:busy: processing");
      c.next_busy = now + busy_interval;
    }
  }
  while (c.open() && !c.blocked && !c.pending.empty() && now >= c.hold_until) {
    Pending& item = c.pending.front();
    if (!item.rolled) {
      item.rolled = true;
      const ReceivedLine rl = split_received_line(item.text);
      if (rl.has_number && !halted) item.fault = roll_fault(rl.command);
      if (item.fault == FaultKind::kSlow) {
        c.hold_until = now + options.faults.slow_seconds;
        continue;
      }
    }
    Pending taken = std::move(item);
    c.pending.pop_front();
    handle_line(c, taken);
  }
  if (c.open() && options.temperature_interval > 0.0 && t() >= c.next_temperature &&
      !options.mute) {
    send(c, " T:24.80 /0.00 B:25.10 /0.00 @:0 B@:0");
    c.next_temperature = t() + options.temperature_interval;
  }
}
}  // namespace robocal::robotio
