#include "live/collect.hpp"

#include "cli/cli_common.hpp"
#include "cli/command_registry.hpp"
#include "cli/pause_key.hpp"
#include "cli/progress.hpp"
#include "live/cell_clearance.hpp"
#include "live/sim_camera.hpp"
#include "robocal/calib/frame_placement.hpp"
#include "robocal/calib/robot_file.hpp"
#include "robocal/core/files.hpp"
#include "robocal/core/yaml.hpp"
#include "robocal/planner/cell.hpp"
#include "robocal/planner/collision_scene.hpp"
#include "robocal/planner/plan_output.hpp"
#include "robocal/robotio/camera_open.hpp"
#include "robocal/robotio/capture.hpp"
#include "robocal/robotio/capture_link.hpp"
#include "robocal/robotio/gcode_link.hpp"
#include "robocal/robotio/klipper_link.hpp"
#include "robocal/robotio/link_error.hpp"
#include "robocal/robotio/link_factory.hpp"
#include "robocal/robotio/safety_guard.hpp"
#include "robocal/robotio/stop_signals.hpp"
#include "robocal/vision/camera_io.hpp"
#include "robocal/vision/target_io.hpp"
#include "robocal_version.hpp"
#include "session/session.hpp"
#include "session/session_robot.hpp"

#include <fmt/core.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <ctime>
#include <iostream>
#include <memory>
#include <set>
#include <thread>

namespace robocal::app {
namespace {

namespace fs = std::filesystem;
using robotio::SafetyGuard;

// Waits between poses while paused (the p key or SIGUSR1); a stop request ends the wait (the guard
// then refuses the next move, and capture stops with the reason).
class PausableRobot final : public robotio::CaptureRobot {
 public:
  PausableRobot(robotio::CaptureRobot& inner, const SafetyGuard& guard, std::FILE* out,
                std::function<void(const Eigen::VectorXd&)> on_settled)
      : inner_(&inner), guard_(&guard), out_(out), on_settled_(std::move(on_settled)) {}
  Eigen::VectorXd move_and_settle(const Eigen::VectorXd& target) override {
    wait_while_paused();
    Eigen::VectorXd readings = inner_->move_and_settle(target);
    if (on_settled_) on_settled_(readings);
    return readings;
  }
  Eigen::VectorXd read_actuators() override { return inner_->read_actuators(); }
  void stop(const std::string& reason) override { inner_->stop(reason); }
  std::optional<Eigen::Isometry3d> flange_pose() const override { return inner_->flange_pose(); }

 private:
  void wait_while_paused() {
    bool said = false;
    while (robotio::StopSignals::paused() && !guard_->stop_requested()) {
      if (!said && out_ != nullptr) {
        fmt::print(out_,
                   "\ncollect: paused (robot standing still). Press p again (or send SIGUSR1: "
                   "kill -USR1 {}) to go on, Ctrl-C to stop.\n",
                   ::getpid());
        std::fflush(out_);
      }
      said = true;
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
    }
    if (said && out_ != nullptr && !guard_->stop_requested())
      fmt::print(out_, "collect: resumed\n");
  }
  robotio::CaptureRobot* inner_;
  const SafetyGuard* guard_;
  std::FILE* out_;
  std::function<void(const Eigen::VectorXd&)> on_settled_;
};

// ---- inputs ------------------------------------------------------------------------------------

struct CollectInputs {
  std::string robot_file;
  calib::Mechanism model;
  planner::Cell cell;
  std::vector<Eigen::VectorXd> targets;
  std::string plan_text;
  // The plan's own verdict (`status:` of `robocal plan`'s file): ok, not_accepted or infeasible;
  // empty for a plan written by hand (no status line).
  std::string plan_status;
  std::vector<int> camera_of;  // per cell camera: index into options.cameras
  // The board's offset on the measured frame (the cell's target pose) as that frame's parameter
  // values for session.yaml (app/SESSION.md, target_mount); empty when the board sits on the frame.
  std::vector<std::pair<std::string, double>> target_mount;
};

// The cell's target pose on its frame, as the frame's parameters (what measure and identify read).
std::vector<std::pair<std::string, double>> target_mount(const CollectInputs& in) {
  const planner::TargetMount& t = in.cell.target;
  if (t.frame_T_board.isApprox(Eigen::Isometry3d::Identity(), 1e-12)) return {};
  const int body = t.frame.empty() ? in.model.tool : in.model.body_index(t.frame);
  if (body < 0)
    throw InputError(fmt::format("{}:{}: the target's frame '{}' is not a body of robot '{}'",
                                 in.cell.source, t.line, t.frame, in.model.name));
  try {
    return calib::mounted_frame_parameters(in.model, in.model.nominal_parameters(), body,
                                           t.frame_T_board);
  } catch (const std::invalid_argument& e) {
    throw InputError(
        fmt::format("{}:{}: the target's pose on its frame: {}", in.cell.source, t.line, e.what()));
  }
}

// The plan's status line, checked: an infeasible plan is refused unless the operator accepts it
// (--accept-infeasible-plan), an unknown word is a bad plan file.
std::string plan_status(const CollectOptions& o, const std::string& plan_text) {
  const YAML::Node status = core::load_yaml_text(plan_text, o.plan)["status"];
  if (!status) return {};
  const std::string where = fmt::format("{}:{}", o.plan, status.Mark().line + 1);
  std::string word = status.IsScalar() ? status.Scalar() : std::string();
  if (word != "ok" && word != "not_accepted" && word != "infeasible")
    throw InputError(fmt::format(
        "{}: status '{}' is not a plan status (ok, not_accepted or infeasible)", where, word));
  if (word == "infeasible" && !o.accept_infeasible_plan)
    throw InputError(fmt::format(
        "{}: the plan's status is 'infeasible': the planner found too few feasible poses for a "
        "calibration of this robot in this cell, so nothing is moved; plan again (more "
        "candidates, a larger workspace, other camera places) or give --accept-infeasible-plan "
        "to collect it anyway",
        where));
  return word;
}

CollectInputs read_inputs(const CollectOptions& o) {
  CollectInputs in;
  if (o.cell.empty()) throw InputError("no cell file: give --cell FILE (planner/README.md)");
  if (o.plan.empty())
    throw InputError("no plan file: give --plan FILE (written by `robocal plan`)");
  in.cell = planner::load_cell_file(o.cell);
  const std::string robot = o.robot.empty() ? in.cell.robot_file : o.robot;
  if (robot.empty())
    throw InputError("no robot: give --robot NAME|FILE or name one in the cell file ('robot:')");
  in.robot_file = resolve_robot(robot);
  try {
    in.model = calib::load_robot_file(in.robot_file);
  } catch (const calib::RobotFileError& e) {
    throw InputError(e.what());
  }
  in.target_mount = target_mount(in);
  in.plan_text = core::read_text_file(o.plan);
  in.targets = planner::read_plan_actuators(o.plan);
  if (in.targets.empty()) throw InputError(o.plan + ": the plan has no poses");
  in.plan_status = plan_status(o, in.plan_text);
  const auto n = static_cast<Eigen::Index>(in.model.actuated.size());
  for (std::size_t i = 0; i < in.targets.size(); ++i) {
    const Eigen::VectorXd& t = in.targets[i];
    if (t.size() != n)
      throw InputError(fmt::format("{}: pose {} has {} actuator readings; robot '{}' has {}",
                                   o.plan, i, t.size(), in.model.name, n));
    if (!t.allFinite())
      throw InputError(
          fmt::format("{}: pose {} has a reading that is not a finite number", o.plan, i));
  }
  // Every camera of the cell needs a source (unless nothing is captured); every source a camera.
  in.camera_of.assign(in.cell.cameras.size(), -1);
  std::set<std::string> seen;
  for (std::size_t k = 0; k < o.cameras.size(); ++k) {
    const CollectCamera& c = o.cameras[k];
    const int index = in.cell.camera_index(c.name);
    if (index < 0) {
      std::string names;
      for (const auto& cc : in.cell.cameras) names += (names.empty() ? "" : ", ") + cc.name;
      throw InputError(fmt::format("--camera {}={}: the cell {} has no camera '{}' (it has: {})",
                                   c.name, c.source, o.cell, c.name, names));
    }
    if (!seen.insert(c.name).second) throw InputError("--camera " + c.name + " is given twice");
    try {
      if (!o.open_camera && c.source.rfind("sim:", 0) != 0)
        (void)robotio::parse_camera_source(c.source);
    } catch (const std::invalid_argument& e) {
      throw InputError(std::string("--camera ") + c.name + ": " + e.what());
    }
    in.camera_of[static_cast<std::size_t>(index)] = static_cast<int>(k);
  }
  if (!o.dry_run) {
    for (std::size_t i = 0; i < in.cell.cameras.size(); ++i)
      if (in.camera_of[i] < 0)
        throw InputError(
            fmt::format("camera '{}' of the cell has no source: give --camera {}=aravis:ID (or "
                        "v4l2:/dev/videoN); `robocal collect --help` shows how to list cameras",
                        in.cell.cameras[i].name, in.cell.cameras[i].name));
  }
  return in;
}

// ---- the session folder ------------------------------------------------------------------------

std::int64_t iso_utc_to_ns(const std::string& iso) {
  std::tm tm{};
  if (strptime(iso.c_str(), "%Y-%m-%dT%H:%M:%SZ", &tm) == nullptr) return 0;
  return static_cast<std::int64_t>(timegm(&tm)) * 1'000'000'000LL;
}

void check_new_session_folder(const fs::path& dir) {
  if (fs::exists(dir) && !fs::is_empty(dir))
    throw InputError(dir.string() +
                     ": exists and is not empty (recorded data is never overwritten); use "
                     "--resume to continue a collection there, or another folder");
}

// A new session: recorded files written once (robot, target, camera intrinsics, plan), then
// session.yaml. Returns the session start (ns, host clock).
std::int64_t start_session(const CollectOptions& o, const CollectInputs& in) {
  const fs::path dir = o.session;
  check_new_session_folder(dir);
  fs::create_directories(dir);
  Session s;
  s.dir = dir;
  s.software = std::string("robocal ") + kVersion;
  s.created = utc_now();
  s.source = "recorded";
  s.robot_name = in.model.name;
  s.actuators = static_cast<int>(in.model.actuated.size());
  s.measured_frame = in.cell.target.frame.empty()
                         ? in.model.bodies[static_cast<std::size_t>(in.model.tool)].name
                         : in.cell.target.frame;
  s.calibration_target = s.ee_target;  // the same board, until calibration views say otherwise
  s.target_mount = in.target_mount;
  for (const auto& c : in.cell.cameras)
    s.cameras.push_back({c.name, c.model.width, c.model.height});
  core::write_file_atomic(s.path(s.robot_file), core::read_text_file(in.robot_file),
                          core::Overwrite::kRefuse);
  fs::create_directories(dir / "targets");
  core::write_file_atomic(s.path(s.ee_target), vision::target_to_yaml(in.cell.target.board.spec),
                          core::Overwrite::kRefuse);
  fs::create_directories(dir / "cameras");
  for (const auto& c : in.cell.cameras)
    core::write_file_atomic(dir / "cameras" / (c.name + ".yaml"),
                            vision::camera_to_yaml(c.model, c.name), core::Overwrite::kRefuse);
  core::write_file_atomic(dir / "plan.yaml", in.plan_text, core::Overwrite::kRefuse);
  core::write_file_atomic(dir / "session.yaml", session_to_yaml(s), core::Overwrite::kRefuse);
  return iso_utc_to_ns(s.created);
}

// An interrupted collection: the same robot and the same plan, or it is refused.
std::int64_t continue_session(const CollectOptions& o, const CollectInputs& in) {
  const fs::path dir = o.session;
  if (!is_session(dir))
    throw InputError(dir.string() +
                     ": no session.yaml, so there is nothing to resume (start without --resume)");
  const Session s = load_session(dir);
  if (s.robot_name != in.model.name)
    throw InputError(fmt::format("{}: recorded with robot '{}', not '{}'",
                                 (dir / "session.yaml").string(), s.robot_name, in.model.name));
  const fs::path stored = dir / "plan.yaml";
  if (!fs::exists(stored))
    throw InputError(stored.string() + ": missing: this session was not recorded by collect");
  if (core::read_text_file(stored.string()) != in.plan_text)
    throw InputError(fmt::format(
        "{}: this session was collected with another plan than {}; resume with its own plan "
        "(--plan {}) so pose numbers keep their meaning",
        stored.string(), o.plan, stored.string()));
  return iso_utc_to_ns(s.created);
}

// ---- operator ----------------------------------------------------------------------------------

bool operator_confirms(const CollectOptions& o, std::FILE* out) {
  if (o.yes) return true;
  if (::isatty(STDIN_FILENO) == 0) return false;  // nobody to ask: never move unconfirmed
  if (o.unlock_protective_stop)
    fmt::print(out,
               "A protective stop of the UR will be unlocked from here before the next move: "
               "inspect the cause of each one on the robot first.\n");
  fmt::print(out, "Type yes to start moving the robot (anything else cancels): ");
  std::fflush(out);
  std::string answer;
  if (!std::getline(std::cin, answer)) return false;
  return answer == "yes";
}

std::string plan_status_words(const std::string& status) {
  if (status.empty()) return "not recorded (a plan written by hand)";
  if (status == "ok") return "ok (accepted by the planner)";
  if (status == "not_accepted")
    return "not_accepted (the planner's acceptance test is not met: some parameters may be "
           "poorly identified)";
  return "infeasible (accepted with --accept-infeasible-plan)";
}

std::string duration_words(double seconds) {
  if (seconds < 90.0) return fmt::format("{:.0f} s", seconds);
  return fmt::format("{:.0f} min {:02.0f} s", std::floor(seconds / 60.0),
                     std::floor(std::fmod(seconds, 60.0)));
}

std::string describe(const CollectOptions& o, const CollectInputs& in, std::size_t remaining,
                     double motion_seconds) {
  std::string cams;
  for (const auto& c : o.cameras)
    cams += fmt::format("{}{} ({})", cams.empty() ? "" : ", ", c.name, c.source);
  return fmt::format(
      "  robot:     {} ({} actuators), controller at {}\n"
      "  plan:      {} ({} poses, {} still to record), status {}\n"
      "  cameras:   {}\n"
      "  speed:     {} {}/s, acceleration {} {}/s²\n"
      "  duration:  about {} of motion between the poses at this speed (--speed), plus the "
      "shots at each pose\n"
      "  workspace: {}\n"
      "  obstacles: {} in the cell, clearance {} mm; every motion is checked before it is sent\n",
      in.model.name, static_cast<int>(in.model.actuated.size()), o.link, o.plan, in.targets.size(),
      remaining, plan_status_words(in.plan_status), cams.empty() ? "(none)" : cams, o.speed,
      actuator_unit(in.model), o.acceleration, actuator_unit(in.model),
      duration_words(motion_seconds),
      in.cell.workspace.declared
          ? fmt::format("x {:.3f}..{:.3f}, y {:.3f}..{:.3f}, z {:.3f}..{:.3f} m",
                        in.cell.workspace.min.x(), in.cell.workspace.max.x(),
                        in.cell.workspace.min.y(), in.cell.workspace.max.y(),
                        in.cell.workspace.min.z(), in.cell.workspace.max.z())
          : "not declared in the cell (only actuator limits apply)",
      in.cell.obstacles.size(), in.cell.margins.clearance * 1e3);
}

std::size_t recorded_on_disk(const fs::path& session, std::size_t count) {
  std::size_t n = 0;
  for (std::size_t i = 0; i < count; ++i)
    if (fs::exists(session / "poses" / robotio::pose_folder_name(static_cast<int>(i)))) ++n;
  return n;
}

// ---- dry run -----------------------------------------------------------------------------------

// Checks the plan's motions in order; the summary gets the refusals, `status` the verdict.
// How a G-code firmware is driven, and the geometry differences the operator accepted, in the
// summary and on the terminal (the session keeps what the calibration was collected under).
void note_gcode_mode(const robotio::RobotLink& link, const CollectOptions& o, nlohmann::json& r,
                     std::FILE* out) {
  const auto* gcode = dynamic_cast<const robotio::GcodeLink*>(&link);
  const auto* klipper = dynamic_cast<const robotio::KlipperLink*>(&link);
  if (gcode == nullptr && klipper == nullptr) return;
  // Klipper is always driven in its own delta kinematics.
  const bool native = klipper != nullptr || gcode->native_frame().has_value();
  const std::vector<std::string>& disagreements =
      gcode != nullptr ? gcode->geometry_disagreements() : klipper->geometry_disagreements();
  r["gcode_mode"] = native ? "native delta" : "raw axes";
  if (out)
    fmt::print(out, "  driven {}\n",
               native ? "in the firmware's own delta kinematics (firmware-native mode)"
                      : "one G-code axis per motor (raw-axis mode)");
  if (disagreements.empty()) return;
  const bool firmware = o.firmware_geometry == robotio::GeometryChoice::kFirmware;
  r["geometry_disagreements"] = disagreements;
  r["geometry_trusted"] = firmware ? "firmware" : "robot-file";
  if (out) {
    fmt::print(out,
               "  the firmware's delta geometry differs from the robot file's; you chose to "
               "trust the {}:\n",
               firmware ? "firmware's" : "robot file's");
    for (const std::string& d : disagreements) fmt::print(out, "    {}\n", d);
  }
}

nlohmann::json dry_run(const CollectInputs& in, SafetyGuard& guard, const CollectOptions& o,
                       std::FILE* out, std::string& status) {
  guard.set_dry_run(true);
  nlohmann::json refused = nlohmann::json::array();
  Eigen::VectorXd from = in.targets.front();
  double path = 0.0;
  double seconds = 0.0;
  for (std::size_t i = 0; i < in.targets.size(); ++i) {
    const robotio::GuardVerdict v =
        guard.check_move(from, in.targets[i], {o.speed, o.acceleration});
    if (!v.allowed) {
      refused.push_back({{"pose", i}, {"reason", v.reason}});
      if (out) fmt::print(out, "  pose {:3}: REFUSED: {}\n", i, v.reason);
    } else {
      path += (in.targets[i] - from).norm();
      // Every actuator moves at the limit; the motion lasts as long as the longest travel.
      seconds +=
          motion_seconds((in.targets[i] - from).cwiseAbs().maxCoeff(), o.speed, o.acceleration);
      from = in.targets[i];
    }
  }
  nlohmann::json r;
  status = refused.empty() ? "dry_run_ok" : "refused";
  r["motions_checked"] = in.targets.size();
  r["refused"] = refused;
  r["actuator_path_length"] = path;
  r["motion_seconds"] = seconds;
  if (out)
    fmt::print(out,
               "dry run: {} motions checked by the safety guard (limits, workspace, obstacles), "
               "{} refused; nothing moved{}\n",
               in.targets.size(), refused.size(),
               refused.empty() ? "" : ": fix the plan or the cell before collecting");
  return r;
}

// ---- capture -----------------------------------------------------------------------------------

struct OpenCameras {
  std::vector<std::unique_ptr<robotio::CameraSource>> sources;
  std::vector<robotio::CaptureCamera> capture;
};

OpenCameras open_cameras(const CollectOptions& o, const CollectInputs& in, std::FILE* out) {
  OpenCameras c;
  for (std::size_t i = 0; i < in.cell.cameras.size(); ++i) {
    const planner::CellCamera& cell_camera = in.cell.cameras[i];
    const CollectCamera& given = o.cameras[static_cast<std::size_t>(in.camera_of[i])];
    auto source =
        o.open_camera ? o.open_camera(given) : open_camera(given.source, cell_camera.name);
    const robotio::Region region = source->region();
    if (region.width != cell_camera.model.width || region.height != cell_camera.model.height)
      source->set_region({0, 0, cell_camera.model.width, cell_camera.model.height});
    source->start(robotio::TriggerMode::kSoftware);
    const robotio::CameraInfo info = source->info();
    if (out)
      fmt::print(out, "camera {}: {} {} (serial {}) via {}\n", cell_camera.name, info.vendor,
                 info.model, info.serial, given.source);
    c.capture.push_back({source.get(), cell_camera.model});
    c.sources.push_back(std::move(source));
  }
  return c;
}

nlohmann::json pose_json(const robotio::PoseCaptureReport& p) {
  return {{"pose", p.name},
          {"retakes", p.retakes},
          {"frame_retries", p.frame_retries},
          {"still_moving", p.still_moving},
          {"motion_chi2", p.motion_chi2},
          {"corners", p.corners},
          {"move_s", p.move_s},
          {"grab_s", p.grab_s},
          {"check_s", p.check_s},
          {"write_s", p.write_s},
          {"wait_s", p.wait_s}};
}

// The summary gets the outcome's status, message and signal.
CollectOutcome finished(CollectOutcome outcome) {
  outcome.summary["status"] = outcome.status;
  if (!outcome.message.empty()) outcome.summary["message"] = outcome.message;
  if (outcome.signal != 0) outcome.summary["signal"] = outcome.signal;
  return outcome;
}

// Every motion of the plan through the guard before anything connects or moves: a pose the
// guard refuses stops the collection here, not after homing and the poses before it. Returns the
// dry run's record (its motion time is shown to the operator); `res` is set when refused.
nlohmann::json check_whole_plan(const CollectOptions& o, const CollectInputs& in,
                                SafetyGuard& guard, std::FILE* out, CollectOutcome& res) {
  std::string plan_verdict;
  nlohmann::json plan_check = dry_run(in, guard, o, nullptr, plan_verdict);
  guard.set_dry_run(false);
  if (plan_verdict == "dry_run_ok") return plan_check;
  const nlohmann::json& first = plan_check.at("refused").front();
  res.status = "refused";
  res.message = fmt::format(
      "the safety guard refuses {} of the plan's {} motions before anything moved; the first, "
      "to pose {}: {} (check the plan and the cell, or the speed)",
      plan_check.at("refused").size(), in.targets.size(), first.at("pose").get<int>(),
      first.at("reason").get<std::string>());
  res.summary["refused"] = plan_check.at("refused");
  if (out) fmt::print(out, "collect: {}\n", res.message);
  return plan_check;
}

// The link the address names: open:HOST:PORT is the open link, ur:HOST a Universal Robots
// controller, manual the operator, anything else G-code.
std::unique_ptr<robotio::RobotLink> make_link(const CollectOptions& o, const CollectInputs& in,
                                              SafetyGuard& guard) {
  robotio::GcodeLinkOptions lo;
  lo.address = o.link;
  lo.baud = o.baud;
  lo.axes = robotio::axes_for_robot(in.model, o.steps_per_mm, o.steps_per_degree);
  lo.reply_timeout = std::chrono::milliseconds(static_cast<long>(o.reply_timeout_s * 1000));
  lo.accept_unknown_firmware = o.accept_unknown_firmware;
  lo.unlock_protective_stop = o.unlock_protective_stop;
  lo.mode = o.gcode_mode;
  lo.geometry = o.firmware_geometry;
  return robotio::make_robot_link(guard, lo);
}

// Connects to the controller and records what it is; false (and `res` says why) when it does not
// answer as a controller of this robot.
bool connect_controller(robotio::RobotLink& link, const CollectOptions& o, std::FILE* out,
                        CollectOutcome& res) {
  nlohmann::json& r = res.summary;
  try {
    const auto firmware = link.connect();
    r["firmware"] = firmware.name;
    if (out) fmt::print(out, "controller at {}: {}\n", o.link, firmware.name);
    // A controller that computes its own flange pose (an industrial arm, an open link adapter
    // with `flange_pose`) has it recorded with every pose, for `robocal handeye`.
    r["flange_pose"] = link.reports_flange_pose();
    if (out && r["flange_pose"].get<bool>())
      fmt::print(out,
                 "the controller reports its base -> flange pose: recorded with every pose "
                 "(pose.yaml flange_pose), for `robocal handeye`\n");
    note_gcode_mode(link, o, r, out);
    return true;
  } catch (const robotio::LinkError& e) {
    res.status = "failed";
    res.message = fmt::format("controller at {}: {}", o.link, e.what());
    return false;
  }
}

// Homing, then every pose not yet on disk: moved to, settled, shot and written. A refused motion
// or a lost controller ends the capture with its reason; what was recorded stays.
robotio::CaptureResult capture_remaining(const CollectOptions& o, const CollectInputs& in,
                                         robotio::RobotLink& link, SafetyGuard& guard,
                                         const OpenCameras& cameras, std::int64_t start_ns,
                                         std::size_t already, std::FILE* out) {
  robotio::CaptureResult result;
  try {
    if (o.home) {
      if (out) fmt::print(out, "homing...\n");
      link.home();
    }
    robotio::LinkCaptureRobot link_robot(link, {o.speed, o.acceleration});
    PausableRobot robot(link_robot, guard, out, o.on_settled);
    robotio::CaptureOptions co_capture;
    co_capture.shots_per_pose = o.shots;
    co_capture.session_start_ns = start_ns;
    StageProgress progress(out, "collect", in.targets.size() - already);
    co_capture.on_pose_recorded = [&](const robotio::PoseCaptureReport&) { progress.advance(); };
    result = robotio::capture_poses(o.session, in.targets, robot, cameras.capture,
                                    in.cell.target.board, co_capture);
    progress.finish(fmt::format("{} poses recorded", result.recorded()));
  } catch (const robotio::MotionRefused& e) {
    result.stop_reason = e.what();
  } catch (const robotio::LinkError& e) {
    result.stop_reason = fmt::format("controller at {}: {}", o.link, e.what());
  }
  return result;
}

// The capture's record in the summary, its status, and what the operator reads at the end.
void record_capture(const CollectOptions& o, const CollectInputs& in,
                    const robotio::CaptureResult& result, std::size_t already, std::FILE* out,
                    CollectOutcome& res) {
  nlohmann::json& r = res.summary;
  nlohmann::json summary_poses = nlohmann::json::array();
  int still_moving = 0;
  int retakes = 0;
  for (const auto& p : result.poses) {
    if (p.status != robotio::PoseCaptureStatus::kRecorded) continue;
    summary_poses.push_back(pose_json(p));
    still_moving += p.still_moving ? 1 : 0;
    retakes += p.retakes;
  }
  const std::size_t on_disk = recorded_on_disk(o.session, in.targets.size());
  r["recorded"] = on_disk - already;
  r["already_recorded"] = already;
  r["recorded_total"] = on_disk;
  r["retakes"] = retakes;
  r["still_moving"] = still_moving;
  r["poses"] = summary_poses;
  r["capture_seconds"] = result.seconds;
  const int sig = robotio::StopSignals::stop_signal();
  if (result.complete && on_disk == in.targets.size()) {
    res.status = "ok";
  } else {
    res.status = sig != 0 ? "interrupted" : "incomplete";
    res.signal = sig;
    res.message = result.stop_reason;
  }
  if (!out) return;
  fmt::print(out, "{} of {} poses recorded ({} now, {} before){}\n", on_disk, in.targets.size(),
             on_disk - already, already,
             still_moving > 0 ? fmt::format("; {} recorded while the target still moved "
                                            "(flagged in pose.yaml)",
                                            still_moving)
                              : "");
  if (res.status != "ok")
    fmt::print(out,
               "collection stopped: {}\nThe robot was stopped. Every recorded pose is complete "
               "on disk. To go on, run the same command with --resume.\n",
               result.stop_reason);
  else if (o.say_next_step)
    fmt::print(out,
               "next: calibration views for the intrinsics and rig (app/SESSION.md), then "
               "`robocal measure {}`\n",
               o.session.string());
}

}  // namespace

CollectOutcome collect_session(const CollectOptions& o, const PipelineLog& log) {
  std::FILE* out = log.out;
  const CollectInputs in = read_inputs(o);
  CollectOutcome res;
  nlohmann::json& r = res.summary;
  r = {{"stage", "collect"},
       {"session", o.session.string()},
       {"robot", in.model.name},
       {"plan", o.plan},
       {"poses_planned", in.targets.size()}};
  // The guard every motion of this collection passes.
  CellGuard cell_guard(in.model, in.cell, {o.speed, o.acceleration});
  SafetyGuard& guard = cell_guard.guard;
  if (o.dry_run) {
    r.update(dry_run(in, guard, o, out, res.status));
    return finished(std::move(res));
  }
  const nlohmann::json plan_check = check_whole_plan(o, in, guard, out, res);
  if (res.status == "refused") return finished(std::move(res));

  // The session folder is checked first (file problems are exit 3, before any connection), and
  // nothing is created or moved until the controller and every camera answer.
  if (o.resume) {
    (void)continue_session(o, in);
  } else {
    check_new_session_folder(o.session);
  }
  const std::unique_ptr<robotio::RobotLink> link = make_link(o, in, guard);
  if (!connect_controller(*link, o, out, res)) return finished(std::move(res));
  OpenCameras cameras;
  try {
    cameras = open_cameras(o, in, out);
  } catch (const std::exception& e) {
    res.status = "failed";
    res.message = std::string("camera: ") + e.what();
    return finished(std::move(res));
  }

  const std::size_t already = recorded_on_disk(o.session, in.targets.size());
  if (out) {
    fmt::print(
        out, "{} collection in {}:\n{}", o.resume ? "Continuing the" : "Starting a",
        o.session.string(),
        describe(o, in, in.targets.size() - already, plan_check.value("motion_seconds", 0.0)));
  }
  if (already == in.targets.size()) {
    res.status = "ok";
    r["already_recorded"] = already;
    r["recorded"] = 0;
    if (out) fmt::print(out, "every pose of the plan is already recorded; nothing to do\n");
    return finished(std::move(res));
  }
  if (!operator_confirms(o, out)) {
    res.status = "cancelled";
    res.message = o.yes || ::isatty(STDIN_FILENO) != 0
                      ? "the operator did not confirm; nothing moved"
                      : "the operator did not confirm (no terminal to ask on): nothing moved; "
                        "check the plan (--dry-run), then give --yes";
    return finished(std::move(res));
  }
  const std::int64_t start_ns = o.resume ? continue_session(o, in) : start_session(o, in);
  guard.arm(o.yes ? "--yes on the command line" : "typed yes at the prompt");

  const robotio::StopSignals signals(guard);
  const PauseKey pause_key;
  if (out != nullptr && pause_key.active())
    fmt::print(out, "press p to pause between poses, Ctrl-C to stop the robot\n");
  const robotio::CaptureResult result =
      capture_remaining(o, in, *link, guard, cameras, start_ns, already, out);
  for (auto& c : cameras.sources) c->close();
  record_capture(o, in, result, already, out, res);
  return finished(std::move(res));
}

double motion_seconds(double distance, double speed, double acceleration) {
  if (distance <= 0.0) return 0.0;
  const double ramp = speed / acceleration;  // time to reach the speed
  if (distance >= speed * ramp) return distance / speed + ramp;
  return 2.0 * std::sqrt(distance / acceleration);
}

std::string actuator_unit(const calib::Mechanism& model) {
  bool linear = false;
  bool rotary = false;
  for (const int a : model.actuated) {
    const bool p = model.bodies[static_cast<std::size_t>(a)].joint == calib::JointType::kPrismatic;
    linear = linear || p;
    rotary = rotary || !p;
  }
  return linear && rotary ? "m or rad" : linear ? "m" : "rad";
}

int collect_exit_code(const CollectOutcome& outcome) {
  if (outcome.status == "ok" || outcome.status == "dry_run_ok") return kExitOk;
  if (outcome.status == "interrupted") return 128 + outcome.signal;
  return kExitFailure;
}

}  // namespace robocal::app
