// The simulate stage: a synthetic session folder from a simulated cell (rendered images,
// actuator readings, and the hidden truth in truth/, which only validate reads).
#include "cli/cli_common.hpp"
#include "session/json_values.hpp"
#include "session/results_files.hpp"
#include "session/session.hpp"
#include "session/session_robot.hpp"
#include "simcell/simulated_cell.hpp"
#include "stages/cell_truth.hpp"
#include "stages/stage_log.hpp"
#include "stages/stages.hpp"

#include "robocal/calib/closure.hpp"
#include "robocal/calib/mechanism_predictor.hpp"
#include "robocal/core/files.hpp"
#include "robocal/core/parallel.hpp"
#include "robocal/core/staging.hpp"
#include "robocal/vision/renderer.hpp"
#include "robocal/vision/target_io.hpp"
#include "robocal_version.hpp"

#include <fmt/core.h>

#include <algorithm>

namespace robocal::app {

namespace fs = std::filesystem;

namespace {

// The realistic truth's elastic sag (simcell elastic_deflection): 16 µm at the rotary Delta's
// 0.4 m reach, 64 µm at 0.8 m, at most 100 µm (kMaxElasticSag). Small against the 0.5 mm / 0.2°
// tolerances, but no kinematic model can represent it, as on a real robot.

// One image to render: a board seen by a camera, written to `file`.
struct Shot {
  int camera = 0;
  const vision::TargetBoard* board = nullptr;
  Eigen::Isometry3d camera_T_board = Eigen::Isometry3d::Identity();
  std::uint64_t seed = 0;
  fs::path file;
};

void render_shots(const SimulatedCell& cell, const std::vector<Shot>& shots,
                  const std::string& label, const PipelineLog& log) {
  StageProgress bar(log.out, label, shots.size());
  core::parallel_for(static_cast<int>(shots.size()), log.threads, [&](int i) {
    const Shot& shot = shots[static_cast<std::size_t>(i)];
    vision::RenderOptions options = cell.options.render;
    options.seed = shot.seed;
    const auto& cam = cell.cameras[static_cast<std::size_t>(shot.camera)];
    const auto rendered = vision::render(*cam.rays, {{*shot.board, shot.camera_T_board}}, options);
    write_image_atomic(shot.file, rendered.image);
    bar.advance();
  });
  bar.finish(fmt::format("{} images", shots.size()));
}

// The session record of a simulated cell in `dir`, with its files written: the robot file as it
// is (the manufacturer's; the designed board mount goes to session.yaml) and the two boards.
Session start_session(const SimulatedCell& cell, const std::string& robot_file, const fs::path& dir,
                      unsigned seed) {
  Session s;
  s.dir = dir;
  s.software = std::string("robocal ") + kVersion;
  s.created = utc_now();
  s.source = "simulated";
  s.seed = seed;
  s.robot_name = cell.model.name;
  s.measured_frame = cell.model.bodies.at(static_cast<std::size_t>(cell.target_frame)).name;
  s.actuators = static_cast<int>(cell.model.actuated.size());
  for (std::size_t c = 0; c < cell.cameras.size(); ++c)
    s.cameras.push_back(
        {fmt::format("cam{}", c), cell.cameras[c].model.width, cell.cameras[c].model.height});

  // The robot file as it is (the manufacturer's); the designed board mount goes to session.yaml.
  const std::string original = core::read_text_file(robot_file);
  for (std::size_t i = 0; i < cell.model.parameters.size(); ++i)
    if (cell.model.parameters[i].body == cell.target_frame)
      s.target_mount.emplace_back(cell.model.parameters[i].name,
                                  cell.nominal[static_cast<Eigen::Index>(i)]);
  core::write_file_atomic(s.path(s.robot_file), original, core::Overwrite::kRefuse);
  core::write_file_atomic(s.path(s.ee_target), vision::target_to_yaml(cell.ee_board.spec),
                          core::Overwrite::kRefuse);
  core::write_file_atomic(s.path(s.calibration_target),
                          vision::target_to_yaml(cell.calibration_board.spec),
                          core::Overwrite::kRefuse);
  return s;
}

}  // namespace

nlohmann::json simulate_session(const SimulateOptions& o, const PipelineLog& log) {
  if (o.out.empty()) throw InputError("simulate needs an output folder (--out DIR)");
  std::error_code ec;
  if (fs::exists(o.out, ec) && !fs::is_empty(o.out, ec))
    throw InputError(
        fmt::format("{}: exists and is not empty; simulate never writes into (or "
                    "over) a recorded session",
                    o.out.string()));
  const std::string robot_file = resolve_robot(o.robot);
  // The random stream is consumed in a fixed order (cell, intrinsic views, rig views, poses):
  // the same seed gives the same images.
  std::mt19937 rng(o.seed);
  CellOptions cell_options = demo_cell_options(o.seed, o.quick, o.idealised_truth);
  if (o.read_noise) cell_options.render.read_noise = *o.read_noise;
  stage(log, "simulate: cell");
  const SimulatedCell cell = make_simulated_cell(robot_file, cell_options, rng);
  say(log, "true robot: {}\n",
      o.idealised_truth ? "idealised (differs from the drawing only in what the model estimates)"
                        : "with unmodelled error (parameters the model holds fixed are off too, "
                          "and the robot sags elastically with its reach)");
  say(log, "cell: {} ({} parameters), {} cameras {}x{}, end-effector board {} corners\n",
      cell.model.name, cell.model.parameters.size(), cell.cameras.size(), cell_options.image_width,
      cell_options.image_height, cell.ee_board.corners.size());

  // The session is written into a staging folder beside --out that becomes --out in one step once
  // everything is written (core/staging.hpp): an unfinished simulation leaves nothing behind.
  core::StagedDirectory staging(o.out, core::StagedDirectory::Start::kEmpty);
  const Session s = start_session(cell, robot_file, staging.path(), o.seed);

  // Intrinsic views per camera, rig views, robot poses.
  stage(log, "simulate: render calibration views");
  std::vector<Shot> shots;
  for (std::size_t c = 0; c < cell.cameras.size(); ++c) {
    int v = 0;
    for (const auto& pose : intrinsic_view_poses(cell, static_cast<int>(c), o.intrinsic_views, rng))
      shots.push_back(
          {static_cast<int>(c), &cell.calibration_board, pose, rng(),
           s.path(s.intrinsics_views) / s.cameras[c].name / fmt::format("view_{:03d}.png", v++)});
  }
  const auto rig_poses = rig_view_poses(cell, o.rig_views, rng);
  for (std::size_t v = 0; v < rig_poses.size(); ++v)
    for (std::size_t c = 0; c < cell.cameras.size(); ++c)
      shots.push_back(
          {static_cast<int>(c), &cell.calibration_board,
           cell.cameras[c].camera_T_world * rig_poses[v], rng(),
           s.path(s.rig_views) / fmt::format("view_{:03d}", v) / (s.cameras[c].name + ".png")});
  render_shots(cell, shots, "render calibration views", log);

  // Robot poses: planned (default) or random. Either way a pose is recorded only when both
  // (true) cameras (two of an array's) see the whole end-effector board on the true robot.
  stage(log, "simulate: robot poses and images");
  say(log, "cameras: {}\n", cell.placement.summary);
  calib::MechanismPredictor true_predictor(cell.model, cell.target_frame);
  std::vector<Eigen::VectorXd> true_readings;
  std::vector<Eigen::Isometry3d> true_board_poses;
  // Every camera of a pair; two cameras at least of an array.
  const int cameras_needed = cell.plan_cell.cameras_needed();
  const std::string seen_by =
      cameras_needed == static_cast<int>(cell.cameras.size())
          ? "both cameras"
          : fmt::format("{} of the {} cameras", cameras_needed, cell.cameras.size());
  auto try_pose = [&](const Eigen::VectorXd& q) {
    Eigen::Isometry3d world_T_board;
    if (!true_frame_pose(cell, q, &world_T_board) ||
        cameras_seeing_board(cell, world_T_board) < cameras_needed)
      return false;
    true_readings.push_back(q);
    true_board_poses.push_back(world_T_board);
    return true;
  };
  std::string pose_source = "random";
  if (!o.random_poses) {
    std::string why;
    const std::vector<Eigen::VectorXd> planned = plan_cell_poses(cell, o.poses, rng, &why);
    if (planned.empty()) {
      say(log, "  note: no planned poses ({}); random poses instead\n", why);
    } else {
      pose_source = "planned";
      say(log, "  {}\n", why);
      std::size_t unseen = 0;
      for (const auto& q : planned) unseen += try_pose(q) ? 0 : 1;
      if (unseen > 0)
        say(log,
            "  {} planned poses not recorded: the board is not wholly in view of {} (true "
            "cameras; the plan knows only the nominal robot and intrinsics)\n",
            unseen, seen_by);
    }
  }
  if (pose_source == "random") {
    // A simple spread: random reachable actuator values, kept when visible.
    for (const auto& q : calib::sample_actuators(true_predictor, {cell.truth, cell.nominal},
                                                 static_cast<std::size_t>(o.poses) * 4, rng)) {
      if (static_cast<int>(true_readings.size()) == o.poses) break;
      try_pose(q);
    }
  }
  if (static_cast<int>(true_readings.size()) < o.poses)
    say(log, "  note: only {} poses with the board in view of {}\n", true_readings.size(), seen_by);
  // Fewer poses than identify needs is no session to calibrate from: a robot file whose range is
  // a sliver (joint limits in the wrong unit, a typo) is said so here, not written as a session
  // of no poses with exit code 0 for measure to refuse later.
  if (true_readings.size() < 3)
    throw InputError(fmt::format(
        "{}: only {} of the {} poses asked have the board in view of {} on the robot: too few "
        "reachable configurations to calibrate from (at least 3); the robot reaches too small a "
        "part of its cell: check its joint limits and lengths (`robocal kin check {}`)",
        robot_file, true_readings.size(), o.poses, seen_by, robot_file));
  shots.clear();
  TruthFile truth = cell_truth(cell, "robocal simulate");
  // The readings are made here (read_actuators), with the cell's noise and step.
  truth.perturbation.actuator_noise = cell_options.actuator_noise;
  truth.perturbation.actuator_step = cell_options.actuator_step;
  for (std::size_t i = 0; i < true_readings.size(); ++i) {
    PoseRecord record;
    record.name = fmt::format("pose_{:03d}", i);
    record.actuators = read_actuators(cell, true_readings[i], rng);
    record.timestamp = 2.0 * static_cast<double>(i);  // a pose every 2 s
    const fs::path dir = s.path(s.poses) / record.name;
    core::write_file_atomic(dir / "pose.yaml", pose_record_yaml(record), core::Overwrite::kRefuse);
    for (std::size_t c = 0; c < cell.cameras.size(); ++c)
      shots.push_back({static_cast<int>(c), &cell.ee_board,
                       cell.cameras[c].camera_T_world * true_board_poses[i], rng(),
                       dir / (s.cameras[c].name + ".png")});
    truth.poses.push_back({record.name, true_readings[i], true_board_poses[i]});
  }
  render_shots(cell, shots, "render pose images", log);

  // The hidden truth: read by validate only.
  write_truth(ResultsLayout{s.dir}, cell.model, truth);
  core::write_file_atomic(s.dir / "session.yaml", session_to_yaml(s), core::Overwrite::kRefuse);
  staging.commit();
  if (log.clock) log.clock->stop();
  say(log, "session written to {} ({} poses)\n", o.out.string(), true_readings.size());
  return {{"status", "ok"},
          {"session", o.out.string()},
          {"robot", cell.model.name},
          {"seed", o.seed},
          {"truth", o.idealised_truth ? "idealised" : "with unmodelled error"},
          {"poses", true_readings.size()},
          {"pose_source", pose_source},
          {"images", 2 * true_readings.size() + 2 * rig_poses.size() +
                         static_cast<std::size_t>(o.intrinsic_views) * cell.cameras.size()}};
}

}  // namespace robocal::app
