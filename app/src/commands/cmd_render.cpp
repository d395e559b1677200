#include "cli/cli_common.hpp"
#include "cli/command_registry.hpp"

#include "robocal/core/files.hpp"
#include "robocal/vision/camera_io.hpp"
#include "robocal/vision/pose.hpp"
#include "robocal/vision/render_io.hpp"
#include "robocal/vision/target_io.hpp"

#include <fmt/core.h>
#include <opencv2/imgcodecs.hpp>

#include <chrono>
#include <filesystem>

namespace robocal::app {

namespace {

struct RenderArgs {
  std::string camera, views, out = "render";
  std::vector<std::string> targets;
  std::vector<std::vector<double>> poses;
  double blur = 0, read_noise = 0, shot_gain = 0, black = 20, white = 220, background = 60;
  double vignetting = 0;
  std::vector<double> gradient;
  int bit_depth = 8;
  int seed = -1;
};

int run_render(const RenderArgs& a) {
  vision::CameraModel camera;
  std::vector<vision::TargetBoard> boards;
  std::vector<vision::RenderView> views;
  try {
    camera = vision::load_camera_file(a.camera);
    for (const auto& t : a.targets) boards.push_back(vision::load_target_file(t));
    if (!a.views.empty()) {
      views = vision::load_render_views(a.views, static_cast<int>(boards.size()));
    }
  } catch (const vision::FileFormatError& e) {
    throw InputError(e.what());
  }
  if (a.views.empty()) {
    if (a.poses.size() != boards.size())
      throw UsageError(fmt::format("give one --pose per --target ({} targets, {} poses) or --views",
                                   boards.size(), a.poses.size()));
    vision::RenderView v;
    v.name = "view000";
    for (const auto& p : a.poses) {
      if (p.size() != 6) throw UsageError("--pose needs 6 numbers: rx,ry,rz,tx,ty,tz");
      v.camera_T_board.push_back(vision::pose_from_rvec_tvec(Eigen::Vector3d(p[0], p[1], p[2]),
                                                             Eigen::Vector3d(p[3], p[4], p[5])));
    }
    views.push_back(v);
  }
  if (a.bit_depth != 8 && a.bit_depth != 16) throw UsageError("--bit-depth must be 8 or 16");
  if (!a.gradient.empty() && a.gradient.size() != 2)
    throw UsageError("--gradient needs 2 numbers: gx,gy");
  std::error_code ec;
  std::filesystem::create_directories(a.out, ec);
  if (ec) throw InputError(fmt::format("cannot create output folder {}: {}", a.out, ec.message()));

  vision::RenderOptions opt;
  opt.black_level = a.black;
  opt.white_level = a.white;
  opt.background_level = a.background;
  opt.blur_sigma = a.blur;
  opt.read_noise = a.read_noise;
  opt.shot_noise_gain = a.shot_gain;
  opt.vignetting = a.vignetting;
  if (a.gradient.size() == 2) opt.lighting_gradient = Eigen::Vector2d(a.gradient[0], a.gradient[1]);
  opt.bit_depth = a.bit_depth;

  const auto t0 = std::chrono::steady_clock::now();
  const vision::CameraRays rays = vision::precompute_rays(camera);
  const double t_rays =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  fmt::print("camera {} {}x{}: rays in {:.2f} s\n", vision::kind_name(camera.kind), camera.width,
             camera.height, t_rays);
  for (const auto& view : views) {
    const auto t1 = std::chrono::steady_clock::now();
    std::vector<vision::RenderTarget> targets;
    for (size_t k = 0; k < boards.size(); ++k)
      targets.push_back({boards[k], view.camera_T_board[k]});
    opt.occluders = view.occluders;
    opt.seed = a.seed >= 0 ? static_cast<std::uint64_t>(a.seed) : view.seed;
    const vision::RenderResult r = vision::render(rays, targets, opt);
    const std::filesystem::path png = std::filesystem::path(a.out) / (view.name + ".png");
    const std::filesystem::path json = std::filesystem::path(a.out) / (view.name + ".json");
    if (!cv::imwrite(png.string(), r.image)) throw InputError("cannot write " + png.string());
    core::write_file_atomic(
        json, vision::render_truth_json(png.filename().string(), camera, targets, opt, r.corners));
    int visible = 0;
    for (const auto& c : r.corners) visible += c.visible;
    fmt::print("{}: {} of {} corners visible, {:.2f} s\n", png.string(), visible, r.corners.size(),
               std::chrono::duration<double>(std::chrono::steady_clock::now() - t1).count());
  }
  return kExitOk;
}

}  // namespace

// `robocal render`: synthetic images of targets with exact ground truth (see vision/renderer.hpp).
CommandSpec render_command() {
  return {"render", "Render synthetic camera images of targets with ground-truth corners",
          [](CLI::App& cmd) -> CommandAction {
            auto a = std::make_shared<RenderArgs>();
            cmd.add_option("--camera", a->camera, "Camera file (YAML)")->required();
            cmd.add_option("--target", a->targets, "Target file (YAML); repeat for several")
                ->required();
            cmd.add_option("--views", a->views,
                           "Views file (YAML): poses per image (render_io.hpp)");
            cmd.add_option("--pose", a->poses,
                           "camera_T_board as rx,ry,rz,tx,ty,tz (rotation vector rad, metres); "
                           "one per target, for a single image")
                ->delimiter(',')
                ->expected(1, 100);
            cmd.add_option("--out", a->out, "Output folder for <view>.png and <view>.json")
                ->capture_default_str();
            cmd.add_option("--blur", a->blur, "Gaussian blur sigma (px)");
            cmd.add_option("--read-noise", a->read_noise, "Read noise sigma (DN)");
            cmd.add_option("--shot-gain", a->shot_gain, "Electrons per DN for shot noise (0: off)");
            cmd.add_option("--black", a->black, "Black level (DN)")->capture_default_str();
            cmd.add_option("--white", a->white, "White level (DN)")->capture_default_str();
            cmd.add_option("--background", a->background, "Background level (DN)")
                ->capture_default_str();
            cmd.add_option("--vignetting", a->vignetting, "Brightness loss at the corners (0..1)");
            cmd.add_option("--gradient", a->gradient, "Lighting gradient gx,gy")->delimiter(',');
            cmd.add_option("--bit-depth", a->bit_depth, "8 or 16")->capture_default_str();
            cmd.add_option("--seed", a->seed, "Noise seed for every view (default: per view)");
            return [a]() { return run_render(*a); };
          }};
}

}  // namespace robocal::app
