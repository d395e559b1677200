#include "wizard/prompter.hpp"

#include "cli/cli_common.hpp"

#include <fmt/core.h>
#include <fnmatch.h>
#include <readline/history.h>
#include <readline/readline.h>
#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cctype>
#include <cstdlib>
#include <fstream>
#include <sstream>

namespace robocal::app::wizard {
namespace {

std::string trim(const std::string& s) {
  const auto b = s.find_first_not_of(" \t\r\n");
  if (b == std::string::npos) return "";
  const auto e = s.find_last_not_of(" \t\r\n");
  return s.substr(b, e - b + 1);
}

void flatten(const YAML::Node& node, const std::string& prefix,
             std::map<std::string, std::string>& out) {
  for (const auto& kv : node) {
    std::string key = prefix;
    if (!key.empty()) key += '.';
    key += kv.first.as<std::string>();
    if (kv.second.IsMap()) {
      flatten(kv.second, key, out);
    } else if (kv.second.IsSequence()) {
      std::string joined;
      for (const auto& item : kv.second) {
        if (!joined.empty()) joined += ' ';
        joined += item.as<std::string>();
      }
      out[key] = joined;
    } else if (kv.second.IsScalar()) {
      out[key] = kv.second.as<std::string>();
    } else {
      out[key] = "";
    }
  }
}

}  // namespace

std::map<std::string, std::string> load_answers(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw InputError(path + ": cannot read the answers file");
  std::stringstream buffer;
  buffer << in.rdbuf();
  const std::string text = buffer.str();
  std::map<std::string, std::string> out;
  try {
    const YAML::Node root = YAML::Load(text);
    if (root.IsMap()) {
      flatten(root, "", out);
      return out;
    }
  } catch (const YAML::Exception&) {
    // not YAML: key=value lines below
  }
  std::istringstream lines(text);
  std::string line;
  int n = 0;
  while (std::getline(lines, line)) {
    ++n;
    const std::string t = trim(line);
    if (t.empty() || t[0] == '#') continue;
    const auto eq = t.find('=');
    if (eq == std::string::npos || eq == 0)
      throw InputError(fmt::format(
          "{}:{}: expected key=value (e.g. robot.model=linear_delta) or a YAML map", path, n));
    out[trim(t.substr(0, eq))] = trim(t.substr(eq + 1));
  }
  return out;
}

void reject_unknown_answers(const std::map<std::string, std::string>& answers,
                            const std::string& path, const std::vector<std::string>& known) {
  const auto is_known = [&known](const std::string& key) {
    return std::any_of(known.begin(), known.end(), [&key](const std::string& pattern) {
      return ::fnmatch(pattern.c_str(), key.c_str(), 0) == 0;
    });
  };
  for (const auto& answer : answers) {
    if (is_known(answer.first)) continue;
    std::string allowed;
    for (const std::string& k : known) allowed += (allowed.empty() ? "" : ", ") + k;
    throw InputError(
        fmt::format("{}: unknown key '{}' (the wizard's questions: {}; * is a "
                    "camera's name)",
                    path, answer.first, allowed));
  }
}

Prompter::Prompter(std::map<std::string, std::string> answers, bool interactive,
                   bool accept_defaults, std::FILE* out)
    : answers_(std::move(answers)),
      interactive_(interactive),
      accept_defaults_(accept_defaults),
      out_(out) {}

std::string Prompter::read_line(const std::string& prompt) {
  std::fflush(out_);
  char* line = ::readline(prompt.c_str());
  if (line == nullptr) throw OperatorQuit("input ended (Ctrl-D)");
  std::string s = trim(line);
  if (!s.empty()) ::add_history(line);
  std::free(line);  // NOLINT(cppcoreguidelines-no-malloc): readline's buffer
  return s;
}

std::string Prompter::ask(const std::string& key, const std::string& question,
                          const std::string& default_value) {
  const std::string shown =
      default_value.empty() ? question : fmt::format("{} [{}]", question, default_value);
  const auto it = answers_.find(key);
  if (it != answers_.end() && used_.count(key) == 0) {
    used_.insert(key);
    std::string value = it->second.empty() ? default_value : it->second;
    fmt::print(out_, "{}: {}   (answers file: {})\n", shown, value, key);
    given_[key] = value;
    return value;
  }
  const bool asked_before = used_.count(key) != 0;
  if (!interactive_) {
    if (accept_defaults_ && !default_value.empty() && !asked_before) {
      used_.insert(key);
      fmt::print(out_, "{}: {}   (default)\n", shown, default_value);
      given_[key] = default_value;
      return default_value;
    }
    throw MissingAnswer(
        key, asked_before
                 ? fmt::format("the answer to '{}' was refused (above) and there is no terminal "
                               "to ask again: correct {} in the answers file",
                               key, key)
                 : fmt::format("no answer for '{}' ({}) and no terminal to ask: add {}=VALUE "
                               "to the answers file",
                               key, question, key));
  }
  used_.insert(key);
  // The key as an answers file names it, so that a run can be scripted from what was asked.
  std::string value = read_line(fmt::format("{} ({}): ", shown, key));
  if (value.empty()) value = default_value;
  given_[key] = value;
  return value;
}

std::string Prompter::choose(const std::string& key, const std::string& question,
                             const std::vector<std::string>& choices,
                             const std::string& default_value) {
  std::string list;
  for (const auto& c : choices) {
    if (!list.empty()) list += '/';
    list += c;
  }
  for (int attempt = 0;; ++attempt) {
    std::string a = ask(key, fmt::format("{} ({})", question, list), default_value);
    std::transform(a.begin(), a.end(), a.begin(), [](unsigned char c) { return std::tolower(c); });
    for (const auto& c : choices)
      if (a == c || (a.size() == 1 && !c.empty() && a[0] == c[0])) return c;
    fmt::print(out_, "  '{}' is not one of {}\n", a, list);
    if (attempt > 20) throw OperatorQuit("no valid choice");
  }
}

bool Prompter::confirm(const std::string& key, const std::string& question, bool default_value) {
  return choose(key, question, {"yes", "no"}, default_value ? "yes" : "no") == "yes";
}

}  // namespace robocal::app::wizard
