// The wizard's probe of a controller address (controller_probe.hpp). Each question is one a
// controller of that kind documents an answer to: the UR dashboard server's greeting line and its
// one-line replies (UR's dashboard server command list), the open link's hello
// (robotio/OPEN_LINK.md), a G-code firmware's M115 report (gcode_dialect.hpp), Moonraker's
// WebSocket upgrade and its server.info and printer.info answers (moonraker.hpp).
#include "robocal/robotio/controller_probe.hpp"

#include "robocal/robotio/gcode_dialect.hpp"
#include "robocal/robotio/link_error.hpp"
#include "robocal/robotio/moonraker.hpp"
#include "robocal/robotio/open_link.hpp"
#include "robocal/robotio/transport.hpp"
#include "robocal/robotio/ur_link.hpp"

#include <fmt/core.h>
#include <nlohmann/json.hpp>

#include <optional>
#include <stdexcept>
#include <utility>

namespace robocal::robotio {
namespace {

using Clock = std::chrono::steady_clock;
using std::chrono::milliseconds;

constexpr int kDashboardPort = 29999;
constexpr int kMoonrakerPort = 7125;
constexpr const char* kDashboardGreeting = "Universal Robots Dashboard Server";

std::string printable(std::string text) {
  for (char& c : text)
    if (static_cast<unsigned char>(c) < 0x20 || static_cast<unsigned char>(c) > 0x7e) c = '?';
  if (text.size() > 120) text = text.substr(0, 117) + "...";
  return text;
}

// "URSoftware 5.11.0.108 (Jan 01 2022)" -> "5.11.0.108" (the dashboard's PolyscopeVersion reply:
// the version between the first space and " (").
std::string polyscope_version(const std::string& reply) {
  if (reply.rfind("URSoftware ", 0) != 0) return "";
  const std::size_t start = reply.find(' ') + 1;
  const std::size_t end = reply.find(" (", start);
  return reply.substr(start, end == std::string::npos ? std::string::npos : end - start);
}

int major_of(const std::string& version) {
  int major = 0;
  for (char c : version) {
    if (c < '0' || c > '9') break;
    major = major * 10 + (c - '0');
  }
  return major;
}

bool at_least(const std::string& version, int major, int minor) {
  const std::size_t dot = version.find('.');
  const int ma = major_of(version);
  const int mi = dot == std::string::npos ? 0 : major_of(version.substr(dot + 1));
  return ma > major || (ma == major && mi >= minor);
}

class Probe {
 public:
  Probe(std::string host, int port, milliseconds timeout)
      : host_(std::move(host)), port_(port), timeout_(timeout) {
    result_.host = host_;
    result_.port = port_;
  }

  ProbeResult run() {
    TcpTransport t(host_, port_, timeout_);
    try {
      t.open();
    } catch (const LinkError&) {
      return nothing();
    }
    // Moonraker's port: a WebSocket server says nothing until it is asked over HTTP.
    if (port_ == kMoonrakerPort) {
      t.close();
      if (std::optional<ProbeResult> r = moonraker()) return *r;
      try {
        t.open();
      } catch (const LinkError&) {
        return unrecognised();
      }
    }
    // A UR dashboard greets every client; a G-code board may print its boot banner.
    const std::optional<std::string> greeting = line(t, milliseconds(timeout_ / 3));
    if (greeting) said(*greeting);
    if (greeting && greeting->find(kDashboardGreeting) != std::string::npos) return ur(t);
    if (greeting)
      if (const std::optional<FirmwareInfo> fw = parse_firmware_line(*greeting)) return gcode(*fw);
    if (std::optional<ProbeResult> r = open_link(t)) return *r;
    // A G-code firmware answered the hello line as an unknown command (or not at all): M115 on
    // the same connection, its report among whatever else the board prints.
    try {
      t.write_line("M115");
      const auto deadline = Clock::now() + timeout_;
      while (const std::optional<std::string> l = t.read_line(deadline)) {
        said(*l);
        if (const std::optional<FirmwareInfo> fw = parse_firmware_line(*l)) return gcode(*fw);
      }
    } catch (const LinkError&) {
      // Closed on us: judged by what it said before.
    }
    // Silent to lines: perhaps a WebSocket server (Moonraker on a port of its own).
    if (result_.said.empty() && port_ != kMoonrakerPort) {
      t.close();
      if (std::optional<ProbeResult> r = moonraker()) return *r;
    }
    return unrecognised();
  }

  // Moonraker: the WebSocket upgrade, then server.info (is Klippy connected and ready) and
  // printer.info (Klipper's version and its state message).
  std::optional<ProbeResult> moonraker() {
    try {
      MoonrakerClient client(host_, port_);
      client.open(Clock::now() + timeout_);
      const nlohmann::json server = client.call("server.info", nullptr, Clock::now() + timeout_);
      std::string words = fmt::format("a Klipper printer through Moonraker {}",
                                      server.value("moonraker_version", std::string("?")));
      const std::string state = server.value("klippy_state", std::string("?"));
      if (server.value("klippy_connected", false)) {
        const nlohmann::json printer =
            client.call("printer.info", nullptr, Clock::now() + timeout_);
        words += fmt::format(", Klipper {}", printer.value("software_version", std::string("?")));
        if (state != "ready") {
          const std::string message = printer.value("state_message", std::string());
          words += fmt::format(", NOT ready (state {}: {})", state,
                               message.substr(0, message.find('\n')));
        }
      } else {
        words += ", but Moonraker is not connected to Klipper (is the klipper service running?)";
      }
      client.close();
      result_.kind = ProbedController::kKlipper;
      result_.link = port_ == kMoonrakerPort ? "moonraker:" + host_
                                             : fmt::format("moonraker:{}:{}", host_, port_);
      result_.explanation = fmt::format("{} on {}", words, where());
      return result_;
    } catch (const LinkError&) {
      return std::nullopt;
    }
  }

 private:
  std::optional<std::string> line(Transport& t, milliseconds wait) {
    try {
      return t.read_line(Clock::now() + wait);
    } catch (const LinkError&) {
      return std::nullopt;
    }
  }
  void said(const std::string& text) {
    if (result_.said.empty() && !text.empty()) result_.said = printable(text);
  }
  std::string where() const { return fmt::format("port {} of {}", port_, host_); }

  ProbeResult nothing() {
    result_.kind = ProbedController::kNothing;
    result_.explanation = fmt::format(
        "nothing answers on {}: is the robot on the network, switched on, and is {} its "
        "address{}?",
        where(), host_,
        port_ == kDashboardPort ? " (a Universal Robots controller answers on 29999)"
                                : fmt::format(" and {} its port", port_));
    return result_;
  }

  ProbeResult ur(Transport& t) {
    auto ask = [&](const std::string& command) -> std::string {
      try {
        t.write_line(command);
      } catch (const LinkError&) {
        return "";
      }
      return line(t, timeout_).value_or("");
    };
    const std::string version = polyscope_version(ask("PolyscopeVersion"));
    const bool e_series = major_of(version) >= 5;
    std::string words = "a Universal Robots controller";
    if (!version.empty())
      words += fmt::format(", PolyScope {}.x ({}, {})", major_of(version), version,
                           e_series ? "e-Series" : "CB-Series");
    // "is in remote control" exists from PolyScope 5.6; a CB3 takes URScript without it.
    if (e_series && at_least(version, 5, 6)) {
      const std::string remote = ask("is in remote control");
      if (remote == "true") words += ", remote control on";
      if (remote == "false")
        words +=
            ", remote control OFF (switch the pendant to Remote Control before robocal "
            "moves it)";
    }
    const std::string mode = ask("robotmode");
    if (mode.rfind("Robotmode: ", 0) == 0) words += ", robot mode " + ur_dashboard_value(mode);
    // safetystatus from PolyScope 5.4; safetymode before it.
    const bool status = e_series && at_least(version, 5, 4);
    const std::string safety = ask(status ? "safetystatus" : "safetymode");
    if (safety.rfind(status ? "Safetystatus: " : "Safetymode: ", 0) == 0)
      words +=
          fmt::format(", safety {} {}", status ? "status" : "mode", ur_dashboard_value(safety));
    result_.kind = ProbedController::kUniversalRobots;
    if (port_ == kDashboardPort) {
      result_.link = "ur:" + host_;
    } else {
      // The dashboard on another port (forwarded, or a simulator): RTDE and the secondary
      // interface are assumed on their standard ports; the operator corrects them if not.
      result_.link = fmt::format("ur:{}:30004:30002:{}", host_, port_);
      words += fmt::format(
          " (its dashboard server on {} rather than 29999: give the RTDE and secondary ports if "
          "they are not 30004 and 30002)",
          port_);
    }
    result_.explanation = fmt::format("{} on {}", words, where());
    return result_;
  }

  std::optional<ProbeResult> open_link(Transport& t) {
    const nlohmann::json hello = {{"id", 1},
                                  {"cmd", "hello"},
                                  {"protocol", kOpenLinkProtocol},
                                  {"version", {kOpenLinkMajor, kOpenLinkMinor}},
                                  {"client", "robocal probe"}};
    try {
      t.write_line(hello.dump());
    } catch (const LinkError&) {
      return std::nullopt;
    }
    const std::optional<std::string> reply = line(t, timeout_);
    if (!reply) return std::nullopt;
    said(*reply);
    const nlohmann::json j = nlohmann::json::parse(*reply, nullptr, false);
    if (!j.is_object() || j.value("protocol", "") != kOpenLinkProtocol) {
      // An open link controller that refuses our version still names the protocol in its error.
      const OpenLinkFailure f = j.is_object() ? open_reply_failure(j) : OpenLinkFailure{};
      if (f.code != 103) return std::nullopt;
      result_.kind = ProbedController::kOpenLink;
      result_.link = fmt::format("open:{}:{}", host_, port_);
      result_.explanation = fmt::format(
          "an open link controller on {}, but it refuses robocal's protocol version {}.{}: {}",
          where(), kOpenLinkMajor, kOpenLinkMinor, f.message);
      return result_;
    }
    result_.kind = ProbedController::kOpenLink;
    result_.link = fmt::format("open:{}:{}", host_, port_);
    try {
      const OpenLinkHello h = parse_open_hello(j);
      std::string names;
      for (const OpenLinkActuator& a : h.actuators)
        names += (names.empty() ? "" : ", ") + a.name + " (" + a.unit + ")";
      result_.explanation = fmt::format(
          "an open link controller, \"{}\", protocol {}.{}, {} actuator{}: {}{} on {}",
          h.controller, h.major, h.minor, h.actuators.size(), h.actuators.size() == 1 ? "" : "s",
          names, h.has("flange_pose") ? "; it reports its flange pose" : "", where());
    } catch (const std::invalid_argument& e) {
      result_.explanation = fmt::format(
          "an open link controller on {}, but its hello is incomplete: {}", where(), e.what());
    }
    return result_;
  }

  ProbeResult gcode(const FirmwareInfo& fw) {
    result_.kind = ProbedController::kGcode;
    result_.link = fmt::format("tcp:{}:{}", host_, port_);
    result_.explanation =
        fmt::format("a G-code board, {}{}, on {}", fw.name,
                    fw.firmware == Firmware::kUnknown
                        ? " (not Marlin or RepRapFirmware: robocal may not read its replies)"
                        : "",
                    where());
    return result_;
  }

  ProbeResult unrecognised() {
    if (result_.said.empty()) {
      result_.kind = ProbedController::kSilent;
      result_.explanation = fmt::format(
          "something accepts connections on {} but says nothing: not a UR dashboard server, an "
          "open link controller, a G-code board or Moonraker (is the port right? is the "
          "controller busy with another client?)",
          where());
    } else {
      result_.kind = ProbedController::kUnknown;
      result_.explanation = fmt::format(
          "something answers on {} but is not a UR dashboard server, an open link controller, "
          "a G-code board or Moonraker; it said: \"{}\"",
          where(), result_.said);
    }
    return result_;
  }

  std::string host_;
  int port_;
  milliseconds timeout_;
  ProbeResult result_;
};

}  // namespace

const char* to_string(ProbedController kind) {
  switch (kind) {
    case ProbedController::kNothing:
      return "nothing";
    case ProbedController::kSilent:
      return "silent";
    case ProbedController::kUnknown:
      return "unknown";
    case ProbedController::kUniversalRobots:
      return "universal-robots";
    case ProbedController::kOpenLink:
      return "open-link";
    case ProbedController::kGcode:
      return "gcode";
    case ProbedController::kKlipper:
      return "klipper";
  }
  return "?";
}

bool is_probe_address(const std::string& text) {
  if (text.empty() || text.front() == '/' || text == "manual") return false;
  const std::size_t colon = text.find(':');
  if (colon == std::string::npos) return true;
  const std::string rest = text.substr(colon + 1);
  return !rest.empty() && rest.find(':') == std::string::npos &&
         rest.find_first_not_of("0123456789") == std::string::npos;
}

ProbeResult probe_controller(const std::string& address, milliseconds timeout) {
  if (!is_probe_address(address)) {
    ProbeResult r;
    r.explanation = fmt::format("'{}' is not HOST or HOST:PORT", address);
    return r;
  }
  const std::size_t colon = address.find(':');
  if (colon == std::string::npos) {
    // A bare host: a UR's dashboard server, else a Klipper printer's Moonraker.
    ProbeResult ur = Probe(address, kDashboardPort, timeout).run();
    if (ur.kind != ProbedController::kNothing) return ur;
    ProbeResult klipper = Probe(address, kMoonrakerPort, timeout).run();
    if (klipper.kind != ProbedController::kNothing) return klipper;
    ur.explanation += " (nor does Moonraker on 7125, a Klipper printer's port)";
    return ur;
  }
  int port = 0;
  for (char c : address.substr(colon + 1)) port = port > 65535 ? port : port * 10 + (c - '0');
  if (port < 1 || port > 65535) {
    ProbeResult r;
    r.host = address.substr(0, colon);
    r.explanation = fmt::format("'{}' is not a port within 1..65535", address.substr(colon + 1));
    return r;
  }
  return Probe(address.substr(0, colon), port, timeout).run();
}

}  // namespace robocal::robotio
