#pragma once
// The messages a Universal Robots controller sends on its primary and secondary client interfaces
// (TCP 30001/30002) as pure functions over bytes. The UR link reads them off the secondary
// interface it sends URScript to, so that a script the controller rejects, a runtime exception or
// an error code reaches the operator in the controller's own words; the simulated controller
// sends them the same way.
//
// Layout (Universal Robots' client interface, as their Universal_Robots_Client_Library parses
// it): every package is int32 size (the whole package, these 4 bytes included), uint8 package
// type, then the body; all numbers big-endian. Package type 16 is a robot state (sub-packages,
// 10 Hz; not read here), 20 a robot message:
//   uint64 timestamp, int8 source, uint8 robot message type, then by type
//   0  text:              the text (the rest of the package)
//   5  safety mode:       int32 code, int32 argument, uint8 safety mode, uint32 report data
//                         type, 4 bytes report data
//   6  error code:        int32 code, int32 argument, int32 report level, uint8 data type,
//                         uint32 data, the text (the rest)
//   10 runtime exception: int32 line, int32 column, the text (the rest)
// Other robot message types (version, key, program label, request value, popups) are framed and
// skipped: robocal does not need them, and the popup type's number differs between software
// generations in the published sources.
#include <cstdint>
#include <optional>
#include <string>

namespace robocal::robotio::ur_primary {

inline constexpr int kHeaderBytes = 5;
inline constexpr std::uint8_t kRobotState = 16;
inline constexpr std::uint8_t kRobotMessage = 20;

enum class MessageType : std::uint8_t {
  kText = 0,
  kSafetyMode = 5,
  kErrorCode = 6,
  kRuntimeException = 10,
};

struct Package {
  std::uint8_t type = 0;
  std::string body;  // after the 5-byte header
};
// Cuts the first complete package off the front of `stream`; nullopt when it is not all there
// yet. Throws std::runtime_error when the size field is smaller than the header or beyond any
// package the controller sends (1 MiB): the stream is out of step.
std::optional<Package> take_package(std::string& stream);

struct RobotMessage {
  std::uint64_t timestamp = 0;
  int source = 0;
  MessageType type = MessageType::kText;
  std::string text;
  int code = 0, argument = 0;  // error code, safety mode
  int report_level = 0;        // error code: 0 debug, 1 info, 2 warning, 3 violation, 4 fault
  int safety_mode = 0;         // safety mode message
  int line = 0, column = 0;    // runtime exception
};
// The robot message in `package` when it is one of the types above; nullopt for robot states and
// other messages. Throws std::runtime_error when the body is shorter than its type's fields.
std::optional<RobotMessage> decode_robot_message(const Package& package);
// The message in plain words, e.g. `runtime exception at line 3, column 7: "…"` or
// `error C204A3 (fault): "…"`.
std::string describe(const RobotMessage& message);
// Whether the operator must see it: a runtime exception, an error code of warning level or
// above, a safety mode message. Text messages and debug/info codes are not.
bool matters(const RobotMessage& message);

// The controller's side (sim-controller): a whole robot message package.
std::string encode_runtime_exception(std::uint64_t timestamp, int line, int column,
                                     const std::string& text);
std::string encode_error_code(std::uint64_t timestamp, int code, int argument, int report_level,
                              const std::string& text);

}  // namespace robocal::robotio::ur_primary
