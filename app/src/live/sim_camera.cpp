#include "live/sim_camera.hpp"

#include "cli/cli_common.hpp"
#include "live/live_cameras.hpp"
#include "live/simulated_setup.hpp"
#include "robocal/core/files.hpp"
#include "robocal/robotio/camera_open.hpp"
#include "robocal/robotio/sim_truth.hpp"

#include <fmt/core.h>
#include <yaml-cpp/yaml.h>

#include <map>
#include <mutex>
#include <random>

namespace robocal::app {

namespace fs = std::filesystem;

namespace {

constexpr const char* kFormat = "robocal-sim-camera-1";
constexpr const char* kPrefix = "sim:";

// The simulated cell a sim: camera belongs to, rebuilt from its robot and seed (the cell is
// deterministic in them) once per process: opening the same camera again (the wizard's check,
// its live views, the collection) reuses it.
std::shared_ptr<const SimulatedCell> cell_of(const SimCameraFile& f) {
  static std::mutex mutex;
  static std::map<std::string, std::shared_ptr<const SimulatedCell>> cells;
  const std::string key = fmt::format("{}|{}|{}|{}", f.robot, f.seed, f.quick, f.idealised_truth);
  const std::lock_guard lock(mutex);
  auto& cell = cells[key];
  if (!cell) {
    std::mt19937 rng(f.seed);
    cell = std::make_shared<const SimulatedCell>(
        make_simulated_cell(f.robot, demo_cell_options(f.seed, f.quick, f.idealised_truth), rng));
  }
  return cell;
}

// What a sim: camera renders from, kept alive with it.
struct SimCameraParts {
  std::shared_ptr<const SimulatedCell> cell;
  std::unique_ptr<robotio::SimControllerTruth> truth;
  std::unique_ptr<SaggingBoard> seen;
};

}  // namespace

std::string sim_camera_yaml(const SimCameraFile& f) {
  YAML::Emitter e;
  e << YAML::BeginMap;
  e << YAML::Key << "format" << YAML::Value << kFormat;
  e << YAML::Key << "robot" << YAML::Value << f.robot;
  e << YAML::Key << "seed" << YAML::Value << f.seed;
  e << YAML::Key << "quick" << YAML::Value << f.quick;
  e << YAML::Key << "idealised_truth" << YAML::Value << f.idealised_truth;
  e << YAML::Key << "camera" << YAML::Value << f.camera;
  e << YAML::Key << "truth" << YAML::Value << f.truth;
  e << YAML::EndMap;
  return "# a simulated camera of robocal sim-cell: open it as sim:THIS_FILE\n" +
         std::string(e.c_str()) + "\n";
}

SimCameraFile load_sim_camera_file(const fs::path& path) {
  SimCameraFile f;
  try {
    const YAML::Node root = YAML::LoadFile(path.string());
    if (root["format"].as<std::string>("") != kFormat)
      throw InputError(
          fmt::format("{}: not a simulated camera file (format: {})", path.string(), kFormat));
    for (const auto& kv : root) {
      const std::string k = kv.first.as<std::string>();
      if (k != "format" && k != "robot" && k != "seed" && k != "quick" && k != "idealised_truth" &&
          k != "camera" && k != "truth")
        throw InputError(fmt::format(
            "{}: unknown key '{}' (allowed: format, robot, seed, quick, idealised_truth, camera, "
            "truth)",
            path.string(), k));
    }
    f.robot = root["robot"].as<std::string>();
    f.seed = root["seed"].as<unsigned>();
    f.quick = root["quick"].as<bool>(false);
    f.idealised_truth = root["idealised_truth"].as<bool>(false);
    f.camera = root["camera"].as<std::string>();
    f.truth = root["truth"].as<std::string>();
  } catch (const YAML::Exception& e) {
    throw InputError(fmt::format("{}: {}", path.string(), e.what()));
  }
  return f;
}

std::unique_ptr<robotio::CameraSource> open_camera(const std::string& text,
                                                   const std::string& name) {
  if (text.rfind(kPrefix, 0) != 0) return robotio::open_camera_source(text, name);
  const fs::path file = text.substr(std::string(kPrefix).size());
  if (!fs::is_regular_file(file))
    throw robotio::CameraError(robotio::CameraError::Kind::kNotFound, name,
                               fmt::format("{}: no simulated camera file there (robocal sim-cell "
                                           "writes it and prints its path)",
                                           file.string()));
  const SimCameraFile f = load_sim_camera_file(file);
  auto parts = std::make_shared<SimCameraParts>();
  parts->cell = cell_of(f);
  const auto specs = camera_specs(*parts->cell, f.seed, 2);
  const LiveCameraSpec* spec = nullptr;
  for (const auto& s : specs)
    if (s.name == f.camera) spec = &s;
  if (spec == nullptr)
    throw InputError(fmt::format("{}: the simulated cell has no camera '{}' (it has {})",
                                 file.string(), f.camera, specs.size()));
  try {
    parts->truth = std::make_unique<robotio::SimControllerTruth>(f.truth, robotio::BoardMounting{});
  } catch (const std::exception& e) {
    throw robotio::CameraError(robotio::CameraError::Kind::kNotFound, name,
                               fmt::format("the simulated cell's true-pose channel {} does not "
                                           "answer ({}): is `robocal sim-cell` still running?",
                                           f.truth, e.what()));
  }
  parts->seen = std::make_unique<SaggingBoard>(*parts->truth, parts->cell->elastic_sag);
  auto cam = std::make_unique<InProcessCamera>(*spec, parts->cell->ee_board, *parts->seen,
                                               std::make_shared<robotio::RenderBusyClock>());
  cam->keep_alive(parts);
  return cam;
}

}  // namespace robocal::app
