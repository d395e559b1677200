// The session pipeline (see session_pipeline.hpp and app/SESSION.md). The measurement stages
// never read truth/: only simulate writes it and only validate reads it.
#include "session_pipeline.hpp"

#include "cli_common.hpp"
#include "measured_region.hpp"
#include "pixel_bridge.hpp"
#include "pose_bridge.hpp"
#include "rig_files.hpp"
#include "session.hpp"
#include "simulated_cell.hpp"

#include "robocal/calib/calibrated_robot_file.hpp"
#include "robocal/calib/closure.hpp"
#include "robocal/calib/identification.hpp"
#include "robocal/calib/identification_json.hpp"
#include "robocal/calib/kinematics.hpp"
#include "robocal/calib/measurements_file.hpp"
#include "robocal/calib/mechanism_predictor.hpp"
#include "robocal/calib/robot_file.hpp"
#include "robocal/vision/apriltag_detector.hpp"
#include "robocal/vision/camera_io.hpp"
#include "robocal/vision/intrinsic_calibration.hpp"
#include "robocal/vision/pose.hpp"
#include "robocal/vision/pose_measurement.hpp"
#include "robocal/vision/rig_calibration.hpp"
#include "robocal/vision/target_detection.hpp"
#include "robocal/vision/target_io.hpp"
#include "robocal_version.hpp"

#include <fmt/core.h>
#include <Eigen/Geometry>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <fstream>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <numeric>
#include <optional>
#include <set>
#include <thread>

namespace robocal::app {

namespace fs = std::filesystem;

namespace {

constexpr double kRadToDeg = 180.0 / 3.14159265358979323846;

// Runs fn(index) for index in [0, n) on `threads` workers; rethrows the first exception.
void parallel_for(int n, int threads, const std::function<void(int)>& fn) {
  std::atomic<int> next{0};
  std::vector<std::thread> pool;
  std::exception_ptr error;
  std::mutex error_mutex;
  for (int w = 0; w < std::max(1, std::min(threads, n)); ++w) {
    pool.emplace_back([&] {
      for (int i = next++; i < n; i = next++) {
        try {
          fn(i);
        } catch (...) {
          const std::lock_guard<std::mutex> lock(error_mutex);
          if (!error) error = std::current_exception();
        }
      }
    });
  }
  for (auto& t : pool) t.join();
  if (error) std::rethrow_exception(error);
}

// A progress bar that exists only when the log prints.
class Progress {
 public:
  Progress(const PipelineLog& log, const std::string& label, std::size_t total) {
    if (log.out) bar_.emplace(label, total, log.out);
  }
  void advance() {
    const std::lock_guard<std::mutex> lock(mutex_);
    if (bar_) bar_->advance();
  }
  void finish(const std::string& message) {
    if (bar_) bar_->finish(message);
  }

 private:
  std::optional<ProgressBar> bar_;
  std::mutex mutex_;
};

template <typename... Args>
void say(const PipelineLog& log, fmt::format_string<Args...> format, Args&&... args) {
  if (log.out) fmt::print(log.out, format, std::forward<Args>(args)...);
}

void stage(const PipelineLog& log, const std::string& name) {
  if (log.clock) log.clock->start(name);
}

nlohmann::json read_json_file(const fs::path& path, const std::string& hint) {
  std::ifstream in(path);
  if (!in) throw InputError(fmt::format("{}: missing ({})", path.string(), hint));
  try {
    return nlohmann::json::parse(in);
  } catch (const nlohmann::json::exception& e) {
    throw InputError(fmt::format("{}: not valid JSON ({})", path.string(), e.what()));
  }
}

Eigen::Isometry3d pose_from_json(const nlohmann::json& j, const std::string& where) {
  try {
    const auto r = j.at("rvec").get<std::vector<double>>();
    const auto t = j.at("tvec").get<std::vector<double>>();
    if (r.size() != 3 || t.size() != 3) throw std::invalid_argument("size");
    return vision::pose_from_rvec_tvec(Eigen::Vector3d(r[0], r[1], r[2]),
                                       Eigen::Vector3d(t[0], t[1], t[2]));
  } catch (const std::exception&) {
    throw InputError(where + ": expected {\"rvec\": [3 numbers], \"tvec\": [3 numbers]}");
  }
}

nlohmann::json vector_json(const Eigen::VectorXd& v) {
  return std::vector<double>(v.data(), v.data() + v.size());
}

// Parameter vector <-> {name: value}.
nlohmann::json params_json(const calib::Mechanism& model, const Eigen::VectorXd& v) {
  nlohmann::json j = nlohmann::json::object();
  for (std::size_t i = 0; i < model.parameters.size(); ++i)
    j[model.parameters[i].name] = v[static_cast<Eigen::Index>(i)];
  return j;
}
Eigen::VectorXd params_from_json(const calib::Mechanism& model, const nlohmann::json& j,
                                 const std::string& where) {
  Eigen::VectorXd v = model.nominal_parameters();
  for (std::size_t i = 0; i < model.parameters.size(); ++i) {
    const auto& name = model.parameters[i].name;
    if (!j.contains(name) || !j[name].is_number())
      throw InputError(
          fmt::format("{}: no value for parameter '{}' of {}", where, name, model.name));
    v[static_cast<Eigen::Index>(i)] = j[name].get<double>();
  }
  return v;
}

calib::Mechanism load_robot(const std::string& path) {
  try {
    return calib::load_robot_file(path);
  } catch (const calib::RobotFileError& e) {
    throw InputError(e.what());
  }
}

// The robot of a session: its own robot file, or `override_file` checked against the session.
struct SessionRobot {
  calib::Mechanism model;
  std::string file;
  int frame = -1;           // measured body
  Eigen::VectorXd nominal;  // the file's values with the session's target mount
};
SessionRobot session_robot(const Session& s, const std::string& override_file) {
  SessionRobot r;
  r.file = override_file.empty() ? s.path(s.robot_file).string() : override_file;
  r.model = load_robot(r.file);
  const std::string recorded = fmt::format("{} ({} actuators)", s.robot_name, s.actuators);
  if (r.model.name != s.robot_name)
    throw InputError(fmt::format(
        "{}: robot '{}' does not match the session {}, which was recorded with robot {}", r.file,
        r.model.name, s.dir.string(), recorded));
  if (static_cast<int>(r.model.actuated.size()) != s.actuators)
    throw InputError(
        fmt::format("{}: robot '{}' has {} actuators; the session {} was recorded with robot {}",
                    r.file, r.model.name, r.model.actuated.size(), s.dir.string(), recorded));
  r.frame = s.measured_frame.empty() ? r.model.tool : r.model.body_index(s.measured_frame);
  if (r.frame < 0)
    throw InputError(fmt::format("{}: the session's measured frame '{}' is not a body of {}",
                                 r.file, s.measured_frame, r.model.name));
  r.nominal = r.model.nominal_parameters();
  for (const auto& [name, value] : s.target_mount) {
    const int i = r.model.parameter_index(name);
    if (i < 0)
      throw InputError(
          fmt::format("{}: robot.target_mount names '{}', which is not a parameter of {} ({})",
                      (s.dir / "session.yaml").string(), name, r.model.name, r.file));
    r.nominal[i] = value;
  }
  return r;
}

vision::TargetBoard load_board(const fs::path& path) {
  try {
    return vision::load_target_file(path);
  } catch (const vision::FileFormatError& e) {
    throw InputError(e.what());
  }
}

std::vector<fs::path> images_in(const fs::path& folder) {
  static const std::set<std::string> kExt = {".png", ".tif", ".tiff", ".pgm",
                                             ".bmp", ".jpg", ".jpeg"};
  std::vector<fs::path> files;
  std::error_code ec;
  for (const auto& e : fs::directory_iterator(folder, ec))
    if (e.is_regular_file() && kExt.count(e.path().extension().string())) files.push_back(e.path());
  std::sort(files.begin(), files.end());
  return files;
}

std::string relative_to(const fs::path& p, const fs::path& base) {
  return fs::relative(p, base).generic_string();
}

// RMS pixel distance between two camera models over a grid of 3-D points 1 m in front of the
// camera spanning the image (the points are placed with the true model).
double projection_difference_px(const vision::CameraModel& estimated,
                                const vision::CameraModel& truth) {
  double sum = 0;
  int n = 0;
  for (int j = 0; j <= 10; ++j) {
    for (int i = 0; i <= 10; ++i) {
      const Eigen::Vector2d px(i * (truth.width - 1) / 10.0, j * (truth.height - 1) / 10.0);
      const auto ray = vision::unproject(truth, px);
      if (!ray) continue;
      const auto p = vision::project(estimated, *ray / ray->z());
      if (!p) continue;
      sum += (*p - px).squaredNorm();
      ++n;
    }
  }
  return n > 0 ? std::sqrt(sum / n) : std::numeric_limits<double>::infinity();
}

struct Errors {
  double rms = 0;
  double max = 0;
  std::size_t n = 0;
  void add(double e) {
    rms += e * e;
    max = std::max(max, e);
    ++n;
  }
  void finish() { rms = n > 0 ? std::sqrt(rms / static_cast<double>(n)) : 0.0; }
  nlohmann::json json() const { return {{"rms_m", rms}, {"max_m", max}, {"poses", n}}; }
};

// Position errors of `predicted` against `truth`, and the same after the rigid transform that
// best aligns them (Umeyama): the latter is the robot's accuracy in its own frame, unaffected by
// where the whole camera world sits.
struct ErrorPair {
  Errors absolute;
  Errors registered;
  std::vector<Eigen::Vector3d> registered_points;  // predicted, after the best-fit transform
};
ErrorPair position_errors(const std::vector<Eigen::Vector3d>& predicted,
                          const std::vector<Eigen::Vector3d>& truth) {
  ErrorPair out;
  Eigen::Matrix3Xd P(3, static_cast<Eigen::Index>(predicted.size()));
  Eigen::Matrix3Xd T(3, P.cols());
  for (std::size_t i = 0; i < predicted.size(); ++i) {
    P.col(static_cast<Eigen::Index>(i)) = predicted[i];
    T.col(static_cast<Eigen::Index>(i)) = truth[i];
    out.absolute.add((predicted[i] - truth[i]).norm());
  }
  if (P.cols() >= 3) {
    const Eigen::Isometry3d align(Eigen::umeyama(P, T, false));
    for (Eigen::Index i = 0; i < P.cols(); ++i) {
      out.registered_points.push_back(align * Eigen::Vector3d(P.col(i)));
      out.registered.add((out.registered_points.back() - T.col(i)).norm());
    }
  }
  out.absolute.finish();
  out.registered.finish();
  return out;
}

std::string fmt_param_change(const std::string& unit, double delta) {
  if (unit == "length") return fmt::format("{:+8.3f} mm", delta * 1e3);
  if (unit == "angle") return fmt::format("{:+8.4f} deg", delta * kRadToDeg);
  return fmt::format("{:+8.2e}", delta);
}

std::string unit_name(calib::ParamUnit unit) {
  switch (unit) {
    case calib::ParamUnit::kLength:
      return "length";
    case calib::ParamUnit::kAngle:
      return "angle";
    default:
      return "scale";
  }
}

nlohmann::json camera_json(const std::string& name, const vision::CameraModel& model,
                           const Eigen::Isometry3d& camera_T_world) {
  return {{"name", name},           {"model", std::string(vision::kind_name(model.kind))},
          {"width", model.width},   {"height", model.height},
          {"params", model.params}, {"camera_T_world", pose_to_json(camera_T_world)}};
}

// ---- simulate ------------------------------------------------------------------------------

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
  Progress bar(log, label, shots.size());
  parallel_for(static_cast<int>(shots.size()), log.threads, [&](int i) {
    const Shot& shot = shots[static_cast<std::size_t>(i)];
    vision::RenderOptions options = cell.options.render;
    options.seed = shot.seed;
    const auto& cam = cell.cameras[static_cast<std::size_t>(shot.camera)];
    const auto rendered = vision::render(cam.rays, {{*shot.board, shot.camera_T_board}}, options);
    write_image_atomic(shot.file, rendered.image);
    bar.advance();
  });
  bar.finish(fmt::format("{} images", shots.size()));
}

}  // namespace

std::string resolve_robot(const std::string& robot) {
  if (fs::exists(robot)) return robot;
  const auto library = fs::path(ROBOCAL_ROBOT_LIBRARY_DIR) / (robot + ".yaml");
  if (fs::exists(library)) return library.string();
  throw InputError(fmt::format("robot '{}' is neither a file nor a library robot in {}", robot,
                               ROBOCAL_ROBOT_LIBRARY_DIR));
}

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
  CellOptions cell_options;
  if (o.quick) {
    cell_options.image_width = 1280;
    cell_options.image_height = 960;
    cell_options.focal_px = 1300;
  }
  stage(log, "simulate: cell");
  SimulatedCell cell;
  try {
    cell = make_simulated_cell(robot_file, cell_options, rng);
  } catch (const calib::RobotFileError& e) {
    throw InputError(e.what());
  }
  say(log, "cell: {} ({} parameters), 2 cameras {}x{}, end-effector board {} corners\n",
      cell.model.name, cell.model.parameters.size(), cell_options.image_width,
      cell_options.image_height, cell.ee_board.corners.size());

  Session s;
  s.dir = o.out;
  s.software = std::string("robocal ") + kVersion;
  s.created = utc_now();
  s.source = "simulated";
  s.seed = o.seed;
  s.robot_name = cell.model.name;
  s.measured_frame = cell.model.bodies.at(static_cast<std::size_t>(cell.target_frame)).name;
  s.actuators = static_cast<int>(cell.model.actuated.size());
  for (std::size_t c = 0; c < cell.cameras.size(); ++c)
    s.cameras.push_back(
        {fmt::format("cam{}", c), cell.cameras[c].model.width, cell.cameras[c].model.height});
  fs::create_directories(o.out);

  // The robot file as it is (the manufacturer's); the designed board mount goes to session.yaml.
  const std::string original = read_text_file(robot_file);
  for (std::size_t i = 0; i < cell.model.parameters.size(); ++i)
    if (cell.model.parameters[i].body == cell.target_frame)
      s.target_mount.emplace_back(cell.model.parameters[i].name,
                                  cell.nominal[static_cast<Eigen::Index>(i)]);
  write_file_atomic(s.path(s.robot_file), original, false);
  write_file_atomic(s.path(s.ee_target), vision::target_to_yaml(cell.ee_board.spec), false);
  write_file_atomic(s.path(s.calibration_target),
                    vision::target_to_yaml(cell.calibration_board.spec), false);

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

  // Robot poses where both cameras see the whole end-effector board (a simple spread: random
  // reachable actuator values, kept when visible).
  stage(log, "simulate: robot poses and images");
  calib::MechanismPredictor true_predictor(cell.model, cell.target_frame);
  std::vector<Eigen::VectorXd> true_readings;
  std::vector<Eigen::Isometry3d> true_board_poses;
  for (const auto& q : calib::sample_actuators(true_predictor, {cell.truth, cell.nominal},
                                               static_cast<std::size_t>(o.poses) * 4, rng)) {
    if (static_cast<int>(true_readings.size()) == o.poses) break;
    Eigen::Isometry3d world_T_board;
    if (!true_frame_pose(cell, q, &world_T_board)) continue;
    bool seen = true;
    for (const auto& cam : cell.cameras) {
      const auto truth = vision::corner_truth(
          cam.model, {{cell.ee_board, cam.camera_T_world * world_T_board}}, cell.options.render);
      seen =
          seen && std::all_of(truth.begin(), truth.end(), [](const auto& t) { return t.visible; });
    }
    if (!seen) continue;
    true_readings.push_back(q);
    true_board_poses.push_back(world_T_board);
  }
  if (static_cast<int>(true_readings.size()) < o.poses)
    say(log, "  note: only {} poses with the board in view of both cameras\n",
        true_readings.size());
  shots.clear();
  nlohmann::json truth_poses = nlohmann::json::array();
  for (std::size_t i = 0; i < true_readings.size(); ++i) {
    PoseRecord record;
    record.name = fmt::format("pose_{:03d}", i);
    record.actuators = read_actuators(cell, true_readings[i], rng);
    record.timestamp = 2.0 * static_cast<double>(i);  // a pose every 2 s
    const fs::path dir = s.path(s.poses) / record.name;
    write_file_atomic(dir / "pose.yaml", pose_record_yaml(record), false);
    for (std::size_t c = 0; c < cell.cameras.size(); ++c)
      shots.push_back({static_cast<int>(c), &cell.ee_board,
                       cell.cameras[c].camera_T_world * true_board_poses[i], rng(),
                       dir / (s.cameras[c].name + ".png")});
    truth_poses.push_back({{"pose", record.name},
                           {"true_actuators", vector_json(true_readings[i])},
                           {"world_T_board", pose_to_json(true_board_poses[i])}});
  }
  render_shots(cell, shots, "render pose images", log);

  // The hidden truth: read by validate only.
  nlohmann::json cams = nlohmann::json::array();
  for (std::size_t c = 0; c < cell.cameras.size(); ++c)
    cams.push_back(
        camera_json(s.cameras[c].name, cell.cameras[c].model, cell.cameras[c].camera_T_world));
  nlohmann::json truth{{"note", "ground truth of a simulated session: only `validate` reads it"},
                       {"world", "the robot's nominal base frame"},
                       {"cameras", cams},
                       {"poses", truth_poses},
                       {"nominal", params_json(cell.model, cell.nominal)},
                       {"truth", params_json(cell.model, cell.truth)},
                       {"perturbation",
                        {{"length_sigma_m", cell_options.length_sigma},
                         {"angle_sigma_rad", cell_options.angle_sigma},
                         {"actuator_noise", cell_options.actuator_noise},
                         {"actuator_step", cell_options.actuator_step}}}};
  write_file_atomic(s.truth() / "truth.json", truth.dump(2) + "\n", false);
  // session.yaml last: a folder without it is an interrupted simulation, not a session.
  write_file_atomic(o.out / "session.yaml", session_to_yaml(s), false);
  if (log.clock) log.clock->stop();
  say(log, "session written to {} ({} poses)\n", o.out.string(), true_readings.size());
  return {{"status", "ok"},
          {"session", o.out.string()},
          {"robot", cell.model.name},
          {"seed", o.seed},
          {"poses", true_readings.size()},
          {"images", 2 * true_readings.size() + 2 * rig_poses.size() +
                         static_cast<std::size_t>(o.intrinsic_views) * cell.cameras.size()}};
}

// ---- measure -------------------------------------------------------------------------------

nlohmann::json measure_session(const fs::path& dir, const std::string& robot_override,
                               const PipelineLog& log) {
  const Session s = load_session(dir);
  const SessionRobot robot = session_robot(s, robot_override);
  const auto ee_board = load_board(s.path(s.ee_target));
  const auto cal_board = load_board(s.path(s.calibration_target));
  const auto names = s.camera_names();
  const std::size_t n_cams = s.cameras.size();
  fs::create_directories(s.results());
  nlohmann::json report{{"stage", "measure"}, {"session", dir.string()}};
  const auto fail = [&](const std::string& message) {
    report["status"] = "failed";
    report["message"] = message;
    write_json(report, (s.results() / "measure.json").string());
    say(log, "measure failed: {}\n", message);
    return report;
  };

  // 1. Intrinsics of each camera from its calibration views.
  stage(log, "measure: intrinsics");
  std::vector<vision::RigCamera> rig_cameras;
  std::vector<double> corner_sigma;
  nlohmann::json intrinsics = nlohmann::json::array();
  for (std::size_t c = 0; c < n_cams; ++c) {
    const auto files = images_in(s.path(s.intrinsics_views) / names[c]);
    std::vector<vision::TargetDetection> detections(files.size());
    std::vector<std::string> problems(files.size());
    Progress bar(log, fmt::format("{} intrinsics", names[c]), files.size());
    parallel_for(static_cast<int>(files.size()), log.threads, [&](int i) {
      static thread_local vision::AprilTagDetector detector;
      const auto k = static_cast<std::size_t>(i);
      const auto img = vision::load_gray_image(files[k]);
      if (!img.error.empty()) {
        problems[k] = img.error;
      } else if (img.gray.cols != s.cameras[c].width || img.gray.rows != s.cameras[c].height) {
        problems[k] =
            fmt::format("{}: image is {}x{}, the session says {}x{}", files[k].string(),
                        img.gray.cols, img.gray.rows, s.cameras[c].width, s.cameras[c].height);
      } else {
        detections[k] = vision::detect_target(img.gray, cal_board, detector);
        if (detections[k].status == vision::DetectionStatus::kRejected)
          problems[k] =
              fmt::format("{}: board not detected ({})", files[k].string(), detections[k].reason);
      }
      bar.advance();
    });
    std::vector<vision::CalibrationView> views;
    for (std::size_t i = 0; i < files.size(); ++i)
      if (problems[i].empty())
        views.push_back(vision::to_calibration_view(detections[i], files[i].stem().string()));
    bar.finish(fmt::format("board found in {} of {} images", views.size(), files.size()));
    vision::IntrinsicCalibrationOptions io;
    io.width = s.cameras[c].width;
    io.height = s.cameras[c].height;
    const auto result = vision::calibrate_intrinsics(views, io);
    nlohmann::json cj{{"camera", names[c]}, {"images", files.size()}, {"views", views.size()}};
    cj["problems"] = nlohmann::json::array();
    for (const auto& p : problems)
      if (!p.empty()) cj["problems"].push_back(p);
    if (result.status != vision::CalibrationStatus::kOk) {
      intrinsics.push_back(cj);
      report["intrinsics"] = intrinsics;
      return fail(
          fmt::format("camera {} calibration {}: {}", names[c],
                      result.status == vision::CalibrationStatus::kRefused ? "refused" : "failed",
                      result.reason));
    }
    const fs::path camera_file = s.results() / "cameras" / (names[c] + ".yaml");
    fs::create_directories(camera_file.parent_path());
    vision::save_camera_file(result.camera, camera_file, names[c]);
    say(log, "  {}: fx {:.2f} ± {:.2f} px, RMS {:.3f} px\n", names[c], result.camera.params[0],
        result.param_stddev[0], result.rms_px);
    for (const auto& w : result.warnings) say(log, "    warning: {}\n", w);
    cj.update({{"rms_px", result.rms_px},
               {"residual_sigma_px", result.residual_sigma_px},
               {"params", result.camera.params},
               {"param_stddev", result.param_stddev},
               {"warnings", result.warnings},
               {"camera_file", relative_to(camera_file, dir)}});
    intrinsics.push_back(cj);
    rig_cameras.push_back({names[c], result.camera, Eigen::Isometry3d::Identity(),
                           Eigen::Matrix<double, 6, 6>::Zero()});
    corner_sigma.push_back(std::max(result.residual_sigma_px, 0.01));
  }
  report["intrinsics"] = intrinsics;

  // 2. Rig: the cameras' relative poses from views they share (rig frame = first camera).
  stage(log, "measure: rig");
  const auto rig_sets = scan_image_folder(s.path(s.rig_views), names);
  std::vector<std::vector<vision::CameraFrame>> rig_views(rig_sets.size(),
                                                          std::vector<vision::CameraFrame>(n_cams));
  std::vector<std::string> rig_problems(rig_sets.size() * n_cams);
  {
    Progress bar(log, "rig views", rig_sets.size() * n_cams);
    parallel_for(static_cast<int>(rig_sets.size() * n_cams), log.threads, [&](int i) {
      const auto v = static_cast<std::size_t>(i) / n_cams;
      const auto c = static_cast<std::size_t>(i) % n_cams;
      std::string problem;
      if (rig_sets[v].frames_of_camera[c].empty()) {
        problem = fmt::format("{}: no image of camera '{}'", rig_sets[v].name, names[c]);
      } else {
        rig_views[v][c] =
            detect_frame(rig_sets[v].frames_of_camera[c][0], rig_cameras[c], cal_board, &problem);
        for (auto& corner : rig_views[v][c].corners) corner.sigma_px = corner_sigma[c];
      }
      rig_problems[static_cast<std::size_t>(i)] = problem;
      bar.advance();
    });
    bar.finish(fmt::format("{} views", rig_sets.size()));
  }
  const auto rig = vision::calibrate_rig(rig_cameras, board_points(cal_board), rig_views);
  nlohmann::json rig_json{{"ok", rig.ok},
                          {"message", rig.message},
                          {"reference", names[0]},
                          {"target", s.calibration_target},
                          {"rms_px", rig.rms_px},
                          {"variance_factor", rig.variance_factor},
                          {"views", rig_sets.size()}};
  rig_json["problems"] = nlohmann::json::array();
  for (const auto& p : rig_problems)
    if (!p.empty()) rig_json["problems"].push_back(p);
  if (!rig.ok) {
    report["rig"] = rig_json;
    return fail("rig calibration failed: " + rig.message);
  }
  const std::vector<vision::RigCamera> measured_rig = rig.rig();
  double sigma_sum = 0;
  for (double x : corner_sigma) sigma_sum += x;
  rig_json["corner_sigma_px"] = sigma_sum / static_cast<double>(corner_sigma.size());
  rig_json["cameras"] = rig_to_json(measured_rig);
  for (std::size_t c = 0; c < n_cams; ++c) {
    rig_json["cameras"][c]["baseline_m"] = rig.cameras.at(c).baseline_m;
    rig_json["cameras"][c]["baseline_sigma_m"] = rig.cameras.at(c).baseline_sigma_m;
  }
  write_json(rig_json, (s.results() / "rig.json").string());
  if (n_cams > 1)
    say(log, "  baseline {:.5f} ± {:.5f} m, RMS {:.3f} px\n", rig.cameras.at(1).baseline_m,
        rig.cameras.at(1).baseline_sigma_m, rig.rms_px);
  report["rig"] = {{"ok", true},
                   {"rms_px", rig.rms_px},
                   {"baseline_m", n_cams > 1 ? rig.cameras.at(1).baseline_m : 0.0},
                   {"baseline_sigma_m", n_cams > 1 ? rig.cameras.at(1).baseline_sigma_m : 0.0},
                   {"file", "results/rig.json"}};

  // 3. The end-effector board's pose at every robot pose.
  stage(log, "measure: poses");
  const auto records = load_pose_records(s);
  if (records.empty()) return fail(s.path(s.poses).string() + ": no pose folders");
  const auto sets = scan_image_folder(s.path(s.poses), names);  // same folders, same order
  struct Job {
    std::size_t pose, camera, frame;
  };
  std::vector<Job> jobs;
  std::vector<std::vector<std::vector<vision::CameraFrame>>> frames(records.size());
  std::vector<std::vector<std::string>> problems(records.size());
  for (std::size_t p = 0; p < records.size(); ++p) {
    std::size_t n_frames = 0;
    for (std::size_t c = 0; c < n_cams; ++c) {
      if (sets[p].frames_of_camera[c].empty())
        problems[p].push_back(
            fmt::format("{}: no image of camera '{}'", records[p].name, names[c]));
      n_frames = std::max(n_frames, sets[p].frames_of_camera[c].size());
    }
    frames[p].assign(n_frames, std::vector<vision::CameraFrame>(n_cams));
    for (std::size_t c = 0; c < n_cams; ++c)
      for (std::size_t f = 0; f < sets[p].frames_of_camera[c].size(); ++f)
        jobs.push_back({p, c, f});
  }
  std::vector<std::string> job_problem(jobs.size());
  {
    Progress bar(log, "pose images", jobs.size());
    parallel_for(static_cast<int>(jobs.size()), log.threads, [&](int i) {
      const Job& j = jobs[static_cast<std::size_t>(i)];
      std::string problem;
      auto frame = detect_frame(sets[j.pose].frames_of_camera[j.camera][j.frame],
                                measured_rig[j.camera], ee_board, &problem);
      for (auto& corner : frame.corners) corner.sigma_px = corner_sigma[j.camera];
      frames[j.pose][j.frame][j.camera] = std::move(frame);
      job_problem[static_cast<std::size_t>(i)] = problem;
      bar.advance();
    });
    bar.finish(fmt::format("{} images", jobs.size()));
  }
  for (std::size_t i = 0; i < jobs.size(); ++i)
    if (!job_problem[i].empty()) problems[jobs[i].pose].push_back(job_problem[i]);

  const auto ee_points = board_points(ee_board);
  calib::MeasurementsFile mfile;
  mfile.robot = robot.model.name;
  mfile.frame = s.measured_frame;
  nlohmann::json poses_json = nlohmann::json::array();
  nlohmann::json pixel_poses = nlohmann::json::array();
  int measured = 0, used = 0;
  for (std::size_t p = 0; p < records.size(); ++p) {
    const auto& rec = records[p];
    vision::PoseMeasurement m;
    if (frames[p].empty()) {
      m.status = vision::PoseStatus::kNotSeen;
      m.message = "no images";
    } else if (frames[p].size() == 1) {
      m = vision::measure_target_pose(measured_rig, ee_points, frames[p][0]);
    } else {
      m = vision::measure_settled_pose(measured_rig, ee_points, frames[p]);
    }
    nlohmann::json pj{{"pose", rec.name},          {"status", vision::pose_status_name(m.status)},
                      {"usable", m.usable()},      {"message", m.message},
                      {"problems", problems[p]},   {"frames", frames[p].size()},
                      {"timestamp", rec.timestamp}};
    if (rec.problem.empty()) pj["actuators"] = vector_json(rec.actuators);
    if (m.status == vision::PoseStatus::kOk || m.status == vision::PoseStatus::kMoving) {
      ++measured;
      pj.update(pose_measurement_to_json(m));
    }
    // Why a pose does not go to identification, in words.
    std::string excluded;
    if (!rec.problem.empty())
      excluded = rec.problem;
    else if (!m.usable())
      excluded = fmt::format("board pose {}{}", vision::pose_status_name(m.status),
                             m.message.empty() ? "" : " (" + m.message + ")");
    pj["used"] = excluded.empty();
    if (!excluded.empty()) {
      pj["excluded"] = excluded;
      say(log, "  {} not used: {}\n", rec.name, excluded);
    } else {
      ++used;
      mfile.measurements.poses.push_back({rec.name, rec.actuators, {to_pose_observation(m)}});
    }
    poses_json.push_back(pj);

    // Raw pixel observations (camera-in-the-loop identification), for every pose with readings.
    nlohmann::json obs = nlohmann::json::array();
    for (std::size_t f = 0; f < frames[p].size(); ++f)
      for (std::size_t c = 0; c < n_cams; ++c) {
        if (frames[p][f][c].corners.empty()) continue;
        nlohmann::json corners = nlohmann::json::array();
        for (const auto& o : frames[p][f][c].corners)
          corners.push_back({o.id, o.pixel.x(), o.pixel.y(), o.sigma_px});
        obs.push_back({{"frame", f}, {"camera", names[c]}, {"corners", corners}});
      }
    nlohmann::json pixel{{"pose", rec.name}, {"used", excluded.empty()}, {"observations", obs}};
    if (rec.problem.empty())
      pixel["actuators"] = vector_json(rec.actuators);
    else
      pixel["excluded"] = rec.problem;
    pixel_poses.push_back(pixel);
  }
  write_json({{"poses", poses_json}}, (s.results() / "measured_poses.json").string());
  write_json({{"format", "robocal pixel observations 1 (app/SESSION.md)"},
              {"robot", s.robot_file},
              {"measured_frame", s.measured_frame},
              {"rig", "results/rig.json"},
              {"target", s.ee_target},
              {"pixel_convention", "OpenCV: (0,0) = centre of the top-left pixel"},
              {"corner_format", "[board corner id, u (px), v (px), sigma (px)]"},
              {"poses", pixel_poses}},
             (s.results() / "pixel_observations.json").string());
  {
    const std::string text = calib::measurements_to_yaml(mfile);
    write_file_atomic(s.results() / "measurements.yaml", text, true);
  }
  say(log, "  {} of {} poses measured, {} used for identification\n", measured, records.size(),
      used);
  report["poses"] = {{"total", records.size()}, {"measured", measured}, {"used", used}};
  report["status"] = used > 0 ? "ok" : "failed";
  if (used == 0) report["message"] = "no pose could be measured";
  report["files"] = {"results/cameras/", "results/rig.json", "results/measured_poses.json",
                     "results/pixel_observations.json", "results/measurements.yaml"};
  write_json(report, (s.results() / "measure.json").string());
  return report;
}

// ---- identify ------------------------------------------------------------------------------

namespace {

// The camera-in-the-loop route on a session: the corner pixels of results/pixel_observations.json
// (the poses the pose route used, first frame per camera) with the measured rig's cameras, camera
// 0 as the world, camera 1.. poses estimated with the robot; started from the pose route's
// base-frame alignment. Returns the route's report (its estimate as {parameter: value}).
nlohmann::json identify_pixel_route(const Session& s, const calib::Mechanism& model,
                                    const calib::FramePredictor& predictor,
                                    const Eigen::VectorXd& start,
                                    const calib::SolveOptions& options, const PipelineLog& log) {
  const fs::path ppath = s.results() / "pixel_observations.json";
  const nlohmann::json doc =
      read_json_file(ppath, "run `robocal measure " + s.dir.string() + "` first");
  double rig_sigma = 0.0;
  const auto rig = load_rig_json(s.results() / "rig.json", &rig_sigma);
  const auto target = board_points(load_board(s.path(s.ee_target)));
  std::map<std::string, std::size_t> camera_index;
  for (std::size_t c = 0; c < rig.size(); ++c) camera_index[rig[c].name] = c;
  std::vector<PosePixels> poses;
  try {
    for (const auto& p : doc.at("poses")) {
      if (!p.value("used", false)) continue;
      const auto id = p.at("pose").get<std::string>();
      const auto q = p.at("actuators").get<std::vector<double>>();
      PosePixels pose{
          id, Eigen::Map<const Eigen::VectorXd>(q.data(), static_cast<Eigen::Index>(q.size())),
          std::vector<vision::CameraFrame>(rig.size())};
      for (const auto& obs : p.at("observations")) {
        if (obs.value("frame", 0) != 0) continue;  // settled frames: the first one is used
        const auto name = obs.at("camera").get<std::string>();
        const auto it = camera_index.find(name);
        if (it == camera_index.end())
          throw InputError(
              fmt::format("{}: pose {} names camera '{}', which results/rig.json "
                          "does not have",
                          ppath.string(), id, name));
        auto& frame = pose.cameras[it->second];
        for (const auto& c : obs.at("corners")) {
          const auto v = c.get<std::vector<double>>();
          if (v.size() != 4)
            throw InputError(fmt::format("{}: pose {} camera {}: a corner is not [id, u, v, sigma]",
                                         ppath.string(), id, name));
          frame.corners.push_back({static_cast<int>(v[0]), Eigen::Vector2d(v[1], v[2]), v[3]});
        }
      }
      poses.push_back(std::move(pose));
    }
  } catch (const nlohmann::json::exception& e) {
    throw InputError(fmt::format("{}: malformed ({})", ppath.string(), e.what()));
  }
  nlohmann::json report;
  const auto route = identify_from_pixels(predictor, start, options, rig, target, poses);
  const auto& r = route.result;
  say(log,
      "  pixels (camera-in-the-loop): {}: {} poses, {} parameters (robot + camera poses), {} "
      "iterations, {:.2f} s, reprojection {:.3f} px RMS\n",
      calib::to_string(r.status), r.residuals.poses.size(), r.estimated.size(), r.iterations,
      r.solve_seconds, route.fit_pixels.rms_px);
  report["result"] = calib::to_json(r);
  report["reprojection_rms_px"] = route.fit_pixels.rms_px;
  report["skipped"] = route.input.skipped;
  report["estimate"] = params_json(model, route.robot_estimate);
  nlohmann::json cams = nlohmann::json::array();
  for (std::size_t c = 0; c < route.world_T_camera.size() && c < rig.size(); ++c)
    cams.push_back(
        {{"camera", rig[c].name}, {"world_T_camera", pose_to_json(route.world_T_camera[c])}});
  report["cameras"] = cams;
  const bool usable = r.status == calib::IdentificationStatus::kConverged ||
                      r.status == calib::IdentificationStatus::kNotConverged;
  report["status"] = usable ? "ok" : "failed";
  if (!usable) report["message"] = r.message;
  return report;
}

}  // namespace

nlohmann::json identify_session(const fs::path& dir, const std::string& robot_override,
                                const PipelineLog& log, const std::string& route, bool priors) {
  if (route != "pose" && route != "pixel" && route != "both")
    throw InputError("identification route '" + route + "': expected pose, pixel or both");
  const Session s = load_session(dir);
  const SessionRobot robot = session_robot(s, robot_override);
  // The used poses of results/measured_poses.json, at full precision (measurements.yaml is the
  // same data for `robocal identify --measurements`, but its rotation vectors and inverted
  // covariances are not bit-exact, and the identification's choice among confounded parameters
  // is that sensitive).
  const fs::path mpath = s.results() / "measured_poses.json";
  const nlohmann::json measured_doc =
      read_json_file(mpath, "run `robocal measure " + dir.string() + "` first");
  calib::MeasurementsFile file;
  try {
    for (const auto& p : measured_doc.at("poses")) {
      if (!p.value("used", false)) continue;
      const auto id = p.at("pose").get<std::string>();
      const auto q = p.at("actuators").get<std::vector<double>>();
      const auto rows = p.at("rig_T_target_matrix").get<std::vector<std::vector<double>>>();
      const auto cov_rows = p.at("covariance").get<std::vector<std::vector<double>>>();
      if (rows.size() != 3 || cov_rows.size() != 6)
        throw InputError(mpath.string() + ": pose " + id + " has a malformed pose or covariance");
      Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
      for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 4; ++c) T.matrix()(r, c) = rows.at(r).at(c);
      Eigen::Matrix<double, 6, 6> cov;
      for (int r = 0; r < 6; ++r)
        for (int c = 0; c < 6; ++c) cov(r, c) = cov_rows.at(r).at(c);
      file.measurements.poses.push_back(
          {id,
           Eigen::Map<const Eigen::VectorXd>(q.data(), static_cast<Eigen::Index>(q.size())),
           {calib::PoseObservation::with_covariance(T, vision_to_calib_covariance(cov))}});
    }
  } catch (const nlohmann::json::exception& e) {
    throw InputError(fmt::format("{}: malformed ({})", mpath.string(), e.what()));
  } catch (const std::out_of_range& e) {
    throw InputError(fmt::format("{}: malformed ({})", mpath.string(), e.what()));
  }
  stage(log, "identify");
  const calib::Mechanism& model = robot.model;
  nlohmann::json report{{"stage", "identify"}, {"session", dir.string()}};
  if (file.measurements.poses.size() < 3) {
    report["status"] = "failed";
    report["message"] = fmt::format("{} usable poses: too few", file.measurements.poses.size());
    write_json(report, (s.results() / "identification.json").string());
    say(log, "identify failed: {}\n", report["message"].get<std::string>());
    return report;
  }
  // The robot's base frame in the camera world: first found by aligning the nominal model's
  // predictions with the measurements (what hand-eye calibration alone gives).
  const Eigen::VectorXd file_values = model.nominal_parameters();
  Eigen::VectorXd start = robot.nominal;
  {
    std::vector<Eigen::Vector3d> predicted, measured;
    for (const auto& pose : file.measurements.poses) {
      const auto fk = calib::forward_kinematics(model, start, pose.actuators, robot.frame);
      const auto* obs = std::get_if<calib::PoseObservation>(&pose.observations.at(0));
      if (!fk.closure.ok() || obs == nullptr) continue;
      predicted.emplace_back(fk.pose.translation());
      measured.push_back(obs->measured_position);
    }
    if (predicted.size() >= 3) {
      Eigen::Matrix3Xd P(3, static_cast<Eigen::Index>(predicted.size())), M(3, P.cols());
      for (std::size_t i = 0; i < predicted.size(); ++i) {
        P.col(static_cast<Eigen::Index>(i)) = predicted[i];
        M.col(static_cast<Eigen::Index>(i)) = measured[i];
      }
      const Eigen::Isometry3d world_T_base(Eigen::umeyama(P, M, false));
      const int root = 0;  // the first body hangs from the world: the base frame
      const auto& q0 = file.measurements.poses[0].actuators;
      const auto root_pose = calib::forward_kinematics(model, start, q0, root).pose;
      set_fixed_frame_pose(model, start, root, q0, world_T_base * root_pose);
    }
  }
  calib::MechanismPredictor predictor(model, robot.frame);
  const auto start_errors = calib::prediction_errors(predictor, start, file.measurements.poses);
  say(log, "  nominal model with the fitted base frame: {:.1f} µm RMS, {:.4f} deg RMS\n",
      start_errors.position_rms * 1e6, start_errors.orientation_rms * kRadToDeg);
  report["nominal_fit"] = calib::to_json(start_errors);
  // The robot file's tolerances as priors (MAP). A cell's design (poses where the cameras see the
  // board) leaves weak directions; along them a maximum-likelihood estimate can trade, e.g., a
  // shoulder axis tilt of 1° against elbow offsets of 7 mm that fit the measured poses and are
  // millimetres off elsewhere (demo seed 1: 234 µm RMS, 5.1 mm max on held-out poses; with the
  // priors 46 µm, 0.26 mm). The base frame has no prior: world <-> robot is genuinely unknown
  // in the cameras' world.
  calib::SolveOptions solve_options = calib::solve_options_from_model(model, priors);
  if (priors)
    for (std::size_t i = 0; i < model.parameters.size(); ++i) {
      const int body = model.parameters[i].body;
      if (body >= 0 && model.bodies[static_cast<std::size_t>(body)].parent < 0)
        solve_options.prior_sigma[i] = 0.0;
    }
  say(log, "  priors: {}\n",
      priors ? "the robot file's tolerances (MAP), base frame free"
             : "none (maximum likelihood from the measurements alone)");
  const auto result = calib::identify(predictor, start, file.measurements, solve_options);
  say(log,
      "  {}: {} of {} candidate parameters identified, condition number {:.3g}, {} iterations, "
      "{:.2f} s\n",
      calib::to_string(result.status), result.estimated.size(), result.candidates.size(),
      result.identifiability.condition_number, result.iterations, result.solve_seconds);
  say(log, "  fit residual: {:.1f} µm RMS position, {:.4f} deg RMS orientation, {} outliers\n",
      result.residuals.position_rms * 1e6, result.residuals.orientation_rms * kRadToDeg,
      result.residuals.outliers);
  if (result.relinearisation.attempted) say(log, "  {}\n", result.relinearisation.message);
  report["result"] = calib::to_json(result);
  report["robot"] = relative_to(robot.file, dir);
  report["measurements"] = "results/measured_poses.json";
  report["priors"] = priors;
  report["not_identified"] = result.identifiability.messages;
  if (result.relinearisation.attempted)
    report["not_identified"].push_back(result.relinearisation.message);
  report["held_at_nominal"] = result.candidates.size() - result.estimated.size();
  report["start"] = params_json(model, start);
  report["estimate"] = params_json(model, result.estimate);
  report["parameter_units"] = nlohmann::json::object();
  report["parameter_sigma"] = nlohmann::json::object();
  for (const auto& p : model.parameters) {
    report["parameter_units"][p.name] = unit_name(p.unit);
    report["parameter_sigma"][p.name] = p.sigma;
  }
  report["software"] = std::string("robocal ") + kVersion;
  const bool usable = result.status == calib::IdentificationStatus::kConverged ||
                      result.status == calib::IdentificationStatus::kNotConverged;
  report["status"] = usable ? "ok" : "failed";
  if (!usable) report["message"] = result.message;
  if (usable) {
    std::set<std::size_t> changed(result.estimated.begin(), result.estimated.end());
    for (std::size_t i = 0; i < model.parameters.size(); ++i)
      if (start[static_cast<Eigen::Index>(i)] != file_values[static_cast<Eigen::Index>(i)])
        changed.insert(i);
    const std::string text = calib::calibrated_robot_yaml(
        read_text_file(robot.file), model, result.estimate,
        std::vector<std::size_t>(changed.begin(), changed.end()),
        {fmt::format("Calibrated by robocal {} identify from session {} ({}).", kVersion,
                     dir.filename().string(), calib::to_string(result.status)),
         fmt::format("{} poses used, {} excluded; {} parameters estimated; fit residual RMS "
                     "{:.3g} m.",
                     result.residuals.poses.size(), result.excluded.size(), result.estimated.size(),
                     result.residuals.position_rms),
         "World frame: the session's rig frame (camera " + s.cameras[0].name + ")."});
    write_file_atomic(s.results() / "calibrated_robot.yaml", text, true);
    report["calibrated_robot"] = "results/calibrated_robot.yaml";
  }
  if (usable && route != "pose") {
    report["pixel_route"] = identify_pixel_route(s, model, predictor, start, solve_options, log);
    const auto& pr = report["pixel_route"];
    if (pr.value("status", "") == "ok") {
      const std::string ident_file = (s.results() / "identification.json").string();
      const Eigen::VectorXd pixel_estimate = params_from_json(model, pr.at("estimate"), ident_file);
      std::vector<std::size_t> changed;
      for (std::size_t i = 0; i < model.parameters.size(); ++i)
        if (pixel_estimate[static_cast<Eigen::Index>(i)] !=
            file_values[static_cast<Eigen::Index>(i)])
          changed.push_back(i);
      const std::string text = calib::calibrated_robot_yaml(
          read_text_file(robot.file), model, pixel_estimate, changed,
          {fmt::format("Calibrated by robocal {} identify (camera-in-the-loop, from corner "
                       "pixels) from session {}.",
                       kVersion, dir.filename().string()),
           fmt::format("Reprojection RMS {:.3f} px.", pr.value("reprojection_rms_px", 0.0)),
           "World frame: the session's rig frame (camera " + s.cameras[0].name + ")."});
      write_file_atomic(s.results() / "calibrated_robot_pixels.yaml", text, true);
      report["pixel_route"]["calibrated_robot"] = "results/calibrated_robot_pixels.yaml";
    }
  }
  write_json(report, (s.results() / "identification.json").string());
  return report;
}

// ---- validate ------------------------------------------------------------------------------

nlohmann::json validate_session(const fs::path& dir, int held_out, const PipelineLog& log) {
  const Session s = load_session(dir);
  nlohmann::json report{{"stage", "validate"}, {"session", dir.string()}};
  if (!fs::is_directory(s.truth()) || !fs::exists(s.truth() / "truth.json")) {
    report["status"] = "no_truth";
    report["message"] = fmt::format(
        "{}: missing. This session has no ground truth (a recorded session, or truth/ was moved "
        "away), so there is nothing to validate against; held-out validation on measured poses "
        "is `robocal identify --holdout-every K` on results/measurements.yaml",
        s.truth().string());
    say(log, "validate: {}\n", report["message"].get<std::string>());
    return report;
  }
  const SessionRobot robot = session_robot(s, "");
  const calib::Mechanism& model = robot.model;
  const nlohmann::json ident = read_json_file(s.results() / "identification.json",
                                              "run `robocal identify` on the session first");
  if (ident.value("status", "") != "ok")
    throw InputError((s.results() / "identification.json").string() +
                     ": the identification did not succeed; nothing to validate");
  const std::string ident_file = (s.results() / "identification.json").string();
  const Eigen::VectorXd start = params_from_json(model, ident.at("start"), ident_file);
  const Eigen::VectorXd estimate = params_from_json(model, ident.at("estimate"), ident_file);
  std::optional<Eigen::VectorXd> pixel_estimate;
  if (ident.contains("pixel_route") && ident["pixel_route"].value("status", "") == "ok")
    pixel_estimate = params_from_json(model, ident["pixel_route"].at("estimate"), ident_file);
  const std::string truth_file = (s.truth() / "truth.json").string();
  const nlohmann::json truth_doc = read_json_file(s.truth() / "truth.json", "simulation truth");
  const Eigen::VectorXd truth = params_from_json(model, truth_doc.at("truth"), truth_file);
  const Eigen::VectorXd true_nominal = params_from_json(model, truth_doc.at("nominal"), truth_file);
  std::vector<vision::CameraModel> true_cams;
  std::vector<Eigen::Isometry3d> true_camera_T_world;
  for (const auto& c : truth_doc.at("cameras")) {
    vision::CameraModel m;
    m.kind = *vision::kind_from_name(c.at("model").get<std::string>());
    m.width = c.at("width").get<int>();
    m.height = c.at("height").get<int>();
    m.params = c.at("params").get<std::vector<double>>();
    true_cams.push_back(m);
    true_camera_T_world.push_back(pose_from_json(c.at("camera_T_world"), truth_file));
  }
  const Eigen::Isometry3d cam0_T_world = true_camera_T_world.at(0);
  stage(log, "validate");

  // The cameras and the rig against the truth.
  nlohmann::json cams = nlohmann::json::array();
  for (std::size_t c = 0; c < s.cameras.size() && c < true_cams.size(); ++c) {
    const fs::path f = s.results() / "cameras" / (s.cameras[c].name + ".yaml");
    if (!fs::exists(f)) continue;
    const auto est = vision::load_camera_file(f);
    const double projection = projection_difference_px(est, true_cams[c]);
    cams.push_back({{"camera", s.cameras[c].name},
                    {"fx", est.params[0]},
                    {"fx_true", true_cams[c].params[0]},
                    {"projection_vs_truth_px", projection}});
    say(log, "  {}: fx {:.2f} px (true {:.2f}), model vs truth {:.4f} px RMS\n", s.cameras[c].name,
        est.params[0], true_cams[c].params[0], projection);
  }
  report["cameras"] = cams;
  if (fs::exists(s.results() / "rig.json") && true_camera_T_world.size() > 1) {
    const auto rig = read_json_file(s.results() / "rig.json", "");
    const auto centre = [](const Eigen::Isometry3d& camera_T_world) {
      return Eigen::Vector3d(camera_T_world.inverse().translation());
    };
    const double true_baseline =
        (centre(true_camera_T_world[1]) - centre(true_camera_T_world[0])).norm();
    const double baseline = rig.at("cameras").at(1).value("baseline_m", 0.0);
    report["rig"] = {{"baseline_m", baseline},
                     {"baseline_true_m", true_baseline},
                     {"baseline_error_m", baseline - true_baseline}};
    say(log, "  baseline {:.5f} m (true {:.5f} m, error {:+.1f} µm)\n", baseline, true_baseline,
        (baseline - true_baseline) * 1e6);
  }
  // The measured board poses against the truth (camera 0's frame); their measured positions
  // span the measured region (measured_region.hpp).
  std::vector<Eigen::Vector3d> measured_positions;
  if (fs::exists(s.results() / "measured_poses.json")) {
    std::map<std::string, Eigen::Isometry3d> true_poses;
    for (const auto& p : truth_doc.at("poses"))
      true_poses[p.at("pose").get<std::string>()] =
          pose_from_json(p.at("world_T_board"), truth_file);
    Errors measured;
    const auto measured_poses = read_json_file(s.results() / "measured_poses.json", "");
    for (const auto& p : measured_poses.at("poses")) {
      if (!p.value("used", false) || !p.contains("rig_T_target")) continue;
      const auto m = pose_from_json(p.at("rig_T_target"), "measured_poses.json");
      measured_positions.emplace_back(m.translation());
      const auto it = true_poses.find(p.at("pose").get<std::string>());
      if (it == true_poses.end()) continue;
      measured.add((m.translation() - cam0_T_world * it->second.translation()).norm());
    }
    measured.finish();
    report["measured_poses_vs_truth"] = measured.json();
    say(log, "  board position measured vs truth: {:.1f} µm RMS over {} poses\n",
        measured.rms * 1e6, measured.n);
  }

  // Held-out configurations the fit never saw (no images needed): nominal (base frame fitted)
  // and calibrated model against the true robot, in camera 0's frame.
  calib::MechanismPredictor true_predictor(model, robot.frame);
  std::mt19937 validation_rng(s.seed + 7919);
  std::vector<Eigen::VectorXd> must_solve = {truth, start, estimate};
  if (pixel_estimate) must_solve.push_back(*pixel_estimate);
  const auto configurations = calib::sample_actuators(
      true_predictor, must_solve, static_cast<std::size_t>(held_out), validation_rng);
  std::vector<Eigen::Vector3d> truth_points, nominal_points, calibrated_points, pixel_points;
  std::vector<Eigen::VectorXd> kept_configurations;
  int branch_disagreements = 0;
  for (const auto& q : configurations) {
    const auto true_fk = calib::forward_kinematics(model, truth, q, robot.frame);
    const auto nominal_fk = calib::forward_kinematics(model, start, q, robot.frame);
    const auto calibrated_fk = calib::forward_kinematics(model, estimate, q, robot.frame);
    const auto pixel_fk = pixel_estimate
                              ? calib::forward_kinematics(model, *pixel_estimate, q, robot.frame)
                              : calibrated_fk;
    // Only configurations every model answers on the intended assembly mode are accuracy
    // figures (assembly_mode.hpp); an answer on another mode (refused by the solver) or at a mode
    // boundary is counted apart.
    const auto off_mode = [](const calib::ForwardResult& fk) {
      return fk.closure.status == calib::SolveStatus::kOtherMode ||
             fk.closure.mode.verdict == calib::ModeVerdict::kOther ||
             fk.closure.mode.verdict == calib::ModeVerdict::kAmbiguous;
    };
    if (off_mode(true_fk) || off_mode(nominal_fk) || off_mode(calibrated_fk) ||
        off_mode(pixel_fk)) {
      ++branch_disagreements;
      continue;
    }
    if (!true_fk.closure.ok() || !nominal_fk.closure.ok() || !calibrated_fk.closure.ok() ||
        !pixel_fk.closure.ok())
      continue;
    const Eigen::Vector3d t = cam0_T_world * true_fk.pose.translation();
    truth_points.push_back(t);
    nominal_points.emplace_back(nominal_fk.pose.translation());
    calibrated_points.emplace_back(calibrated_fk.pose.translation());
    pixel_points.emplace_back(pixel_fk.pose.translation());
    kept_configurations.push_back(q);
  }
  if (branch_disagreements > 0)
    say(log,
        "  note: {} held-out configurations left out: a model's closure is not on the intended "
        "assembly mode there (another mode or a mode boundary)\n",
        branch_disagreements);
  const ErrorPair nominal_errors = position_errors(nominal_points, truth_points);
  const ErrorPair calibrated_errors = position_errors(calibrated_points, truth_points);
  report["held_out_poses"] = calibrated_errors.absolute.n;
  report["held_out_requested"] = held_out;
  report["seed"] = s.seed + 7919;
  report["assembly_mode_disagreements"] = branch_disagreements;
  report["nominal"] = nominal_errors.absolute.json();
  report["calibrated"] = calibrated_errors.absolute.json();
  report["nominal_registered"] = nominal_errors.registered.json();
  report["calibrated_registered"] = calibrated_errors.registered.json();
  ErrorPair pixel_errors;
  if (pixel_estimate) {
    pixel_errors = position_errors(pixel_points, truth_points);
    report["calibrated_pixels"] = pixel_errors.absolute.json();
    report["calibrated_pixels_registered"] = pixel_errors.registered.json();
  }
  // Interpolation or extrapolation: where each held-out position lies relative to the measured
  // region (the convex hull of the measured board positions). Far outside it, the model is
  // extrapolated along directions the measured poses constrain weakly.
  std::vector<RegionDistance> region(truth_points.size());
  if (!measured_positions.empty()) {
    std::vector<bool> inside(truth_points.size());
    std::vector<double> outside_m(truth_points.size());
    for (std::size_t k = 0; k < truth_points.size(); ++k) {
      region[k] = distance_to_region(measured_positions, truth_points[k]);
      inside[k] = region[k].inside;
      outside_m[k] = region[k].outside_m;
    }
    Eigen::Vector3d lo = measured_positions[0], hi = measured_positions[0];
    for (const auto& m : measured_positions) {
      lo = lo.cwiseMin(m);
      hi = hi.cwiseMax(m);
    }
    report["measured_region"] = {
        {"definition",
         "convex hull of the measured end-effector board positions (results/measured_poses.json, "
         "used poses) in camera 0's frame; a held-out configuration is inside when its true board "
         "position lies in the hull (within inside_tolerance_m), outside otherwise; "
         "outside_measured_region_m (worst_held_out) and distance_*_m (held_out_by_region) are "
         "distances to the hull"},
        {"measured_poses", measured_positions.size()},
        {"inside_tolerance_m", kRegionInsideTolerance},
        {"bounding_box_m", {{"min", {lo.x(), lo.y(), lo.z()}}, {"max", {hi.x(), hi.y(), hi.z()}}}}};
    std::vector<NamedPoints> predictions = {{"nominal", &nominal_points},
                                            {"calibrated", &calibrated_points}};
    if (pixel_estimate) predictions.push_back({"calibrated_pixels", &pixel_points});
    // The registered figures keep the one transform fitted over all held-out configurations.
    const auto add_registered = [&](const char* name, const ErrorPair& e) {
      if (e.registered_points.size() == truth_points.size())
        predictions.push_back({name, &e.registered_points});
    };
    add_registered("nominal_registered", nominal_errors);
    add_registered("calibrated_registered", calibrated_errors);
    if (pixel_estimate) add_registered("calibrated_pixels_registered", pixel_errors);
    report["held_out_by_region"] =
        split_errors_by_region(inside, outside_m, truth_points, predictions);
  }
  // The worst held-out configurations with the true robot's task conditioning there
  // (σ_min/σ_max of d(position)/d(actuators)): one pose near a singularity can carry most of the
  // RMS, and the user should see that rather than a mean.
  {
    std::vector<std::size_t> order(truth_points.size());
    std::iota(order.begin(), order.end(), std::size_t{0});
    auto worst_of = [&](std::size_t k) {
      double e = (calibrated_points[k] - truth_points[k]).norm();
      if (pixel_estimate) e = std::max(e, (pixel_points[k] - truth_points[k]).norm());
      return e;
    };
    std::sort(order.begin(), order.end(),
              [&](std::size_t a, std::size_t b) { return worst_of(a) > worst_of(b); });
    nlohmann::json worst = nlohmann::json::array();
    for (std::size_t w = 0; w < std::min<std::size_t>(5, order.size()); ++w) {
      const std::size_t k = order[w];
      const Eigen::VectorXd& q = kept_configurations[k];
      nlohmann::json row = {
          {"actuators", std::vector<double>(q.data(), q.data() + q.size())},
          {"calibrated_error_m", (calibrated_points[k] - truth_points[k]).norm()},
          {"task_conditioning", calib::task_conditioning(true_predictor, truth, q)}};
      if (pixel_estimate)
        row["calibrated_pixels_error_m"] = (pixel_points[k] - truth_points[k]).norm();
      if (!measured_positions.empty()) {
        row["inside_measured_region"] = region[k].inside;
        row["outside_measured_region_m"] = region[k].outside_m;
        row["nearest_measured_pose_m"] = region[k].nearest_measured_m;
      }
      worst.push_back(row);
    }
    report["worst_held_out"] = worst;
  }

  // Parameters: estimated change next to the true change, largest (in tolerance sigmas) first.
  std::vector<std::size_t> order;
  for (std::size_t i = 0; i < model.parameters.size(); ++i)
    if (estimate[static_cast<Eigen::Index>(i)] != start[static_cast<Eigen::Index>(i)])
      order.push_back(i);
  const auto score = [&](std::size_t i) {
    const auto k = static_cast<Eigen::Index>(i);
    return std::abs(estimate[k] - start[k]) / std::max(model.parameters[i].sigma, 1e-12);
  };
  std::stable_sort(order.begin(), order.end(),
                   [&](std::size_t a, std::size_t b) { return score(a) > score(b); });
  // A parameter that stands in for confounded ones (identifiability redundancies name it as a
  // partner) carries their combination: its change is not comparable with its own true change.
  // The base frame is the cell's placement (camera 0 <- robot base), not a robot dimension.
  std::map<std::string, int> carries;
  const nlohmann::json no_redundancies = nlohmann::json::array();
  const nlohmann::json& analysis = ident.contains("result") ? ident.at("result") : ident;
  const nlohmann::json& redundancies =
      analysis.contains("identifiability") &&
              analysis.at("identifiability").contains("redundancies")
          ? analysis.at("identifiability").at("redundancies")
          : no_redundancies;
  for (const auto& red : redundancies)
    for (const auto& partner : red.value("partners", nlohmann::json::array()))
      ++carries[partner.value("name", "")];
  nlohmann::json params = nlohmann::json::array();
  for (std::size_t i : order) {
    const auto k = static_cast<Eigen::Index>(i);
    const int body = model.parameters[i].body;
    const bool base_frame = body >= 0 && model.bodies[static_cast<std::size_t>(body)].parent < 0;
    const auto carried = carries.find(model.parameters[i].name);
    params.push_back({{"name", model.parameters[i].name},
                      {"unit", unit_name(model.parameters[i].unit)},
                      {"estimated_change", estimate[k] - start[k]},
                      {"true_change", truth[k] - true_nominal[k]},
                      {"base_frame", base_frame},
                      {"stands_in_for", carried == carries.end() ? 0 : carried->second}});
  }
  report["parameters"] = params;
  report["status"] = calibrated_errors.absolute.n > 0 ? "ok" : "failed";
  report["improved"] = calibrated_errors.absolute.n > 0 &&
                       calibrated_errors.absolute.rms < nominal_errors.absolute.rms;
  write_json(report, (s.results() / "validation.json").string());
  return report;
}

void print_validation_summary(std::FILE* out, const nlohmann::json& v,
                              const nlohmann::json& ident) {
  if (v.value("status", "") == "no_truth") {
    fmt::print(out, "\n=== No validation: {}\n", v.value("message", ""));
    return;
  }
  const double before = v.at("nominal").at("rms_m").get<double>();
  const double after = v.at("calibrated").at("rms_m").get<double>();
  fmt::print(out,
             "\n=== Result: end-effector position error on {} held-out poses, against the truth\n",
             v.at("held_out_poses").get<int>());
  fmt::print(out, "  nominal model (base frame fitted): {:8.1f} µm RMS, {:8.1f} µm max\n",
             before * 1e6, v.at("nominal").at("max_m").get<double>() * 1e6);
  fmt::print(
      out,
      "  calibrated model:                  {:8.1f} µm RMS, {:8.1f} µm max  ({:.0f}x better)\n",
      after * 1e6, v.at("calibrated").at("max_m").get<double>() * 1e6,
      after > 0 ? before / after : 0.0);
  if (v.contains("calibrated_pixels"))
    fmt::print(out,
               "  calibrated from pixels (camera-in-the-loop): {:5.1f} µm RMS, {:8.1f} µm max  "
               "(line above: from measured 6-D poses)\n",
               v["calibrated_pixels"].at("rms_m").get<double>() * 1e6,
               v["calibrated_pixels"].at("max_m").get<double>() * 1e6);
  if (v.contains("held_out_by_region") && v.contains("measured_region")) {
    const auto& by_region = v["held_out_by_region"];
    fmt::print(out,
               "  by region (measured region = convex hull of the {} measured board positions):\n",
               v["measured_region"].value("measured_poses", 0));
    for (const char* side : {"inside", "outside"}) {
      const auto& part = by_region.at(side);
      const int n = part.value("held_out_poses", 0);
      const bool in = std::string(side) == "inside";
      std::string line = fmt::format(
          "    {:<24} {:4} poses", in ? "inside (interpolation):" : "outside (extrapolation):", n);
      if (n > 0) {
        line += fmt::format(": calibrated {:.1f} µm RMS, {:.1f} µm max",
                            part.at("calibrated").at("rms_m").get<double>() * 1e6,
                            part.at("calibrated").at("max_m").get<double>() * 1e6);
        if (part.contains("calibrated_pixels"))
          line += fmt::format("; from pixels {:.1f} µm RMS, {:.1f} µm max",
                              part["calibrated_pixels"].at("rms_m").get<double>() * 1e6,
                              part["calibrated_pixels"].at("max_m").get<double>() * 1e6);
        if (!in)
          line += fmt::format(" (up to {:.0f} mm outside, median {:.0f} mm)",
                              part.value("distance_max_m", 0.0) * 1e3,
                              part.value("distance_median_m", 0.0) * 1e3);
      }
      fmt::print(out, "{}\n", line);
    }
  }
  fmt::print(out, "  robot accuracy in its own frame (after best-fit rigid registration):\n");
  fmt::print(out, "    nominal {:.1f} µm RMS, calibrated {:.1f} µm RMS ({:.1f} µm max)\n",
             v.at("nominal_registered").at("rms_m").get<double>() * 1e6,
             v.at("calibrated_registered").at("rms_m").get<double>() * 1e6,
             v.at("calibrated_registered").at("max_m").get<double>() * 1e6);
  if (v.contains("held_out_by_region")) {
    const auto& in = v["held_out_by_region"].at("inside");
    const auto& out_part = v["held_out_by_region"].at("outside");
    if (in.contains("calibrated_registered") && out_part.contains("calibrated_registered"))
      fmt::print(out,
                 "    calibrated inside the measured region {:.1f} µm RMS, outside {:.1f} µm "
                 "RMS\n",
                 in["calibrated_registered"].at("rms_m").get<double>() * 1e6,
                 out_part["calibrated_registered"].at("rms_m").get<double>() * 1e6);
  }
  fmt::print(
      out,
      "\n  robot dimensions that changed most (estimated change; true change in brackets;"
      "\n  the base frame, i.e. where the robot stands in the cameras' world, is left out):\n");
  int listed = 0;
  bool any_stand_in = false;
  for (const auto& p : v.at("parameters")) {
    if (listed == 8) break;
    if (p.value("base_frame", false)) continue;
    const auto unit = p.at("unit").get<std::string>();
    const int stands_in_for = p.value("stands_in_for", 0);
    any_stand_in = any_stand_in || stands_in_for > 0;
    fmt::print(out, "    {:<24} {}  ({}){}\n", p.at("name").get<std::string>(),
               fmt_param_change(unit, p.at("estimated_change").get<double>()),
               fmt_param_change(unit, p.at("true_change").get<double>()),
               stands_in_for > 0 ? fmt::format("  *{}", stands_in_for) : std::string());
    ++listed;
  }
  if (any_stand_in)
    fmt::print(out,
               "    *N: also carries N parameters it cannot be told apart from (held at nominal), "
               "so its change is\n       their combination, not comparable with its own true "
               "change\n");
  if (ident.contains("not_identified") && !ident["not_identified"].empty()) {
    const auto& messages = ident["not_identified"];
    fmt::print(out, "\n  what could not be identified ({} parameters held at nominal):\n",
               ident.value("held_at_nominal", 0));
    for (std::size_t k = 0; k < std::min<std::size_t>(6, messages.size()); ++k) {
      const auto m = messages[k].get<std::string>();
      fmt::print(out, "    - {}\n", m.size() > 240 ? m.substr(0, 237) + "..." : m);
    }
    if (messages.size() > 6)
      fmt::print(out, "    ... {} more in results/identification.json\n", messages.size() - 6);
  }
}

}  // namespace robocal::app
