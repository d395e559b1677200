// UR primary/secondary client interface messages (ur_primary.hpp).
#include "robocal/robotio/ur_primary.hpp"

#include <fmt/core.h>

#include <stdexcept>

namespace robocal::robotio::ur_primary {
namespace {

constexpr std::size_t kMaxPackage = 1 << 20;
constexpr int kSourceController = -2;  // the source robocal's simulator names (any int8 is read)

std::uint64_t get_be(const std::string& in, std::size_t& offset, int bytes, const char* what) {
  if (offset + static_cast<std::size_t>(bytes) > in.size())
    throw std::runtime_error(fmt::format("UR robot message ends before its {}", what));
  std::uint64_t v = 0;
  for (int i = 0; i < bytes; ++i) v = (v << 8) | static_cast<unsigned char>(in[offset++]);
  return v;
}
int get_i32(const std::string& in, std::size_t& offset, const char* what) {
  return static_cast<std::int32_t>(static_cast<std::uint32_t>(get_be(in, offset, 4, what)));
}
void put_be(std::string& out, std::uint64_t v, int bytes) {
  for (int i = bytes - 1; i >= 0; --i) out.push_back(static_cast<char>((v >> (8 * i)) & 0xff));
}

std::string package_of(std::uint64_t timestamp, MessageType type, const std::string& fields) {
  std::string body;
  put_be(body, timestamp, 8);
  body.push_back(static_cast<char>(kSourceController));
  body.push_back(static_cast<char>(type));
  body += fields;
  std::string out;
  put_be(out, body.size() + kHeaderBytes, 4);
  out.push_back(static_cast<char>(kRobotMessage));
  return out + body;
}

const char* level_name(int level) {
  switch (level) {
    case 0:
      return "debug";
    case 1:
      return "info";
    case 2:
      return "warning";
    case 3:
      return "violation";
    case 4:
      return "fault";
    default:
      return "level ?";
  }
}

}  // namespace

std::optional<Package> take_package(std::string& stream) {
  if (stream.size() < 4) return std::nullopt;
  std::size_t offset = 0;
  const auto size = static_cast<std::uint32_t>(get_be(stream, offset, 4, "size"));
  if (size < kHeaderBytes || size > kMaxPackage)
    throw std::runtime_error(
        fmt::format("a UR client interface package of size {} (at least {}, at most {})", size,
                    kHeaderBytes, kMaxPackage));
  if (stream.size() < size) return std::nullopt;
  Package p;
  p.type = static_cast<std::uint8_t>(stream[4]);
  p.body = stream.substr(kHeaderBytes, size - kHeaderBytes);
  stream.erase(0, size);
  return p;
}

std::optional<RobotMessage> decode_robot_message(const Package& package) {
  if (package.type != kRobotMessage) return std::nullopt;
  const std::string& b = package.body;
  std::size_t o = 0;
  RobotMessage m;
  m.timestamp = get_be(b, o, 8, "timestamp");
  const auto source = static_cast<int>(get_be(b, o, 1, "source"));  // int8 on the wire
  m.source = source > 127 ? source - 256 : source;
  const auto type = static_cast<std::uint8_t>(get_be(b, o, 1, "message type"));
  switch (static_cast<MessageType>(type)) {
    case MessageType::kText:
      break;
    case MessageType::kSafetyMode:
      m.code = get_i32(b, o, "safety mode code");
      m.argument = get_i32(b, o, "safety mode argument");
      m.safety_mode = static_cast<int>(get_be(b, o, 1, "safety mode"));
      (void)get_be(b, o, 4, "report data type");
      (void)get_be(b, o, 4, "report data");
      break;
    case MessageType::kErrorCode:
      m.code = get_i32(b, o, "error code");
      m.argument = get_i32(b, o, "error code argument");
      m.report_level = get_i32(b, o, "report level");
      (void)get_be(b, o, 1, "data type");
      (void)get_be(b, o, 4, "data");
      break;
    case MessageType::kRuntimeException:
      m.line = get_i32(b, o, "line number");
      m.column = get_i32(b, o, "column number");
      break;
    default:
      return std::nullopt;
  }
  m.type = static_cast<MessageType>(type);
  if (m.type != MessageType::kSafetyMode) m.text = b.substr(o);
  return m;
}

std::string describe(const RobotMessage& m) {
  switch (m.type) {
    case MessageType::kRuntimeException:
      return fmt::format("runtime exception at line {}, column {}: \"{}\"", m.line, m.column,
                         m.text);
    case MessageType::kErrorCode:
      return fmt::format("error C{}A{} ({}): \"{}\"", m.code, m.argument,
                         level_name(m.report_level), m.text);
    case MessageType::kSafetyMode:
      return fmt::format("safety mode {} (C{}A{})", m.safety_mode, m.code, m.argument);
    case MessageType::kText:
      return fmt::format("\"{}\"", m.text);
  }
  return m.text;
}

bool matters(const RobotMessage& m) {
  switch (m.type) {
    case MessageType::kRuntimeException:
    case MessageType::kSafetyMode:
      return true;
    case MessageType::kErrorCode:
      return m.report_level >= 2 && m.report_level < 128;
    case MessageType::kText:
      return false;
  }
  return false;
}

std::string encode_runtime_exception(std::uint64_t timestamp, int line, int column,
                                     const std::string& text) {
  std::string f;
  put_be(f, static_cast<std::uint32_t>(line), 4);
  put_be(f, static_cast<std::uint32_t>(column), 4);
  return package_of(timestamp, MessageType::kRuntimeException, f + text);
}

std::string encode_error_code(std::uint64_t timestamp, int code, int argument, int report_level,
                              const std::string& text) {
  std::string f;
  put_be(f, static_cast<std::uint32_t>(code), 4);
  put_be(f, static_cast<std::uint32_t>(argument), 4);
  put_be(f, static_cast<std::uint32_t>(report_level), 4);
  f.push_back('\0');  // data type
  put_be(f, 0, 4);    // data
  return package_of(timestamp, MessageType::kErrorCode, f + text);
}

}  // namespace robocal::robotio::ur_primary
