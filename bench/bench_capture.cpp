// Capture bench: N poses collected from a simulated cell through two fake GigE
// Vision cameras (127.0.0.1 and 127.0.0.2: run it inside a network namespace, e.g.
//   tests/integration/robotio_camera/run_in_netns.sh build/release/bench/bench_capture
// ), checks every pose was recorded bit-exact, and reports robocal's overhead per pose: the
// wall time of a pose minus the robot's move and the renderer's time. Prints JSON.
// Options: --poses N (60), --size WxH (1600x1200 or 640x480; default 1600x1200), --shots K (2),
// --out DIR (a fresh folder; default under /tmp), --resume (keep DIR: capture resumes),
// --controller gantry|sim: the robot is an in-process gantry that moves instantly (default), or
// `robocal sim-controller` as its own process (a perturbed linear delta, Marlin over TCP,
// driven through the guarded G-code link; the cameras render from its true-pose channel). With
// sim, the simulated motion time (the controller's own trapezoid durations, from its log) is
// what is subtracted as "move"; the link's round trips count as robocal's overhead.
#include "sim_camera_cell.hpp"

#include "robocal/robotio/sim_process.hpp"

#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <iostream>
#include <string>
#include <vector>

namespace fs = std::filesystem;
using namespace robocal;
using namespace robocal::robotio;

namespace {

vision::CameraModel camera_model(int width, int height) {
  const double f = width == 1600 ? 1600.0 : 620.0;
  return vision::parse_camera_yaml(
      "model: pinhole_radtan\nwidth: " + std::to_string(width) +
          "\nheight: " + std::to_string(height) + "\nfx: " + std::to_string(f) +
          "\nfy: " + std::to_string(f) + "\ncx: " + std::to_string(width / 2.0 - 0.3) + "\ncy: " +
          std::to_string(height / 2.0 + 0.2) + "\ndistortion: [-0.12, 0.05, 0.0, 0.0, 0.0]\n",
      "bench camera");
}

// Times each move (the start of a pose window) around any CaptureRobot.
class TimedRobot final : public CaptureRobot {
 public:
  TimedRobot(CaptureRobot& inner, std::vector<std::chrono::steady_clock::time_point>& starts)
      : inner_(&inner), starts_(&starts) {}
  Eigen::VectorXd move_and_settle(const Eigen::VectorXd& target) override {
    starts_->push_back(std::chrono::steady_clock::now());
    return inner_->move_and_settle(target);
  }
  Eigen::VectorXd read_actuators() override { return inner_->read_actuators(); }
  void stop(const std::string& reason) override { inner_->stop(reason); }

 private:
  CaptureRobot* inner_;
  std::vector<std::chrono::steady_clock::time_point>* starts_;
};

double percentile(std::vector<double> values, double p) {
  std::sort(values.begin(), values.end());
  const auto index =
      static_cast<std::size_t>(std::lround(p * static_cast<double>(values.size() - 1)));
  return values[index];
}

}  // namespace

int main(int argc, char** argv) {
  int poses = 60;
  int width = 1600;
  int height = 1200;
  int shots = 2;
  fs::path out = fs::temp_directory_path() / "robocal_bench_capture";
  bool resume = false;
  bool sim_controller = false;
  for (int i = 1; i < argc; i += 2) {
    const std::string key = argv[i];
    if (key == "--resume") {  // keep the folder: capture skips the poses already recorded
      resume = true;
      --i;
      continue;
    }
    if (i + 1 >= argc) {
      std::cerr << "bench_capture: " << key << " needs a value\n";
      return 2;
    }
    const std::string value = argv[i + 1];
    if (key == "--poses") {
      poses = std::stoi(value);
    } else if (key == "--size") {
      width = std::stoi(value.substr(0, value.find('x')));
      height = std::stoi(value.substr(value.find('x') + 1));
    } else if (key == "--shots") {
      shots = std::stoi(value);
    } else if (key == "--out") {
      out = value;
    } else if (key == "--controller" && (value == "sim" || value == "gantry")) {
      sim_controller = value == "sim";
    } else {
      std::cerr << "bench_capture: unknown option " << key << "\n";
      return 2;
    }
  }
  if (!resume) {
    fs::remove_all(out);
  }
  fs::create_directories(out);

  testing::GantryCell gantry;
  std::unique_ptr<testing::SimCell> sim;
  std::unique_ptr<LinkCaptureRobot> link_robot;
  TruePoseSource* truth = &gantry;
  CaptureRobot* robot = &gantry;
  if (sim_controller) {
    const fs::path sim_dir = out.parent_path() / (out.filename().string() + "_sim");
    fs::create_directories(sim_dir);
    sim = std::make_unique<testing::SimCell>(sim_dir);
    link_robot = std::make_unique<LinkCaptureRobot>(*sim->link, testing::kSimCellSpeed);
    truth = sim->truth.get();
    robot = link_robot.get();
  }
  const vision::TargetBoard board =
      vision::load_target_file(testing::testdata("vision/apriltag_4x3.yaml"));
  std::vector<std::unique_ptr<SimulatedGigECamera>> simulated;
  std::vector<std::unique_ptr<AravisCamera>> clients;
  std::vector<CaptureCamera> cameras;
  for (int c = 0; c < 2; ++c) {
    SimulatedCameraSpec spec = testing::camera_spec(c);
    spec.model = camera_model(width, height);
    // Fewer blur sub-cells than the tests (2 instead of 4): the fake camera renders inside its
    // only thread, which also answers the control channel; on a busy machine a 1600x1200 render
    // of several seconds outlasts Aravis' 5 s heartbeat window and the camera is reported lost.
    spec.render.blur_subcells = 2;
    simulated.push_back(std::make_unique<SimulatedGigECamera>(spec, board, *truth));
    simulated.back()->set_history(static_cast<std::size_t>(poses * shots * 4));
    auto client = std::make_unique<AravisCamera>(spec.serial, "cam" + std::to_string(c));
    client->set_region({0, 0, width, height});
    client->start(TriggerMode::kSoftware);
    cameras.push_back({client.get(), spec.model});
    clients.push_back(std::move(client));
  }

  const auto targets = sim_controller ? testing::sim_cell_targets(sim->model, poses)
                                      : testing::gantry_targets(poses);
  std::vector<Clock::time_point> pose_start;
  TimedRobot timed(*robot, pose_start);
  CaptureOptions options;
  options.shots_per_pose = shots;
  options.session_start_ns = host_time_ns();
  // The simulated cameras render on this machine's CPU (seconds per 1600x1200 frame when the
  // machine is busy); a real camera answers in milliseconds.
  options.grab_timeout = std::chrono::milliseconds(20000);
  const CaptureResult result = capture_poses(out, targets, timed, cameras, board, options);
  pose_start.push_back(Clock::now());

  // Bit-exact: each camera's recorded frames, in pose order, are rendered frames in render
  // order (a retaken or re-grabbed frame is rendered but not recorded).
  int mismatched = 0;
  int retakes = 0;
  int frame_retries = 0;
  for (const auto& pose : result.poses) {
    retakes += pose.retakes;
    frame_retries += pose.frame_retries;
  }
  std::vector<std::pair<Clock::time_point, Clock::time_point>> renders;
  for (int c = 0; c < 2; ++c) {
    const auto rendered = simulated[static_cast<std::size_t>(c)]->rendered();
    for (const RenderedFrame& frame : rendered) {
      renders.emplace_back(frame.render_start, frame.render_end);
    }
    std::size_t next = 0;
    for (const PoseCaptureReport& pose : result.poses) {
      if (pose.status != PoseCaptureStatus::kRecorded) {
        continue;  // recorded by an earlier run
      }
      const int i = pose.index;
      for (int k = 0; k < shots; ++k) {
        const fs::path file = out / "poses" / pose_folder_name(i) /
                              ("cam" + std::to_string(c) + "_" + std::to_string(k) + ".png");
        const cv::Mat image = cv::imread(file.string(), cv::IMREAD_UNCHANGED);
        bool found = false;
        while (!found && next < rendered.size()) {
          const cv::Mat& served = rendered[next++].image;
          found = image.size() == served.size() && cv::norm(image, served, cv::NORM_INF) == 0.0;
        }
        mismatched += found ? 0 : 1;
      }
    }
  }
  // Rendering time per pose window: the union of the render intervals (both cameras render at
  // the same time) that start in it.
  std::sort(renders.begin(), renders.end());
  std::vector<double> render_s(pose_start.size(), 0.0);
  for (std::size_t r = 0; r < renders.size();) {
    auto [begin_r, end_r] = renders[r];
    std::size_t s_next = r + 1;
    while (s_next < renders.size() && renders[s_next].first <= end_r) {
      end_r = std::max(end_r, renders[s_next].second);
      ++s_next;
    }
    const auto window = std::upper_bound(pose_start.begin(), pose_start.end(), begin_r);
    if (window != pose_start.begin()) {
      render_s[static_cast<std::size_t>(window - pose_start.begin() - 1)] +=
          std::chrono::duration<double>(end_r - begin_r).count();
    }
    r = s_next;
  }
  const std::size_t windows = pose_start.size() - 1;  // one per move (retakes add moves)
  std::vector<double> overhead;
  double sum_render = 0.0;
  double sum_move = 0.0;
  double sum_check = 0.0;
  double sum_write = 0.0;
  double sum_grab = 0.0;
  double sum_wait = 0.0;
  for (const auto& pose : result.poses) {
    sum_wait += pose.wait_s;
    sum_move += pose.move_s;
    sum_check += pose.check_s;
    sum_write += pose.write_s;
    sum_grab += pose.grab_s;
  }
  // The robot's own time per window: the simulator's motion durations (sim), or move_and_settle
  // (the gantry: instantaneous).
  std::vector<double> motion_s(windows, 0.0);
  if (sim_controller) {
    const std::vector<double> motions = robotio::simulated_motion_seconds(sim->log);
    for (std::size_t w = 0; w < windows && w < motions.size(); ++w) {
      motion_s[w] = motions[w];
    }
  }
  double sum_motion = 0.0;
  for (std::size_t w = 0; w < windows; ++w) {
    const double wall = std::chrono::duration<double>(pose_start[w + 1] - pose_start[w]).count();
    sum_render += render_s[w];
    sum_motion += motion_s[w];
    overhead.push_back(wall - render_s[w] - motion_s[w]);
  }
  const double n = static_cast<double>(windows);
  double mean_overhead = 0.0;
  for (double o : overhead) {
    mean_overhead += o / n;
  }
  if (!sim_controller) {
    mean_overhead -= sum_move / n;
  }
  const double total_s =
      std::chrono::duration<double>(pose_start.back() - pose_start.front()).count();
  nlohmann::json report = {
      {"bench", "capture"},
      {"poses_requested", poses},
      {"poses_recorded", result.recorded()},
      {"poses_already_recorded", result.already_recorded()},
      {"pose_folders",
       std::distance(fs::directory_iterator(out / "poses"), fs::directory_iterator{})},
      {"complete", result.complete},
      {"stop_reason", result.stop_reason},
      {"controller", sim_controller ? "sim-controller over TCP (linear delta, Marlin)"
                                    : "in-process gantry (instant moves)"},
      {"cameras", 2},
      {"image", std::to_string(width) + "x" + std::to_string(height)},
      {"shots_per_pose", shots},
      {"retakes", retakes},
      {"frame_retries", frame_retries},
      {"frames_mismatched", mismatched},
      {"overhead_per_pose_ms",
       {{"mean", 1e3 * mean_overhead},
        {"median", 1e3 * percentile(overhead, 0.5)},
        {"max", 1e3 * percentile(overhead, 1.0)}}},
      {"wall_per_pose_ms", {{"mean", 1e3 * total_s / n}}},
      {"mean_per_pose_ms",
       {{"render", 1e3 * sum_render / n},
        {"move", 1e3 * sum_move / n},
        {"simulated_motion", 1e3 * sum_motion / n},
        {"waiting_for_frames_incl_render", 1e3 * sum_grab / n},
        {"motion_check_background", 1e3 * sum_check / n},
        {"write_background", 1e3 * sum_write / n},
        {"waiting_for_check_and_write", 1e3 * sum_wait / n}}},
      {"definition",
       "overhead = wall time per pose - the robot's motion (sim: the controller's simulated "
       "motion durations, so link round trips count as overhead; gantry: move_and_settle) - "
       "rendering (union of both cameras' render intervals); the motion check and the writing of a "
       "pose run while the next pose "
       "is taken and count only when the robot waits for them"}};
  std::cout << report.dump(2) << "\n";
  return result.complete && mismatched == 0 ? 0 : 1;
}
