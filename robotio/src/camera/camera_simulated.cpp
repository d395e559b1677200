#include "robocal/robotio/camera_simulated.hpp"

#include <algorithm>
#include <chrono>
#include <stdexcept>
#include <utility>

namespace robocal::robotio {

SimulatedGigECamera::SimulatedGigECamera(SimulatedCameraSpec spec, vision::TargetBoard board,
                                         TruePoseSource& truth)
    : spec_(std::move(spec)), board_(std::move(board)), truth_(&truth) {
  if (spec_.model.width > 2048 || spec_.model.height > 2048) {
    throw std::invalid_argument(
        "simulated camera " + spec_.serial + ": " + std::to_string(spec_.model.width) + "x" +
        std::to_string(spec_.model.height) + " exceeds the fake GigE sensor (2048 x 2048)");
  }
  renderer_ = std::make_unique<vision::StillSceneRenderer>(
      spec_.rays && spec_.rays->camera == spec_.model
          ? spec_.rays
          : std::make_shared<const vision::CameraRays>(vision::precompute_rays(spec_.model)));
  server_ = std::make_unique<FakeGigECamera>(
      spec_.address, spec_.serial,
      [this](const FakeFrameRequest& request) { return render_frame(request); });
  server_->set_sensor_size(spec_.model.width, spec_.model.height);
}

void RenderBusyClock::begin() {
  const std::lock_guard lock(mutex_);
  if (active_++ == 0) since_ = std::chrono::steady_clock::now();
}

void RenderBusyClock::end() {
  const std::lock_guard lock(mutex_);
  if (--active_ == 0) busy_ += std::chrono::steady_clock::now() - since_;
}

double RenderBusyClock::seconds() const {
  const std::lock_guard lock(mutex_);
  auto busy = busy_;
  if (active_ > 0) busy += std::chrono::steady_clock::now() - since_;
  return std::chrono::duration<double>(busy).count();
}

cv::Mat SimulatedGigECamera::render_frame(const FakeFrameRequest& request) {
  const Region& r = request.region;
  if (r.x + r.width > spec_.model.width || r.y + r.height > spec_.model.height) {
    throw std::runtime_error("region " + std::to_string(r.width) + "x" + std::to_string(r.height) +
                             "+" + std::to_string(r.x) + "+" + std::to_string(r.y) +
                             " outside the simulated " + std::to_string(spec_.model.width) + "x" +
                             std::to_string(spec_.model.height) + " image");
  }
  const RenderBusyScope busy(spec_.busy_clock.get());
  const auto start = std::chrono::steady_clock::now();
  const Eigen::Isometry3d world_T_board = truth_->world_T_board();
  vision::RenderOptions options = spec_.render;
  options.bit_depth = request.pixel_format == "Mono16" ? 16 : 8;
  options.seed = spec_.render.seed + request.frame_index;
  if (request.exposure_us > 0.0 && spec_.reference_exposure_us > 0.0) {
    const double scale = request.exposure_us / spec_.reference_exposure_us;
    options.black_level *= scale;
    options.white_level *= scale;
    options.background_level *= scale;
  }
  const vision::RenderTarget target{board_, spec_.camera_T_world * world_T_board};
  const cv::Mat full = renderer_->render({target}, options);
  cv::Mat image = full(cv::Rect(r.x, r.y, r.width, r.height)).clone();
  const auto end = std::chrono::steady_clock::now();
  {
    const std::lock_guard lock(history_mutex_);
    history_.push_back({request.frame_index, world_T_board, image, start, end});
    while (history_.size() > keep_) {
      history_.pop_front();
    }
  }
  return image;
}

std::deque<RenderedFrame> SimulatedGigECamera::rendered() const {
  const std::lock_guard lock(history_mutex_);
  return history_;
}

void SimulatedGigECamera::set_history(std::size_t keep) {
  const std::lock_guard lock(history_mutex_);
  keep_ = std::max<std::size_t>(keep, 1);
}

}  // namespace robocal::robotio
