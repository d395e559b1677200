#pragma once
// The G-code firmware dialects, in one place: how Marlin and RepRapFirmware (RRF) phrase their
// replies, report positions and stepper counts, identify themselves, and request resends.
// Everything here is a pure function over text, so the link and the tests share one reading of
// the protocol. Sources (looked up, not guessed):
// - Marlin: `ok`; `echo:busy: processing` keep-alive while a blocking command runs; `Error:...`;
//   `Resend: N` after a checksum or line-number error; M114 `X:.. Y:.. Z:.. E:.. Count X:n Y:n
//   Z:n`; M115 `FIRMWARE_NAME:Marlin 2.x ... ` then `Cap:` lines; boot banner `start`.
// - RepRapFirmware: `ok`; `Error: ...`; `rs N` resend request; M114 `X:.. Y:.. Z:.. E:.. Count
//   n n n Machine .. .. .. Bed comp ..`; M115 `FIRMWARE_NAME: RepRapFirmware for Duet ...
//   FIRMWARE_VERSION: 3.x`.
// - Both: line numbers `N<n> <command>*<checksum>` with checksum = XOR of every byte before
//   `*`; `M110 N<n>` sets the expected line number; `!!` marks a fatal halt (printed by Marlin's
//   kill() path and by Klipper's G-code front end on shutdown).
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

namespace robocal::robotio {

// Klipper is reached through Moonraker (klipper.hpp), not a G-code line protocol; it is named
// here because the delta geometry (delta_firmware.hpp) is shared by all three.
enum class Firmware : std::uint8_t { kUnknown, kMarlin, kRepRapFirmware, kKlipper };
const char* to_string(Firmware firmware);

// What a firmware line means to the link.
enum class ReplyKind : std::uint8_t {
  kOk,           // command accepted ("ok", "ok N12", "ok T:..." all count)
  kBusy,         // keep-alive while a command runs (Marlin "echo:busy: processing")
  kError,        // "Error:..." (the command was not executed; an "ok" may follow)
  kFatal,        // "!!" or a halt message: firmware stopped, needs a reset
  kResend,       // "Resend: N" / "rs N": send line N again
  kPosition,     // an M114 report
  kFirmware,     // an M115 report or a boot banner naming the firmware
  kTemperature,  // " T:25.0 /0.0 B:..." auto-report or M105 answer
  kEcho,         // "echo:..." informational
  kOther,        // anything else (Cap: lines, blank, unknown)
};

struct Reply {
  ReplyKind kind = ReplyKind::kOther;
  std::string text;       // the line without its line ending
  long resend_line = -1;  // kResend: the line number asked for
};

// Classifies one received line. Unknown text is kOther, never an exception.
Reply classify_reply(const std::string& line);

// An M114 report: axis positions (G-code units) and, when the firmware gives them after `Count`,
// the stepper positions (microsteps) per axis, in axis order.
struct PositionReport {
  std::vector<double> positions;
  std::vector<long> counts;
};
// Parses M114 for `axis_letters` (e.g. "XYZ"). Marlin names the counts per axis ("Count X:800
// Y:..."), RRF lists them in axis order ("Count 800 1600 2000"). Marlin on a delta names the
// counts by tower ("Count A:800 B:.. C:.."): `count_letters` ("ABC") then, empty = the axis
// letters. Returns nullopt when a position or count of a requested axis is missing or not a
// number.
std::optional<PositionReport> parse_position_report(const std::string& line,
                                                    const std::string& axis_letters,
                                                    const std::string& count_letters = "");

struct FirmwareInfo {
  Firmware firmware = Firmware::kUnknown;
  std::string name;     // e.g. "Marlin 2.1.2", "RepRapFirmware for Duet 3 MB6HC"
  std::string version;  // e.g. "2.1.2", "3.4.5" ("" when not given)
  std::string raw;      // the line it came from
};
// Reads an M115 report or boot banner; nullopt when the line names no firmware.
std::optional<FirmwareInfo> parse_firmware_line(const std::string& line);

// Checksum of a numbered line: XOR of all bytes of `text` (everything before '*').
int gcode_checksum(const std::string& text);
// "N<n> <command>*<checksum>".
std::string numbered_line(long number, const std::string& command);
// Splits a received line into number, command and checksum check. `valid` is false when a `*`
// is present and the checksum does not match, or the number is malformed.
struct ReceivedLine {
  bool has_number = false;
  long number = -1;
  bool has_checksum = false;
  bool valid = true;
  std::string command;  // without N, checksum and comment
};
ReceivedLine split_received_line(const std::string& line);

// The resend request a firmware sends for line `number`.
std::string resend_request(Firmware firmware, long number);

// Stop commands. A controlled (quick) stop halts motion and keeps the firmware running:
// Marlin M410 (position kept, may need re-homing if steps were lost). RRF has no quick stop
// (no M410); its stop is M112 followed by M999 to restart. Returns "" when the firmware has no
// controlled stop.
std::string quick_stop_command(Firmware firmware);
inline std::string emergency_stop_command() {
  return "M112";
}

// Whether the firmware keeps a connection alive with busy lines during M400/G28 (Marlin's
// HOST_KEEPALIVE_FEATURE); RRF stays silent until "ok".
bool sends_busy(Firmware firmware);

}  // namespace robocal::robotio
