#include "stages/measured_region.hpp"

#include <algorithm>
#include <cmath>

namespace robocal::app {

nlohmann::json split_errors_by_region(const std::vector<bool>& inside,
                                      const std::vector<double>& outside_m,
                                      const std::vector<Eigen::Vector3d>& truth,
                                      const std::vector<NamedPoints>& predictions) {
  nlohmann::json out = nlohmann::json::object();
  for (const bool side : {true, false}) {
    std::vector<std::size_t> members;
    for (std::size_t k = 0; k < truth.size() && k < inside.size(); ++k)
      if (inside[k] == side) members.push_back(k);
    nlohmann::json part{{"held_out_poses", members.size()}};
    for (const auto& prediction : predictions) {
      double sum_sq = 0.0;
      double max = 0.0;
      for (std::size_t k : members) {
        const double e = ((*prediction.points)[k] - truth[k]).norm();
        sum_sq += e * e;
        max = std::max(max, e);
      }
      const double rms =
          members.empty() ? 0.0 : std::sqrt(sum_sq / static_cast<double>(members.size()));
      part[prediction.name] = {{"rms_m", rms}, {"max_m", max}, {"poses", members.size()}};
    }
    if (!side) {
      std::vector<double> distances;
      for (std::size_t k : members)
        if (k < outside_m.size()) distances.push_back(outside_m[k]);
      std::sort(distances.begin(), distances.end());
      part["distance_max_m"] = distances.empty() ? 0.0 : distances.back();
      part["distance_median_m"] = distances.empty() ? 0.0 : distances[distances.size() / 2];
    }
    out[side ? "inside" : "outside"] = part;
  }
  return out;
}

}  // namespace robocal::app
