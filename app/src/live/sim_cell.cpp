#include "live/sim_cell.hpp"

#include "cli/cli_common.hpp"
#include "cli/command_registry.hpp"
#include "live/live_cameras.hpp"
#include "live/live_cell.hpp"
#include "live/sim_camera.hpp"
#include "live/simulated_setup.hpp"
#include "robocal/calib/robot_file.hpp"
#include "robocal/core/files.hpp"
#include "robocal/planner/cell.hpp"
#include "robocal/robotio/gcode_link.hpp"
#include "robocal/robotio/link_factory.hpp"
#include "robocal/robotio/safety_guard.hpp"
#include "robocal/robotio/sim_process.hpp"
#include "robocal/robotio/sim_truth.hpp"
#include "session/results_files.hpp"
#include "session/results_layout.hpp"
#include "session/session_robot.hpp"
#include "stages/cell_truth.hpp"

#include <fmt/core.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <csignal>
#include <fstream>
#include <thread>

namespace robocal::app {

namespace fs = std::filesystem;

namespace {

std::atomic<bool> g_cell_stop{false};
extern "C" void on_cell_signal(int /*signal*/) {
  g_cell_stop = true;
}

// The folder's identity: a folder made for another robot or seed is not reused.
std::string identity(const SimCellOptions& o, const std::string& robot_file) {
  return fmt::format("robot: {}\nseed: {}\nquick: {}\nidealised_truth: {}\n",
                     fs::absolute(robot_file).string(), o.seed, o.quick, o.idealised_truth);
}

void prepare_folder(const SimCellOptions& o, const std::string& robot_file,
                    const SimCellLayout& at) {
  const fs::path id = at.simulator() / "cell_identity.yaml";
  if (fs::exists(at.dir) && !fs::is_empty(at.dir)) {
    if (!fs::exists(id))
      throw InputError(at.dir.string() +
                       ": exists and is not a sim-cell folder; give a new folder with --out");
    if (core::read_text_file(id) != identity(o, robot_file))
      throw InputError(fmt::format(
          "{}: holds a simulated cell of another robot or seed ({}); give a new folder with --out",
          at.dir.string(), id.string()));
  }
  fs::create_directories(at.simulator());
  core::write_file_atomic(id, identity(o, robot_file));
}

// The true robot and cameras, where validation (never the pipeline) reads them: copied into a
// recorded session's truth/ folder, `robocal validate` compares the calibration with them.
void write_simulator_truth(const LiveCell& lc, const SimCellLayout& at) {
  const TruthFile truth =
      cell_truth(lc.cell, "robocal sim-cell: the simulated controller's true robot");
  write_truth(ResultsLayout{at.simulator()}, lc.cell.model, truth);
}

// Whether `pid` still runs (a child that ended and was not yet waited for is a zombie: 'Z').
bool process_running(pid_t pid) {
  std::ifstream in(fmt::format("/proc/{}/stat", pid));
  std::string stat;
  std::getline(in, stat);
  const auto close = stat.rfind(')');
  return close != std::string::npos && close + 2 < stat.size() && stat[close + 2] != 'Z';
}

// Like an operator who jogs the robot until the cameras see the board before starting the
// wizard (whose cameras step checks a frame): the controller homed, then the robot moved to the
// first pose of the nominal robot where the cell's cameras see the whole board.
void jog_into_view(const LiveCell& lc, const std::string& robot_file, const LiveCellFiles& files,
                   const std::string& link_address, unsigned seed, const Commandable& commandable,
                   std::FILE* out) {
  const calib::Mechanism model = calib::load_robot_file(robot_file);
  const double speed = default_speed(model);
  const robotio::MoveSpeed move{speed, 10.0 * speed};
  const planner::Cell pcell = planner::load_cell_file(files.cell.string());
  const auto poses = sampled_poses(lc.cell, model, pcell, 1, seed, move, commandable);
  if (poses.empty()) {
    fmt::print(out, "  (no pose found where the cameras see the board: the robot stays home)\n");
    return;
  }
  robotio::SafetyLimits limits;
  limits.max_speed = move.speed;
  limits.max_acceleration = move.acceleration;
  robotio::SafetyGuard guard(model, model.nominal_parameters(), limits);
  guard.arm("sim-cell: the simulated robot is moved into the cameras' view");
  robotio::GcodeLinkOptions lo;
  lo.address = link_address;
  lo.axes = robotio::axes_for_robot(model, 80.0, 100.0);  // sim-controller's defaults
  lo.mode = robotio::GcodeMode::kAuto;  // a delta printer in its firmware's own kinematics
  // The address names the protocol (open:HOST:PORT, tcp:HOST:PORT or moonraker:HOST:PORT).
  const std::unique_ptr<robotio::RobotLink> link = robotio::make_robot_link(guard, lo);
  link->connect();
  link->home();
  link->move_actuators(poses.front(), move);
  link->disconnect();
}

struct Answer {
  std::string key, question, value;
};

// What to answer in the wizard, where the wizard has no default that fits this cell.
std::vector<Answer> wizard_answers(const SimCellOptions& o, const SimCellLayout& at,
                                   const std::string& link, const std::string& cameras,
                                   const std::vector<std::string>& names) {
  std::vector<Answer> a = {{"robot.model", "Robot", o.robot},
                           {"controller.link", "Controller address", link},
                           {"cameras.list", "Cameras", cameras},
                           {"cameras.target", "Target file of the board on the end-effector",
                            (at.cell_dir() / "end_effector.yaml").string()}};
  for (const auto& n : names)
    a.push_back(
        {"intrinsics." + n, "Intrinsics of " + n, (at.views() / "intrinsics" / n).string()});
  a.push_back({"intrinsics.board", "Target file of the calibration board",
               (at.cell_dir() / "calibration.yaml").string()});
  a.push_back({"cell.file", "Cell file", (at.cell_dir() / "cell.yaml").string()});
  a.push_back({"identify.views", "Folder with the calibration views", at.views().string()});
  return a;
}

std::string answers_yaml(const std::vector<Answer>& answers) {
  std::string text =
      "# Answers for `robocal wizard --answers THIS_FILE` on this simulated cell (the wizard\n"
      "# asks the rest, each with a default). Written by robocal sim-cell.\n";
  for (const auto& a : answers) text += fmt::format("{}: \"{}\"\n", a.key, a.value);
  return text;
}

}  // namespace

int run_sim_cell(const SimCellOptions& o) {
  if (o.seed == 0) throw UsageError("--seed must be 1 or more (0 would be the nominal robot)");
  if (o.tcp_port < 0 || o.tcp_port > 65535)
    throw InputError(
        fmt::format("--port {}: give a TCP port 1-65535, or 0 for any free one", o.tcp_port));
  const std::string robot_file = resolve_robot(o.robot);
  const SimCellLayout at{fs::absolute(
      o.out.empty() ? fmt::format("sim-cell-{}-seed{}", fs::path(o.robot).stem().string(), o.seed)
                    : o.out)};
  prepare_folder(o, robot_file, at);
  std::FILE* out = stdout;
  const PipelineLog log{out, nullptr, 2};
  fmt::print(out, "robocal sim-cell: a simulated {} (seed {}) in {}\n", o.robot, o.seed,
             at.dir.string());

  LiveDemoOptions lo;
  lo.robot = o.robot;
  lo.seed = o.seed;
  lo.quick = o.quick;
  lo.idealised_truth = o.idealised_truth;
  const LiveCell lc = make_live_cell(lo, robot_file);
  const LiveCellFiles files = write_live_cell(lc.cell, robot_file, at.cell_dir());
  // The true geometry is the simulator's, not the operator's: out of the cell's folder.
  const fs::path truth_txt = at.simulator() / "true_parameters.txt";
  fs::rename(files.perturbation, truth_txt);
  // The same robot and seed give the same truth: a reused folder keeps the one it has.
  if (!fs::exists(ResultsLayout{at.simulator()}.truth())) write_simulator_truth(lc, at);
  const auto specs = camera_specs(lc.cell, o.seed, 2);
  if (!fs::exists(at.views() / "done")) {
    // Views without the done mark are what an interrupted run left: the simulator's own
    // renderings (the same seed renders the same pixels), taken again whole.
    fs::remove_all(at.views());
    fmt::print(out, "calibration images: the board held in front of the cameras ({} views)\n",
               lc.intrinsic_views.empty() ? 0 : lc.intrinsic_views.front().size());
    nlohmann::json ignored;
    take_calibration_views(lc, specs, o.gige, at.views(), log, ignored);
    core::write_file_atomic(at.views() / "done", "ok\n");
  }

  const bool native = simulated_native_delta(lc.cell.model, o.protocol, o.firmware, o.gcode_mode);
  const bool klipper = native && o.firmware == "klipper";
  std::vector<std::string> args = {
      "--robot",         robot_file,
      "--seed",          std::to_string(o.seed),
      "--perturbation",  truth_txt.string(),
      "--firmware",      o.firmware,
      "--kinematics",    native ? "delta" : "axes",
      "--protocol",      o.protocol,
      "--tcp-port",      std::to_string(o.tcp_port),
      "--log",           (at.simulator() / "sim-controller.jsonl").string(),
      "--busy-interval", "1"};
  // A Klipper printer is reached through Moonraker on the network, never over a serial line.
  if (klipper) {
    args.emplace_back("--no-pty");
  } else {
    args.insert(args.end(), {"--pty-link", (at.simulator() / "tty").string()});
  }
  robotio::SimControllerProcess sim(robocal_binary(), args);
  const std::string link_address = simulated_link_address(sim, o.protocol, klipper);
  jog_into_view(lc, robot_file, files, link_address, o.seed,
                native ? drawing_commandability(lc.cell.model, o.firmware) : Commandable{}, out);
  robotio::SimControllerTruth truth(sim.pose(), robotio::BoardMounting{});
  SaggingBoard seen(truth, lc.cell.elastic_sag);
  LiveCameras cams(specs, lc.cell.ee_board, {&seen}, o.gige, fmt::format("S{}-", ::getpid()));
  std::string camera_list;
  std::vector<std::string> names;
  for (std::size_t c = 0; c < specs.size(); ++c) {
    std::string source = cams.source(c);
    if (!cams.served(c)) {
      const fs::path file = at.simulator() / (specs[c].name + ".camera.yaml");
      core::write_file_atomic(file, sim_camera_yaml({robot_file, o.seed, o.quick, o.idealised_truth,
                                                     specs[c].name, sim.pose()}));
      source = "sim:" + file.string();
    }
    camera_list += (camera_list.empty() ? "" : " ") + specs[c].name + "=" + source;
    names.push_back(specs[c].name);
  }
  const auto answers = wizard_answers(o, at, link_address, camera_list, names);
  core::write_file_atomic(at.answers(), answers_yaml(answers));

  if (o.protocol == "open")
    fmt::print(out,
               "\ncontroller: the open link protocol at {} (read replies carry the flange pose)\n",
               link_address);
  else if (klipper)
    fmt::print(out, "\ncontroller: a Klipper delta printer, Moonraker at {}\n",
               link_address.substr(link_address.find(':') + 1));
  else
    fmt::print(out, "\ncontroller: {} firmware{}, G-code at {} (serial: {})\n", o.firmware,
               native ? " in its own delta kinematics" : "", sim.tcp(),
               (at.simulator() / "tty").string());
  for (std::size_t c = 0; c < specs.size(); ++c)
    fmt::print(out, "camera {}: {}\n", specs[c].name,
               cams.served(c) ? fmt::format("GigE Vision through Aravis' fake camera on {}",
                                            live_camera_address(c))
                              : std::string("rendered by the program that opens it (sim:)"));
  if (specs.size() > 1 && !cams.served(1) && cams.served(0))
    fmt::print(out,
               "  (only 127.0.0.1 serves a fake GigE camera here; as root, `ip addr add "
               "127.0.0.2/32 dev lo` gives the second camera an address of its own)\n");
  else
    for (const auto& n : cams.notes()) fmt::print(out, "  {}\n", n);
  fmt::print(out,
             "\nIn another terminal, run `robocal wizard FOLDER` and answer (Enter takes the "
             "default elsewhere):\n");
  for (const auto& a : answers) fmt::print(out, "  {:<46} {}\n", a.question + ":", a.value);
  fmt::print(out,
             "or give these answers at once: robocal wizard FOLDER --answers {}\n"
             "The simulator's true robot (for `robocal validate` after the wizard): copy {} into "
             "the wizard's session folder.\n"
             "ready: Ctrl-C stops the cell\n",
             at.answers().string(), (at.simulator() / "truth").string());
  std::fflush(out);

  g_cell_stop = false;
  struct sigaction sa {};
  sa.sa_handler = on_cell_signal;
  sigemptyset(&sa.sa_mask);
  sigaction(SIGINT, &sa, nullptr);
  sigaction(SIGTERM, &sa, nullptr);
  const auto start = std::chrono::steady_clock::now();
  while (!g_cell_stop) {
    std::this_thread::sleep_for(std::chrono::milliseconds(200));
    if (o.max_seconds > 0 &&
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count() >
            o.max_seconds)
      break;
    if (!process_running(sim.pid())) {
      fmt::print(stderr, "sim-cell: the simulated controller (pid {}) ended; stopping the cell\n",
                 sim.pid());
      return kExitFailure;
    }
  }
  fmt::print(out, "sim-cell: stopped\n");
  sim.stop();
  return kExitOk;
}

}  // namespace robocal::app
