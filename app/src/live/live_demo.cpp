#include "live/live_demo.hpp"

#include "cli/cli_common.hpp"
#include "live/collect.hpp"
#include "live/live_cameras.hpp"
#include "live/live_cell.hpp"
#include "live/simulated_setup.hpp"
#include "live/truth_log.hpp"
#include "robocal/core/files.hpp"
#include "robocal/robotio/sim_process.hpp"
#include "robocal/robotio/sim_truth.hpp"
#include "robocal/vision/camera_io.hpp"
#include "robocal/vision/intrinsics_pipeline.hpp"
#include "robocal/vision/target_io.hpp"
#include "session/results_files.hpp"
#include "session/results_layout.hpp"
#include "session/session.hpp"
#include "session/session_robot.hpp"
#include "simcell/simulated_cell.hpp"
#include "stages/cell_truth.hpp"
#include "stages/stage_log.hpp"
#include "summary/validation_summary.hpp"

#include <fmt/core.h>
#include <sys/resource.h>
#include <unistd.h>

#include <array>
#include <atomic>
#include <future>
#include <memory>
#include <optional>
#include <random>
#include <set>
#include <thread>

namespace robocal::app {

namespace fs = std::filesystem;

namespace {

fs::path fresh_folder(unsigned seed) {
  const auto base = fs::temp_directory_path();
  std::string pattern = (base / fmt::format("robocal-live-seed{}-XXXXXX", seed)).string();
  if (mkdtemp(pattern.data()) == nullptr)
    throw InputError("cannot create a folder in " + base.string());
  return pattern;
}

// The intrinsics from the calibration views, before anything moves (the planner and the
// settled-frame test use them): the cell's camera files get the calibrated models in place of
// the datasheet's, and measure reuses them (the same views join the session). nullopt (and says
// why) when a camera cannot be calibrated.
std::optional<CalibratedIntrinsics> calibrate_before_collection(
    const std::vector<LiveCameraSpec>& specs, const LiveCell& lc, const fs::path& views,
    const fs::path& cell_dir, const PipelineLog& log, nlohmann::json& report) {
  CalibratedIntrinsics calibrated;
  nlohmann::json cams = nlohmann::json::array();
  std::vector<CameraViews> cameras;
  cameras.reserve(specs.size());
  for (const auto& spec : specs)
    cameras.push_back({spec.name, spec.model.width, spec.model.height,
                       vision::list_image_files(views / spec.name)});
  std::vector<IntrinsicsStep> steps =
      calibrate_cameras(cameras, lc.cell.calibration_board, step_log(log));
  for (std::size_t c = 0; c < specs.size(); ++c) {
    const auto& spec = specs[c];
    IntrinsicsStep& step = steps[c];
    if (step.result.status == vision::CalibrationStatus::kFailed ||
        step.result.status == vision::CalibrationStatus::kRefused) {
      say(log, "camera {} cannot be calibrated: {}\n", spec.name, step.result.reason);
      return std::nullopt;
    }
    say(log, "  {}: fx {:.2f} px, RMS {:.3f} px from {} views\n", spec.name,
        step.result.camera.params[0], step.result.rms_px, step.views.size());
    core::write_file_atomic(cell_dir / (spec.name + ".yaml"),
                            vision::camera_to_yaml(step.result.camera, spec.name));
    cams.push_back({{"camera", spec.name}, {"rms_px", step.result.rms_px}});
    calibrated.emplace(spec.name, std::move(step));
  }
  report["intrinsics_before_collection"] = cams;
  return calibrated;
}

// After collection: the calibration views and board join the session, session.yaml names them
// with the board's designed mount, and truth/ holds what validate compares with.
void complete_session(const LiveCell& lc, const LiveDemoOptions& o, const fs::path& setup,
                      const fs::path& session, const TruthLog& truth_log) {
  Session s = load_session(session);
  const fs::path cal = session / "calibration";
  if (!fs::exists(cal)) fs::rename(setup / "calibration", cal);
  s.calibration_target = "targets/calibration.yaml";
  core::write_file_atomic(s.path(s.calibration_target),
                          vision::target_to_yaml(lc.cell.calibration_board.spec));
  s.intrinsics_views = "calibration/intrinsics";
  s.rig_views = "calibration/rig";
  s.seed = o.seed;
  s.target_mount.clear();
  for (std::size_t i = 0; i < lc.cell.model.parameters.size(); ++i)
    if (lc.cell.model.parameters[i].body == lc.cell.target_frame)
      s.target_mount.emplace_back(lc.cell.model.parameters[i].name,
                                  lc.cell.nominal[static_cast<Eigen::Index>(i)]);
  core::write_file_atomic(session / "session.yaml", session_to_yaml(s));

  TruthFile truth = cell_truth(lc.cell, "robocal sim-controller (live demo), truth channel");
  truth.poses = truth_log.match(session);
  write_truth(ResultsLayout{session}, lc.cell.model, truth);
}

// Robocal's own time per pose in collection, as the operator waits for it: the capture's wall
// time minus the robot's simulated motion (the controller's own durations, from its log, so the
// link's round trips count as robocal's) and the rendering (the simulated exposure). The
// detection, settled-frame test and writing of a pose run while the robot moves to the next one:
// their time is reported beside it, and counts only where the capture waited for them (wait).
nlohmann::json collection_overhead(const nlohmann::json& summary, double render_s,
                                   double motion_s) {
  double grab = 0, check = 0, write = 0, move = 0, wait = 0;
  int n = 0;
  for (const auto& p : summary.value("poses", nlohmann::json::array())) {
    grab += p.value("grab_s", 0.0);
    check += p.value("check_s", 0.0);
    write += p.value("write_s", 0.0);
    move += p.value("move_s", 0.0);
    wait += p.value("wait_s", 0.0);
    ++n;
  }
  if (n == 0) return {};
  const double per = 1.0 / n;
  const double wall = summary.value("capture_seconds", 0.0);
  return {{"poses", n},
          {"capture_s_per_pose", wall * per},
          {"move_s_per_pose", move * per},
          {"simulated_motion_s_per_pose", motion_s * per},
          {"render_s_per_pose", render_s * per},
          {"frame_wait_minus_render_s_per_pose", std::max(0.0, grab - render_s) * per},
          {"detect_and_check_s_per_pose", check * per},
          {"write_s_per_pose", write * per},
          {"waiting_for_check_and_write_s_per_pose", wait * per},
          {"overhead_s_per_pose", (wall - motion_s - render_s) * per},
          {"definition",
           "overhead = capture wall time - the controller's simulated motion - rendering; "
           "detection, the settled-frame test and writing overlap the next motion and count "
           "where the capture waited for them"}};
}

// What is done while the robot collects.
struct EarlyWork {
  CalibratedRig rig;
  EarlyDetections detections;
};

// Sets `flag` when it goes out of scope: the background work ends with the collection, however
// run_live_demo returns.
struct CollectionEnds {
  explicit CollectionEnds(std::atomic<bool>& f) : flag(f) {}
  std::atomic<bool>& flag;
  CollectionEnds(const CollectionEnds&) = delete;
  CollectionEnds& operator=(const CollectionEnds&) = delete;
  CollectionEnds(CollectionEnds&&) = delete;
  CollectionEnds& operator=(CollectionEnds&&) = delete;
  ~CollectionEnds() { flag = true; }
};

// Each pose folder collect writes (whole at once: it renames its staging folder), as it appears,
// until `collected` is set and a last look is taken: the shots measure would detect in full.
EarlyDetections detect_while_collecting(const fs::path& poses, const vision::TargetBoard& board,
                                        const std::atomic<bool>& collected) {
  EarlyDetections out;
  std::set<std::string> seen;
  for (;;) {
    const bool last_look = collected.load();
    std::error_code ec;
    if (fs::is_directory(poses, ec))
      for (const auto& e : fs::directory_iterator(poses, ec)) {
        const std::string name = e.path().filename().string();
        if (!e.is_directory() || !seen.insert(name).second) continue;
        vision::DetectionRecord found = detect_unrecorded_shots(e.path(), board);
        if (!found.empty()) out[name] = std::move(found);
      }
    if (last_look) return out;
    std::this_thread::sleep_for(std::chrono::milliseconds(200));
  }
}

// Work done while the robot collects yields to the collection: this thread (and any it starts)
// runs at the lowest priority, on the machine's idle time.
void run_in_background() {
  (void)::setpriority(PRIO_PROCESS, static_cast<id_t>(::gettid()), 19);
}

// The link a library robot's real controller offers: the UR5 is driven through the Universal
// Robots interfaces (RTDE, URScript, dashboard); the printer-style linear delta runs G-code
// firmware; the lab and research robots, which have no standard interface, speak the open link
// protocol (robotio/OPEN_LINK.md). A robot file outside the library keeps G-code, the link most
// hobby controllers offer.
std::string natural_protocol(const std::string& robot_name) {
  static const std::set<std::string> open = {"rotary_delta", "gantry_tau", "four_bar",
                                             "modular_arm", "wire_robot_branch"};
  if (robot_name == "ur5") return "ur";
  return open.count(robot_name) > 0 ? "open" : "gcode";
}

// The controller's simulated motion time logged since `first` motions (homing left out).
double motion_seconds_since(const fs::path& log, std::size_t first) {
  const std::vector<double> motions = robotio::simulated_motion_seconds(log);
  double sum = 0.0;
  for (std::size_t i = first; i < motions.size(); ++i) sum += motions[i];
  return sum;
}

// The true robot in its own process, reached through the robot's natural link.
struct LiveController {
  std::unique_ptr<robotio::SimControllerProcess> sim;
  std::string protocol;
  bool native = false;       // a delta printer run in its firmware's own kinematics
  std::string link_address;  // collect's --link
  std::string link_note;     // what the operator reads
};

// Every true parameter is given, so the simulated robot's geometry is the offline demo's (its
// elastic sag is added where the cameras look: SaggingBoard).
LiveController start_controller(const LiveDemoOptions& o, const LiveCell& lc,
                                const std::string& robot_file, const LiveCellFiles& files,
                                const fs::path& setup, const PipelineLog& log,
                                nlohmann::json& report) {
  LiveController c;
  c.protocol = natural_protocol(lc.cell.model.name);
  // A delta printer runs its firmware's own kinematics when native mode is asked for.
  const bool klipper = c.protocol == "gcode" && o.firmware == "klipper";
  c.native = simulated_native_delta(lc.cell.model, c.protocol, o.firmware, o.gcode_mode);
  std::vector<std::string> sim_args = {"--robot",
                                       robot_file,
                                       "--seed",
                                       std::to_string(o.seed),
                                       "--perturbation",
                                       files.perturbation.string(),
                                       "--protocol",
                                       c.protocol,
                                       "--no-pty",
                                       "--log",
                                       (setup / "sim-controller.jsonl").string(),
                                       "--busy-interval",
                                       "1",
                                       "--max-seconds",
                                       "3600"};
  if (c.protocol == "gcode")
    sim_args.insert(sim_args.end(),
                    {"--firmware", o.firmware, "--kinematics", c.native ? "delta" : "axes"});
  c.sim = std::make_unique<robotio::SimControllerProcess>(robocal_binary(), sim_args);
  c.link_address = simulated_link_address(*c.sim, c.protocol, klipper);
  // "open link at 127.0.0.1:P", "Universal Robots link at 127.0.0.1:R:S:D", "marlin G-code, raw
  // axes at 127.0.0.1:P" (the address after the protocol's prefix).
  const std::string gcode_note =
      klipper ? std::string("Klipper link (Moonraker), Klipper's own delta kinematics")
              : o.firmware + (c.native ? " G-code, firmware-native delta" : " G-code, raw axes");
  c.link_note = fmt::format("{} at {}",
                            c.protocol == "ur"     ? "Universal Robots link"
                            : c.protocol == "open" ? "open link"
                                                   : gcode_note,
                            c.link_address.substr(c.link_address.find(':') + 1));
  say(log, "sim-controller (pid {}): {}, truth channel at {}\n", c.sim->pid(), c.link_note,
      c.sim->pose());
  report["controller"] = {
      {"link", c.link_address}, {"protocol", c.protocol}, {"pid", c.sim->pid()}};
  return c;
}

// The measurement poses, planned once (a resumed demo keeps its plan).
void plan_once(const LiveDemoOptions& o, const LiveCell& lc, const std::string& robot_file,
               const LiveCellFiles& files, const LiveController& controller,
               const fs::path& plan_file, const PipelineLog& log, nlohmann::json& report) {
  if (o.resume && fs::exists(plan_file)) return;
  const double speed = o.speed > 0 ? o.speed : default_speed(lc.cell.model);
  // The simulated firmware's kinematics is the robot file's drawing (sim-controller
  // --kinematics delta): the planner's candidates it cannot command are left out.
  const Commandable commandable =
      controller.native ? drawing_commandability(lc.cell.model, o.firmware) : Commandable{};
  const LivePlan plan = plan_live_poses(lc.cell, robot_file, files, o.poses, o.seed, o.quick,
                                        plan_file, {speed, 10.0 * speed}, log.out, commandable);
  say(log, "plan: {}\n", plan.how);
  report["plan"] = {{"poses", plan.readings.size()},
                    {"planner", plan.planner},
                    {"how", plan.how},
                    {"predicted_rms_um", plan.predicted_rms_m * 1e6}};
}

// Collection through `robocal collect`'s own code (guard, confirmation, progress, resume), with
// the cameras served as GigE Vision devices where they can be. A camera lost on a busy machine (a
// render beyond the GigE heartbeat window) is rendered in-process from then on and the collection
// resumed (`--resume`). The report gets the cameras, the collection and its time per pose.
CollectOutcome collect_live(const LiveDemoOptions& o, const LiveCell& lc,
                            const std::vector<LiveCameraSpec>& specs, const std::string& robot_file,
                            const LiveCellFiles& files, const LiveController& controller,
                            const fs::path& setup, const fs::path& session,
                            const TruthLog& truth_log, const PipelineLog& log,
                            nlohmann::json& report) {
  robotio::SimControllerTruth truth(controller.sim->pose(), robotio::BoardMounting{});
  SaggingBoard seen(truth, lc.cell.elastic_sag);
  LiveCameras cams(specs, lc.cell.ee_board, {&seen}, o.gige, fmt::format("L{}-", ::getpid()));
  std::string camera_note;
  for (std::size_t c = 0; c < specs.size(); ++c)
    camera_note += fmt::format(
        "{}{}: {}", c ? ", " : "", specs[c].name,
        cams.served(c) ? "GigE Vision (Aravis fake camera on " + live_camera_address(c) + ")"
                       : std::string("rendered in-process"));
  say(log, "cameras: {}\n", camera_note);
  for (const auto& n : cams.notes()) say(log, "  {}\n", n);
  report["cameras"] = {{"how", camera_note}, {"notes", cams.notes()}};
  CollectOptions co;
  co.session = session;
  co.robot = robot_file;
  co.cell = files.cell.string();
  co.plan = (setup / "plan.yaml").string();
  co.link = controller.link_address;
  co.gcode_mode =
      controller.native ? robotio::GcodeMode::kNativeDelta : robotio::GcodeMode::kRawAxes;
  for (std::size_t c = 0; c < specs.size(); ++c)
    co.cameras.push_back({specs[c].name, cams.source(c)});
  co.speed = o.speed > 0 ? o.speed : default_speed(lc.cell.model);
  co.acceleration = 10.0 * co.speed;
  co.resume = o.resume && fs::exists(session / "session.yaml");
  co.yes = o.yes;
  co.open_camera = [&cams](const CollectCamera& c) { return cams.open(c.name); };
  co.on_settled = [&](const Eigen::VectorXd& readings) {
    truth_log.append(readings, truth.read(), lc.cell.elastic_sag);
  };
  const fs::path sim_log = setup / "sim-controller.jsonl";
  // The overhead reported is that of the last attempt (capture_seconds is its wall time).
  double render_start = cams.render_seconds();
  std::size_t motions_start = robotio::simulated_motion_seconds(sim_log).size();
  CollectOutcome collected = collect_session(co, log);
  bool served = false;
  for (std::size_t c = 0; c < specs.size(); ++c) served = served || cams.served(c);
  if ((collected.status == "incomplete" || collected.status == "failed") && served &&
      collected.message.find("camera") != std::string::npos) {
    for (std::size_t c = 0; c < specs.size(); ++c)
      cams.fall_back(c, "collection stopped (" + collected.message + ")");
    say(log, "resuming the collection with the cameras rendered in-process\n");
    report["collect_first_attempt"] = collected.summary;
    co.resume = fs::exists(session / "session.yaml");
    render_start = cams.render_seconds();
    motions_start = robotio::simulated_motion_seconds(sim_log).size();
    collected = collect_session(co, log);
  }
  report["cameras"]["notes"] = cams.notes();
  report["collect"] = collected.summary;
  report["collect"]["overhead"] =
      collection_overhead(collected.summary, cams.render_seconds() - render_start,
                          motion_seconds_since(sim_log, motions_start));
  return collected;
}

void print_collection_overhead(std::FILE* out, const nlohmann::json& ov) {
  if (ov.empty()) return;
  fmt::print(
      out,
      "\n  collection, per pose: {:.0f} ms = robot motion {:.0f} + rendering {:.0f} + "
      "robocal's own {:.0f} (of which waiting for frames beyond rendering {:.0f}, for "
      "earlier poses' checks and writing {:.0f}; these took {:.0f} and {:.0f} ms "
      "while the robot moved)\n",
      ov.value("capture_s_per_pose", 0.0) * 1e3, ov.value("simulated_motion_s_per_pose", 0.0) * 1e3,
      ov.value("render_s_per_pose", 0.0) * 1e3, ov.value("overhead_s_per_pose", 0.0) * 1e3,
      ov.value("frame_wait_minus_render_s_per_pose", 0.0) * 1e3,
      ov.value("waiting_for_check_and_write_s_per_pose", 0.0) * 1e3,
      ov.value("detect_and_check_s_per_pose", 0.0) * 1e3, ov.value("write_s_per_pose", 0.0) * 1e3);
}

// The summary the operator reads, the time per stage, the HTML report and demo.json; the exit
// code says whether the calibration improved the model.
int report_live_demo(const LiveDemoOptions& o, const fs::path& session,
                     const std::string& link_note, StageClock& clock, nlohmann::json& report) {
  std::FILE* out = human_stream(o.json);
  print_validation_summary(out, report["validate"], report["identify"]);
  print_collection_overhead(out, report["collect"]["overhead"]);
  fmt::print(out, "\n  robot driven through the {}\n", link_note);
  fmt::print(out, "\n  time per stage:\n{}", clock.table());
  nlohmann::json stages = nlohmann::json::object();
  for (const auto& s : clock.stages()) stages[s.name] = s.seconds;
  report["seconds"] = stages;
  report["total_seconds"] = clock.total_seconds();
  report["seed"] = o.seed;
  report["robot"] = o.robot;
  report["session"] = session.string();
  std::vector<std::pair<std::string, double>> seconds;
  for (const auto& s : clock.stages()) seconds.emplace_back(s.name, s.seconds);
  report["report"] = report_session(session, PipelineLog{nullptr}, seconds);
  const std::string json_path =
      !o.json.empty() ? o.json : ResultsLayout{session}.report("demo").string();
  write_json(report, json_path);
  fmt::print(out, "  session: {}\n  report: {}\n", session.string(), json_path);
  const bool improved = report["validate"].value("improved", false);
  if (!improved) fmt::print(stderr, "calibration did not improve the model\n");
  return improved ? kExitOk : kExitFailure;
}

}  // namespace

// The mission's loop, each stage as its real command runs it: the cell, the controller, the
// calibration views and intrinsics, the plan, the collection (the rig and the detections computed
// meanwhile at the lowest priority), then measure, identify and validate.
int run_live_demo(const LiveDemoOptions& o) {
  std::FILE* out = human_stream(o.json);
  StageClock clock;
  const PipelineLog log{out, &clock, o.threads};
  const fs::path dir = o.out.empty() ? fresh_folder(o.seed) : fs::path(o.out);
  const fs::path setup = dir / "setup";
  const fs::path session = dir / "session";
  if (!o.resume && fs::exists(session))
    throw InputError(dir.string() +
                     ": already holds a live demo; --resume continues it, or "
                     "give another --out");
  const std::string robot_file = resolve_robot(o.robot);
  fmt::print(out,
             "robocal demo --live: calibrating a simulated {} through the live loop (seed {})\n"
             "  folder: {}\n\n",
             o.robot, o.seed, dir.string());
  nlohmann::json report;

  stage(log, "live: cell");
  const LiveCell lc = make_live_cell(o, robot_file);
  const LiveCellFiles files = write_live_cell(lc.cell, robot_file, setup);
  const auto specs = camera_specs(lc.cell, o.seed, o.threads);

  stage(log, "live: start sim-controller");
  const LiveController controller = start_controller(o, lc, robot_file, files, setup, log, report);

  stage(log, "live: calibration views");
  if (!fs::exists(session / "calibration") && !fs::exists(setup / "calibration" / "done")) {
    say(log, "calibration views: the operator shows the calibration board to the cameras\n");
    take_calibration_views(lc, specs, o.gige, setup / "calibration", log, report);
    core::write_file_atomic(setup / "calibration" / "done", "ok\n");
  }
  stage(log, "live: intrinsics");
  const fs::path views = fs::exists(session / "calibration")
                             ? session / "calibration" / "intrinsics"
                             : setup / "calibration" / "intrinsics";
  const auto intrinsics = calibrate_before_collection(specs, lc, views, setup, log, report);
  if (!intrinsics) return kExitFailure;
  // While the robot collects (the machine waits on it most of that time), at the lowest priority:
  // the rig from its views, then the pose images measure would detect in full (the later shots
  // of cameras that did not see the board), as collect writes each pose. Measure takes what
  // nothing has changed since.
  std::vector<std::string> names;
  names.reserve(specs.size());
  for (const auto& spec : specs) names.push_back(spec.name);
  std::atomic<bool> collection_over{false};
  std::future<EarlyWork> early =
      std::async(std::launch::async, [&names, &intrinsics, &lc, &collection_over, views, session,
                                      threads = o.threads, ee_board = files.ee_target] {
        run_in_background();
        EarlyWork work;
        work.rig = calibrate_rig_before_measure(names, *intrinsics, views.parent_path() / "rig",
                                                lc.cell.calibration_board, threads);
        work.detections =
            detect_while_collecting(session / "poses", load_board(ee_board), collection_over);
        return work;
      });
  const CollectionEnds collection_ends(collection_over);  // whatever way this function ends

  stage(log, "live: plan");
  plan_once(o, lc, robot_file, files, controller, setup / "plan.yaml", log, report);

  stage(log, "live: collect");
  const TruthLog truth_log{setup / "truth_poses.jsonl"};
  const CollectOutcome collected = collect_live(o, lc, specs, robot_file, files, controller, setup,
                                                session, truth_log, log, report);
  if (collected.status != "ok") {
    clock.stop();
    fmt::print(out, "collection: {}{}\n", collected.status,
               collected.message.empty() ? "" : ": " + collected.message);
    return collect_exit_code(collected);
  }
  // Before the calibration views move into the session: the rig reads them.
  collection_over = true;
  std::optional<EarlyWork> work;
  try {
    work = early.get();
  } catch (const std::exception& e) {
    say(log, "the rig could not be calibrated while collecting ({}): measure calibrates it\n",
        e.what());
  }
  complete_session(lc, o, setup, session, truth_log);
  controller.sim->stop();

  fmt::print(out, "\nmeasure: cameras, rig and end-effector poses from the recorded images\n");
  report["measure"] =
      measure_session(session, "", log, {}, *intrinsics, work ? &work->rig : nullptr,
                      work ? &work->detections : nullptr);
  if (report["measure"]["status"] != "ok") return kExitFailure;
  fmt::print(out, "\nidentify\n");
  report["identify"] = identify_session(session, "", log, o.route, true);
  if (report["identify"]["status"] != "ok") return kExitFailure;
  fmt::print(out, "\nvalidate (against the simulator's truth, which only this stage reads)\n");
  report["validate"] = validate_session(session, o.held_out, log);
  clock.stop();
  return report_live_demo(o, session, controller.link_note, clock, report);
}

}  // namespace robocal::app
