#include "wizard/live_views.hpp"

#include "live/sim_camera.hpp"

#include "robocal/robotio/camera_checks.hpp"
#include "robocal/robotio/camera_open.hpp"
#include "robocal/vision/image_detection.hpp"
#include "robocal/vision/target_detection.hpp"
#include "session/session.hpp"

#include <fmt/core.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <map>
#include <sstream>

namespace robocal::app::wizard {

namespace fs = std::filesystem;

namespace {

// A calibration needs this many views before its checks say anything useful; the operator is
// told to aim for kSuggestedViews (near and far, tilted, over the whole image).
constexpr std::size_t kFirstCheck = 4;
constexpr std::size_t kSuggestedViews = 20;

// The views already in `folder` (a resumed wizard), by file, and the next free view number.
std::vector<fs::path> kept_views(const fs::path& folder, int* next_number) {
  std::vector<fs::path> files;
  *next_number = 0;
  if (!fs::is_directory(folder)) return files;
  for (const auto& e : fs::directory_iterator(folder)) {
    // view_NNN.png: the number, and nothing after ".png".
    const std::string file = e.path().filename().string();
    int n = 0;
    int end = 0;
    if (std::sscanf(file.c_str(), "view_%d.png%n", &n, &end) != 1 ||
        end != static_cast<int>(file.size()) || n < 0)
      continue;
    files.push_back(e.path());
    *next_number = std::max(*next_number, n + 1);
  }
  std::sort(files.begin(), files.end());
  return files;
}

// What the views so far give, and what to add: the calibration's own refusal, warnings and
// advice (its checks of tilt, coverage and corner count), with the coverage map.
void show_guidance(const WizardContext& ctx, const std::vector<vision::CalibrationView>& views,
                   int width, int height) {
  if (views.size() < kFirstCheck) {
    fmt::print(ctx.out, "  {} more view(s) before the first check of coverage and tilt\n",
               kFirstCheck - views.size());
    return;
  }
  vision::IntrinsicCalibrationOptions options;
  options.width = width;
  options.height = height;
  const vision::IntrinsicCalibrationResult r = vision::calibrate_intrinsics(views, options);
  print_coverage(ctx.out, r.coverage);
  if (r.status != vision::CalibrationStatus::kOk) {
    fmt::print(ctx.out, "  not enough yet: {}\n", r.reason);
  } else {
    fmt::print(ctx.out, "  so far: focal length {:.1f} ± {:.2f} px, RMS {:.3f} px\n",
               r.camera.params[0], r.param_stddev.empty() ? 0.0 : r.param_stddev[0], r.rms_px);
  }
  for (const auto& w : r.warnings) fmt::print(ctx.out, "  warning: {}\n", w);
  for (const auto& a : r.advice) fmt::print(ctx.out, "  advice: {}\n", a);
  if (r.status == vision::CalibrationStatus::kOk && r.warnings.empty()) {
    fmt::print(ctx.out, "  {}\n",
               views.size() >= kSuggestedViews
                   ? "enough views: type 'done' to calibrate"
                   : fmt::format("good so far; about {} more views, other distances and tilts",
                                 kSuggestedViews - views.size()));
  }
}

}  // namespace

std::string camera_source(const WizardState& s, const std::string& camera) {
  std::istringstream in(s.get("cameras.list"));
  std::string item;
  while (in >> item)
    if (item.substr(0, item.find('=')) == camera) return item.substr(item.find('=') + 1);
  return "";
}

std::pair<int, int> camera_frame_size(const WizardState& s) {
  int width = 0;
  int height = 0;
  if (std::sscanf(s.get("cameras.size", "keep").c_str(), "%dx%d", &width, &height) != 2)
    return {0, 0};
  return {width, height};
}

namespace {

// Two views whose shared corners lie this close (median, px) show the board in the same place:
// a second copy adds nothing to the calibration (and counts as a view where none was added).
constexpr double kSameViewPx = 3.0;

// The kept view that `view` repeats (its name), if any.
std::optional<std::string> same_view_as(const vision::CalibrationView& view,
                                        const std::vector<vision::CalibrationView>& kept) {
  for (const auto& k : kept) {
    std::map<int, Eigen::Vector2d> at;
    for (std::size_t i = 0; i < k.corner_ids.size(); ++i) at[k.corner_ids[i]] = k.pixels[i];
    std::vector<double> moved;
    for (std::size_t i = 0; i < view.corner_ids.size(); ++i) {
      const auto it = at.find(view.corner_ids[i]);
      if (it != at.end()) moved.push_back((it->second - view.pixels[i]).norm());
    }
    if (moved.size() * 2 < view.corner_ids.size()) continue;  // mostly other corners
    std::nth_element(moved.begin(), moved.begin() + static_cast<long>(moved.size() / 2),
                     moved.end());
    if (moved[moved.size() / 2] < kSameViewPx) return k.name;
  }
  return std::nullopt;
}

}  // namespace

std::unique_ptr<robotio::CameraSource> open_camera_at(const std::string& source,
                                                      const std::string& camera, int width,
                                                      int height) {
  auto cam = open_camera(source, camera);
  const robotio::CameraInfo info = cam->info();
  const robotio::Region wanted = width > 0
                                     ? robotio::Region{0, 0, width, height}
                                     : robotio::Region{0, 0, info.sensor_width, info.sensor_height};
  if (cam->region() != wanted) cam->set_region(wanted);
  return cam;
}

void print_coverage(std::FILE* out, const vision::CoverageMap& map) {
  if (map.cols == 0) return;
  fmt::print(out, "  coverage of the image by board corners (. none, : few, # many):\n");
  for (int r = 0; r < map.rows; ++r) {
    std::string line = "    ";
    for (int c = 0; c < map.cols; ++c) {
      const int n = map.corner_count[static_cast<std::size_t>(r * map.cols + c)];
      line += n == 0 ? '.' : n < 10 ? ':' : '#';
    }
    fmt::print(out, "{}\n", line);
  }
}

std::optional<fs::path> take_live_views(WizardContext& ctx, const std::string& camera,
                                        const std::string& source, const vision::TargetBoard& board,
                                        int width, int height, std::string& why) {
  if (!ctx.ask.interactive()) {
    why = camera +
          ": live calibration views need an operator at a terminal (each view is taken when "
          "the board is held still); without one, give a folder of board images";
    return std::nullopt;
  }
  const fs::path folder = ctx.state.folder / "calibration" / "intrinsics" / camera;
  fs::create_directories(folder);
  auto cam = open_camera_at(source, camera, width, height);
  cam->start(robotio::TriggerMode::kSoftware);
  vision::AprilTagDetector detector(vision::detector_options_for(board));

  // Views kept before (the wizard was stopped and resumed) count towards the guidance.
  int number = 0;
  std::vector<vision::CalibrationView> views;
  for (const fs::path& f : kept_views(folder, &number)) {
    const vision::LoadedImage image = vision::load_gray_image(f);
    if (!image.error.empty()) continue;
    if (width <= 0) {
      width = image.gray.cols;
      height = image.gray.rows;
    }
    const auto d = vision::detect_target(image.gray, board, detector);
    if (d.status != vision::DetectionStatus::kRejected)
      views.push_back(vision::to_calibration_view(d, f.stem().string()));
  }
  fmt::print(ctx.out,
             "{}: hold the calibration board in front of the camera, still, and press Enter for "
             "each view. Aim for about {} views: near and far, tilted 20-40 degrees in every "
             "direction, the board reaching every part of the image. Views are kept in {}.\n",
             camera, kSuggestedViews, folder.string());
  if (!views.empty()) fmt::print(ctx.out, "  {} view(s) kept before\n", views.size());

  for (;;) {
    const std::string answer = ctx.ask.ask(
        "intrinsics." + camera + ".view",
        fmt::format("{} view {}: Enter to take it ('done' to calibrate, 'quit' to stop)", camera,
                    views.size() + 1));
    if (answer == "quit") {
      why = fmt::format("{}: {} calibration view(s) kept in {}; resume to take more", camera,
                        views.size(), folder.string());
      cam->stop();
      return std::nullopt;
    }
    if (answer == "done") {
      if (views.size() < kFirstCheck) {
        fmt::print(ctx.out, "  {} view(s) so far: at least {} are needed, about {} advised\n",
                   views.size(), kFirstCheck, kSuggestedViews);
        continue;
      }
      cam->stop();
      return folder;
    }
    if (!answer.empty()) {
      fmt::print(ctx.out, "  '{}': press Enter for a view, or type done or quit\n", answer);
      continue;
    }
    const robotio::Frame frame = cam->grab(std::chrono::milliseconds(5000));
    if (width <= 0) {
      width = frame.image.cols;
      height = frame.image.rows;
    }
    // The frame as measure will read its file: a frame it could not read is not kept.
    const vision::LoadedImage gray = vision::gray_image(frame.image, camera);
    if (!gray.error.empty()) {
      fmt::print(ctx.out, "  not kept: {} (set the camera to 8-bit, e.g. Mono8)\n", gray.error);
      continue;
    }
    const robotio::LiveCheckReport checks = robotio::check_live_frame(frame.image, board, detector);
    const vision::TargetDetection d = vision::detect_target(gray.gray, board, detector);
    if (d.status == vision::DetectionStatus::kRejected) {
      fmt::print(ctx.out, "  no board in this view ({}): not kept. Hold the whole board in view.\n",
                 d.reason);
      continue;
    }
    for (const auto& k : checks.checks)
      if (!k.ok && k.name != "target" && k.name != "corners")
        fmt::print(ctx.out, "  {}: {}{}\n", k.name, k.summary,
                   k.advice.empty() ? "" : " - " + k.advice);
    vision::CalibrationView view = vision::to_calibration_view(d, "");
    if (const auto same = same_view_as(view, views)) {
      fmt::print(ctx.out,
                 "  not kept: the board has not moved since {} (its corners within {:.0f} px); "
                 "move or tilt it before the next view\n",
                 *same, kSameViewPx);
      continue;
    }
    const std::string name = fmt::format("view_{:03d}", number++);
    write_image_atomic(folder / (name + ".png"), frame.image);
    view.name = name;
    views.push_back(std::move(view));
    fmt::print(ctx.out, "  view {} kept: {} corners ({})\n", views.size(), d.corner_ids.size(),
               (folder / (name + ".png")).string());
    show_guidance(ctx, views, width, height);
  }
}

std::optional<fs::path> take_live_rig_views(
    WizardContext& ctx, const std::vector<std::pair<std::string, std::string>>& cameras,
    const vision::TargetBoard& board, int width, int height, const fs::path& into,
    std::string& why) {
  constexpr int kSuggestedRigViews = 10;
  if (!ctx.ask.interactive()) {
    why =
        "live rig views need an operator at a terminal; without one, give a folder of "
        "calibration views";
    return std::nullopt;
  }
  std::vector<std::unique_ptr<robotio::CameraSource>> sources;
  for (const auto& [name, source] : cameras) {
    sources.push_back(open_camera_at(source, name, width, height));
    sources.back()->start(robotio::TriggerMode::kSoftware);
  }
  const auto stop_all = [&] {
    for (auto& s : sources) s->stop();
  };
  vision::AprilTagDetector detector(vision::detector_options_for(board));
  int kept = 0;
  int number = 0;
  if (fs::is_directory(into))
    for (const auto& e : fs::directory_iterator(into)) {
      int n = 0;
      if (std::sscanf(e.path().filename().string().c_str(), "view_%d", &n) == 1) {
        ++kept;
        number = std::max(number, n + 1);
      }
    }
  fmt::print(ctx.out,
             "Rig views: hold the calibration board where two or more cameras see it at once, "
             "still, and press Enter for each view; about {} views at different places and "
             "tilts. Views are kept in {}.\n",
             kSuggestedRigViews, into.string());
  if (kept > 0) fmt::print(ctx.out, "  {} view(s) kept before\n", kept);
  for (;;) {
    const std::string answer = ctx.ask.ask(
        "identify.rig_view",
        fmt::format("rig view {}: Enter to take it ('done' to go on, 'quit' to stop)", kept + 1));
    if (answer == "quit") {
      stop_all();
      why = fmt::format("{} rig view(s) kept in {}; resume to take more", kept, into.string());
      return std::nullopt;
    }
    if (answer == "done") {
      if (kept < 3) {
        fmt::print(ctx.out, "  {} rig view(s) so far: at least 3 are needed, about {} advised\n",
                   kept, kSuggestedRigViews);
        continue;
      }
      stop_all();
      return into;
    }
    if (!answer.empty()) {
      fmt::print(ctx.out, "  '{}': press Enter for a view, or type done or quit\n", answer);
      continue;
    }
    for (auto& s : sources) s->trigger();
    std::vector<cv::Mat> images;
    std::string seen_by;
    int seeing = 0;
    for (std::size_t c = 0; c < sources.size(); ++c) {
      images.push_back(sources[c]->receive(std::chrono::milliseconds(5000)).image);
      // As measure will read the file; a frame it could not read does not count as seeing.
      const vision::LoadedImage gray = vision::gray_image(images.back(), cameras[c].first);
      if (!gray.error.empty()) {
        fmt::print(ctx.out, "  {} (set the camera to 8-bit, e.g. Mono8)\n", gray.error);
        continue;
      }
      const auto d = vision::detect_target(gray.gray, board, detector);
      if (d.status != vision::DetectionStatus::kRejected && d.corner_ids.size() >= 8) {
        ++seeing;
        seen_by += (seen_by.empty() ? "" : ", ") + cameras[c].first;
      }
    }
    if (seeing < 2) {
      fmt::print(ctx.out, "  the board is seen by {}: not kept (two or more cameras must see it)\n",
                 seeing == 0 ? std::string("no camera") : seen_by + " only");
      continue;
    }
    const fs::path view = into / fmt::format("view_{:03d}", number++);
    for (std::size_t c = 0; c < sources.size(); ++c)
      write_image_atomic(view / (cameras[c].first + ".png"), images[c]);
    ++kept;
    fmt::print(ctx.out, "  rig view {} kept: the board seen by {}{}\n", kept, seen_by,
               kept >= kSuggestedRigViews ? "; enough views: type 'done'" : "");
  }
}

}  // namespace robocal::app::wizard
