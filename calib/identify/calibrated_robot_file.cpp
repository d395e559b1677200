#include "robocal/calib/calibrated_robot_file.hpp"

#include "robocal/calib/robot_file.hpp"

#include <fmt/core.h>

#include <cmath>
#include <sstream>
#include <stdexcept>

namespace robocal::calib {
namespace {

std::vector<std::string> split_lines(const std::string& text) {
  std::vector<std::string> lines;
  std::stringstream in(text);
  std::string line;
  while (std::getline(in, line)) lines.push_back(line);
  return lines;
}

// Position just after "key:" (and following spaces) where `key` starts the line or follows a
// space, '{' or ','; npos when absent. (Plain scanning: std::regex trips GCC 12's
// -Wmaybe-uninitialized at -O1.)
std::size_t find_key(const std::string& line, const std::string& key) {
  for (std::size_t pos = line.find(key); pos != std::string::npos; pos = line.find(key, pos + 1)) {
    if (pos > 0 && line[pos - 1] != ' ' && line[pos - 1] != '{' && line[pos - 1] != ',') continue;
    std::size_t i = pos + key.size();
    while (i < line.size() && line[i] == ' ') ++i;
    if (i >= line.size() || line[i] != ':') continue;
    ++i;
    while (i < line.size() && line[i] == ' ') ++i;
    return i;
  }
  return std::string::npos;
}

// Replaces the value of `key:` on `line` (flow or block style); false when the key is absent.
bool replace_value(std::string& line, const std::string& key, const std::string& value) {
  const std::size_t start = find_key(line, key);
  if (start == std::string::npos) return false;
  // The value runs to the next ',' or '}' at bracket depth 0, or a comment, or the line's end.
  int depth = 0;
  std::size_t end = start;
  for (; end < line.size(); ++end) {
    const char c = line[end];
    if (c == '(' || c == '[') ++depth;
    if (c == ')' || c == ']') --depth;
    if (depth == 0 && (c == ',' || c == '}' || c == '#')) break;
  }
  while (end > start && line[end - 1] == ' ') --end;
  line.replace(start, end - start, value);
  return true;
}

std::string number(double v) {
  return fmt::format("{:.17g}", v);
}

int indent_of(const std::string& line) {
  return static_cast<int>(
      line.find_first_not_of(' ') == std::string::npos ? 0 : line.find_first_not_of(' '));
}

// Inserts `key: value` into the flow map that follows `map_key:` on `line`; false if absent.
bool insert_into_flow_map(std::string& line, const std::string& map_key, const std::string& key,
                          const std::string& value) {
  const std::size_t open = find_key(line, map_key);
  if (open == std::string::npos || open >= line.size() || line[open] != '{') return false;
  int depth = 0;
  for (std::size_t i = open; i < line.size(); ++i) {
    if (line[i] == '{') ++depth;
    if (line[i] == '}' && --depth == 0) {
      const bool empty = line.find_first_not_of(' ', open + 1) == i;
      line.insert(i, fmt::format("{}{}: {}", empty ? "" : ", ", key, value));
      return true;
    }
  }
  return false;
}

}  // namespace

std::string calibrated_robot_yaml(const std::string& original, const Mechanism& model,
                                  const Eigen::VectorXd& values,
                                  const std::vector<std::size_t>& changed,
                                  const std::vector<std::string>& provenance) {
  if (values.size() != static_cast<Eigen::Index>(model.parameters.size()))
    throw std::invalid_argument("calibrated_robot_yaml: one value per parameter needed");
  std::vector<std::string> lines = split_lines(original);
  // Extra lines to insert after a given (0-based) line, applied at the end so indices stay valid.
  std::vector<std::vector<std::string>> after(lines.size());

  for (std::size_t i : changed) {
    const Parameter& p = model.parameters[i];
    const double v = values(static_cast<Eigen::Index>(i));
    const std::string key = p.name.substr(p.name.rfind('.') + 1);
    const std::string file_key = key == "encoder_offset"  ? "offset"
                                 : key == "encoder_scale" ? "scale"
                                                          : key;
    if (p.line < 1 || p.line > static_cast<int>(lines.size()))
      throw std::runtime_error(
          fmt::format("{}: parameter {} has no line in the file", model.source, p.name));
    const auto li = static_cast<std::size_t>(p.line - 1);
    if (replace_value(lines[li], file_key, number(v))) continue;
    // Not written in the file (default value): insert it into the owning body's entry.
    const std::string map_key = file_key == key ? "params" : "encoder";
    // The body's entry spans from its line to the next list item at the same or lower indent.
    std::size_t end = li + 1;
    const int item_indent = indent_of(lines[li]);
    while (end < lines.size() &&
           !(indent_of(lines[end]) <= item_indent &&
             lines[end].find_first_not_of(' ') != std::string::npos &&
             lines[end][static_cast<std::size_t>(indent_of(lines[end]))] == '-'))
      ++end;
    bool done = false;
    if (map_key == "encoder")  // the encoder map may sit on any line of the body's entry
      for (std::size_t k = li; k < end && !done; ++k)
        done = lines[k].find("encoder:") != std::string::npos &&
               replace_value(lines[k], file_key, number(v));
    for (std::size_t k = li; k < end && !done; ++k)
      done = insert_into_flow_map(lines[k], map_key, file_key, number(v));
    for (std::size_t k = 0; k < after[li].size() && !done; ++k)
      done = insert_into_flow_map(after[li][k], map_key, file_key, number(v));
    if (done) continue;
    const std::string& first = lines[li];
    const auto brace = first.rfind('}');
    if (first.find('{') != std::string::npos && brace != std::string::npos &&
        first.find("- {") != std::string::npos) {
      // A whole body written as one flow map: add the map before its closing brace.
      lines[li].insert(brace, fmt::format(", {}: {{{}: {}}}", map_key, file_key, number(v)));
    } else {
      // Block-style body: a new line at the body's key indentation.
      const int key_indent = item_indent + 2;
      after[li].push_back(
          fmt::format("{:{}}{}: {{{}: {}}}", "", key_indent, map_key, file_key, number(v)));
    }
  }

  std::string out;
  for (const auto& l : provenance) out += "# " + l + "\n";
  for (std::size_t k = 0; k < lines.size(); ++k) {
    out += lines[k] + "\n";
    for (const auto& extra : after[k]) out += extra + "\n";
  }

  // Read it back: every parameter must load as the value intended.
  const Mechanism check = parse_robot_yaml(out, model.source + " (calibrated)");
  if (check.parameters.size() != model.parameters.size())
    throw std::runtime_error("calibrated robot file: parameter count changed on re-reading");
  Eigen::VectorXd expected = model.nominal_parameters();
  for (std::size_t i : changed)
    expected(static_cast<Eigen::Index>(i)) = values(static_cast<Eigen::Index>(i));
  for (std::size_t i = 0; i < check.parameters.size(); ++i) {
    const double want = expected(static_cast<Eigen::Index>(i));
    if (check.parameters[i].name != model.parameters[i].name ||
        std::abs(check.parameters[i].value - want) > 1e-12 * std::max(1.0, std::abs(want)))
      throw std::runtime_error(
          fmt::format("calibrated robot file: {} reads back as {} instead of {}",
                      model.parameters[i].name, check.parameters[i].value, want));
  }
  return out;
}

}  // namespace robocal::calib
