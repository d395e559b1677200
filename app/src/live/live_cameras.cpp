#include "live/live_cameras.hpp"

#include "robocal/robotio/camera_open.hpp"
#include "simcell/simulated_cell.hpp"

#include <fmt/core.h>
#include <fmt/ranges.h>

#include <algorithm>
#include <chrono>
#include <deque>
#include <exception>
#include <utility>

namespace robocal::app {

namespace {
constexpr const char* kInProcess = "inprocess:";
}  // namespace

void ScriptedBoard::set(const Eigen::Isometry3d& world_T_board) {
  const std::lock_guard lock(mutex_);
  pose_ = world_T_board;
}

Eigen::Isometry3d ScriptedBoard::world_T_board() {
  const std::lock_guard lock(mutex_);
  return pose_;
}

Eigen::Isometry3d SaggingBoard::world_T_board() {
  return elastic_deflection(inner_->world_T_board(), sag_);
}

// ---- in-process camera ------------------------------------------------------------------------

InProcessCamera::InProcessCamera(LiveCameraSpec spec, const vision::TargetBoard& board,
                                 robotio::TruePoseSource& truth,
                                 std::shared_ptr<robotio::RenderBusyClock> busy,
                                 std::shared_ptr<std::atomic<std::uint64_t>> frames)
    : spec_(std::move(spec)),
      board_(&board),
      truth_(&truth),
      renderer_(std::make_unique<vision::StillSceneRenderer>(
          spec_.rays && spec_.rays->camera == spec_.model
              ? spec_.rays
              : std::make_shared<const vision::CameraRays>(vision::precompute_rays(spec_.model)))),
      frames_(frames ? std::move(frames) : std::make_shared<std::atomic<std::uint64_t>>(0)),
      busy_(std::move(busy)) {}

InProcessCamera::~InProcessCamera() {
  if (pending_.valid()) pending_.wait();
}

void InProcessCamera::check_open() const {
  if (!open_)
    throw robotio::CameraError(robotio::CameraError::Kind::kDisconnected, spec_.name,
                               "the in-process simulated camera is closed");
}

robotio::CameraInfo InProcessCamera::info() const {
  robotio::CameraInfo i;
  i.driver = "simulated";
  i.id = kInProcess + spec_.name;
  i.vendor = "robocal";
  i.model = "in-process renderer";
  i.serial = spec_.name;
  i.sensor_width = spec_.model.width;
  i.sensor_height = spec_.model.height;
  i.pixel_formats = {"Mono8"};
  return i;
}

void InProcessCamera::set_pixel_format(const std::string& format) {
  if (format != "Mono8")
    throw robotio::CameraError(robotio::CameraError::Kind::kUnsupported, spec_.name,
                               "pixel format " + format + ": only Mono8 is rendered");
}

void InProcessCamera::set_region(const robotio::Region& region) {
  if (region != this->region())
    throw robotio::CameraError(robotio::CameraError::Kind::kUnsupported, spec_.name,
                               "only the full frame is rendered");
}

robotio::Region InProcessCamera::region() const {
  return {0, 0, spec_.model.width, spec_.model.height};
}

void InProcessCamera::start(robotio::TriggerMode /*mode*/) {
  check_open();
  started_ = true;
}

void InProcessCamera::trigger() {
  check_open();
  if (!started_)
    throw robotio::CameraError(robotio::CameraError::Kind::kIo, spec_.name,
                               "trigger before start()");
  if (pending_.valid()) pending_.wait();  // one frame in flight, as a camera's single trigger
  // The board is where the truth says at the trigger (the exposure), rendered on a thread.
  const Eigen::Isometry3d camera_T_board = spec_.camera_T_world * truth_->world_T_board();
  vision::RenderOptions options = spec_.render;
  options.seed = spec_.render.seed + (*frames_)++;
  options.bit_depth = 8;
  pending_ = std::async(std::launch::async, [this, camera_T_board, options] {
    const robotio::RenderBusyScope busy(busy_.get());
    return renderer_->render({{*board_, camera_T_board}}, options);
  });
}

robotio::Frame InProcessCamera::receive(std::chrono::milliseconds timeout) {
  check_open();
  if (!pending_.valid())
    throw robotio::CameraError(robotio::CameraError::Kind::kTimeout, spec_.name,
                               "no frame was triggered");
  if (pending_.wait_for(timeout) != std::future_status::ready)
    throw robotio::CameraError(robotio::CameraError::Kind::kTimeout, spec_.name,
                               fmt::format("no frame within {} ms", timeout.count()));
  robotio::Frame f;
  f.image = pending_.get();
  f.pixel_format = "Mono8";
  f.frame_id = frames_->load();
  f.host_time_ns = robotio::host_time_ns();
  return f;
}

void InProcessCamera::stop() {
  if (pending_.valid()) pending_.wait();
  started_ = false;
}

void InProcessCamera::close() {
  stop();
  open_ = false;
}

// ---- the cell's cameras -----------------------------------------------------------------------

std::string live_camera_address(std::size_t camera) {
  return fmt::format("127.0.0.{}", camera + 1);
}

LiveCameras::LiveCameras(const std::vector<LiveCameraSpec>& specs, const vision::TargetBoard& board,
                         const std::vector<robotio::TruePoseSource*>& truths, bool gige,
                         const std::string& serial_prefix)
    : specs_(specs), board_(&board), prefix_(serial_prefix) {
  // Cameras that cannot be served, said in one note: on a plain machine every camera but the
  // first fails for the same reason (only 127.0.0.1 is on the loopback interface).
  std::vector<std::string> unserved;
  std::string first_reason;
  for (std::size_t i = 0; i < specs_.size(); ++i) {
    truths_.push_back(truths.size() == 1 ? truths.front() : truths.at(i));
    gige_.emplace_back();
    frames_.push_back(std::make_shared<std::atomic<std::uint64_t>>(0));
    if (!gige) continue;
    robotio::SimulatedCameraSpec s;
    s.serial = fmt::format("{}{}", prefix_, i);  // Aravis: at most 15 characters
    s.address = live_camera_address(i);
    s.model = specs_[i].model;
    s.camera_T_world = specs_[i].camera_T_world;
    s.render = specs_[i].render;
    s.busy_clock = busy_;
    s.rays = specs_[i].rays;
    try {
      gige_[i] = std::make_unique<robotio::SimulatedGigECamera>(s, board, *truths_[i]);
      gige_[i]->set_history(1);
    } catch (const std::exception& e) {
      if (unserved.empty()) first_reason = fmt::format("on {}: {}", s.address, e.what());
      unserved.push_back(specs_[i].name);
    }
  }
  if (unserved.size() == 1) {
    notes_.push_back(fmt::format("{}: no fake GigE camera ({}); rendered in-process",
                                 unserved.front(), first_reason));
  } else if (unserved.size() > 1) {
    notes_.push_back(
        fmt::format("{}: no fake GigE cameras ({}; the same for the other {}); rendered in-process",
                    fmt::join(unserved, ", "), first_reason, unserved.size() - 1));
  }
}

std::string LiveCameras::source(std::size_t camera) const {
  if (gige_[camera]) return "aravis:" + gige_[camera]->spec().serial;
  return kInProcess + specs_[camera].name;
}

std::unique_ptr<robotio::CameraSource> LiveCameras::open(std::size_t camera) {
  if (gige_[camera]) {
    try {
      return robotio::open_camera_source(source(camera), specs_[camera].name);
    } catch (const std::exception& e) {
      notes_.push_back(
          fmt::format("{}: served on {} but Aravis cannot open it ({}); rendered "
                      "in-process",
                      specs_[camera].name, live_camera_address(camera), e.what()));
      stop_serving(camera);
    }
  }
  return std::make_unique<InProcessCamera>(specs_[camera], *board_, *truths_[camera], busy_,
                                           frames_[camera]);
}

std::unique_ptr<robotio::CameraSource> LiveCameras::open(const std::string& name) {
  for (std::size_t i = 0; i < specs_.size(); ++i)
    if (specs_[i].name == name) return open(i);
  throw robotio::CameraError(robotio::CameraError::Kind::kNotFound, name,
                             "not a camera of the live cell");
}

void LiveCameras::stop_serving(std::size_t camera) {
  // The in-process renderer goes on from the GigE camera's next frame index.
  const std::deque<robotio::RenderedFrame> last = gige_[camera]->rendered();
  if (!last.empty())
    *frames_[camera] = std::max(frames_[camera]->load(), last.back().frame_index + 1);
  gige_[camera].reset();
}

void LiveCameras::fall_back(std::size_t camera, const std::string& why) {
  if (!gige_[camera]) return;
  stop_serving(camera);
  notes_.push_back(
      fmt::format("{}: {}; rendered in-process from now on", specs_[camera].name, why));
}

}  // namespace robocal::app
