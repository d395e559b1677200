#include "live/simulated_setup.hpp"

#include "cli/cli_common.hpp"
#include "session/session.hpp"
#include "stages/stage_log.hpp"

#include <fmt/core.h>
#include <unistd.h>

#include <array>
#include <random>

namespace robocal::app {

namespace fs = std::filesystem;

std::string robocal_binary() {
  std::array<char, 4096> buf{};
  const ssize_t n = ::readlink("/proc/self/exe", buf.data(), buf.size() - 1);
  if (n <= 0) throw InputError("cannot find the robocal program (/proc/self/exe)");
  return {buf.data(), static_cast<std::size_t>(n)};
}

LiveCell make_live_cell(const LiveDemoOptions& o, const std::string& robot_file) {
  std::mt19937 rng(o.seed);
  const CellOptions co = demo_cell_options(o.seed, o.quick, o.idealised_truth);
  LiveCell c{make_simulated_cell(robot_file, co, rng), {}, {}};
  const int views = o.intrinsic_views > 0       ? o.intrinsic_views
                    : c.cell.cameras.size() > 2 ? kArrayIntrinsicViews
                                                : SimulateOptions{}.intrinsic_views;
  for (std::size_t k = 0; k < c.cell.cameras.size(); ++k)
    c.intrinsic_views.push_back(intrinsic_view_poses(c.cell, static_cast<int>(k), views, rng));
  c.rig_views = rig_view_poses(c.cell, o.rig_views, rng);
  return c;
}

std::vector<LiveCameraSpec> camera_specs(const SimulatedCell& cell, unsigned seed, int threads) {
  std::vector<LiveCameraSpec> specs;
  for (std::size_t c = 0; c < cell.cameras.size(); ++c) {
    LiveCameraSpec s{fmt::format("cam{}", c), cell.cameras[c].model, cell.cameras[c].camera_T_world,
                     cell.options.render, cell.cameras[c].rays};
    s.render.seed = 1000003ULL * (seed + 1) + 7919ULL * c;
    // Each camera renders its frame on a thread of its own; a frame split in bands of rows as
    // well keeps both cores busy when one camera sees the board close up and the others little
    // (a pose waits for its slowest camera's frame).
    s.render.threads = threads;
    specs.push_back(s);
  }
  return specs;
}

void take_calibration_views(const LiveCell& lc, const std::vector<LiveCameraSpec>& specs, bool gige,
                            const fs::path& dir, const PipelineLog& log, nlohmann::json& report) {
  // Each camera shown its own board for its intrinsic views (both at once), then one board shown
  // to both for the rig views.
  std::vector<std::unique_ptr<ScriptedBoard>> boards;
  std::vector<robotio::TruePoseSource*> truths;
  for (std::size_t c = 0; c < specs.size(); ++c) {
    boards.push_back(std::make_unique<ScriptedBoard>());
    truths.push_back(boards.back().get());
  }
  LiveCameras cams(specs, lc.cell.calibration_board, truths, gige, fmt::format("C{}-", ::getpid()));
  for (const auto& n : cams.notes()) say(log, "  {}\n", n);
  std::vector<std::unique_ptr<robotio::CameraSource>> src;
  for (std::size_t c = 0; c < specs.size(); ++c) {
    src.push_back(cams.open(c));
    const robotio::Region full{0, 0, specs[c].model.width, specs[c].model.height};
    if (src.back()->region() != full) src.back()->set_region(full);
    src.back()->start(robotio::TriggerMode::kSoftware);
  }
  // A served camera that sends nothing for 5 s is lost; an in-process one is only rendering,
  // which takes longer on a busy machine (six 1600x1200 cameras on two loaded cores).
  const auto timeout = [&](std::size_t c) {
    return std::chrono::milliseconds(cams.served(c) ? 5000 : 120000);
  };
  std::size_t total = lc.rig_views.size();
  std::size_t rounds = 0;
  for (const auto& v : lc.intrinsic_views) {
    total += v.size();
    rounds = std::max(rounds, v.size());
  }
  StageProgress bar(log.out, "calibration views", total);
  // A frame of camera c: a camera lost on a busy machine (a render beyond the GigE heartbeat)
  // is rendered in-process from then on, and the frame taken again.
  const auto take = [&](std::size_t c, bool triggered) {
    for (int attempt = 0;; ++attempt) {
      try {
        if (!triggered) src[c]->trigger();
        return src[c]->receive(timeout(c)).image;
      } catch (const robotio::CameraError& e) {
        if (attempt > 0 || !cams.served(c)) throw;
        cams.fall_back(c, e.what());
        say(log, "\n  {}\n", cams.notes().back());
        src[c]->close();
        src[c] = cams.open(c);
        src[c]->start(robotio::TriggerMode::kSoftware);
        triggered = false;
      }
    }
  };
  // Triggers every camera first (they render at once); a camera lost at its trigger is taken
  // again by `take`, which falls back to in-process rendering.
  const auto trigger = [&](std::size_t c) {
    try {
      src[c]->trigger();
      return true;
    } catch (const robotio::CameraError&) {
      return false;
    }
  };
  // The frames of one round are written while the cameras render the next one.
  std::vector<std::pair<fs::path, cv::Mat>> unwritten;
  const auto write_unwritten = [&] {
    for (const auto& [path, image] : unwritten) write_image_atomic(path, image);
    unwritten.clear();
  };
  for (std::size_t v = 0; v < rounds; ++v) {
    std::vector<std::pair<std::size_t, bool>> shown;
    for (std::size_t c = 0; c < specs.size(); ++c)
      if (v < lc.intrinsic_views[c].size()) {
        boards[c]->set(specs[c].camera_T_world.inverse() * lc.intrinsic_views[c][v]);
        shown.emplace_back(c, trigger(c));
      }
    write_unwritten();
    for (const auto& [c, triggered] : shown) {
      unwritten.emplace_back(dir / "intrinsics" / specs[c].name / fmt::format("view_{:03d}.png", v),
                             take(c, triggered));
      bar.advance();
    }
  }
  for (std::size_t v = 0; v < lc.rig_views.size(); ++v) {
    for (auto& b : boards) b->set(lc.rig_views[v]);
    std::vector<bool> triggered(specs.size());
    for (std::size_t c = 0; c < specs.size(); ++c) triggered[c] = trigger(c);
    write_unwritten();
    for (std::size_t c = 0; c < specs.size(); ++c)
      unwritten.emplace_back(dir / "rig" / fmt::format("view_{:03d}", v) / (specs[c].name + ".png"),
                             take(c, triggered[c]));
    bar.advance();
  }
  write_unwritten();
  bar.finish(fmt::format("{} views", total));
  for (auto& s : src) s->close();
  report["calibration_views"] = total;
}

// The simulated robot's speed. 2 rad/s moves the library Delta's 0.6 m upper arms at 1.2 m/s;
// carriages on rails (linear delta, Gantry-Tau) move at 0.5 m/s, the travel speed of a printer
// firmware's delta configuration and well below the Delta's. (`robocal collect` on a real robot
// starts at a cautious 0.02 unless the operator gives --speed.)
double default_speed(const calib::Mechanism& model) {
  for (int a : model.actuated)
    if (model.bodies[static_cast<std::size_t>(a)].joint == calib::JointType::kPrismatic)
      return 0.5;  // m/s
  return 2.0;      // rad/s
}

}  // namespace robocal::app
