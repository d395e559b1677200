#include "robocal/robotio/capture.hpp"

#include "robocal/robotio/png_encode.hpp"

#include "robocal/core/parallel.hpp"
#include "robocal/vision/apriltag_detector.hpp"
#include "robocal/vision/detection_record.hpp"
#include "robocal/vision/image_detection.hpp"
#include "robocal/vision/pose_measurement.hpp"
#include "robocal/vision/target_detection.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <deque>
#include <fstream>
#include <future>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <stdexcept>
#include <system_error>

namespace robocal::robotio {
namespace fs = std::filesystem;

namespace {

using SteadyClock = std::chrono::steady_clock;

double seconds_since(SteadyClock::time_point start) {
  return std::chrono::duration<double>(SteadyClock::now() - start).count();
}

// shots[k][c]: shot k of camera c.
using ShotSeries = std::vector<std::vector<Frame>>;

// A capture that cannot go on: the robot is stopped and the reason reported.
struct CaptureStop {
  std::string reason;
  std::optional<CameraError::Kind> kind;
};

// One frame of `camera` after a trigger was sent; a timeout or an incomplete frame is retaken
// (trigger and receive again) up to options.frame_retries times.
Frame receive_checked(const CaptureCamera& camera, const CaptureOptions& options,
                      PoseCaptureReport& report) {
  for (int attempt = 0;; ++attempt) {
    try {
      if (attempt > 0) {
        camera.source->trigger();
      }
      Frame frame = camera.source->receive(options.grab_timeout);
      if (frame.image.cols != camera.model.width || frame.image.rows != camera.model.height) {
        throw CameraError(
            CameraError::Kind::kIncompleteFrame, camera.source->name(),
            fmt::format("frame of the wrong size: {}x{}, the camera is {}x{}", frame.image.cols,
                        frame.image.rows, camera.model.width, camera.model.height));
      }
      return frame;
    } catch (const CameraError& error) {
      const bool retryable = error.kind() == CameraError::Kind::kTimeout ||
                             error.kind() == CameraError::Kind::kIncompleteFrame;
      if (!retryable || attempt >= options.frame_retries) {
        throw;
      }
      ++report.frame_retries;
    }
  }
}

// Each shot triggers every camera first, then collects their frames: the cameras expose
// together, and their transfers overlap.
ShotSeries grab_series(const std::vector<CaptureCamera>& cameras, const CaptureOptions& options,
                       PoseCaptureReport& report) {
  ShotSeries shots(static_cast<std::size_t>(options.shots_per_pose));
  for (auto& shot : shots) {
    for (const CaptureCamera& camera : cameras) {
      camera.source->trigger();
    }
    for (const CaptureCamera& camera : cameras) {
      shot.push_back(receive_checked(camera, options, report));
    }
  }
  return shots;
}

cv::Mat gray_8bit(const cv::Mat& image) {
  cv::Mat gray = image;
  if (image.depth() == CV_16U) {
    image.convertTo(gray, CV_8U, 1.0 / 257.0);
  }
  return gray;
}

// A later shot of the series: an AprilTag board is refined where the first shot had it (a
// fraction of a detection's time, and all the settled-frame test needs); others are detected.
vision::TargetDetection detect_again(const cv::Mat& gray, const vision::TargetBoard& board,
                                     const vision::TargetDetection& first,
                                     vision::AprilTagDetector& detector) {
  if (board.spec.kind == vision::TargetKind::kAprilTagGrid) {
    return vision::redetect_apriltag_board(gray, board, first, detector);
  }
  return vision::detect_target(gray, board, detector);
}

// The settled-frame test of every camera that sees the target: each later shot against the
// first, as single-camera measurements (no rig calibration is needed yet). Returns the largest
// chi-square and whether any camera saw motion.
struct MotionVerdict {
  bool moving = false;
  double chi2 = 0.0;
  std::vector<int> corners;
  // detections[c][shot]: what the test detected (see CameraMotion).
  std::vector<std::vector<std::optional<vision::TargetDetection>>> detections;
};

// One camera's part of the settled-frame test, with the detections it made (by shot; shots it
// did not need to detect have none), which the pose's folder records for measure.
struct CameraMotion {
  int corners = 0;
  bool moving = false;
  double chi2 = 0.0;
  std::vector<std::optional<vision::TargetDetection>> detections;
};

CameraMotion check_camera_motion(const ShotSeries& shots, std::size_t c,
                                 const CaptureCamera& camera, const vision::TargetBoard& board,
                                 const vision::BoardPoints& points,
                                 vision::AprilTagDetector& detector, double false_alarm) {
  CameraMotion out;
  out.detections.resize(shots.size());
  // Only what measure would detect the same way is recorded: it reads 8-bit gray images as they
  // are.
  const auto keep = [&](std::size_t shot, const vision::TargetDetection& d) {
    if (shots[shot][c].image.type() == CV_8UC1) out.detections[shot] = d;
  };
  const std::vector<vision::RigCamera> rig = {
      {camera.source->name(), camera.model, Eigen::Isometry3d::Identity(), {}}};
  const vision::TargetDetection first_detection =
      vision::detect_target(gray_8bit(shots[0][c].image), board, detector);
  keep(0, first_detection);
  const vision::CameraFrame first = vision::camera_frame(first_detection);
  out.corners = static_cast<int>(first.corners.size());
  if (first.corners.size() < 4 || shots.size() < 2) {
    return out;
  }
  const vision::PoseMeasurement reference = vision::measure_target_pose(rig, points, {first});
  if (reference.status != vision::PoseStatus::kOk) {
    return out;
  }
  for (std::size_t k = 1; k < shots.size(); ++k) {
    const vision::TargetDetection again =
        detect_again(gray_8bit(shots[k][c].image), board, first_detection, detector);
    keep(k, again);
    const vision::CameraFrame later = vision::camera_frame(again);
    const vision::PoseMeasurement other =
        vision::refine_target_pose(rig, points, {later}, reference.world_T_target);
    if (other.status != vision::PoseStatus::kOk) {
      out.moving = true;  // seen once, lost in a later shot: something changed
      continue;
    }
    const vision::MotionCheck check = vision::check_target_still(reference, other, false_alarm);
    out.chi2 = std::max(out.chi2, check.chi2);
    out.moving = out.moving || check.moving;
  }
  return out;
}

// The cameras are checked side by side (each has its own detector): with an array of cameras
// the test would otherwise outlast the robot's next motion.
MotionVerdict check_motion(const ShotSeries& shots, const std::vector<CaptureCamera>& cameras,
                           const vision::TargetBoard& board, const vision::BoardPoints& points,
                           std::vector<std::unique_ptr<vision::AprilTagDetector>>& detectors,
                           double false_alarm, int workers) {
  std::vector<CameraMotion> per_camera(cameras.size());
  core::parallel_for(static_cast<int>(cameras.size()), workers, [&](int i) {
    const auto c = static_cast<std::size_t>(i);
    per_camera[c] =
        check_camera_motion(shots, c, cameras[c], board, points, *detectors[c], false_alarm);
  });
  MotionVerdict verdict;
  for (const CameraMotion& m : per_camera) {
    verdict.corners.push_back(m.corners);
    verdict.chi2 = std::max(verdict.chi2, m.chi2);
    verdict.moving = verdict.moving || m.moving;
  }
  for (CameraMotion& m : per_camera) verdict.detections.push_back(std::move(m.detections));
  return verdict;
}

std::string numbers(const Eigen::VectorXd& values) {
  std::string text = "[";
  for (Eigen::Index i = 0; i < values.size(); ++i) {
    text += fmt::format("{}{:.17g}", i > 0 ? ", " : "", values[i]);
  }
  return text + "]";
}

// The controller's flange pose as pose.yaml keeps it: the keys of a hand-eye pose file
// (vision/hand_eye_io.hpp), so the line is one a person can copy into one.
std::string flange_pose_line(const Eigen::Isometry3d& base_T_flange) {
  const Eigen::Vector3d p = base_T_flange.translation();
  const Eigen::Quaterniond q(base_T_flange.linear());
  return fmt::format(
      "flange_pose: {{x: {:.17g}, y: {:.17g}, z: {:.17g}, qx: {:.17g}, qy: {:.17g}, qz: {:.17g}, "
      "qw: {:.17g}}}   # base -> flange as the controller reported it with `actuators` (m)\n",
      p.x(), p.y(), p.z(), q.x(), q.y(), q.z(), q.w());
}

std::string frame_file_name(const std::string& camera, int shot, int shots) {
  return shots == 1 ? camera + ".png" : fmt::format("{}_{}.png", camera, shot);
}

void write_text(const fs::path& file, const std::string& text) {
  std::ofstream out(file, std::ios::binary | std::ios::trunc);
  out << text;
  out.flush();
  if (!out) {
    throw std::runtime_error(file.string() + ": cannot write");
  }
}

// Writes the pose into staging/<name>, then renames it to poses/<name>: the pose appears whole.
void write_pose(const fs::path& staging, const fs::path& poses_dir, const std::string& name,
                const ShotSeries& shots, const std::vector<CaptureCamera>& cameras,
                const Eigen::VectorXd& before, const Eigen::VectorXd& after,
                const std::optional<Eigen::Isometry3d>& flange, const PoseCaptureReport& report,
                const MotionVerdict& verdict, const std::string& detector,
                const CaptureOptions& options) {
  const fs::path dir = staging / name;
  std::error_code error;
  fs::remove_all(dir, error);
  fs::create_directories(dir);
  const int n_shots = static_cast<int>(shots.size());
  // The images are encoded side by side (PNG encoding is most of the writing), then reported and
  // listed in shot and camera order.
  const std::size_t n_frames = static_cast<std::size_t>(n_shots) * cameras.size();
  const auto frame_of = [&](std::size_t i) -> const Frame& {
    return shots[i / cameras.size()][i % cameras.size()];
  };
  const auto file_of = [&](std::size_t i) {
    return frame_file_name(cameras[i % cameras.size()].source->name(),
                           static_cast<int>(i / cameras.size()), n_shots);
  };
  std::vector<std::optional<vision::RecordedDetection>> recorded(n_frames);
  core::parallel_for(static_cast<int>(n_frames), options.workers, [&](int k) {
    const auto i = static_cast<std::size_t>(k);
    const fs::path path = dir / file_of(i);
    const cv::Mat& image = frame_of(i).image;
    // Huffman coding only: camera noise leaves deflate's string matching little to find, so
    // skipping it wrote 20 % faster and 13-16 % smaller files than deflate's default (1600x1200,
    // rendered and real images; lossless either way). No row filter on top of that: half the
    // time again, 4 % larger (png_encode.hpp).
    const std::string png = encode_png(image, options.png_compression, path.string());
    write_text(path, png);
    const auto& detection = verdict.detections[i % cameras.size()][i / cameras.size()];
    if (detection) {
      recorded[i] = vision::RecordedDetection{png.size(), vision::content_hash(png), image.cols,
                                              image.rows, *detection};
    }
  });
  vision::DetectionRecord record;
  for (std::size_t i = 0; i < n_frames; ++i) {
    if (recorded[i]) record[file_of(i)] = std::move(*recorded[i]);
  }
  std::string frames_yaml;
  for (std::size_t i = 0; i < n_frames; ++i) {
    const Frame& frame = frame_of(i);
    const std::string file = file_of(i);
    if (options.on_file_written) {
      options.on_file_written(dir / file);
    }
    frames_yaml += fmt::format(
        "  - {{camera: {}, shot: {}, file: {}, pixel_format: {}, frame_id: {}, "
        "camera_timestamp_ns: {}, host_time_ns: {}}}\n",
        cameras[i % cameras.size()].source->name(), i / cameras.size(), file, frame.pixel_format,
        frame.frame_id, frame.timestamp_ns, frame.host_time_ns);
  }
  const double timestamp =
      static_cast<double>(shots[0][0].host_time_ns - options.session_start_ns) * 1e-9;
  std::string text =
      fmt::format("# robot pose {} (format: app/SESSION.md), recorded by capture\n", name);
  text += fmt::format("actuators: {}   # settled readings before the shots\n", numbers(before));
  text += fmt::format("timestamp: {:.6f}\n", timestamp);
  if (flange) text += flange_pose_line(*flange);
  text += fmt::format("actuators_after: {}   # readings after the last shot\n", numbers(after));
  text += fmt::format("retakes: {}\nstill_moving: {}\nmotion_chi2: {:.6g}\n", report.retakes,
                      report.still_moving ? "true" : "false", report.motion_chi2);
  text += "frames:\n" + frames_yaml;
  write_text(dir / "pose.yaml", text);
  if (options.on_file_written) {
    options.on_file_written(dir / "pose.yaml");
  }
  if (!record.empty()) {
    write_text(dir / vision::kDetectionRecordFile,
               vision::detection_record_to_json(detector, record));
    if (options.on_file_written) {
      options.on_file_written(dir / vision::kDetectionRecordFile);
    }
  }
  fs::rename(dir, poses_dir / name);  // atomic on one filesystem; refuses a non-empty target
}

}  // namespace

int CaptureResult::recorded() const {
  return static_cast<int>(std::count_if(poses.begin(), poses.end(), [](const auto& p) {
    return p.status == PoseCaptureStatus::kRecorded;
  }));
}

int CaptureResult::already_recorded() const {
  return static_cast<int>(std::count_if(poses.begin(), poses.end(), [](const auto& p) {
    return p.status == PoseCaptureStatus::kAlreadyRecorded;
  }));
}

std::string pose_folder_name(int index) {
  return fmt::format("pose_{:03d}", index);
}

namespace {

// A pose whose frames are taken, on its way through the motion check and the writer.
struct TakenPose {
  PoseCaptureReport report;
  ShotSeries shots;
  Eigen::VectorXd before;
  Eigen::VectorXd after;
  std::optional<Eigen::Isometry3d> flange;  // reported with `before`
  bool moving = false;                      // set by the check
  bool written = false;
  MotionVerdict verdict;  // set by the check
};

// Refuses a capture that cannot start, in words.
void check_capture_arguments(const std::vector<CaptureCamera>& cameras,
                             const CaptureOptions& options) {
  if (cameras.empty()) {
    throw std::invalid_argument("capture: no camera");
  }
  for (const CaptureCamera& camera : cameras) {
    if (camera.source == nullptr) {
      throw std::invalid_argument("capture: a camera without a source");
    }
  }
  if (options.shots_per_pose < 1) {
    throw std::invalid_argument("capture: shots_per_pose must be at least 1");
  }
}

// One detector per camera for each pose in flight: two poses' tests may run at once.
using DetectorSet = std::vector<std::unique_ptr<vision::AprilTagDetector>>;
std::vector<DetectorSet> make_detectors(std::size_t in_flight_limit, std::size_t cameras,
                                        const vision::AprilTagDetectorOptions& options) {
  std::vector<DetectorSet> detectors(in_flight_limit);
  for (auto& set : detectors) {
    for (std::size_t c = 0; c < cameras; ++c) {
      set.push_back(std::make_unique<vision::AprilTagDetector>(options));
    }
  }
  return detectors;
}

// What the robot does next: move to a target and take its pose, or only pass through it on the
// way back from a retake.
struct Step {
  int index = 0;
  bool capture = true;
};

// The steps taking every target whose pose folder does not exist yet; the others are reported
// in `result` as already recorded.
std::deque<Step> first_steps(std::size_t targets, const fs::path& poses_dir,
                             CaptureResult& result) {
  std::deque<Step> queue;
  std::error_code error;
  for (std::size_t i = 0; i < targets; ++i) {
    PoseCaptureReport report;
    report.index = static_cast<int>(i);
    report.name = pose_folder_name(report.index);
    if (fs::exists(poses_dir / report.name, error)) {
      report.status = PoseCaptureStatus::kAlreadyRecorded;
      result.poses.push_back(report);
    } else {
      queue.push_back({report.index, true});
    }
  }
  return queue;
}

// Queues `pose` to be taken again: the robot goes back along the motions it made to reach it
// (`visited`, in order; each was planned and checked: a new straight motion from elsewhere might
// not be safe, and the guard would refuse it), takes it again, and returns the same way to go on
// with the plan when there is more to take.
void plan_retake(int pose, const std::vector<int>& visited, std::deque<Step>& queue) {
  const auto last = std::find(visited.rbegin(), visited.rend(), pose);
  const auto at = last == visited.rend()
                      ? visited.size()
                      : static_cast<std::size_t>(std::distance(visited.begin(), last.base()) - 1);
  if (at + 1 >= visited.size()) {
    queue.push_front({pose, true});  // the robot is still there
    return;
  }
  std::vector<Step> steps;
  for (std::size_t k = visited.size() - 1; k-- > at;) {
    steps.push_back({visited[k], k == at});
  }
  const bool more_to_take =
      std::any_of(queue.begin(), queue.end(), [](const Step& s) { return s.capture; });
  for (std::size_t k = at + 1; more_to_take && k < visited.size(); ++k) {
    steps.push_back({visited[k], false});
  }
  queue.insert(queue.begin(), steps.begin(), steps.end());
}

// Takes the shot series at the pose the robot has settled at. The readings tell at once whether
// the robot moved during the shots: the series is taken again right away, up to
// options.max_retakes times.
void take_shots(TakenPose& taken, CaptureRobot& robot, const std::vector<CaptureCamera>& cameras,
                const CaptureOptions& options) {
  for (;;) {
    const auto t = SteadyClock::now();
    taken.shots = grab_series(cameras, options, taken.report);
    taken.after = robot.read_actuators();
    taken.report.grab_s += seconds_since(t);
    taken.moving = taken.after.size() != taken.before.size() ||
                   (taken.after - taken.before).cwiseAbs().maxCoeff() > options.reading_tolerance;
    if (!taken.moving || taken.report.retakes >= options.max_retakes) {
      break;
    }
    ++taken.report.retakes;
    taken.before = taken.after;
    taken.flange = robot.flange_pose();
  }
}

// `options` with its file observer serialised: poses in flight write side by side, and the
// observer hears of their files one at a time.
CaptureOptions one_file_at_a_time(const CaptureOptions& options, std::mutex& observer_mutex) {
  CaptureOptions writing = options;
  if (options.on_file_written) {
    writing.on_file_written = [&observer_mutex, &options](const fs::path& file) {
      const std::lock_guard lock(observer_mutex);
      options.on_file_written(file);
    };
  }
  return writing;
}

// What checking and writing a taken pose needs, the same for every pose of the capture.
struct PoseWriter {
  const std::vector<CaptureCamera>& cameras;
  const vision::TargetBoard& board;
  const vision::BoardPoints& points;
  const CaptureOptions& options;
  const CaptureOptions& writing;  // options, its observer hearing of one file at a time
  const fs::path& staging;
  const fs::path& poses_dir;
  const std::string& detector_signature;
};

// The motion check of a taken pose (with `detectors`, its own while it is in flight), then its
// writing; a pose whose target moved is returned unwritten while it may be taken again.
TakenPose check_and_write(TakenPose taken, const PoseWriter& w, DetectorSet& detectors) {
  auto t = SteadyClock::now();
  taken.verdict = check_motion(taken.shots, w.cameras, w.board, w.points, detectors,
                               w.options.motion_false_alarm, w.options.workers);
  taken.report.check_s += seconds_since(t);
  taken.report.motion_chi2 = taken.verdict.chi2;
  taken.report.corners = taken.verdict.corners;
  taken.moving = taken.moving || taken.verdict.moving;
  if (taken.moving && taken.report.retakes < w.options.max_retakes) {
    return taken;  // not written: taken again (plan_retake)
  }
  taken.report.still_moving = taken.moving;
  t = SteadyClock::now();
  write_pose(w.staging, w.poses_dir, taken.report.name, taken.shots, w.cameras, taken.before,
             taken.after, taken.flange, taken.report, taken.verdict, w.detector_signature,
             w.writing);
  taken.report.write_s = seconds_since(t);
  taken.written = true;
  return taken;
}

}  // namespace

CaptureResult capture_poses(const fs::path& session_dir,
                            const std::vector<Eigen::VectorXd>& targets, CaptureRobot& robot,
                            const std::vector<CaptureCamera>& cameras,
                            const vision::TargetBoard& board, const CaptureOptions& options) {
  check_capture_arguments(cameras, options);
  const fs::path poses_dir = session_dir / "poses";
  // Staging sits beside poses/, never inside it: the pipeline lists every folder in poses/.
  // What is left there from an interrupted run is an incomplete pose, never recorded data.
  const fs::path staging = session_dir / ".capture-staging";
  fs::create_directories(poses_dir);
  std::error_code error;
  fs::remove_all(staging, error);
  fs::create_directories(staging);

  vision::BoardPoints points;
  for (const auto& corner : board.corners) {
    points[corner.id] = corner.point;
  }
  // The board's detector, as measure builds it: the detections it makes are recorded for measure.
  const vision::AprilTagDetectorOptions detector_options = vision::detector_options_for(board);
  const std::string detector_signature = vision::detection_signature(board, detector_options);
  const auto in_flight_limit = static_cast<std::size_t>(std::max(1, options.poses_in_flight));
  std::vector<DetectorSet> detectors =
      make_detectors(in_flight_limit, cameras.size(), detector_options);

  CaptureResult result;
  const auto started = SteadyClock::now();
  std::deque<Step> queue = first_steps(targets.size(), poses_dir, result);
  std::vector<int> visited;    // the targets the robot moved to, in order
  std::map<int, int> retakes;  // by pose index: shot series rejected so far

  // The motion check and the writing of a pose run while the robot moves on (at most
  // options.poses_in_flight poses in flight). A pose whose target moved is taken again as soon as
  // that is known (plan_retake).
  std::mutex observer_mutex;
  const CaptureOptions writing = one_file_at_a_time(options, observer_mutex);
  const PoseWriter writer{cameras, board,   points,    options,
                          writing, staging, poses_dir, detector_signature};
  std::deque<std::future<TakenPose>> in_flight;  // oldest first
  std::size_t launched = 0;
  // `slot`: the detector set of this pose; the pose that used it last is settled (FIFO, at most
  // in_flight_limit at once).
  const auto check_and_write_in = [&](TakenPose taken, std::size_t slot) {
    return check_and_write(std::move(taken), writer, detectors[slot]);
  };
  // Collects the oldest pose in flight; a rejected one is taken again next (plan_retake).
  const auto settle_oldest = [&] {
    if (in_flight.empty()) {
      return;
    }
    std::future<TakenPose> oldest = std::move(in_flight.front());
    in_flight.pop_front();
    TakenPose done = oldest.get();  // rethrows a write failure
    if (done.written) {
      result.poses.push_back(done.report);
      if (options.on_pose_recorded) options.on_pose_recorded(done.report);
    } else {
      retakes[done.report.index] = done.report.retakes + 1;
      plan_retake(done.report.index, visited, queue);
    }
  };
  const auto stop = [&](const std::string& reason, std::optional<CameraError::Kind> kind) {
    std::string stop_error;
    try {
      robot.stop(reason);
    } catch (const std::exception& failure) {
      stop_error = failure.what();
    }
    // The poses in flight were taken whole: let them finish writing.
    while (!in_flight.empty()) {
      try {
        settle_oldest();
      } catch (const std::exception& failure) {
        stop_error += (stop_error.empty() ? "" : "; ") + std::string(failure.what());
      }
    }
    result.stop_reason = stop_error.empty()
                             ? reason + " (robot stopped; the poses recorded so far are kept)"
                             : reason + "; " + stop_error;
    result.camera_error = kind;
    result.seconds = seconds_since(started);
  };

  while (!queue.empty() || !in_flight.empty()) {
    if (queue.empty()) {
      try {
        settle_oldest();
      } catch (const std::exception& failure) {
        stop(failure.what(), std::nullopt);
        return result;
      }
      continue;
    }
    const Step step = queue.front();
    queue.pop_front();
    const int index = step.index;
    if (!step.capture) {  // on the way back from a retake: the robot only passes through
      try {
        (void)robot.move_and_settle(targets[static_cast<std::size_t>(index)]);
        visited.push_back(index);
      } catch (const std::exception& failure) {
        stop(fmt::format("on the way back from a retake, at {}: {}", pose_folder_name(index),
                         failure.what()),
             std::nullopt);
        return result;
      }
      continue;
    }
    TakenPose taken;
    taken.report.index = index;
    taken.report.name = pose_folder_name(index);
    taken.report.retakes = retakes[index];
    try {
      auto t = SteadyClock::now();
      taken.before = robot.move_and_settle(targets[static_cast<std::size_t>(index)]);
      taken.flange = robot.flange_pose();
      taken.report.move_s = seconds_since(t);
      visited.push_back(index);
      take_shots(taken, robot, cameras, options);
      t = SteadyClock::now();
      while (in_flight.size() >= in_flight_limit) {
        settle_oldest();
      }
      taken.report.wait_s = seconds_since(t);
    } catch (const CameraError& camera_error) {
      stop(fmt::format("pose {}: {}", taken.report.name, camera_error.what()), camera_error.kind());
      return result;
    } catch (const std::exception& other) {
      stop(fmt::format("pose {}: {}", taken.report.name, other.what()), std::nullopt);
      return result;
    }
    in_flight.push_back(std::async(std::launch::async, check_and_write_in, std::move(taken),
                                   launched++ % in_flight_limit));
  }
  std::sort(result.poses.begin(), result.poses.end(),
            [](const auto& a, const auto& b) { return a.index < b.index; });
  fs::remove_all(staging, error);
  result.complete = true;
  result.seconds = seconds_since(started);
  return result;
}

}  // namespace robocal::robotio
