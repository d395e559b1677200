// The simulated Klipper delta printer behind Moonraker: the WebSocket upgrade and frames
// (websocket.hpp), JSON-RPC 2.0 requests and answers, `printer.gcode.script` run line by line
// through the simulator's G-code engine (its motion queue, truth and log) with Klipper's own
// answers where they differ (GET_POSITION, "Must home axis first", "Move out of range", errors
// as JSON-RPC errors and "!! " responses), Klippy's shutdown on `printer.emergency_stop`, and the
// faults a network printer shows (a dropped connection, a late answer, an error answer, Klippy
// shutting down). Formats from Moonraker's docs/external_api and Klipper's klippy sources
// (robotio/include/robocal/robotio/klipper.hpp, moonraker.hpp).
#include "robocal/robotio/klipper.hpp"
#include "robocal/robotio/websocket.hpp"
#include "sim_internal.hpp"

#include <fmt/format.h>

#include <cctype>
#include <sstream>

namespace robocal::robotio {
namespace {

// Klipper's microcontroller counts start wherever the board powered up: an origin per tower far
// from zero, so a link that took them for positions would be visibly wrong.
constexpr std::array<long, 3> kMcuOrigin = {-184320, 52117, 9003};

std::string upper_command(const std::string& line) {
  std::string code;
  std::stringstream(line) >> code;
  for (char& ch : code) ch = static_cast<char>(std::toupper(static_cast<unsigned char>(ch)));
  return code;
}

// Klipper halts with this state message after an emergency stop (klippy.py, webhooks.py).
std::string shutdown_message(const std::string& why) {
  return why +
         "\nOnce the underlying issue is corrected, use the\n\"FIRMWARE_RESTART\" command to "
         "reset the firmware, reload the\nconfig, and restart the host software.\nPrinter is "
         "shutdown";
}

}  // namespace

void SimController::Impl::moonraker_send(Channel& c, const nlohmann::json& message) {
  if (!c.open()) return;
  const std::string text = message.dump();
  write_log({{"ev", "tx"}, {"ch", c.name}, {"line", text}});
  write_all(c.fd, encode_ws_frame({true, WsOpcode::kText, text}, std::nullopt));
}

void SimController::Impl::moonraker_answer(Channel& c, const nlohmann::json& id,
                                           const nlohmann::json& result) {
  moonraker_send(c, {{"jsonrpc", "2.0"}, {"result", result}, {"id", id}});
}

void SimController::Impl::moonraker_error(Channel& c, const nlohmann::json& id, int code,
                                          const std::string& message) {
  moonraker_send(
      c, {{"jsonrpc", "2.0"}, {"error", {{"code", code}, {"message", message}}}, {"id", id}});
}

void SimController::Impl::moonraker_notify(Channel& c, const std::string& method,
                                           nlohmann::json params) {
  nlohmann::json n = {{"jsonrpc", "2.0"}, {"method", method}};
  if (!params.is_null()) n["params"] = std::move(params);
  moonraker_send(c, n);
}

std::string SimController::Impl::klipper_get_position() const {
  const CarriageFrame& f = *options.delta;
  std::array<long, 3> mcu{};
  std::array<double, 3> stepper{};
  for (int i = 0; i < 3; ++i) {
    const auto k = static_cast<std::size_t>(i);
    mcu[k] = kMcuOrigin[k] + counts[k] - endstop_count(f, i);
    stepper[k] = coordinate_of_count(f, i, counts[k]);
  }
  const Eigen::Vector3d xyz = nozzle_of(counts);
  return get_position_text(mcu, stepper, xyz, xyz);
}

void SimController::Impl::klippy_shutdown(Channel& c, const std::string& why) {
  if (klippy_state == "shutdown") return;
  quick_stop("shutdown");
  klippy_state = "shutdown";
  klippy_message = shutdown_message(why);
  klipper_homed = false;
  c.blocked = false;
  write_log({{"ev", "klippy_shutdown"}, {"why", why}});
  moonraker_notify(c, "notify_gcode_response", {"!! " + why});
  moonraker_notify(c, "notify_klippy_shutdown", nullptr);
  if (!c.script.empty() || !c.script_id.is_null()) {
    moonraker_error(c, c.script_id, 400, why);
    c.script.clear();
    c.script_id = nullptr;
  }
}

std::optional<FaultKind> SimController::Impl::moonraker_roll_fault(const std::string& method) {
  // Faults strike G-code scripts (what moves the printer); the identification, the queries and
  // the emergency stop always get through.
  if (method != "printer.gcode.script") return std::nullopt;
  const std::optional<FaultKind> f = draw_fault();
  if (!f) return f;
  switch (*f) {
    case FaultKind::kDrop:
    case FaultKind::kError:
    case FaultKind::kSlow:
    case FaultKind::kShutdown:
      return f;
    default:
      return std::nullopt;
  }
}

void SimController::Impl::moonraker_run_script(Channel& c) {
  while (!c.script.empty()) {
    if (c.blocked) return;  // G28 or M400 waits for the motion queue (moonraker_process)
    const std::string line = c.script.front();
    c.script.pop_front();
    const std::string code = upper_command(line);
    if (code.empty()) continue;
    std::string error;
    if (klippy_state != "ready") {
      error = klippy_message.substr(0, klippy_message.find('\n'));
    } else if (code == "GET_POSITION") {
      moonraker_notify(c, "notify_gcode_response", {klipper_get_position()});
    } else if (code == "SET_VELOCITY_LIMIT") {
      // Klipper's extended syntax, NAME=VALUE (docs/G-Codes.md): the acceleration robocal sets.
      const auto at = line.find("ACCEL=");
      if (at != std::string::npos) {
        try {
          acceleration = std::stod(line.substr(at + 6));
        } catch (const std::exception&) {
          error = fmt::format("Unable to parse '{}' as a float", line.substr(at + 6));
        }
      }
    } else if (code == "M112") {
      klippy_shutdown(c, "Shutdown due to M112 command");
      return;
    } else if ((code == "G0" || code == "G1") && !klipper_homed) {
      error = "Must home axis first: 0.000 0.000 0.000 [0.000]";
    } else if ((code == "G0" || code == "G1") && !move_target(line)) {
      error = fmt::format("Move out of range: {}", line);
    } else {
      std::vector<std::string> replies;
      gcode_capture = &replies;
      execute(c, line, -1, std::nullopt);
      gcode_capture = nullptr;
      if (code == "G28") klipper_homed = true;
      for (const std::string& r : replies) {
        if (r == "ok") continue;
        if (r.rfind("echo:Unknown command", 0) == 0) {
          error = fmt::format("Unknown command:\"{}\"", code);
        } else if (r.rfind("Error:", 0) == 0) {
          error = r.substr(6);
        } else {
          moonraker_notify(c, "notify_gcode_response", {"// " + r});
        }
      }
    }
    if (!error.empty()) {
      moonraker_notify(c, "notify_gcode_response", {"!! " + error});
      if (!c.script_lost) moonraker_error(c, c.script_id, 400, error);
      c.script.clear();
      c.script_id = nullptr;
      return;
    }
  }
  if (c.blocked || c.script_id.is_null()) return;
  if (!c.script_lost) moonraker_answer(c, c.script_id, "ok");
  c.script_id = nullptr;
  if (c.script_lost) {
    c.script_lost = false;
    write_log({{"ev", "drop"}, {"ch", c.name}, {"executed", true}});
    close_channel(c, false);
  }
}

void SimController::Impl::moonraker_request(Channel& c, const nlohmann::json& request,
                                            std::optional<FaultKind> fault) {
  const nlohmann::json id = request.contains("id") ? request["id"] : nlohmann::json();
  if (!request.contains("method") || !request["method"].is_string()) {
    moonraker_error(c, id, -32600, "Invalid Request");
    return;
  }
  const std::string method = request["method"].get<std::string>();
  const nlohmann::json params =
      request.contains("params") ? request["params"] : nlohmann::json::object();
  if (fault) {
    ++counters.faults[static_cast<std::size_t>(*fault)];
    write_log({{"ev", "fault"}, {"kind", to_string(*fault)}, {"ch", c.name}, {"cmd", method}});
  }
  if (method == "server.info") {
    moonraker_answer(c, id,
                     {{"klippy_connected", true},
                      {"klippy_state", klippy_state},
                      {"components", {"klippy_connection", "websockets", "machine"}},
                      {"failed_components", nlohmann::json::array()},
                      {"registered_directories", {"config", "logs", "gcodes"}},
                      {"warnings", nlohmann::json::array()},
                      {"websocket_count", 1},
                      {"moonraker_version", "v0.9.3 (robocal simulator)"},
                      {"api_version", {1, 5, 0}},
                      {"api_version_string", "1.5.0"}});
  } else if (method == "printer.info") {
    moonraker_answer(c, id,
                     {{"state", klippy_state},
                      {"state_message", klippy_message},
                      {"hostname", "robocal-sim"},
                      {"klipper_path", "/home/pi/klipper"},
                      {"python_path", "/home/pi/klippy-env/bin/python"},
                      {"log_file", "/tmp/klippy.log"},
                      {"config_file", "/home/pi/printer_data/config/printer.cfg"},
                      {"software_version", "v0.12.0-robocal-sim"},
                      {"cpu_info", "simulated"}});
  } else if (method == "printer.objects.query") {
    nlohmann::json status = nlohmann::json::object();
    const nlohmann::json objects =
        params.contains("objects") ? params["objects"] : nlohmann::json::object();
    if (objects.contains("configfile"))
      status["configfile"] = {{"settings", klipper_delta_settings(options.delta->geometry,
                                                                  options.delta->steps_per_mm)},
                              {"save_config_pending", false}};
    if (objects.contains("toolhead"))
      status["toolhead"] = {{"homed_axes", klipper_homed ? "xyz" : ""},
                            {"status", klippy_state == "ready" ? "Ready" : "Shutdown"}};
    if (objects.contains("webhooks"))
      status["webhooks"] = {{"state", klippy_state}, {"state_message", klippy_message}};
    moonraker_answer(c, id, {{"eventtime", t()}, {"status", status}});
  } else if (method == "printer.emergency_stop") {
    klippy_shutdown(c, "Shutdown due to webhooks request");
    moonraker_answer(c, id, "ok");
  } else if (method == "printer.firmware_restart" || method == "printer.restart") {
    klippy_state = "ready";
    klippy_message = "Printer is ready";
    klipper_homed = false;
    write_log({{"ev", "reset"}});
    moonraker_answer(c, id, "ok");
    moonraker_notify(c, "notify_klippy_ready", nullptr);
  } else if (method == "printer.gcode.script") {
    if (!params.contains("script") || !params["script"].is_string()) {
      moonraker_error(c, id, 400, "Invalid argument: script");
      return;
    }
    if (fault == FaultKind::kError) {
      moonraker_notify(c, "notify_gcode_response", {"!! command rejected (injected fault)"});
      moonraker_error(c, id, 400, "command rejected (injected fault)");
      return;
    }
    if (fault == FaultKind::kShutdown) {
      klippy_shutdown(c, "MCU 'mcu' shutdown: Timer too close (injected fault)");
      moonraker_error(c, id, 400, "MCU 'mcu' shutdown: Timer too close (injected fault)");
      return;
    }
    bool lost = false;
    if (fault == FaultKind::kDrop) {
      // Half the drops lose the request on the wire, half the answer after the script ran.
      std::uniform_int_distribution<int> coin(0, 1);
      if (coin(fault_rng) == 0) {
        write_log({{"ev", "drop"}, {"ch", c.name}, {"executed", false}});
        close_channel(c, false);
        return;
      }
      lost = true;
    }
    std::stringstream lines(params["script"].get<std::string>());
    std::string line;
    while (std::getline(lines, line)) c.script.push_back(line);
    c.script_id = id.is_null() ? nlohmann::json(0) : id;
    c.script_lost = lost;
    moonraker_run_script(c);
  } else {
    moonraker_error(c, id, -32601, fmt::format("Method not found: {}", method));
  }
}

void SimController::Impl::moonraker_receive(Channel& c) {
  if (!read_input(c)) return;
  if (!c.upgraded) {
    const auto end = c.inbuf.find("\r\n\r\n");
    if (end == std::string::npos) return;
    const WsClientRequest r = ws_parse_client_request(c.inbuf.substr(0, end + 4));
    c.inbuf.erase(0, end + 4);
    if (!r.problem.empty() || r.path != "/websocket") {
      write_all(c.fd, "HTTP/1.1 404 Not Found\r\nContent-Length: 0\r\n\r\n");
      write_log({{"ev", "bad_upgrade"}, {"why", r.problem.empty() ? r.path : r.problem}});
      close_channel(c, false);
      return;
    }
    write_all(c.fd, ws_server_response(r.key));
    c.upgraded = true;
  }
  for (;;) {
    std::optional<WsFrame> frame;
    try {
      frame = take_ws_frame(c.inbuf, /*from_client=*/true);
    } catch (const std::runtime_error& e) {
      write_log({{"ev", "bad_frame"}, {"why", e.what()}});
      close_channel(c, false);
      return;
    }
    if (!frame) return;
    if (frame->opcode == WsOpcode::kClose) {
      close_channel(c, false);
      return;
    }
    if (frame->opcode == WsOpcode::kPing) {
      write_all(c.fd, encode_ws_frame({true, WsOpcode::kPong, frame->payload}, std::nullopt));
      continue;
    }
    if (frame->opcode != WsOpcode::kText) continue;
    ++counters.lines;
    write_log({{"ev", "rx"}, {"ch", c.name}, {"line", frame->payload}});
    if (options.mute) continue;
    const nlohmann::json request =
        nlohmann::json::parse(frame->payload, nullptr, /*allow_exceptions=*/false);
    if (!request.is_object()) {
      moonraker_error(c, nullptr, -32700, "Parse error");
      continue;
    }
    // The emergency stop acts on receipt, even while a script waits for the motion queue.
    if (request.value("method", "") == "printer.emergency_stop") {
      moonraker_request(c, request, std::nullopt);
      continue;
    }
    c.pending.push_back({frame->payload, false, std::nullopt});
  }
}

void SimController::Impl::moonraker_process(Channel& c, double now) {
  if (!c.open()) return;
  if (c.blocked && queue.empty()) {
    c.blocked = false;
    moonraker_run_script(c);
  }
  while (c.open() && !c.blocked && c.script_id.is_null() && !c.pending.empty() &&
         now >= c.hold_until) {
    Pending& item = c.pending.front();
    if (!item.rolled) {
      item.rolled = true;
      const nlohmann::json r = nlohmann::json::parse(item.text, nullptr, false);
      item.fault = moonraker_roll_fault(r.is_object() ? r.value("method", "") : "");
      if (item.fault == FaultKind::kSlow) {
        // A late answer: Klippy takes the request after a while, then runs it as usual.
        ++counters.faults[static_cast<std::size_t>(FaultKind::kSlow)];
        write_log({{"ev", "fault"}, {"kind", "slow"}, {"ch", c.name}});
        c.hold_until = now + options.faults.slow_seconds;
        item.fault = std::nullopt;
        continue;
      }
    }
    const Pending taken = std::move(item);
    c.pending.pop_front();
    moonraker_request(c, nlohmann::json::parse(taken.text), taken.fault);
  }
}

}  // namespace robocal::robotio
