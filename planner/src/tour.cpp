// Motion ordering: nearest neighbour + 2-opt over free segments (see tour.hpp).
#include "robocal/planner/tour.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <utility>

namespace robocal::planner {
namespace {

// Lazily checked, memoised segment feasibility (nodes: poses, plus the start as the last node).
class SegmentCache {
 public:
  SegmentCache(const std::vector<Eigen::VectorXd>& nodes, const SegmentTest& test)
      : nodes_(nodes), test_(test) {}
  bool free(std::size_t a, std::size_t b, std::string* why = nullptr) {
    const auto key = std::minmax(a, b);
    const auto it = cache_.find(key);
    if (it != cache_.end()) {
      if (why != nullptr) *why = it->second.second;
      return it->second.first;
    }
    std::string reason;
    const bool ok = test_(nodes_[a], nodes_[b], &reason);
    ++checked_;
    cache_[key] = {ok, reason};
    if (why != nullptr) *why = reason;
    return ok;
  }
  std::size_t checked() const { return checked_; }

 private:
  const std::vector<Eigen::VectorXd>& nodes_;
  const SegmentTest& test_;
  std::map<std::pair<std::size_t, std::size_t>, std::pair<bool, std::string>> cache_;
  std::size_t checked_ = 0;
};

}  // namespace

Tour plan_tour(const std::vector<Eigen::VectorXd>& poses, const SegmentTest& segment_free,
               const Eigen::VectorXd& start, const Eigen::VectorXd& metric) {
  Tour tour;
  const std::size_t n = poses.size();
  if (n == 0) {
    tour.complete = true;
    return tour;
  }
  std::vector<Eigen::VectorXd> nodes = poses;
  const bool has_start = start.size() > 0;
  if (has_start) nodes.push_back(start);
  auto dist = [&](std::size_t a, std::size_t b) {
    const Eigen::VectorXd d = nodes[a] - nodes[b];
    return metric.size() == d.size() ? d.cwiseProduct(metric).norm() : d.norm();
  };
  SegmentCache cache(nodes, segment_free);
  // Nearest neighbour over free segments, from the start (or pose 0).
  std::vector<std::size_t> path;
  std::vector<bool> used(n, false);
  std::size_t current = has_start ? n : 0;
  if (!has_start) {
    path.push_back(0);
    used[0] = true;
  }
  while (path.size() < n) {
    std::vector<std::pair<double, std::size_t>> next;
    for (std::size_t j = 0; j < n; ++j)
      if (!used[j]) next.emplace_back(dist(current, j), j);
    std::sort(next.begin(), next.end());
    bool moved = false;
    for (const auto& [d, j] : next) {
      if (cache.free(current, j)) {
        path.push_back(j);
        used[j] = true;
        current = j;
        moved = true;
        break;
      }
    }
    if (!moved) break;
  }
  // Poses the nearest-neighbour walk could not reach from its end (a straight motion there
  // passes an obstacle): insert each where both new motions are free, cheapest first.
  for (std::size_t j = 0; j < n; ++j) {
    if (used[j]) continue;
    std::vector<std::size_t> seq0;
    if (has_start) seq0.push_back(n);
    seq0.insert(seq0.end(), path.begin(), path.end());
    double best = std::numeric_limits<double>::infinity();
    std::size_t best_pos = 0;
    for (std::size_t k = 0; k + 1 <= seq0.size(); ++k) {
      const bool last = k + 1 == seq0.size();
      const double cost =
          dist(seq0[k], j) + (last ? 0.0 : dist(j, seq0[k + 1]) - dist(seq0[k], seq0[k + 1]));
      if (cost >= best) continue;
      if (!cache.free(seq0[k], j)) continue;
      if (!last && !cache.free(j, seq0[k + 1])) continue;
      best = cost;
      best_pos = k;
    }
    if (std::isfinite(best)) {
      const std::size_t offset =
          has_start ? 1 : 0;  // seq0 index k -> insert after path[k - offset]
      path.insert(path.begin() + static_cast<std::ptrdiff_t>(best_pos + 1 - offset), j);
      used[j] = true;
    }
  }
  for (std::size_t j = 0; j < n; ++j)
    if (!used[j]) {
      std::string why;
      cache.free(current, j, &why);
      tour.problems.push_back("pose " + std::to_string(j) +
                              " cannot be reached by a free straight motion from the tour (" + why +
                              ")");
    }
  // Open path (optionally anchored at the start node): sequence = [start?] + path.
  std::vector<std::size_t> seq;
  if (has_start) seq.push_back(n);
  seq.insert(seq.end(), path.begin(), path.end());
  auto seq_length = [&]() {
    double l = 0.0;
    for (std::size_t k = 1; k < seq.size(); ++k) l += dist(seq[k - 1], seq[k]);
    return l;
  };
  tour.nearest_neighbour_length = seq_length();
  // 2-opt on the open path: reverse seq[i..j]; the start (if any) stays first.
  bool improved = true;
  int passes = 0;
  while (improved && passes < 50) {
    improved = false;
    ++passes;
    for (std::size_t i = 1; i + 1 < seq.size(); ++i) {
      for (std::size_t j = i + 1; j < seq.size(); ++j) {
        const double before =
            dist(seq[i - 1], seq[i]) + (j + 1 < seq.size() ? dist(seq[j], seq[j + 1]) : 0.0);
        const double after =
            dist(seq[i - 1], seq[j]) + (j + 1 < seq.size() ? dist(seq[i], seq[j + 1]) : 0.0);
        if (after < before - 1e-12) {
          if (!cache.free(seq[i - 1], seq[j])) continue;
          if (j + 1 < seq.size() && !cache.free(seq[i], seq[j + 1])) continue;
          std::reverse(seq.begin() + static_cast<std::ptrdiff_t>(i),
                       seq.begin() + static_cast<std::ptrdiff_t>(j) + 1);
          improved = true;
        }
      }
    }
  }
  tour.length = seq_length();
  for (const std::size_t k : seq)
    if (k < n) tour.order.push_back(k);
  tour.complete = tour.order.size() == n;
  tour.segments_checked = cache.checked();
  return tour;
}

}  // namespace robocal::planner
