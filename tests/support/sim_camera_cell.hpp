#pragma once
// A simulated camera cell around `robocal sim-controller` (a separate process holding a perturbed
// linear delta, Marlin over TCP): the guarded G-code link robocal drives, and the true-pose
// channel the simulated cameras (camera_cell.hpp's CameraRig) render from. Used by the capture
// integration test and bench_capture --controller sim.
#include "camera_cell.hpp"
#include "robocal/robotio/capture_link.hpp"
#include "robocal/robotio/gcode_link.hpp"
#include "robocal/robotio/sim_process.hpp"
#include "robocal/robotio/sim_truth.hpp"
#include "robotio_sim.hpp"

#include <filesystem>
#include <memory>
#include <random>
#include <stdexcept>
#include <string>
#include <vector>

namespace robocal::robotio::testing {

inline constexpr MoveSpeed kSimCellSpeed{0.2, 4.0};

// The delta's workspace centre; the board sits 0.45 m in front of camera 0 (the world frame)
// when the effector is there, and moves with the effector.
inline const Eigen::Vector3d kSimCellCentre(0.0, 0.0, 0.09);

inline BoardMounting sim_cell_mounting() {
  const Eigen::Vector3d board_centre(0.08, 0.06, 0.0);
  const Eigen::Isometry3d world_T_board_at_centre = vision::camera_T_board_look_at(
      board_centre + Eigen::Vector3d(0.0, 0.0, -0.45), board_centre, Eigen::Vector3d(0, -1, 0));
  BoardMounting m;
  m.world_T_base = world_T_board_at_centre * Eigen::Translation3d(-kSimCellCentre);
  return m;
}

// Effector positions within 2.5 cm of the centre (the board stays in both views), drawn from a
// fixed seed, as nominal IK readings.
inline std::vector<Eigen::VectorXd> sim_cell_targets(const calib::Mechanism& model, int count) {
  std::mt19937 rng(17);
  std::uniform_real_distribution<double> offset(-0.025, 0.025);
  std::vector<Eigen::VectorXd> out;
  for (int i = 0; i < count; ++i) {
    calib::TaskTarget t;
    // One draw a statement, z first (robocal/core/random_draws.hpp says why).
    const double z = 0.8 * offset(rng);
    const double y = offset(rng);
    const double x = offset(rng);
    t.pose.translation() = kSimCellCentre + Eigen::Vector3d(x, y, z);
    const calib::IkResult ik = calib::solve_ik(model, model.nominal_parameters(), t);
    if (!ik.ok()) {
      throw std::runtime_error("sim cell: target " + std::to_string(i) + " has no IK solution");
    }
    out.push_back(ik.actuator_readings);
  }
  return out;
}

// The simulator process (truth perturbed with seed 5), the guard (armed), the link (connected
// and homed) and the true-pose channel.
struct SimCell {
  calib::Mechanism model = test::linear_delta();
  std::string log;
  std::unique_ptr<SimControllerProcess> sim;
  std::unique_ptr<SafetyGuard> guard;
  std::unique_ptr<GcodeLink> link;
  std::unique_ptr<SimControllerTruth> truth;

  explicit SimCell(const std::filesystem::path& dir) : log((dir / "sim.jsonl").string()) {
    sim = std::make_unique<SimControllerProcess>(ROBOCAL_BINARY,
                                                 test::sim_args(log, {"--seed", "5"}));
    guard = std::make_unique<SafetyGuard>(model, model.nominal_parameters(), test::delta_limits());
    guard->arm("test: simulated cell, nothing can be hurt");
    link = std::make_unique<GcodeLink>(*guard, test::link_options(model, sim->tcp()));
    link->connect();
    link->home();
    truth = std::make_unique<SimControllerTruth>(sim->pose(), sim_cell_mounting());
  }
};

}  // namespace robocal::robotio::testing
