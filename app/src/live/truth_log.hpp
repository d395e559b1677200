#pragma once
// The live demo's record of the truth: after every motion, the simulator's truth channel's board
// pose with the readings the controller reported then, one JSON line each beside the session
// (setup/truth_poses.jsonl), so that a resumed collection keeps what was seen before. A recorded
// pose is matched to it by its readings; validate compares with what it holds.
#include "robocal/robotio/sim_truth.hpp"
#include "session/results_files.hpp"

#include <Eigen/Core>

#include <filesystem>
#include <vector>

namespace robocal::app {

struct TruthLog {
  std::filesystem::path path;
  // Appends the truth seen at `readings`, carried through the true robot's elastic `sag`.
  void append(const Eigen::VectorXd& readings, const robotio::TruePoseReading& r, double sag) const;
  // The truth of each recorded pose of `session`: the last motion that ended at its readings.
  [[nodiscard]] std::vector<TruthPose> match(const std::filesystem::path& session) const;
};

}  // namespace robocal::app
