#pragma once
// What answers at an address the operator gives (the wizard's controller step): a Universal
// Robots dashboard server (its "Connected: Universal Robots Dashboard Server" greeting, then
// PolyscopeVersion, robotmode, safetystatus and, from PolyScope 5.6, "is in remote control"), an
// open link controller (its `hello` reply, robotio/OPEN_LINK.md), a G-code board (its M115
// report) or a Klipper printer's Moonraker (its WebSocket upgrade, server.info and printer.info;
// port 7125, or any port silent to lines). Only questions are sent: nothing moves, nothing is
// unlocked or changed.
#include <chrono>
#include <cstdint>
#include <string>

namespace robocal::robotio {

enum class ProbedController : std::uint8_t {
  kNothing,  // nothing accepts connections there
  kSilent,   // a connection is accepted, nothing ever answers
  kUnknown,  // something answers, none of the controllers robocal speaks to
  kUniversalRobots,
  kOpenLink,
  kGcode,
  kKlipper,  // Moonraker in front of Klipper
};
const char* to_string(ProbedController kind);

struct ProbeResult {
  ProbedController kind = ProbedController::kNothing;
  std::string host;
  int port = 0;
  std::string explanation;  // in plain words, for the operator
  std::string link;         // the link address to use ("" when none fits)
  std::string said;         // what the device said first ("" when nothing)
};

// "HOST" (probes a UR's dashboard server on 29999, then Moonraker on 7125) or "HOST:PORT". An
// address that is neither gives kNothing with the explanation.
ProbeResult probe_controller(const std::string& address,
                             std::chrono::milliseconds timeout = std::chrono::milliseconds(1500));

// Whether `text` is a bare network address the probe takes ("HOST" or "HOST:PORT"; not a serial
// device path and no link scheme such as tcp:, ur:, open:, manual).
bool is_probe_address(const std::string& text);

}  // namespace robocal::robotio
