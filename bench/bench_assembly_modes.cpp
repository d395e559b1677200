// Dense assembly-mode sweep: every parallel robot of the library, 20 values per
// actuator over its whole range (limits included), the nominal model and 20 perturbed draws at 5x
// the file's tolerances. Forward kinematics through the library (cold), judged against the
// independent reference of tests/support/mode_sweep.hpp (closed forms written there, parameter
// continuation for perturbed models). Prints JSON: per robot, answers on the intended mode,
// ambiguous, refused (other mode), not closing, silent wrong-mode answers (must be 0), the largest
// disagreement with the reference, and where refusals / ambiguous verdicts lie (the reference's
// distance to the nearest mode boundary).
// Run: build/release/bench/bench_assembly_modes [--warm] [values_per_actuator] [draws] [robot
// file...]
// --warm: the perturbed models are solved warm-started from the design's answer (the seed
// compensation and tracking callers pass) instead of cold.
// (default: all five; the rotary Delta alone takes ~25 min on a loaded 2-core machine)
#include "mode_sweep.hpp"

#include <nlohmann/json.hpp>

#include <chrono>
#include <cstdlib>
#include <iostream>
#include <string>
#include <vector>

int main(int argc, char** argv) {
  using namespace robocal::calib;
  const bool warm = argc > 1 && std::string(argv[1]) == "--warm";
  if (warm) {
    --argc;
    ++argv;
  }
  const int values = argc > 1 ? std::atoi(argv[1]) : 20;
  const int draws = argc > 2 ? std::atoi(argv[2]) : 20;
  nlohmann::json doc = {{"values_per_actuator", values},
                        {"perturbed_draws", draws},
                        {"tolerance_factor", 5.0},
                        {"agreement_m", 1e-9},
                        {"perturbed_seed", warm ? "warm, from the design's answer" : "cold"}};
  nlohmann::json robots = nlohmann::json::array();
  std::vector<std::string> files = {"rotary_delta.yaml", "linear_delta.yaml", "gantry_tau.yaml",
                                    "four_bar.yaml", "wire_robot_branch.yaml"};
  if (argc > 3) files.assign(argv + 3, argv + argc);
  for (const std::string& file : files) {
    const Mechanism m = load_robot_file(std::string(ROBOCAL_TESTDATA_DIR) + "/robots/" + file);
    const auto t0 = std::chrono::steady_clock::now();
    const sweep::Counts c = sweep::sweep_robot(m, values, draws, 5.0, 1e-9, 15, warm);
    const double seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    robots.push_back({{"robot", m.name},
                      {"configurations", c.configurations},
                      {"intended", c.intended},
                      {"ambiguous", c.ambiguous},
                      {"refused_other_mode", c.refused_other},
                      {"not_closed", c.not_closed},
                      {"compared_with_reference", c.compared},
                      {"intended_without_reference", c.no_reference},
                      {"silent_wrong_mode", c.silent_wrong},
                      {"max_error_m", c.max_error},
                      {"refused_by_reference_distance", c.refused_by_distance},
                      {"ambiguous_by_reference_distance", c.ambiguous_by_distance},
                      {"refused_with_clear_reference", c.refused_with_clear_reference},
                      {"seconds", seconds}});
    // Each robot's figures as soon as they exist (the whole sweep takes tens of minutes).
    std::cerr << robots.back().dump() << "\n";
  }
  doc["robots"] = robots;
  std::cout << doc.dump(2) << "\n";
  return 0;
}
