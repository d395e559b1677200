// `robocal demo`: the whole pipeline on a simulated cell, from rendered images to a calibrated
// robot proven against the hidden truth, through a session folder (app/SESSION.md):
//   1. simulate  a true robot (library robot + realistic perturbations), cameras, boards;
//                rendered calibration views and pose images, actuator readings, truth/
//   2. measure   intrinsics per camera, stereo rig, board pose per robot pose (multi-camera PnP
//                with a 6x6 covariance), pixel observations
//   3. identify  closed-loop identification from the measured poses (base frame estimated)
//   4. validate  calibrated vs nominal model against the true robot on held-out poses
// Each stage is the same function `robocal simulate / measure / identify / validate` runs; the
// measurement stages never read truth/.
#include "cli/cli_common.hpp"
#include "cli/command_registry.hpp"
#include "live/live_demo.hpp"
#include "session/results_layout.hpp"
#include "session/session_robot.hpp"
#include "stages/stages.hpp"
#include "summary/validation_summary.hpp"

#include <fmt/core.h>

#include <cstdlib>
#include <filesystem>
#include <memory>
#include <string>

namespace robocal::app {

namespace {

struct DemoOptions {
  SimulateOptions simulate;
  int held_out = 500;
  int threads = 2;
  std::string out;
  std::string json;
  std::string route = "both";  // pose | pixel | both (identification routes reported)
  bool no_priors = false;
  bool live = false;  // the live loop (live/live_demo.hpp)
  bool intrinsic_views_given = false;
  bool in_process = false;
  bool yes = false;
  bool resume = false;
  double speed = 0.0;
  std::string firmware = "marlin";
  std::string gcode_mode = "raw";
};

int run_live(const DemoOptions& o) {
  if (o.no_priors) throw UsageError("--no-priors is not available with --live");
  LiveDemoOptions l;
  l.robot = o.simulate.robot;
  l.seed = o.simulate.seed;
  l.poses = o.simulate.poses;
  l.held_out = o.held_out;
  // Not given: the live demo's own default (kLiveIntrinsicViews per camera).
  l.intrinsic_views = o.intrinsic_views_given || o.simulate.quick ? o.simulate.intrinsic_views
                                                                  : kLiveIntrinsicViews;
  l.rig_views = o.simulate.rig_views;
  l.threads = o.threads;
  l.quick = o.simulate.quick;
  l.idealised_truth = o.simulate.idealised_truth;
  l.gige = !o.in_process;
  l.yes = o.yes;
  l.resume = o.resume;
  l.speed = o.speed;
  l.firmware = o.firmware;
  l.gcode_mode = o.gcode_mode;
  l.route = o.route;
  l.out = o.out;
  l.json = o.json;
  return run_live_demo(l);
}

// A fresh folder for the session when --out is not given.
std::filesystem::path fresh_folder(unsigned seed) {
  const auto base = std::filesystem::temp_directory_path();
  std::string pattern = (base / fmt::format("robocal-demo-seed{}-XXXXXX", seed)).string();
  if (mkdtemp(pattern.data()) == nullptr)
    throw InputError("cannot create a folder in " + base.string());
  return pattern;
}

int run_demo(DemoOptions o) {
  std::FILE* out = human_stream(o.json);
  StageClock clock;
  PipelineLog log{out, &clock, o.threads};
  // An unknown robot is refused before a folder is made or anything is announced.
  resolve_robot(o.simulate.robot);
  o.simulate.out = o.out.empty() ? fresh_folder(o.simulate.seed) : std::filesystem::path(o.out);
  const auto dir = o.simulate.out;
  fmt::print(out,
             "robocal demo: calibrating a simulated {} from rendered camera images (seed {})\n"
             "session folder: {}\n\n",
             o.simulate.robot, o.simulate.seed, dir.string());

  nlohmann::json report;
  report["simulate"] = simulate_session(o.simulate, log);
  fmt::print(out, "\nmeasure: cameras, rig and end-effector poses from the images\n");
  // A stage that cannot go on ends the demo with its reason in one line (the stage's own lines
  // above say the details); nothing written so far is removed.
  const auto stopped = [&](const char* stage, const nlohmann::json& result) {
    const auto& message = result.value("message", nlohmann::json());
    fmt::print(out, "\ndemo stopped at {} ({}): {}. The session folder keeps what was done: {}\n",
               stage, result.value("status", std::string("failed")),
               message.is_string() ? message.get<std::string>() : std::string("see above"),
               dir.string());
    return kExitFailure;
  };
  report["measure"] = measure_session(dir, "", log);
  if (report["measure"]["status"] != "ok") return stopped("measure", report["measure"]);
  fmt::print(out, "\nidentify\n");
  report["identify"] = identify_session(dir, "", log, o.route, !o.no_priors);
  if (report["identify"]["status"] != "ok") return stopped("identify", report["identify"]);
  fmt::print(out, "\nvalidate (against the truth, which only this stage reads)\n");
  report["validate"] = validate_session(dir, o.held_out, log);
  clock.stop();

  print_validation_summary(out, report["validate"], report["identify"]);
  fmt::print(out, "\n  time per stage:\n{}", clock.table());
  nlohmann::json stages = nlohmann::json::object();
  for (const auto& s : clock.stages()) stages[s.name] = s.seconds;
  report["seconds"] = stages;
  report["seed"] = o.simulate.seed;
  report["robot"] = o.simulate.robot;
  report["session"] = dir.string();
  // The page for people (results/report.html), with the stage times measured here.
  std::vector<std::pair<std::string, double>> seconds;
  for (const auto& s : clock.stages()) seconds.emplace_back(s.name, s.seconds);
  report["report"] = report_session(dir, PipelineLog{nullptr}, seconds);
  const std::string json_path =
      !o.json.empty() ? o.json : ResultsLayout{dir}.report("demo").string();
  write_json(report, json_path);
  fmt::print(out, "  session: {}\n  report: {}\n  page: {}\n", dir.string(), json_path,
             report["report"].value("page", ""));
  const bool improved = report["validate"].value("improved", false);
  if (!improved) fmt::print(stderr, "calibration did not improve the model\n");
  return improved ? kExitOk : kExitFailure;
}

}  // namespace

CommandSpec demo_command() {
  return {"demo",
          "Calibrate a simulated robot end to end from rendered camera images and prove it "
          "against the hidden truth",
          [](CLI::App& cmd) -> CommandAction {
            auto o = std::make_shared<DemoOptions>();
            cmd.footer(
                "Builds a simulated cell (a library robot whose real geometry differs from its "
                "drawing by realistic tolerances, two cameras (an array of pairs where one pair "
                "sees too little of its range), a board on the end-effector) and "
                "records it as a session folder (app/SESSION.md), then runs the real pipeline on "
                "that folder: camera intrinsics, stereo rig, end-effector pose measurement, "
                "closed-loop identification, and validation against the hidden truth on held-out "
                "poses. Same as `robocal simulate --out DIR` followed by `robocal measure DIR`, "
                "`robocal identify DIR` and `robocal validate DIR`.");
            cmd.add_option("--robot", o->simulate.robot, "Library robot name or robot file")
                ->capture_default_str();
            cmd.add_option("--seed", o->simulate.seed, "Random seed (same seed, same result)")
                ->capture_default_str();
            cmd.add_option("--poses", o->simulate.poses, "Robot poses measured for identification")
                ->check(CLI::Range(10, 1000))
                ->capture_default_str();
            cmd.add_option("--held-out", o->held_out, "Held-out poses for validation")
                ->check(CLI::Range(10, 100000))
                ->capture_default_str();
            cmd.add_option("--threads", o->threads, "Worker threads for rendering and detection")
                ->check(CLI::Range(1, 64))
                ->capture_default_str();
            cmd.add_option("--intrinsic-views", o->simulate.intrinsic_views,
                           fmt::format("Calibration-board views per camera (default {}, 12 with "
                                       "--quick; --live: {})",
                                       SimulateOptions{}.intrinsic_views, kLiveIntrinsicViews))
                ->check(CLI::Range(4, 1000));
            cmd.add_option("--rig-views", o->simulate.rig_views,
                           fmt::format("Board views the cameras see together (default {}, 6 "
                                       "with --quick)",
                                       SimulateOptions{}.rig_views))
                ->check(CLI::Range(2, 1000));
            cmd.add_flag("--random-poses", o->simulate.random_poses,
                         "Random reachable poses with the board in view (for comparison) "
                         "instead of poses planned by observability (planner/)");
            cmd.add_flag("--idealised-truth", o->simulate.idealised_truth,
                         "The true robot differs from its drawing only where the model can follow "
                         "(default: also where it cannot, as a real robot does)");
            cmd.add_flag("--quick", o->simulate.quick,
                         "Smaller images and fewer views (for CI); pair with --poses 20");
            cmd.add_option("--out", o->out,
                           "Session folder to create (default: a fresh folder in the temp dir)");
            cmd.add_option("--route", o->route,
                           "Identification routes: pose (from measured 6-D poses), or pixel / "
                           "both (also camera-in-the-loop from the corner pixels, started from "
                           "the pose route's base-frame alignment; both are reported)")
                ->check(CLI::IsMember({"pose", "pixel", "both"}))
                ->capture_default_str();
            cmd.add_flag("--no-priors", o->no_priors,
                         "Identify by maximum likelihood from the measurements alone (default: "
                         "the robot file's tolerances as priors, base frame free)");
            cmd.add_flag("--live", o->live,
                         "The live loop: sim-controller as a separate process (the true robot), "
                         "the cameras served as GigE Vision cameras where this machine allows "
                         "it, calibration views, plan, collect (as `robocal collect`), then "
                         "measure, identify, validate; --out is then the demo folder");
            cmd.add_flag("--in-process", o->in_process,
                         "--live: render the cameras in-process instead of serving them through "
                         "Aravis' fake GigE camera");
            cmd.add_flag("--yes", o->yes,
                         "--live: the operator's confirmation before the first motion");
            cmd.add_flag("--resume", o->resume,
                         "--live: continue an interrupted live demo in --out");
            cmd.add_option("--speed", o->speed,
                           "--live: actuator speed, m/s or rad/s (default 0.5 m/s prismatic, "
                           "2 rad/s revolute)");
            cmd.add_option("--firmware", o->firmware,
                           "--live, a G-code printer (linear_delta): the simulated printer's "
                           "firmware, marlin, rrf or klipper (through Moonraker, always in its "
                           "own delta kinematics)")
                ->check(CLI::IsMember({"marlin", "rrf", "klipper"}));
            cmd.add_option("--gcode-mode", o->gcode_mode,
                           "--live, a delta printer: raw (one G-code axis per motor, the "
                           "default) or native (its firmware's own delta kinematics)")
                ->check(CLI::IsMember({"native", "raw"}));
            cmd.add_option("--json", o->json,
                           "Write the JSON report here ('-' = stdout; default: "
                           "<session>/results/demo.json)");
            return [o, &cmd]() {
              o->intrinsic_views_given = cmd.count("--intrinsic-views") > 0;
              if (o->simulate.quick) {
                if (cmd.count("--intrinsic-views") == 0) o->simulate.intrinsic_views = 12;
                if (cmd.count("--rig-views") == 0) o->simulate.rig_views = 6;
              }
              return o->live ? run_live(*o) : run_demo(*o);
            };
          }};
}

}  // namespace robocal::app
