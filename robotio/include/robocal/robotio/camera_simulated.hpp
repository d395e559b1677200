#pragma once
// Simulated cameras: the end-effector board rendered (vision's renderer) at the pose the
// simulated controller really holds, read from its truth channel (never from the measurement
// pipeline), and served as a GigE Vision camera through Aravis' fake camera. Capture then opens
// it with AravisCamera, exactly as a real camera.
//
// The frame is rendered inside the fake camera's thread, which also answers the GigE Vision
// control channel: a render that takes longer than the client's heartbeat window (Aravis: about
// 5 s) makes the client report the camera lost. Keep renders short (image size, blur) on a busy
// machine.
#include "robocal/robotio/camera_fake_gige.hpp"
#include "robocal/vision/camera_model.hpp"
#include "robocal/vision/renderer.hpp"
#include "robocal/vision/target.hpp"

#include <Eigen/Geometry>

#include <chrono>
#include <cstdint>
#include <deque>
#include <memory>
#include <mutex>
#include <string>

namespace robocal::robotio {

// Where the board really is now (truth world). The simulated controller's truth channel
// (sim-controller, robotio/README.md) implements it through an adapter; tests use a scripted
// pose. Throws std::runtime_error when the truth is not available.
class TruePoseSource {
 public:
  virtual ~TruePoseSource() = default;
  TruePoseSource() = default;
  TruePoseSource(const TruePoseSource&) = delete;
  TruePoseSource& operator=(const TruePoseSource&) = delete;
  TruePoseSource(TruePoseSource&&) = delete;
  TruePoseSource& operator=(TruePoseSource&&) = delete;
  [[nodiscard]] virtual Eigen::Isometry3d world_T_board() = 0;
};

// Wall time during which at least one of several simulated cameras was rendering: the union of
// their render intervals. A capture triggers every camera and then waits for them all, so this
// union (not the sum, nor one camera's total) is the time it waited on simulated exposures, which
// benches and the live demo subtract to get robocal's own time. Thread safe; one per cell, shared
// by its cameras.
class RenderBusyClock {
 public:
  void begin();
  void end();
  [[nodiscard]] double seconds() const;  // so far, including a render in progress

 private:
  mutable std::mutex mutex_;
  int active_ = 0;
  std::chrono::steady_clock::time_point since_;
  std::chrono::steady_clock::duration busy_{0};
};

// begin() now, end() when it goes (also when a render throws).
class RenderBusyScope {
 public:
  explicit RenderBusyScope(RenderBusyClock* clock) : clock_(clock) {
    if (clock_ != nullptr) clock_->begin();
  }
  ~RenderBusyScope() {
    if (clock_ != nullptr) clock_->end();
  }
  RenderBusyScope(const RenderBusyScope&) = delete;
  RenderBusyScope& operator=(const RenderBusyScope&) = delete;
  RenderBusyScope(RenderBusyScope&&) = delete;
  RenderBusyScope& operator=(RenderBusyScope&&) = delete;

 private:
  RenderBusyClock* clock_;
};

struct SimulatedCameraSpec {
  std::string serial;                 // GigE serial number it is served under
  std::string address = "127.0.0.1";  // its own IP address (one per fake camera)
  vision::CameraModel model;          // true intrinsics; the sensor region must fit in 2048 x 2048
  Eigen::Isometry3d camera_T_world = Eigen::Isometry3d::Identity();
  vision::RenderOptions render;  // seed: the first frame's; each frame adds its index
  // Exposure at which `render`'s levels hold; other exposures scale them (and clip at white).
  double reference_exposure_us = 10000.0;
  // Counts this camera's renders into a clock shared with the cell's other cameras (optional).
  std::shared_ptr<RenderBusyClock> busy_clock;
  // The rays of `model`, when another renderer of the same camera has them (optional: computed
  // from `model` otherwise).
  std::shared_ptr<const vision::CameraRays> rays;
};

// A frame as rendered, kept so tests can check what went over the wire bit for bit.
struct RenderedFrame {
  std::uint64_t frame_index = 0;
  Eigen::Isometry3d world_T_board = Eigen::Isometry3d::Identity();
  cv::Mat image;  // the served region
  std::chrono::steady_clock::time_point render_start;
  std::chrono::steady_clock::time_point render_end;
};

class SimulatedGigECamera {
 public:
  // Starts serving. `truth` must outlive the camera. Throws CameraError kIo (address) or
  // std::invalid_argument (a camera larger than the fake sensor).
  SimulatedGigECamera(SimulatedCameraSpec spec, vision::TargetBoard board, TruePoseSource& truth);

  [[nodiscard]] const SimulatedCameraSpec& spec() const { return spec_; }
  [[nodiscard]] FakeGigECamera& server() { return *server_; }
  // The last `keep` rendered frames, oldest first.
  [[nodiscard]] std::deque<RenderedFrame> rendered() const;
  void set_history(std::size_t keep);

 private:
  cv::Mat render_frame(const FakeFrameRequest& request);

  SimulatedCameraSpec spec_;
  vision::TargetBoard board_;
  TruePoseSource* truth_;
  // Repeated shots of a robot standing still draw only new noise (vision::StillSceneRenderer).
  std::unique_ptr<vision::StillSceneRenderer> renderer_;
  mutable std::mutex history_mutex_;
  std::deque<RenderedFrame> history_;
  std::size_t keep_ = 8;
  std::unique_ptr<FakeGigECamera> server_;  // last: stops serving before the rest goes
};

}  // namespace robocal::robotio
