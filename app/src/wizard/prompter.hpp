#pragma once
// The wizard's questions: each has a key (step.prompt, e.g. "robot.model"), a question in plain
// words and a default shown in brackets. The answer comes from the answers file (--answers), or
// from the operator at a terminal (GNU readline: line editing and history), or, with neither, the
// wizard stops with MissingAnswer naming the key (nothing recorded is lost).
#include <cstdio>
#include <map>
#include <set>
#include <stdexcept>
#include <string>
#include <vector>

namespace robocal::app::wizard {

// No answer for `key` and nobody to ask (no terminal, or the answers file's answer was refused
// and there is no terminal to ask again).
class MissingAnswer : public std::runtime_error {
 public:
  MissingAnswer(std::string key, const std::string& why)
      : std::runtime_error(why), key_(std::move(key)) {}
  [[nodiscard]] const std::string& key() const { return key_; }

 private:
  std::string key_;
};

// The operator ended the input (Ctrl-D at a prompt): stop, keep everything, resumable.
class OperatorQuit : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// Answers by key from a file: YAML (nested maps flattened with dots: `robot: {model: x}` ->
// robot.model) or `key=value` lines (# comments). Throws core::InputError naming the file.
std::map<std::string, std::string> load_answers(const std::string& path);

// Refuses (core::InputError naming `path`, the key and the keys allowed) an answer whose key
// matches none of `known` (glob patterns, e.g. "intrinsics.*.view"): a misspelled key would
// otherwise be ignored and its question answered by the default, or end the run on a question
// that seems to have no answer.
void reject_unknown_answers(const std::map<std::string, std::string>& answers,
                            const std::string& path, const std::vector<std::string>& known);

class Prompter {
 public:
  // interactive: ask on the terminal when the answers file has no (usable) answer.
  // accept_defaults: a prompt with a default takes it without asking when nothing answers.
  Prompter(std::map<std::string, std::string> answers, bool interactive, bool accept_defaults,
           std::FILE* out);

  // The answer to `key` (trimmed); an empty line takes the default. A key asked a second time in
  // a run (its first answer was refused) is asked on the terminal, not taken from the file again.
  std::string ask(const std::string& key, const std::string& question,
                  const std::string& default_value = "");
  // One of `choices` (the first letter or the whole word); asks again on anything else.
  std::string choose(const std::string& key, const std::string& question,
                     const std::vector<std::string>& choices, const std::string& default_value);
  // yes / no.
  bool confirm(const std::string& key, const std::string& question, bool default_value);

  [[nodiscard]] bool interactive() const { return interactive_; }
  // Whether the answers file answers `key` (a script's run can skip a question it leaves out).
  [[nodiscard]] bool has_answer(const std::string& key) const { return answers_.count(key) != 0; }
  [[nodiscard]] const std::map<std::string, std::string>& given() const { return given_; }

 private:
  std::string read_line(const std::string& prompt);

  std::map<std::string, std::string> answers_;
  std::set<std::string> used_;                // keys answered from the file in this run
  std::map<std::string, std::string> given_;  // every answer of this run
  bool interactive_;
  bool accept_defaults_;
  std::FILE* out_;
};

}  // namespace robocal::app::wizard
