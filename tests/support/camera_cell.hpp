#pragma once
// A small simulated camera cell for camera and capture tests: a Cartesian "gantry" whose three
// actuators translate the AprilTag test board (so its true pose is known in closed form), and
// two rendered cameras served as fake GigE Vision cameras on 127.0.0.1 and 127.0.0.2.
// It is the CaptureRobot and the TruePoseSource at once, like sim-controller with its truth
// channel.
#include "robocal/robotio/camera_aravis.hpp"
#include "robocal/robotio/camera_simulated.hpp"
#include "robocal/robotio/capture.hpp"
#include "robocal/vision/camera_io.hpp"
#include "robocal/vision/pose.hpp"
#include "robocal/vision/target_io.hpp"

#include <Eigen/Geometry>

#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

namespace robocal::robotio::testing {

inline std::string testdata(const std::string& relative) {
  return std::string(ROBOCAL_TESTDATA_DIR) + "/" + relative;
}

class GantryCell final : public CaptureRobot, public TruePoseSource {
 public:
  GantryCell() : q_(Eigen::VectorXd::Zero(3)) {
    // Board 0.45 m in front of camera 0 (world = camera 0's frame), facing it.
    const vision::TargetBoard board =
        vision::load_target_file(testdata("vision/apriltag_4x3.yaml"));
    const Eigen::Vector3d centre(0.08, 0.06, 0.0);
    home_ = vision::camera_T_board_look_at(centre + Eigen::Vector3d(0.0, 0.0, -0.45), centre,
                                           Eigen::Vector3d(0.0, -1.0, 0.0));
  }

  Eigen::VectorXd move_and_settle(const Eigen::VectorXd& target) override {
    if (before_move) {
      before_move(moves_);
    }
    const std::lock_guard lock(mutex_);
    q_ = target;
    ++moves_;
    moved_to_.push_back(target);
    return q_;
  }
  // Every target the robot was moved to, in order.
  [[nodiscard]] std::vector<Eigen::VectorXd> moved_to() const {
    const std::lock_guard lock(mutex_);
    return moved_to_;
  }
  Eigen::VectorXd read_actuators() override {
    const std::lock_guard lock(mutex_);
    return q_;
  }
  void stop(const std::string& /*reason*/) override {
    const std::lock_guard lock(mutex_);
    ++stops_;
  }
  Eigen::Isometry3d world_T_board() override {
    const std::lock_guard lock(mutex_);
    Eigen::Vector3d offset = q_.head<3>();
    if (wobble_renders_ > 0) {  // still swinging after "settled": 1.5 mm per remaining render
      offset.x() += 1.5e-3 * wobble_renders_;
      --wobble_renders_;
    }
    return Eigen::Translation3d(offset) * home_;
  }
  // The next `renders` rendered frames see the board displaced (decaying), as if the robot
  // reported settled while still swinging.
  void wobble(int renders) {
    const std::lock_guard lock(mutex_);
    wobble_renders_ = renders;
  }
  [[nodiscard]] int stops() const {
    const std::lock_guard lock(mutex_);
    return stops_;
  }

  std::function<void(int move_index)> before_move;  // runs before each move (test hooks)

 private:
  mutable std::mutex mutex_;
  Eigen::VectorXd q_;
  Eigen::Isometry3d home_ = Eigen::Isometry3d::Identity();
  int moves_ = 0;
  int stops_ = 0;
  int wobble_renders_ = 0;
  std::vector<Eigen::VectorXd> moved_to_;
};

// Poses of the gantry: a few cm around home, all with the board fully in both views.
inline std::vector<Eigen::VectorXd> gantry_targets(int count) {
  std::vector<Eigen::VectorXd> targets;
  for (int i = 0; i < count; ++i) {
    Eigen::VectorXd q(3);
    q << 0.004 * ((i % 5) - 2), 0.003 * (((i / 5) % 4) - 1.5), 0.01 * ((i % 3) - 1);
    targets.push_back(q);
  }
  return targets;
}

inline SimulatedCameraSpec camera_spec(int index) {
  SimulatedCameraSpec spec;
  spec.serial = index == 0 ? "SIM-CAM0" : "SIM-CAM1";
  spec.address = index == 0 ? "127.0.0.1" : "127.0.0.2";
  spec.model = vision::load_camera_file(testdata("vision/camera_640x480.yaml"));
  // Camera 1 sits 6 cm to the right of camera 0, toed in by 4 degrees.
  spec.camera_T_world = index == 0
                            ? Eigen::Isometry3d::Identity()
                            : Eigen::Isometry3d(Eigen::AngleAxisd(-4.0 * 3.14159265358979 / 180.0,
                                                                  Eigen::Vector3d::UnitY())) *
                                  Eigen::Translation3d(-0.06, 0.0, 0.0);
  spec.render.blur_sigma = 0.6;
  spec.render.read_noise = 1.0;
  spec.render.seed = 1000U * static_cast<unsigned>(index + 1);
  return spec;
}

// The two simulated cameras and the Aravis clients that read them.
struct CameraRig {
  std::vector<std::unique_ptr<SimulatedGigECamera>> simulated;
  std::vector<std::unique_ptr<AravisCamera>> clients;
  std::vector<CaptureCamera> capture;

  CameraRig(TruePoseSource& truth, std::size_t history) {
    const vision::TargetBoard board =
        vision::load_target_file(testdata("vision/apriltag_4x3.yaml"));
    for (int c = 0; c < 2; ++c) {
      simulated.push_back(std::make_unique<SimulatedGigECamera>(camera_spec(c), board, truth));
      simulated.back()->set_history(history);
    }
    for (int c = 0; c < 2; ++c) {
      add_client(c);
    }
  }
  void add_client(int c) {
    const SimulatedCameraSpec& spec = simulated[static_cast<std::size_t>(c)]->spec();
    auto client = std::make_unique<AravisCamera>(spec.serial, "cam" + std::to_string(c));
    client->set_region({0, 0, spec.model.width, spec.model.height});
    client->start(TriggerMode::kSoftware);
    capture.push_back({client.get(), spec.model});
    clients.push_back(std::move(client));
  }
};

}  // namespace robocal::robotio::testing
