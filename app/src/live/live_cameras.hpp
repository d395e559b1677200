#pragma once
// The live demo's cameras: the simulated cell's two cameras, rendering the board where a
// TruePoseSource says it is, served as GigE Vision cameras through Aravis' fake camera where this
// machine gives each its own IPv4 address (robotio/camera_simulated.hpp), otherwise rendered
// in-process behind the same CameraSource interface. Either way capture reads them as cameras.
//
// Aravis serves a fake camera only on an address of a local interface: 127.0.0.1 always exists,
// 127.0.0.2 only where it was added (`ip addr add 127.0.0.2/32 dev lo`, e.g. in the test's
// network namespace); Linux answering the whole 127/8 on lo is not enough. Two fake cameras on
// one address collide, so the second camera is then rendered in-process.
#include "robocal/robotio/camera_simulated.hpp"
#include "robocal/robotio/camera_source.hpp"
#include "robocal/vision/camera_model.hpp"
#include "robocal/vision/renderer.hpp"
#include "robocal/vision/target.hpp"

#include <Eigen/Geometry>

#include <atomic>
#include <future>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

namespace robocal::app {

// A board held where a script puts it (the operator waving the calibration board).
class ScriptedBoard final : public robotio::TruePoseSource {
 public:
  void set(const Eigen::Isometry3d& world_T_board);
  Eigen::Isometry3d world_T_board() override;

 private:
  std::mutex mutex_;
  Eigen::Isometry3d pose_ = Eigen::Isometry3d::Identity();
};

// Another source seen through the true robot's elastic sag (simcell's elastic_deflection, which
// the simulator's rigid robot lacks), so the live cell's truth is the offline demo's.
class SaggingBoard final : public robotio::TruePoseSource {
 public:
  SaggingBoard(robotio::TruePoseSource& inner, double sag) : inner_(&inner), sag_(sag) {}
  Eigen::Isometry3d world_T_board() override;

 private:
  robotio::TruePoseSource* inner_;
  double sag_;
};

// One simulated camera of the cell: its true intrinsics and extrinsics (truth world).
struct LiveCameraSpec {
  std::string name;  // session camera name (cam0, cam1)
  vision::CameraModel model;
  Eigen::Isometry3d camera_T_world = Eigen::Isometry3d::Identity();
  vision::RenderOptions render;
  // The rays of `model`, shared by every source that renders this camera (optional: computed from
  // `model` where missing).
  std::shared_ptr<const vision::CameraRays> rays;
};

// A simulated camera rendered in this process on trigger (a thread per frame, so triggering
// both cameras before receiving renders them at once). Mono8, full frame only.
class InProcessCamera final : public robotio::CameraSource {
 public:
  // `busy` counts the rendering time, with the cell's other cameras (shared: it outlives the
  // source). `frames` counts the camera's frames, from which each frame's noise is drawn: shared
  // with the camera's earlier sources (a GigE camera it replaces, an earlier attempt's), so no
  // frame repeats another's noise; null: this source's own count from zero.
  InProcessCamera(LiveCameraSpec spec, const vision::TargetBoard& board,
                  robotio::TruePoseSource& truth, std::shared_ptr<robotio::RenderBusyClock> busy,
                  std::shared_ptr<std::atomic<std::uint64_t>> frames = nullptr);
  ~InProcessCamera() override;
  InProcessCamera(const InProcessCamera&) = delete;
  InProcessCamera& operator=(const InProcessCamera&) = delete;
  InProcessCamera(InProcessCamera&&) = delete;
  InProcessCamera& operator=(InProcessCamera&&) = delete;

  [[nodiscard]] const std::string& name() const override { return spec_.name; }
  [[nodiscard]] robotio::CameraInfo info() const override;
  void set_exposure_us(double exposure_us) override { exposure_us_ = exposure_us; }
  [[nodiscard]] double exposure_us() const override { return exposure_us_; }
  void set_gain(double gain) override { gain_ = gain; }
  [[nodiscard]] double gain() const override { return gain_; }
  void set_pixel_format(const std::string& format) override;
  [[nodiscard]] std::string pixel_format() const override { return "Mono8"; }
  void set_region(const robotio::Region& region) override;
  [[nodiscard]] robotio::Region region() const override;
  void start(robotio::TriggerMode mode) override;
  void trigger() override;
  robotio::Frame receive(std::chrono::milliseconds timeout) override;
  void stop() override;
  void close() override;
  // Keeps what the board and the truth source belong to alive as long as the camera (a camera
  // opened on its own, e.g. sim:FILE, owns its cell and its truth channel).
  void keep_alive(std::shared_ptr<const void> owner) { owner_ = std::move(owner); }

 private:
  void check_open() const;
  LiveCameraSpec spec_;
  const vision::TargetBoard* board_;
  robotio::TruePoseSource* truth_;
  // Repeated shots of a robot standing still draw only new noise (vision::StillSceneRenderer).
  std::unique_ptr<vision::StillSceneRenderer> renderer_;
  double exposure_us_ = 10000.0;
  double gain_ = 0.0;
  bool open_ = true;
  bool started_ = false;
  std::shared_ptr<std::atomic<std::uint64_t>> frames_;
  std::future<cv::Mat> pending_;
  std::shared_ptr<robotio::RenderBusyClock> busy_;
  std::shared_ptr<const void>
      owner_;  // released after the destructor waited for the frame in flight
};

// The cameras of the cell showing one board, served as GigE where possible.
class LiveCameras {
 public:
  // Tries GigE for camera i on live_camera_address(i) (none when `gige` is false), serial
  // `serial_prefix` + i (unique per process: another program's fake camera on the same address
  // must not be taken for ours); a camera that cannot be served there is rendered in-process,
  // and `notes` says why.
  // `truths`: one source for every camera (the board on the robot), or one per camera (each
  // camera shown its own calibration board).
  LiveCameras(const std::vector<LiveCameraSpec>& specs, const vision::TargetBoard& board,
              const std::vector<robotio::TruePoseSource*>& truths, bool gige,
              const std::string& serial_prefix);
  // The source string for collect (aravis:SERIAL, or inprocess:NAME).
  [[nodiscard]] std::string source(std::size_t camera) const;
  // Opens camera `camera`'s source: Aravis for a served camera (when Aravis cannot open it, the
  // camera is rendered in-process from then on, and `notes` says why), in-process otherwise.
  [[nodiscard]] std::unique_ptr<robotio::CameraSource> open(std::size_t camera);
  // The same, by the camera's name.
  [[nodiscard]] std::unique_ptr<robotio::CameraSource> open(const std::string& name);
  [[nodiscard]] bool served(std::size_t camera) const { return gige_[camera] != nullptr; }
  // Stops serving camera `camera` (e.g. Aravis lost it: on a busy machine a render longer than
  // the GigE heartbeat window looks like a lost camera); it is rendered in-process from then on.
  void fall_back(std::size_t camera, const std::string& why);
  [[nodiscard]] const std::vector<std::string>& notes() const { return notes_; }
  // Wall time so far during which at least one camera was rendering (s).
  [[nodiscard]] double render_seconds() const { return busy_->seconds(); }

 private:
  void stop_serving(std::size_t camera);
  std::vector<LiveCameraSpec> specs_;
  const vision::TargetBoard* board_;
  std::vector<robotio::TruePoseSource*> truths_;  // per camera
  std::vector<std::unique_ptr<robotio::SimulatedGigECamera>> gige_;
  // Per camera, the frames rendered so far (GigE or in-process): the next frame's noise index.
  std::vector<std::shared_ptr<std::atomic<std::uint64_t>>> frames_;
  std::shared_ptr<robotio::RenderBusyClock> busy_ = std::make_shared<robotio::RenderBusyClock>();
  std::vector<std::string> notes_;
  std::string prefix_;
};

// The address camera i is served on: 127.0.0.(i+1).
std::string live_camera_address(std::size_t camera);

}  // namespace robocal::app
