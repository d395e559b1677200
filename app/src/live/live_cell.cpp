#include "live/live_cell.hpp"

#include "cli/cli_common.hpp"
#include "live/cell_clearance.hpp"
#include "robocal/calib/kinematics.hpp"
#include "robocal/calib/mechanism_predictor.hpp"
#include "robocal/calib/robot_file.hpp"
#include "robocal/core/files.hpp"
#include "robocal/planner/cell.hpp"
#include "robocal/planner/collision_scene.hpp"
#include "robocal/planner/plan.hpp"
#include "robocal/planner/plan_output.hpp"
#include "robocal/planner/task_sampling.hpp"
#include "robocal/robotio/delta_firmware.hpp"
#include "robocal/robotio/safety_guard.hpp"
#include "robocal/robotio/sim_process.hpp"
#include "robocal/vision/camera_io.hpp"
#include "robocal/vision/target_io.hpp"

#include <fmt/core.h>

#include <algorithm>
#include <functional>
#include <random>

namespace robocal::app {

namespace fs = std::filesystem;

namespace {

std::string vec(const Eigen::Vector3d& v) {
  return fmt::format("[{:.9f}, {:.9f}, {:.9f}]", v.x(), v.y(), v.z());
}

// The lens as its datasheet gives it: the designed focal length, the principal point in the
// image centre, no distortion (the true camera differs; the calibration views measure it).
vision::CameraModel datasheet_camera(const CellOptions& o) {
  return vision::make_camera(vision::CameraKind::kPinholeRadtan, o.image_width, o.image_height,
                             o.focal_px, o.focal_px, 0.5 * (o.image_width - 1),
                             0.5 * (o.image_height - 1), {0.0, 0.0, 0.0, 0.0, 0.0});
}

// The board's pose on the library robot's tool frame: the cell moved the tool frame's
// parameters to the board (set_fixed_frame_pose); both frames compared at one configuration.
Eigen::Isometry3d tool_T_board(const SimulatedCell& cell, const calib::Mechanism& library) {
  const Eigen::VectorXd original = library.nominal_parameters();
  std::mt19937 rng(1);
  const calib::MechanismPredictor predictor(library);
  for (const auto& q : calib::sample_actuators(predictor, {original}, 8, rng)) {
    const auto tool = calib::forward_kinematics(library, original, q, library.tool);
    const auto board = calib::forward_kinematics(cell.model, cell.nominal, q, cell.target_frame);
    if (tool.closure.ok() && board.closure.ok()) return tool.pose.inverse() * board.pose;
  }
  throw InputError(library.name + ": no configuration to place the board on the tool");
}

}  // namespace

LiveCellFiles write_live_cell(const SimulatedCell& cell, const std::string& robot_file,
                              const fs::path& dir) {
  fs::create_directories(dir);
  LiveCellFiles f;
  f.cell = dir / "cell.yaml";
  f.perturbation = dir / "truth.txt";
  f.ee_target = dir / "end_effector.yaml";
  f.calibration_target = dir / "calibration.yaml";
  core::write_file_atomic(f.ee_target, vision::target_to_yaml(cell.ee_board.spec));
  core::write_file_atomic(f.calibration_target,
                          vision::target_to_yaml(cell.calibration_board.spec));

  // The simulator's true robot: every parameter, so its true geometry is exactly the cell's.
  std::string truth = fmt::format(
      "# true parameters of the live demo's robot ({}), for robocal sim-controller "
      "--perturbation\n",
      cell.model.name);
  for (std::size_t i = 0; i < cell.model.parameters.size(); ++i)
    truth += fmt::format("{}={:.17g}\n", cell.model.parameters[i].name,
                         cell.truth[static_cast<Eigen::Index>(i)]);
  core::write_file_atomic(f.perturbation, truth);

  const calib::Mechanism library = calib::load_robot_file(robot_file);
  const vision::CameraModel datasheet = datasheet_camera(cell.options);
  std::string cams;
  for (std::size_t c = 0; c < cell.cameras.size(); ++c) {
    const std::string name = fmt::format("cam{}", c);
    core::write_file_atomic(dir / (name + ".yaml"), vision::camera_to_yaml(datasheet, name));
    const Eigen::Isometry3d world_T_cam = cell.cameras[c].camera_T_world.inverse();
    const Eigen::Vector3d p = world_T_cam.translation();
    cams += fmt::format(
        "  - name: {}\n    file: {}.yaml\n    pose: {{position: {}, look_at: {}, up: {}}}\n", name,
        name, vec(p), vec(p + world_T_cam.linear().col(2)), vec(-world_T_cam.linear().col(1)));
  }
  // The declared workspace: where the nominal robot reaches, grown by the board's size (the
  // measured frame and the board stay inside).
  const Eigen::Vector3d grow = Eigen::Vector3d::Constant(
      0.05 + std::max(cell.ee_board.extent_max.x() - cell.ee_board.extent_min.x(),
                      cell.ee_board.extent_max.y() - cell.ee_board.extent_min.y()));
  const Eigen::Isometry3d mount = tool_T_board(cell, library);
  const Eigen::Vector3d ypr = mount.linear().eulerAngles(2, 1, 0);
  const std::string text = fmt::format(
      "cell: live_demo_{}\nunits: m\ncameras:\n{}workspace: {{min: {}, max: {}}}\n"
      "margins: {{clearance: 0.005, self_clearance: 0.0005}}\n"
      "target:\n  file: end_effector.yaml\n  frame: {}\n  position: {}\n"
      "  rpy: [{:.12f}, {:.12f}, {:.12f}]\n",
      cell.model.name, cams, vec(cell.volume_centre - cell.volume_extent - grow),
      vec(cell.volume_centre + cell.volume_extent + grow),
      library.bodies.at(static_cast<std::size_t>(library.tool)).name, vec(mount.translation()),
      ypr[2], ypr[1], ypr[0]);
  // An array of camera pairs: any two of its cameras measure a pose.
  const std::string visibility =
      cell.placement.min_cameras > 0
          ? fmt::format("visibility: {{min_cameras: {}}}\n", cell.placement.min_cameras)
          : std::string();
  core::write_file_atomic(f.cell, text + visibility);
  return f;
}

namespace {

// Where the controller's homing leaves the robot: the robot file's home joint values, read on
// the nominal robot (the firmware's endstops are where it believes them).
Eigen::VectorXd home_readings(const calib::Mechanism& library) {
  return calib::readings_from_joint_values(library, library.nominal_parameters(),
                                           library.home_actuated());
}

}  // namespace

bool simulated_native_delta(const calib::Mechanism& model, const std::string& protocol,
                            const std::string& firmware, const std::string& gcode_mode) {
  const bool klipper = protocol == "gcode" && firmware == "klipper";
  const bool native = protocol == "gcode" && (gcode_mode != "raw" || klipper) &&
                      robotio::robot_file_delta(model).problem.empty();
  if (klipper && !native)
    throw InputError("--firmware klipper: robot '" + model.name +
                     "' is not a linear delta, the only robot Klipper's delta kinematics drives");
  return native;
}

std::string simulated_link_address(const robotio::SimControllerProcess& sim,
                                   const std::string& protocol, bool klipper) {
  if (protocol == "ur") return sim.ur();
  // tcp() is "tcp:HOST:PORT"; the open protocol and Moonraker are served on the same port.
  const std::string port = sim.tcp().substr(sim.tcp().find(':') + 1);
  if (protocol == "open") return "open:" + port;
  return klipper ? "moonraker:" + port : sim.tcp();
}

Commandable drawing_commandability(const calib::Mechanism& model, const std::string& firmware) {
  robotio::CarriageFrame frame;
  const robotio::RobotFileDelta file = robotio::robot_file_delta(model);
  const robotio::Firmware kind = firmware == "klipper" ? robotio::Firmware::kKlipper
                                 : firmware == "rrf"   ? robotio::Firmware::kRepRapFirmware
                                                       : robotio::Firmware::kMarlin;
  frame.geometry = robotio::drawing_geometry(file, kind);
  frame.endstop_reading = file.endstop_reading;
  return [frame](const Eigen::VectorXd& q) {
    return robotio::firmware_can_command(frame, robotio::delta_counts(frame, q));
  };
}

std::vector<Eigen::VectorXd> sampled_poses(const SimulatedCell& cell,
                                           const calib::Mechanism& library,
                                           const planner::Cell& pcell, int count, unsigned seed,
                                           const robotio::MoveSpeed& speed,
                                           const Commandable& commandable) {
  CellGuard cell_guard(library, pcell, speed);
  robotio::SafetyGuard& guard = cell_guard.guard;
  guard.set_dry_run(true);
  Eigen::VectorXd from = home_readings(library);

  std::mt19937 rng(seed + 101);
  const calib::MechanismPredictor predictor(cell.model, cell.target_frame);
  std::vector<Eigen::VectorXd> out;
  for (const auto& q : calib::sample_actuators(predictor, {cell.nominal},
                                               static_cast<std::size_t>(count) * 20, rng)) {
    if (static_cast<int>(out.size()) == count) break;
    const auto fk = calib::forward_kinematics(cell.model, cell.nominal, q, cell.target_frame);
    if (!fk.closure.ok()) continue;
    if ((commandable && !commandable(q)) ||
        cameras_seeing_board(cell, fk.pose) < cell.plan_cell.cameras_needed() ||
        !guard.check_move(from, q, speed).allowed)
      continue;
    out.push_back(q);
    from = q;
  }
  return out;
}

LivePlan plan_live_poses(const SimulatedCell& cell, const std::string& robot_file,
                         const LiveCellFiles& files, int count, unsigned seed, bool quick,
                         const fs::path& plan_file, const robotio::MoveSpeed& speed, std::FILE* out,
                         const Commandable& commandable) {
  LivePlan plan;
  const calib::Mechanism library = calib::load_robot_file(robot_file);
  std::string why;
  try {
    const planner::Cell pcell = planner::load_cell_file(files.cell.string());
    // With the planner's collision-checked tour: where no tour joins the chosen poses (a
    // straight motion would pass a singular configuration, where the true robot may change its
    // assembly mode), another candidate pool; after three, the selection unordered (the guard
    // then checks every motion before it is sent, but not the assembly mode).
    for (int attempt = 0; attempt < 4; ++attempt) {
      const bool order = attempt < 3;
      planner::PlanOptions po;
      po.pool = quick ? 1500 : 3000;
      po.seed = seed + 7919U * static_cast<unsigned>(attempt % 3);
      po.order = order;
      po.selection.count = static_cast<std::size_t>(count);
      // The controller homes before collection: the tour starts at home, so the first motion
      // is checked like the others (the UR5's first pose was reached through its wrist
      // singularity, and the guard refused the move).
      po.start = home_readings(library);
      // The true robot is millimetres from the nominal one planned on: poses it cannot reach
      // within that spread are left out (a Gantry-Tau pose 0.09 from its carts' plane stopped
      // seed 3's collection at pose 22).
      po.tolerance_sigma = truth_spread(cell);
      // A robot whose own joints turn its board (fewer than six actuators: the wire robot's
      // platform) has it turned towards the cameras, as the offline demo does; in joint space
      // its board faces them at a few per cent of the samples.
      po.task_space = planner::target_turned_by_joints(library, library.task.frame);
      // Where the cell sees so small a part of the robot's range that the pool cannot hold the
      // poses asked (the wire robot's pair: one feasible candidate in 1500), sampled again as
      // the offline demo does; other robots' plans stay as they were.
      // Candidates the firmware cannot command are left out before the selection and the tour,
      // so the tour joins commandable poses only.
      std::size_t left_out = 0;
      if (commandable)
        po.admissible = [&](const Eigen::VectorXd& q) {
          const bool ok = commandable(q);
          if (!ok) ++left_out;
          return ok;
        };
      planner::PlanResult r = planner::plan_with_enough_candidates(
          library, library.nominal_parameters(), pcell, po, po.selection.count);
      if ((r.status != planner::PlanStatus::kOk && r.status != planner::PlanStatus::kNotAccepted) ||
          r.poses.size() != static_cast<std::size_t>(count)) {
        why +=
            (why.empty() ? "" : "; then ") +
            (r.message.empty() ? fmt::format("{} of {} poses", r.poses.size(), count) : r.message);
        continue;
      }
      for (const auto& p : r.poses) plan.readings.push_back(p.readings);
      plan.predicted_rms_m = r.selection.predicted_rms;
      plan.how = fmt::format(
          "planner: {} poses chosen by observability from {} feasible candidates, {} "
          "(predicted {:.1f} µm RMS{})",
          r.poses.size(), r.pool.size(),
          order ? "in a collision-checked tour"
                : fmt::format("not ordered into a tour ({}); the guard checks each motion", why),
          r.selection.predicted_rms * 1e6,
          r.selection.accepted ? "" : "; the acceptance test is not met");
      if (left_out > 0)
        plan.how += fmt::format(
            "; {} feasible candidates left out: the firmware's delta kinematics cannot command "
            "them (a carriage below the nozzle)",
            left_out);
      core::write_file_atomic(plan_file, planner::plan_to_yaml(library, pcell, r, po));
      core::write_file_atomic(fs::path(plan_file).replace_extension(".svg"),
                              planner::plan_to_svg(pcell, r));
      return plan;
    }
  } catch (const std::exception& e) {
    why += (why.empty() ? "" : "; then ") + std::string(e.what());
  }
  // Planning is not possible for this robot in this cell: the cell's own poses, said so.
  plan.planner = false;
  try {
    plan.readings = sampled_poses(cell, library, planner::load_cell_file(files.cell.string()),
                                  count, seed, speed, commandable);
  } catch (const std::exception& e) {
    throw InputError(fmt::format("{}: no poses to collect: {}", library.name, e.what()));
  }
  plan.how = fmt::format(
      "NOT planned: the planner could not plan for {} ({}); using {} poses sampled on the "
      "nominal robot where both cameras see the board (the offline demo's way), chained so "
      "that the safety guard allows every motion",
      library.name, why, plan.readings.size());
  if (out) fmt::print(out, "  {}\n", plan.how);
  std::string text = "# live demo: poses sampled on the nominal robot (no planner)\nposes:\n";
  for (const auto& q : plan.readings) {
    std::string values;
    for (Eigen::Index i = 0; i < q.size(); ++i)
      values += fmt::format("{}{:.12g}", i == 0 ? "" : ", ", q[i]);
    text += fmt::format("  - {{actuators: [{}]}}\n", values);
  }
  core::write_file_atomic(plan_file, text);
  return plan;
}

}  // namespace robocal::app
