#include "robocal/robotio/gcode_dialect.hpp"

#include <cctype>
#include <charconv>
#include <cstdlib>
#include <string_view>

namespace robocal::robotio {
namespace {

bool starts_with(std::string_view s, std::string_view prefix) {
  return s.substr(0, prefix.size()) == prefix;
}

std::string_view trim(std::string_view s) {
  while (!s.empty() && (std::isspace(static_cast<unsigned char>(s.front())) != 0))
    s.remove_prefix(1);
  while (!s.empty() && (std::isspace(static_cast<unsigned char>(s.back())) != 0))
    s.remove_suffix(1);
  return s;
}

std::optional<long> to_long(std::string_view s) {
  s = trim(s);
  long v = 0;
  const auto* end = s.data() + s.size();
  const auto r = std::from_chars(s.data(), end, v);
  if (r.ec != std::errc() || s.empty()) return std::nullopt;
  return v;
}

// Number at the start of `s` (strtod syntax); nullopt when there is none.
std::optional<double> leading_double(std::string_view s, std::size_t* used) {
  const std::string text(s.substr(0, 40));
  char* end = nullptr;
  const double v = std::strtod(text.c_str(), &end);
  if (end == text.c_str()) return std::nullopt;
  *used = static_cast<std::size_t>(end - text.c_str());
  return v;
}

std::optional<long> leading_long(std::string_view s, std::size_t* used) {
  long v = 0;
  const auto r = std::from_chars(s.data(), s.data() + s.size(), v);
  if (r.ec != std::errc()) return std::nullopt;
  *used = static_cast<std::size_t>(r.ptr - s.data());
  return v;
}

// Value after "<letter>:" in `s` searching from the start; the letter must begin a token.
std::optional<double> axis_value(std::string_view s, char letter, std::size_t* after = nullptr) {
  for (std::size_t i = 0; i + 1 < s.size(); ++i) {
    if (s[i] != letter || s[i + 1] != ':') continue;
    if (i > 0 && s[i - 1] != ' ') continue;
    std::size_t used = 0;
    const auto v = leading_double(s.substr(i + 2), &used);
    if (!v) return std::nullopt;
    if (after != nullptr) *after = i + 2 + used;
    return v;
  }
  return std::nullopt;
}

}  // namespace

const char* to_string(Firmware firmware) {
  switch (firmware) {
    case Firmware::kMarlin:
      return "Marlin";
    case Firmware::kRepRapFirmware:
      return "RepRapFirmware";
    case Firmware::kKlipper:
      return "Klipper";
    case Firmware::kUnknown:
      break;
  }
  return "unknown";
}

Reply classify_reply(const std::string& line) {
  Reply r;
  r.text = std::string(trim(line));
  const std::string_view t = r.text;
  if (t == "ok" || starts_with(t, "ok ")) {
    r.kind = ReplyKind::kOk;
  } else if (starts_with(t, "echo:busy:") || starts_with(t, "busy:")) {
    r.kind = ReplyKind::kBusy;
  } else if (starts_with(t, "!!") || t.find("kill() called") != std::string_view::npos) {
    r.kind = ReplyKind::kFatal;
  } else if (starts_with(t, "Resend:") || starts_with(t, "rs ")) {
    const auto n = to_long(t.substr(t.find_first_of(": ") + 1));
    if (n) {
      r.kind = ReplyKind::kResend;
      r.resend_line = *n;
    }
  } else if (starts_with(t, "Error:") || starts_with(t, "error:")) {
    r.kind = ReplyKind::kError;
  } else if (parse_firmware_line(r.text)) {
    r.kind = ReplyKind::kFirmware;
  } else if (starts_with(t, "echo:")) {
    r.kind = ReplyKind::kEcho;
  } else if (t.find("Count") != std::string_view::npos && axis_value(t, 'X')) {
    r.kind = ReplyKind::kPosition;
  } else if (starts_with(t, "T:") || t.find(" B:") != std::string_view::npos) {
    r.kind = ReplyKind::kTemperature;
  }
  return r;
}

std::optional<PositionReport> parse_position_report(const std::string& line,
                                                    const std::string& axis_letters,
                                                    const std::string& count_letters) {
  const std::string& counted = count_letters.empty() ? axis_letters : count_letters;
  std::string_view s = trim(line);
  if (starts_with(s, "C: ")) s.remove_prefix(3);  // RRF prefixes with "C: " in some versions
  const std::size_t count_at = s.find("Count");
  if (count_at == std::string_view::npos) return std::nullopt;
  const std::string_view head = s.substr(0, count_at);
  std::string_view tail = s.substr(count_at + 5);
  PositionReport report;
  for (const char letter : axis_letters) {
    const auto v = axis_value(head, letter);
    if (!v) return std::nullopt;
    report.positions.push_back(*v);
  }
  tail = trim(tail);
  const bool named = tail.size() > 1 && tail[1] == ':';  // Marlin "X:800", RRF "800"
  if (named) {
    for (const char letter : counted) {
      // Counts are integers: reject "X:12.5" rather than truncate it.
      std::size_t i = 0;
      bool found = false;
      for (; i + 1 < tail.size(); ++i)
        if (tail[i] == letter && tail[i + 1] == ':' && (i == 0 || tail[i - 1] == ' ')) {
          found = true;
          break;
        }
      if (!found) return std::nullopt;
      std::size_t used = 0;
      const auto n = leading_long(tail.substr(i + 2), &used);
      const std::string_view rest = tail.substr(i + 2 + used);
      if (!n || (!rest.empty() && rest.front() != ' ')) return std::nullopt;
      report.counts.push_back(*n);
    }
  } else {
    for (std::size_t k = 0; k < counted.size(); ++k) {
      tail = trim(tail);
      std::size_t used = 0;
      const auto n = leading_long(tail, &used);
      if (!n || (used < tail.size() && tail[used] != ' ')) return std::nullopt;
      report.counts.push_back(*n);
      tail.remove_prefix(used);
    }
  }
  return report;
}

std::optional<FirmwareInfo> parse_firmware_line(const std::string& line) {
  const std::string_view t = trim(line);
  FirmwareInfo info;
  info.raw = std::string(t);
  const std::size_t name_at = t.find("FIRMWARE_NAME:");
  std::string_view name;
  if (name_at != std::string_view::npos) {
    name = trim(t.substr(name_at + 14));
    // Marlin: "FIRMWARE_NAME:Marlin 2.1.2 (Github) SOURCE_CODE_URL:..."; RRF: "FIRMWARE_NAME:
    // RepRapFirmware for Duet 3 MB6HC FIRMWARE_VERSION: 3.4.5 ELECTRONICS: ...".
    const std::size_t next_key = name.find(':');
    if (next_key != std::string_view::npos) {
      const std::size_t key_start = name.rfind(' ', next_key);
      name = trim(name.substr(0, key_start == std::string_view::npos ? 0 : key_start));
    }
  } else if (starts_with(t, "echo:Marlin ") || starts_with(t, "Marlin ")) {
    name = trim(t.substr(t.find("Marlin")));
  } else {
    return std::nullopt;
  }
  if (starts_with(name, "Marlin")) {
    info.firmware = Firmware::kMarlin;
    const std::string_view rest = trim(name.substr(6));
    info.version = std::string(rest.substr(0, rest.find(' ')));
  } else if (starts_with(name, "RepRapFirmware")) {
    info.firmware = Firmware::kRepRapFirmware;
    const std::size_t v = t.find("FIRMWARE_VERSION:");
    if (v != std::string_view::npos) {
      const std::string_view rest = trim(t.substr(v + 17));
      info.version = std::string(rest.substr(0, rest.find(' ')));
    }
  }
  info.name = std::string(name);
  return info;
}

int gcode_checksum(const std::string& text) {
  unsigned char cs = 0;
  for (const char c : text) cs ^= static_cast<unsigned char>(c);
  return cs;
}

std::string numbered_line(long number, const std::string& command) {
  std::string line = "N";
  line += std::to_string(number);
  line += ' ';
  line += command;
  const int checksum = gcode_checksum(line);
  line += '*';
  line += std::to_string(checksum);
  return line;
}

ReceivedLine split_received_line(const std::string& line) {
  ReceivedLine out;
  std::string_view s = trim(line);
  const std::size_t star = s.rfind('*');
  if (star != std::string_view::npos) {
    out.has_checksum = true;
    const auto given = to_long(s.substr(star + 1));
    const int actual = gcode_checksum(std::string(s.substr(0, star)));
    out.valid = given.has_value() && *given == actual;
    s = s.substr(0, star);
  }
  if (!s.empty() && s.front() == 'N') {
    std::size_t used = 0;
    const auto n = leading_long(s.substr(1), &used);
    if (!n) {
      out.valid = false;
    } else {
      out.has_number = true;
      out.number = *n;
      s.remove_prefix(1 + used);
    }
  }
  const std::size_t comment = s.find(';');
  if (comment != std::string_view::npos) s = s.substr(0, comment);
  out.command = std::string(trim(s));
  return out;
}

std::string resend_request(Firmware firmware, long number) {
  if (firmware == Firmware::kRepRapFirmware) return "rs " + std::to_string(number);
  return "Resend: " + std::to_string(number);
}

std::string quick_stop_command(Firmware firmware) {
  return firmware == Firmware::kMarlin ? "M410" : "";
}

bool sends_busy(Firmware firmware) {
  return firmware == Firmware::kMarlin;
}

}  // namespace robocal::robotio
