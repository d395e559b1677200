// Universal Robots link bench: prints JSON.
//  1. Fault soak: N moves of a UR5 through the UR link against `robocal sim-controller --protocol
//     ur` with every fault kind of that protocol injected at a given rate per kind (drop, error,
//     stall, slow = late RTDE packages, missing RTDE packages, pstop = protective stop; the link
//     may unlock protective stops, as after the operator's confirmation). Each move must end
//     confirmed at its target or failed with its reason; the simulator's log must show no motion
//     completed twice, no confirmed move it never executed, and no motion whose target lies
//     outside the declared workspace or the joint limits.
//  2. Link overhead per pose, fault-free, beside the G-code and open links' in the same run:
//     (move issued -> settled -> readings read) minus the simulator's own time for that motion.
// Usage: bench_ur_link [--moves 200] [--rate 0.05] [--overhead-moves 50] [--seed 1]
#include "robocal/calib/closure.hpp"
#include "robocal/robotio/link_error.hpp"
#include "robocal/robotio/open_link.hpp"
#include "robocal/robotio/ur_link.hpp"
#include "robotio_sim.hpp"

#include <fmt/core.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <iostream>
#include <map>
#include <numbers>
#include <numeric>
#include <random>

namespace {

using namespace robocal;
namespace fs = std::filesystem;

constexpr double kStepsPerDegree = 10000.0;
constexpr robotio::MoveSpeed kUrSpeed{0.8, 4.0};
constexpr robotio::MoveSpeed kDeltaSpeed{0.2, 4.0};

calib::Mechanism ur5() {
  return calib::load_robot_file(std::string(ROBOCAL_TESTDATA_DIR) + "/robots/ur5.yaml");
}

robotio::SafetyLimits ur5_limits() {
  robotio::SafetyLimits l;
  l.workspace_min = Eigen::Vector3d::Constant(-1.2);
  l.workspace_max = Eigen::Vector3d::Constant(1.2);
  l.max_speed = 1.0;
  l.max_acceleration = 6.0;
  l.path_step = 5e-3;
  return l;
}

std::vector<Eigen::VectorXd> ur5_targets(const calib::Mechanism& model, int count, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> d(-0.3, 0.3);
  std::vector<Eigen::VectorXd> out;
  for (int k = 0; k < count; ++k) {
    Eigen::VectorXd t = model.home_actuated();
    for (Eigen::Index i = 0; i < t.size(); ++i) t[i] += d(rng);
    out.push_back(t);
  }
  return out;
}

// The simulator's joint counts at `readings` (rad -> degrees -> steps), worked out here.
std::vector<long> ur_counts(const calib::Mechanism& model, const Eigen::VectorXd& readings) {
  const Eigen::VectorXd scale = calib::encoder_scales(model, model.nominal_parameters());
  std::vector<long> c;
  for (Eigen::Index i = 0; i < readings.size(); ++i)
    c.push_back(std::lround(readings[i] * scale[i] * 180.0 / std::numbers::pi * kStepsPerDegree));
  return c;
}

robotio::UrLinkOptions ur_options(const std::string& address, bool unlock) {
  robotio::UrLinkOptions o;
  o.address = address;
  o.reply_timeout = std::chrono::milliseconds(500);
  o.package_timeout = std::chrono::milliseconds(800);
  o.unlock_protective_stop = unlock;
  return o;
}

std::vector<std::string> ur_sim_args(const std::string& log, std::vector<std::string> extra) {
  std::vector<std::string> a = {
      "--robot",   "ur5", "--protocol",         "ur",    "--log",  log, "--max-seconds", "1800",
      "--slow-ms", "300", "--steps-per-degree", "10000", "--seed", "3"};
  a.insert(a.end(), extra.begin(), extra.end());
  return a;
}

bool inside_limits(const calib::Mechanism& model, const robotio::SafetyGuard& guard,
                   const Eigen::VectorXd& readings) {
  const Eigen::Vector3d p =
      calib::forward_kinematics(model, model.nominal_parameters(), readings, model.tool)
          .pose.translation();
  const robotio::SafetyLimits& l = guard.limits();
  return (p.array() >= l.workspace_min.array()).all() &&
         (p.array() <= l.workspace_max.array()).all() &&
         (readings.array() >= l.actuator_lower.array() - 1e-9).all() &&
         (readings.array() <= l.actuator_upper.array() + 1e-9).all();
}

// What the simulator's log says of the soak: faults, motions completed per target, motions
// outside the limits.
nlohmann::json soak_audit(const std::string& log, const calib::Mechanism& model,
                          const robotio::SafetyGuard& guard,
                          const std::vector<std::vector<long>>& target_counts,
                          const std::vector<bool>& move_confirmed) {
  const std::vector<nlohmann::json> entries = test::read_sim_log(log);
  std::map<std::string, int> faults;
  for (const auto& f : test::events(entries, "fault")) ++faults[f["kind"].get<std::string>()];
  std::map<long, std::vector<long>> motion_to;
  int outside = 0, motions = 0;
  for (const auto& m : test::events(entries, "motion_start")) {
    ++motions;
    motion_to[m["id"].get<long>()] = m["to"].get<std::vector<long>>();
    const std::vector<double> r = m["target_readings"].get<std::vector<double>>();
    if (!inside_limits(model, guard, Eigen::Map<const Eigen::VectorXd>(r.data(), 6))) ++outside;
  }
  std::map<std::vector<long>, int> completed;  // motions that ran to their end, per target
  for (const auto& e : test::events(entries, "motion_end"))
    if (!e["stopped"].get<bool>()) ++completed[motion_to[e["id"].get<long>()]];
  int duplicated = 0, lost = 0;
  for (std::size_t i = 0; i < target_counts.size(); ++i) {
    const int n = completed.count(target_counts[i]) != 0 ? completed[target_counts[i]] : 0;
    if (n > 1) ++duplicated;
    if (move_confirmed[i] && n == 0) ++lost;
  }
  return {{"faults_injected", faults},
          {"simulator_motions", motions},
          {"moves_completed_twice", duplicated},
          {"confirmed_moves_never_executed", lost},
          {"motions_outside_workspace_or_limits", outside}};
}

nlohmann::json ur_soak(int moves, double rate, unsigned seed, const fs::path& dir) {
  const calib::Mechanism model = ur5();
  robotio::SafetyGuard guard(model, model.nominal_parameters(), ur5_limits());
  guard.arm("bench");
  const std::string log = (dir / "soak_ur.jsonl").string();
  robotio::SimControllerProcess sim(
      ROBOCAL_BINARY, ur_sim_args(log, {"--faults", fmt::format("all={}", rate), "--fault-seed",
                                        std::to_string(seed), "--ur-unlock-delay", "1"}));
  robotio::UrLink link(guard, ur_options(sim.ur(), true));
  link.connect();
  std::vector<std::vector<long>> target_counts;
  std::vector<bool> move_confirmed;
  int confirmed = 0, failed = 0, unexplained = 0;
  std::map<std::string, int> failure_reasons;
  const auto t0 = std::chrono::steady_clock::now();
  for (const Eigen::VectorXd& t : ur5_targets(model, moves, seed + 100)) {
    target_counts.push_back(ur_counts(model, t));
    move_confirmed.push_back(false);
    try {
      const robotio::MoveResult r = link.move_actuators(t, kUrSpeed);
      move_confirmed.back() = r.confirmed;
      r.confirmed ? ++confirmed : ++failed;
      if (!r.confirmed) ++failure_reasons[r.reason];
    } catch (const std::exception& e) {
      ++failed;
      const std::string reason = e.what();
      if (reason.empty()) ++unexplained;
      // Group by the problem, not the numbers after it.
      ++failure_reasons[reason.substr(0, reason.find_first_of("0123456789", 16))];
      try {
        link.read_actuators();  // the guard's next path starts from where the arm is
      } catch (const std::exception&) {
        link.reconnect();
      }
    }
  }
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  const robotio::LinkStatus st = link.status();
  link.disconnect();
  sim.stop();
  nlohmann::json j = soak_audit(log, model, guard, target_counts, move_confirmed);
  j["link"] = "ur";
  j["moves"] = moves;
  j["fault_rate_per_kind"] = rate;
  j["unlock_delay_s"] = 1.0;
  j["confirmed"] = confirmed;
  j["failed"] = failed;
  j["failed_without_reason"] = unexplained;
  j["failure_reasons"] = failure_reasons;
  j["link_counters"] = {{"commands", st.commands},
                        {"resends", st.resends},
                        {"timeouts", st.timeouts},
                        {"reconnects", st.reconnects},
                        {"errors", st.errors}};
  j["seconds"] = seconds;
  return j;
}

// Overhead of one link: every move's wall time minus the simulator's duration of the motion it
// started (fault-free, so the i-th move is the i-th motion).
nlohmann::json overhead_of(robotio::RobotLink& link, const std::vector<Eigen::VectorXd>& targets,
                           const robotio::MoveSpeed& speed, robotio::SimControllerProcess& sim,
                           const std::string& log) {
  std::vector<double> wall;
  for (const Eigen::VectorXd& t : targets) {
    const robotio::MoveResult r = link.move_actuators(t, speed);
    if (!r.confirmed) throw std::runtime_error("overhead run: move not confirmed: " + r.reason);
    wall.push_back(r.seconds);
  }
  link.disconnect();
  sim.stop();
  const std::vector<double> motion = robotio::simulated_motion_seconds(log);
  if (motion.size() != wall.size())
    throw std::runtime_error(
        fmt::format("overhead run: {} moves, {} simulator motions", wall.size(), motion.size()));
  std::vector<double> over_ms;
  for (std::size_t i = 0; i < wall.size(); ++i) over_ms.push_back(1000.0 * (wall[i] - motion[i]));
  std::sort(over_ms.begin(), over_ms.end());
  const auto pct = [&](double p) {
    return over_ms[static_cast<std::size_t>(p * static_cast<double>(over_ms.size() - 1))];
  };
  const double n = static_cast<double>(over_ms.size());
  return {
      {"moves", over_ms.size()},
      {"mean_simulated_move_ms", 1000.0 * std::accumulate(motion.begin(), motion.end(), 0.0) / n},
      {"overhead_ms",
       {{"mean", std::accumulate(over_ms.begin(), over_ms.end(), 0.0) / n},
        {"median", pct(0.5)},
        {"p95", pct(0.95)},
        {"max", over_ms.back()}}},
      {"limit_ms", 5.0}};
}

nlohmann::json overheads(int moves, unsigned seed, const fs::path& dir) {
  nlohmann::json out = nlohmann::json::array();
  const calib::Mechanism delta = test::linear_delta();
  const auto delta_targets = test::delta_targets(delta, moves, seed + 200);
  for (const std::string protocol : {"gcode", "open"}) {
    robotio::SafetyGuard guard(delta, delta.nominal_parameters(), test::delta_limits());
    guard.arm("bench");
    const std::string log = (dir / ("overhead_" + protocol + ".jsonl")).string();
    robotio::SimControllerProcess sim(ROBOCAL_BINARY,
                                      test::sim_args(log, {"--protocol", protocol, "--no-pty"}));
    std::unique_ptr<robotio::RobotLink> link;
    if (protocol == "gcode") {
      link = std::make_unique<robotio::GcodeLink>(guard, test::link_options(delta, sim.tcp()));
    } else {
      robotio::OpenLinkOptions o;
      o.address = "open:" + sim.tcp().substr(4);
      link = std::make_unique<robotio::OpenLink>(guard, o);
    }
    link->connect();
    nlohmann::json j = overhead_of(*link, delta_targets, kDeltaSpeed, sim, log);
    j["link"] = protocol;
    j["robot"] = "linear_delta";
    out.push_back(j);
  }
  // The UR at CB3's RTDE rate (125 Hz) and e-Series' (500 Hz): the settle's dwell is
  // settle_packages packages, so its share of the overhead scales with the period.
  const calib::Mechanism arm = ur5();
  for (const double hz : {125.0, 500.0}) {
    robotio::SafetyGuard guard(arm, arm.nominal_parameters(), ur5_limits());
    guard.arm("bench");
    const std::string log = (dir / fmt::format("overhead_ur_{}hz.jsonl", hz)).string();
    robotio::SimControllerProcess sim(ROBOCAL_BINARY, ur_sim_args(log, {}));
    robotio::UrLinkOptions o = ur_options(sim.ur(), false);
    o.frequency = hz;
    robotio::UrLink link(guard, o);
    link.connect();
    nlohmann::json j = overhead_of(link, ur5_targets(arm, moves, seed + 200), kUrSpeed, sim, log);
    j["link"] = "ur";
    j["robot"] = "ur5";
    j["rtde_frequency_hz"] = hz;
    out.push_back(j);
  }
  return out;
}

}  // namespace

int main(int argc, char** argv) {
  int moves = 200, overhead_moves = 50;
  double rate = 0.05;
  unsigned seed = 1;
  std::string only;
  for (int i = 1; i + 1 < argc; i += 2) {
    const std::string a = argv[i];
    if (a == "--moves") moves = std::atoi(argv[i + 1]);
    if (a == "--overhead-moves") overhead_moves = std::atoi(argv[i + 1]);
    if (a == "--rate") rate = std::atof(argv[i + 1]);
    if (a == "--seed") seed = static_cast<unsigned>(std::atoi(argv[i + 1]));
    if (a == "--only") only = argv[i + 1];  // soak | overhead
  }
  const fs::path dir = fs::temp_directory_path() / "robocal_bench_ur_link";
  fs::create_directories(dir);
  nlohmann::json out;
  try {
    if (only != "soak") out["overhead"] = overheads(overhead_moves, seed, dir);
    if (only != "overhead") out["soak"] = ur_soak(moves, rate, seed, dir);
  } catch (const std::exception& e) {
    out["error"] = e.what();
    std::cout << out.dump(2) << "\n";
    return 1;
  }
  out["logs"] = dir.string();
  std::cout << out.dump(2) << "\n";
  return 0;
}
