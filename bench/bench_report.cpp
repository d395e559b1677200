// The calibration report's speed and size (a report for 500 held-out poses written in
// <= 2 s, page <= 2 MB). Usage: bench_report SESSION [repeats]
// SESSION: a validated session, e.g. `robocal demo --out SESSION` (500 held-out poses by default).
// Prints JSON: held-out poses, wall time per report (median and worst of the repeats), page size.
#include "stages/stages.hpp"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

int main(int argc, char** argv) {
  if (argc < 2) {
    std::fprintf(stderr, "usage: bench_report SESSION [repeats]\n");
    return 2;
  }
  const std::string session = argv[1];
  const int repeats = argc > 2 ? std::max(1, std::atoi(argv[2])) : 5;
  robocal::app::PipelineLog silent{nullptr};
  std::vector<double> seconds;
  nlohmann::json last;
  try {
    for (int i = 0; i < repeats; ++i) {
      const auto t0 = std::chrono::steady_clock::now();
      last = robocal::app::report_session(session, silent);
      seconds.push_back(
          std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "error: %s\n", e.what());
    return 3;
  }
  std::sort(seconds.begin(), seconds.end());
  const double median = seconds[seconds.size() / 2];
  const auto bytes = last.value("bytes", std::size_t{0});
  const nlohmann::json out{{"bench", "report"},
                           {"session", session},
                           {"held_out_poses", last.value("held_out_poses", 0)},
                           {"repeats", repeats},
                           {"seconds_median", median},
                           {"seconds_max", seconds.back()},
                           {"page_bytes", bytes},
                           {"limit_seconds", 2.0},
                           {"limit_bytes", 2 * 1024 * 1024},
                           {"within_limits", seconds.back() <= 2.0 && bytes <= 2U * 1024U * 1024U}};
  std::printf("%s\n", out.dump(2).c_str());
  return 0;
}
