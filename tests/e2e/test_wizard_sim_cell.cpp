// The wizard as a newcomer meets it: `robocal sim-cell` (the simulated controller in its own
// process, the cameras served as GigE Vision cameras or as sim: cameras) and `robocal wizard` on
// a real pseudo-terminal, answered only with what sim-cell printed where the wizard has no
// default, Enter everywhere else, and "yes" where the robot is about to move. The result is
// judged against the simulator's truth (its true robot and cameras, which only `robocal
// validate` reads), never against the wizard's own figures.
#include "child_process.hpp"
#include "pty_process.hpp"
#include "test_paths.hpp"

#include <fmt/core.h>
#include <fmt/ranges.h>
#include <gtest/gtest.h>
#include <yaml-cpp/yaml.h>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <regex>
#include <set>
#include <sstream>
#include <string>
#include <thread>

namespace {

namespace fs = std::filesystem;
using namespace std::chrono_literals;

std::string robocal() {
  return robocal::test::robocal_binary();
}

std::string read_text(const fs::path& p) {
  std::ifstream in(p);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

// sim-cell started and ready: its answers for the wizard, by key.
struct Cell {
  std::unique_ptr<robocal::test::ChildProcess> process;
  std::map<std::string, std::string> answers;
  fs::path dir;
};

Cell start_cell(const fs::path& dir, const std::string& robot, unsigned seed,
                const std::vector<std::string>& extra) {
  Cell c;
  c.dir = dir;
  std::vector<std::string> args = {"sim-cell",           "--robot", robot,       "--seed",
                                   std::to_string(seed), "--out",   dir.string()};
  args.insert(args.end(), extra.begin(), extra.end());
  c.process = std::make_unique<robocal::test::ChildProcess>(
      robocal(), args, (dir.parent_path() / "sim-cell.log").string());
  const auto end = std::chrono::steady_clock::now() + 600s;
  while (c.process->output().find("ready:") == std::string::npos) {
    if (!c.process->running() || std::chrono::steady_clock::now() > end) {
      ADD_FAILURE() << "sim-cell did not become ready:\n" << c.process->output();
      return c;
    }
    std::this_thread::sleep_for(200ms);
  }
  const YAML::Node root = YAML::LoadFile((dir / "wizard_answers.yaml").string());
  for (const auto& kv : root) c.answers[kv.first.as<std::string>()] = kv.second.as<std::string>();
  return c;
}

// The last prompt the wizard shows, if the output ends with one: "question [default] (key): ".
std::optional<std::string> pending_prompt(const std::string& output, std::size_t from) {
  static const std::regex prompt(R"(\(([a-z_0-9]+(\.[a-z_0-9]+)+)\): $)");
  if (output.size() <= from) return std::nullopt;
  std::smatch m;
  const std::string tail = output.substr(
      output.rfind('\n') == std::string::npos ? from : std::max(from, output.rfind('\n') + 1));
  if (std::regex_search(tail, m, prompt)) return m[1].str();
  return std::nullopt;
}

struct WizardRun {
  int code = -1;
  std::string output;
  std::vector<std::string> asked;  // keys, in order
};

// Runs the wizard on a pseudo-terminal: sim-cell's answer where it gave one, "yes" to the
// motion confirmations, Enter elsewhere. Stops typing and sends Ctrl-C when `interrupt_at` is
// asked (empty: never).
WizardRun run_wizard(const std::vector<std::string>& args,
                     const std::map<std::string, std::string>& answers,
                     const std::string& interrupt_at = "") {
  robocal::test::PtyProcess wizard(robocal(), args);
  WizardRun run;
  std::size_t answered_up_to = 0;
  const auto end = std::chrono::steady_clock::now() + 1500s;
  for (;;) {
    if (!wizard.pump(100)) break;
    if (std::chrono::steady_clock::now() > end) break;
    const std::string& out = wizard.output();
    const auto key = pending_prompt(out, answered_up_to);
    if (!key) continue;
    // A prompt is complete once nothing more arrives for a moment.
    std::this_thread::sleep_for(150ms);
    wizard.pump(10);
    if (wizard.output().size() != out.size()) continue;
    answered_up_to = out.size();
    run.asked.push_back(*key);
    // A problem the wizard keeps meeting ("retry" is its default) fails the run, not a hang.
    if (key->find(".problem") != std::string::npos &&
        std::count(run.asked.begin(), run.asked.end(), *key) > 3) {
      ADD_FAILURE() << *key << " asked again and again:\n" << out;
      wizard.type("\x03");
      break;
    }
    if (*key == interrupt_at) {
      wizard.type("\x03");
      break;
    }
    std::string answer;
    if (answers.count(*key) != 0) {
      answer = answers.at(*key);
    } else if (*key == "safety.confirm" || *key == "collection.continue") {
      answer = "yes";
    }
    wizard.type(answer + "\r");
  }
  run.code = wizard.wait(120s);
  run.output = wizard.output();
  return run;
}

double validate_rms(const fs::path& session, const fs::path& cell) {
  fs::remove_all(session / "truth");
  fs::copy(cell / "simulator" / "truth", session / "truth", fs::copy_options::recursive);
  const fs::path json = session.parent_path() / "validation.json";
  robocal::test::ChildProcess v(
      robocal(), {"validate", session.string(), "--held-out", "200", "--json", json.string()},
      (session.parent_path() / "validate.log").string());
  EXPECT_EQ(v.wait(600s), 0) << v.output();
  const auto j = nlohmann::json::parse(read_text(json));
  return j.at("calibrated").at("rms_m").get<double>();
}

// A wizard run's answers and results (wizard.yaml's values), paths into its own folder written
// FOLDER so that two runs compare.
std::map<std::string, std::string> kept_values(const fs::path& folder) {
  std::map<std::string, std::string> v;
  const YAML::Node state = YAML::LoadFile((folder / "wizard.yaml").string());
  for (const auto& kv : state["values"]) {
    std::string text = kv.second.as<std::string>();
    const std::string own = folder.string();
    for (auto at = text.find(own); at != std::string::npos; at = text.find(own))
      text.replace(at, own.size(), "FOLDER");
    v[kv.first.as<std::string>()] = text;
  }
  return v;
}

// A file of a wizard run with the run's own folder written FOLDER and its creation time left out
// (two runs record at different times).
std::string run_file(const fs::path& folder, const fs::path& file) {
  std::string text = read_text(folder / file);
  for (auto at = text.find(folder.string()); at != std::string::npos;
       at = text.find(folder.string()))
    text.replace(at, folder.string().size(), "FOLDER");
  const auto created = text.find("\ncreated: ");
  if (created != std::string::npos) text.erase(created, text.find('\n', created + 1) - created);
  return text;
}

// The uninterrupted run: Enter wherever the wizard has a default.
WizardRun calibrate(const Cell& cell, const fs::path& folder, const std::string& robot) {
  WizardRun run = run_wizard({"wizard", folder.string()}, cell.answers);
  EXPECT_EQ(run.code, 0) << run.output;
  EXPECT_NE(run.output.find("All steps done"), std::string::npos) << run.output;
  // One unit throughout, and nothing the wizard does itself offered as a next command.
  EXPECT_EQ(run.output.find(" um "), std::string::npos) << run.output;
  EXPECT_EQ(run.output.find("next: "), std::string::npos) << run.output;
  if (run.code == 0) {
    // The simulator's truth on 200 held-out poses (validate_rms): the product's 50 µm for a
    // first calibration. The rotary Delta runs at the cameras' full size, which that bound needs
    // (its quick cell's smaller images measure the board too coarsely for it).
    EXPECT_LE(validate_rms(folder / "session", cell.dir), 50e-6) << robot;
  }
  return run;
}

// Ctrl-C at the first question of every step, then --resume: each run goes one step further;
// the answers kept, the plan and the session description are the uninterrupted run's, and the
// calibration is as good.
void interrupt_every_step(const Cell& cell, const fs::path& folder, const WizardRun& whole,
                          const fs::path& straight) {
  std::vector<std::string> firsts;
  std::set<std::string> steps;
  for (const auto& key : whole.asked)
    if (steps.insert(key.substr(0, key.find('.'))).second) firsts.push_back(key);
  ASSERT_GE(firsts.size(), 8u) << fmt::format("{}", fmt::join(whole.asked, " "));
  for (std::size_t k = 0; k < firsts.size(); ++k) {
    const std::vector<std::string> args =
        k == 0 ? std::vector<std::string>{"wizard", folder.string()}
               : std::vector<std::string>{"wizard", "--resume", folder.string()};
    const WizardRun run = run_wizard(args, cell.answers, firsts[k]);
    ASSERT_EQ(run.code, 130) << "Ctrl-C at " << firsts[k] << "\n" << run.output;
  }
  const WizardRun last = run_wizard({"wizard", "--resume", folder.string()}, cell.answers);
  ASSERT_EQ(last.code, 0) << last.output;
  const auto a = kept_values(straight);
  const auto b = kept_values(folder);
  for (const auto& [key, value] : a) {
    if (key.rfind("validate.", 0) == 0) continue;  // held-out figures of two collections
    ASSERT_EQ(b.count(key), 1u) << key << " lost on resume";
    EXPECT_EQ(b.at(key), value) << key;
  }
  EXPECT_EQ(run_file(straight, "plan.yaml"), run_file(folder, "plan.yaml"));
  EXPECT_EQ(run_file(straight, "session/session.yaml"), run_file(folder, "session/session.yaml"));
  EXPECT_LE(validate_rms(folder / "session", cell.dir), 50e-6);
}

// The wizard's export against the simulator's truth: the file the export step wrote is the one
// `robocal export` writes for its session, and the exports test's own checks (test_exports.cpp,
// computed from the true robot independently of the export code: the true nozzle driven through
// the Klipper settings, the URDF's tool, base and camera links, the rotary Delta's program in
// shoulder angles; tool and base within 0.1 mm) pass on the wizard's session. Needs the truth in
// the session (validate_rms copies it there).
void exports_match_truth(const fs::path& folder, const std::string& robot,
                         const std::string& check) {
  // (No format is asked where none describes the robot: the rotary Delta's controller takes
  // the compensated program instead.)
  const auto values = kept_values(folder);
  const std::string format =
      values.count("export.format") != 0 ? values.at("export.format") : "none";
  if (format != "none") {
    const fs::path written = folder / "export" / ("calibrated." + format);
    ASSERT_TRUE(fs::exists(written)) << written;
    const fs::path again = folder.parent_path() / ("export_again." + format);
    robocal::test::ChildProcess e(
        robocal(),
        {"export", (folder / "session").string(), "--format", format, "--out", again.string()},
        (folder.parent_path() / "export.log").string());
    ASSERT_EQ(e.wait(300s), 0) << e.output();
    EXPECT_EQ(read_text(written), read_text(again)) << written;
  }
  const char* checks = std::getenv("ROBOCAL_EXPORTS_TEST");
  ASSERT_NE(checks, nullptr) << "ROBOCAL_EXPORTS_TEST (the exports test binary) is not set";
  const fs::path sessions = folder.parent_path() / "exports_sessions";
  fs::create_directories(sessions);
  fs::create_directory_symlink(fs::absolute(folder / "session"),
                               sessions / ("robocal_e2e_exports_" + robot));
  ::setenv("ROBOCAL_E2E_SESSIONS", sessions.c_str(), 1);
  robocal::test::ChildProcess t(checks, {"--gtest_filter=ExportsAgainstTruth." + check},
                                (folder.parent_path() / "exports_test.log").string());
  const int code = t.wait(600s);
  ::unsetenv("ROBOCAL_E2E_SESSIONS");
  EXPECT_EQ(code, 0) << t.output();
  EXPECT_NE(t.output().find("[  PASSED  ] 1 test"), std::string::npos) << t.output();
}

void stop(Cell& cell) {
  cell.process->signal(SIGINT);
  EXPECT_EQ(cell.process->wait(60s), 0) << cell.process->output();
}

fs::path fresh(const std::string& name) {
  const fs::path root = fs::temp_directory_path() / name;
  fs::remove_all(root);
  fs::create_directories(root);
  return root;
}

// The rotary Delta with its cameras served as GigE Vision cameras: once without a stop, then
// stopped with Ctrl-C at every step and resumed, on the same simulated cell.
TEST(WizardOnSimCell, RotaryDeltaFromRobotChoiceToExportAndCtrlCAtEveryStep) {
  const fs::path root = fresh("robocal_e2e_wizard_rotary_delta");
  Cell cell = start_cell(root / "cell", "rotary_delta", 1, {});
  ASSERT_FALSE(cell.answers.empty());
  const WizardRun whole = calibrate(cell, root / "straight", "rotary_delta");
  if (whole.code == 0) {
    exports_match_truth(root / "straight", "rotary_delta", "RotaryDelta*");
    interrupt_every_step(cell, root / "resumed", whole, root / "straight");
  }
  stop(cell);
}

// Both cameras rendered by the wizard's own process (sim: cameras), as on a machine that serves
// no GigE camera, on an arm.
TEST(WizardOnSimCell, Ur5WithSimCamerasFromRobotChoiceToExport) {
  const fs::path root = fresh("robocal_e2e_wizard_ur5");
  Cell cell = start_cell(root / "cell", "ur5", 1, {"--quick", "--in-process"});
  ASSERT_FALSE(cell.answers.empty());
  if (calibrate(cell, root / "cal1", "ur5").code == 0)
    exports_match_truth(root / "cal1", "ur5", "Ur5*");
  stop(cell);
}

// The linear delta printer as its owner runs it: Klipper, reached through Moonraker, in its own
// delta kinematics. Its board hangs on the effector's side (its bed hides a board facing down),
// seen by an array of cameras; the first served as a GigE Vision camera, the others as sim:
// cameras where the namespace has no address for them. The export step proposes the settings for
// the firmware the link talked to, and Enter takes them.
TEST(WizardOnSimCell, LinearDeltaOnKlipperFromRobotChoiceToKlipperExport) {
  const fs::path root = fresh("robocal_e2e_wizard_linear_delta");
  Cell cell = start_cell(root / "cell", "linear_delta", 1, {"--quick", "--firmware", "klipper"});
  ASSERT_FALSE(cell.answers.empty());
  EXPECT_EQ(cell.answers.at("controller.link").rfind("moonraker:", 0), 0U)
      << cell.answers.at("controller.link");
  const WizardRun run = calibrate(cell, root / "cal1", "linear_delta");
  EXPECT_NE(run.output.find("driven in the firmware's own delta kinematics"), std::string::npos)
      << run.output;
  EXPECT_NE(run.output.find("[klipper] (export.format)"), std::string::npos) << run.output;
  if (run.code == 0) {
    EXPECT_EQ(kept_values(root / "cal1").at("export.format"), "klipper");
    exports_match_truth(root / "cal1", "linear_delta", "Klipper*");
  }
  stop(cell);
}

}  // namespace
