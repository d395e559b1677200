#include "live/truth_log.hpp"

#include "session/session.hpp"
#include "simcell/simulated_cell.hpp"

#include <nlohmann/json.hpp>

#include <Eigen/Geometry>

#include <fstream>
#include <string>
#include <utility>

namespace robocal::app {

namespace fs = std::filesystem;

void TruthLog::append(const Eigen::VectorXd& readings, const robotio::TruePoseReading& r,
                      double sag) const {
  const Eigen::Isometry3d p = elastic_deflection(r.base_T_task, sag);
  const Eigen::Quaterniond q(p.linear());
  const std::vector<double> read(readings.data(), readings.data() + readings.size());
  const nlohmann::json j = {{"readings", read},
                            {"t", {p.translation().x(), p.translation().y(), p.translation().z()}},
                            {"q", {q.w(), q.x(), q.y(), q.z()}},
                            {"actuators_true", r.actuators_true}};
  std::ofstream(path, std::ios::app) << j.dump() << "\n";
}

std::vector<TruthPose> TruthLog::match(const fs::path& session) const {
  std::vector<std::pair<Eigen::VectorXd, TruthPose>> seen;
  std::ifstream in(path);
  std::string line;
  while (std::getline(in, line)) {
    const auto j = nlohmann::json::parse(line, nullptr, false);
    if (j.is_discarded()) continue;
    const auto read = j.at("readings").get<std::vector<double>>();
    const auto a = j.at("actuators_true").get<std::vector<double>>();
    TruthPose t;
    t.true_actuators =
        Eigen::Map<const Eigen::VectorXd>(a.data(), static_cast<Eigen::Index>(a.size()));
    t.world_T_board.linear() =
        Eigen::Quaterniond(j["q"][0], j["q"][1], j["q"][2], j["q"][3]).toRotationMatrix();
    t.world_T_board.translation() = Eigen::Vector3d(j["t"][0], j["t"][1], j["t"][2]);
    seen.emplace_back(
        Eigen::Map<const Eigen::VectorXd>(read.data(), static_cast<Eigen::Index>(read.size())), t);
  }
  std::vector<TruthPose> out;
  for (const PoseRecord& p : load_pose_records(load_session(session))) {
    if (!p.problem.empty()) continue;
    for (auto it = seen.rbegin(); it != seen.rend(); ++it)
      if (it->first.size() == p.actuators.size() &&
          (it->first - p.actuators).norm() <= 1e-12 * (1.0 + p.actuators.norm())) {
        out.push_back(it->second);
        out.back().pose = p.name;
        break;
      }
  }
  return out;
}

}  // namespace robocal::app
