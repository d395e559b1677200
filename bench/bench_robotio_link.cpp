// Controller-link bench: prints JSON.
//  1. Fault soak: N moves against `robocal sim-controller` over TCP and over the pty with every
//     fault kind injected at a given rate: each move must end confirmed at its target or failed
//     with its reason; the simulator's log must show no motion duplicated or lost and no motion
//     whose target lies outside the declared workspace or actuator limits.
//     The same through Moonraker against a Klipper delta (faults: drop, error, slow, shutdown).
//  2. Link overhead per pose: (move issued -> settled -> readings parsed) minus the simulator's
//     own move time for that motion (from its log), fault-free, over TCP and the pty.
// Usage: bench_robotio_link [--moves 200] [--rate 0.05] [--overhead-moves 100] [--seed 1]
//                           [--only soak|overhead|klipper]
#include "robocal/calib/closure.hpp"
#include "robocal/calib/kinematics.hpp"
#include "robocal/robotio/klipper_link.hpp"
#include "robocal/robotio/link_error.hpp"
#include "robocal/robotio/moonraker.hpp"
#include "robotio_sim.hpp"

#include <fmt/core.h>

#include <algorithm>
#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <functional>
#include <iostream>
#include <map>
#include <numeric>

namespace {

using namespace robocal;

constexpr robotio::MoveSpeed kSpeed{0.2, 4.0};

std::unique_ptr<robotio::GcodeLink> connect_with_retries(robotio::SafetyGuard& guard,
                                                         const calib::Mechanism& model,
                                                         const std::string& address) {
  std::string why;
  for (int attempt = 0; attempt < 5; ++attempt) {
    auto link = std::make_unique<robotio::GcodeLink>(guard, test::link_options(model, address));
    try {
      link->connect();
      return link;
    } catch (const robotio::LinkError& e) {
      why = e.what();
    }
  }
  throw std::runtime_error("cannot connect: " + why);
}

// One soak's moves as the link reported them: each confirmed, or failed with its reason.
struct SoakTally {
  std::vector<std::vector<long>> target_counts;
  std::vector<bool> move_confirmed;
  int confirmed = 0, failed = 0, unexplained = 0;
  std::map<std::string, int> failure_reasons;

  // Moves to `target` (the controller's `counts` there); after a failure, `recover` puts the
  // link back in a state to go on (the guard's next path starts from where the robot is).
  void move(robotio::RobotLink& link, const Eigen::VectorXd& target, std::vector<long> counts,
            const std::function<void()>& recover) {
    target_counts.push_back(std::move(counts));
    move_confirmed.push_back(false);
    try {
      const robotio::MoveResult r = link.move_actuators(target, kSpeed);
      if (r.confirmed) {
        ++confirmed;
        move_confirmed.back() = true;
        return;
      }
      ++failed;
      ++failure_reasons[r.reason];
      if (r.reason.empty()) ++unexplained;
    } catch (const std::exception& e) {
      ++failed;
      const std::string reason = e.what();
      if (reason.empty()) ++unexplained;
      // Group by the problem, not the changing numbers after it.
      ++failure_reasons[reason.substr(0, reason.find(" (controller said"))];
      recover();
    }
  }
  void add_to(nlohmann::json& j) const {
    j["confirmed"] = confirmed;
    j["failed"] = failed;
    j["failed_without_reason"] = unexplained;
    j["failure_reasons"] = failure_reasons;
  }
};

// What the simulator's log says of a soak: the faults it injected, its motions, a target reached
// by more than one motion (duplicated), a move the link confirmed that never ran (lost), a
// motion outside the declared workspace or limits.
nlohmann::json judge_soak(const std::vector<nlohmann::json>& entries, const calib::Mechanism& model,
                          const robotio::SafetyGuard& guard,
                          const std::vector<std::vector<long>>& target_counts,
                          const std::vector<bool>& move_confirmed) {
  const Eigen::VectorXd params = model.nominal_parameters();
  const robotio::SafetyLimits& limits = guard.limits();
  std::map<std::string, int> faults;
  for (const auto& f : test::events(entries, "fault")) ++faults[f["kind"].get<std::string>()];
  // Drawn for a line the firmware then rejected as a duplicate: never took effect.
  for (const auto& f : test::events(entries, "fault_void")) --faults[f["kind"].get<std::string>()];
  std::map<std::vector<long>, int> motions_to;
  int outside = 0, motions = 0;
  calib::ClosureSolver solver(model, params);
  for (const auto& m : test::events(entries, "motion_start")) {
    ++motions;
    ++motions_to[m["to"].get<std::vector<long>>()];
    const std::vector<double> r = m["target_readings"].get<std::vector<double>>();
    const Eigen::VectorXd readings = Eigen::Map<const Eigen::VectorXd>(r.data(), 3);
    const calib::ClosureResult c = solver.solve(readings);
    bool inside = c.ok();
    if (inside) {
      const Eigen::Vector3d p =
          calib::frame_pose(model, params,
                            calib::make_joint_state(model, params, readings, c.passive), model.tool)
              .translation();
      inside = (p.array() >= limits.workspace_min.array()).all() &&
               (p.array() <= limits.workspace_max.array()).all();
    }
    inside = inside && (readings.array() >= guard.limits().actuator_lower.array() - 1e-9).all() &&
             (readings.array() <= guard.limits().actuator_upper.array() + 1e-9).all();
    if (!inside) ++outside;
  }
  int duplicated = 0, lost = 0;
  for (const auto& c : target_counts) {
    const int n = motions_to.count(c) != 0 ? motions_to[c] : 0;
    if (n > 1) ++duplicated;
  }
  // Lost: a move the link confirmed that the controller never executed.
  for (std::size_t i = 0; i < target_counts.size(); ++i)
    if (move_confirmed[i] && motions_to.count(target_counts[i]) == 0) ++lost;
  nlohmann::json j;
  j["faults_injected"] = faults;
  j["simulator_motions"] = motions;
  j["moves_duplicated"] = duplicated;
  j["confirmed_moves_never_executed"] = lost;
  j["motions_outside_workspace_or_limits"] = outside;
  return j;
}

nlohmann::json soak(const std::string& wire, int moves, double rate, unsigned seed,
                    const std::filesystem::path& dir) {
  const calib::Mechanism model = test::linear_delta();
  const Eigen::VectorXd params = model.nominal_parameters();
  const robotio::SafetyLimits limits = test::delta_limits();
  robotio::SafetyGuard guard(model, params, limits);
  guard.arm("bench");
  const std::string log = (dir / ("soak_" + wire + ".jsonl")).string();
  robotio::SimControllerProcess sim(
      ROBOCAL_BINARY,
      test::sim_args(log, {"--faults", fmt::format("all={}", rate), "--fault-seed",
                           std::to_string(seed), "--slow-ms", "200", "--seed", "3"}));
  auto link = connect_with_retries(guard, model, wire == "tcp" ? sim.tcp() : sim.pty());
  const std::vector<Eigen::VectorXd> targets = test::delta_targets(model, moves, seed + 100);
  SoakTally tally;
  const auto t0 = std::chrono::steady_clock::now();
  for (const Eigen::VectorXd& t : targets)
    tally.move(*link, t, link->counts_for(t), [&] {
      try {
        if (link->status().state == robotio::LinkState::kDisconnected) link->reconnect();
        link->read_actuators();
      } catch (const std::exception&) {
        link = connect_with_retries(guard, model, wire == "tcp" ? sim.tcp() : sim.pty());
      }
    });
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  const robotio::LinkStatus st = link->status();
  sim.stop();

  nlohmann::json j =
      judge_soak(test::read_sim_log(log), model, guard, tally.target_counts, tally.move_confirmed);
  j["wire"] = wire;
  j["moves"] = moves;
  j["fault_rate_per_kind"] = rate;
  tally.add_to(j);
  j["link_counters"] = {{"commands", st.commands},     {"resends", st.resends},
                        {"timeouts", st.timeouts},     {"reconnects", st.reconnects},
                        {"busy_lines", st.busy_lines}, {"errors", st.errors},
                        {"garbage", st.garbage}};
  j["seconds"] = seconds;
  return j;
}

// The same soak through Moonraker: a Klipper delta (`sim-controller --firmware klipper`) driven in
// its own kinematics, with the faults a network printer shows (a dropped connection, a late
// answer, an error answer, Klippy shutting down) each at rate / 4, so that about `rate` of the
// scripts meet one. After a shutdown the operator's recovery: FIRMWARE_RESTART, then homing.
nlohmann::json klipper_soak(int moves, double rate, unsigned seed,
                            const std::filesystem::path& dir) {
  const calib::Mechanism model = test::linear_delta();
  robotio::SafetyLimits limits = test::delta_limits();
  limits.workspace_max.z() = 0.225;  // the homed position (carriages at their tops)
  robotio::SafetyGuard guard(model, model.nominal_parameters(), limits);
  guard.arm("bench");
  const std::string log = (dir / "soak_klipper.jsonl").string();
  const double each = rate / 4.0;
  robotio::SimControllerProcess sim(
      ROBOCAL_BINARY,
      test::sim_args(log,
                     {"--firmware", "klipper", "--kinematics", "delta", "--no-pty", "--faults",
                      fmt::format("drop={0},error={0},slow={0},shutdown={0}", each), "--fault-seed",
                      std::to_string(seed), "--slow-ms", "200", "--seed", "3"}));
  const std::string address = "moonraker:" + sim.tcp().substr(4);
  const int port = std::stoi(sim.tcp().substr(sim.tcp().rfind(':') + 1));
  robotio::GcodeLinkOptions o = test::link_options(model, address);
  auto link = std::make_unique<robotio::KlipperLink>(guard, o);
  // Connecting and homing see faults too: retried as an operator would.
  const auto restart_and_home = [&] {
    for (int attempt = 0;; ++attempt) {
      try {
        robotio::MoonrakerClient client("127.0.0.1", port);
        client.open(robotio::Clock::now() + std::chrono::seconds(2));
        client.call("printer.firmware_restart", nullptr,
                    robotio::Clock::now() + std::chrono::seconds(2));
        client.close();
        link = std::make_unique<robotio::KlipperLink>(guard, o);
        link->connect();
        link->home();
        return;
      } catch (const std::exception& e) {
        if (attempt >= 5) throw std::runtime_error(std::string("cannot recover: ") + e.what());
      }
    }
  };
  restart_and_home();
  const std::vector<Eigen::VectorXd> targets = test::delta_targets(model, moves, seed + 100);
  SoakTally tally;
  int restarts = 0;
  const auto t0 = std::chrono::steady_clock::now();
  for (const Eigen::VectorXd& t : targets)
    tally.move(*link, t, robotio::delta_counts(*link->native_frame(), t), [&] {
      try {
        link->read_actuators();
        if (link->status().state == robotio::LinkState::kFault) throw std::runtime_error("fault");
      } catch (const std::exception&) {
        ++restarts;
        restart_and_home();
      }
    });
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  const robotio::LinkStatus st = link->status();
  sim.stop();
  nlohmann::json j =
      judge_soak(test::read_sim_log(log), model, guard, tally.target_counts, tally.move_confirmed);
  j["wire"] = "moonraker";
  j["moves"] = moves;
  j["fault_rate_per_kind"] = each;
  tally.add_to(j);
  j["restarts_after_shutdown"] = restarts;
  j["link_counters_since_last_restart"] = {{"commands", st.commands},
                                           {"timeouts", st.timeouts},
                                           {"reconnects", st.reconnects},
                                           {"errors", st.errors}};
  j["seconds"] = seconds;
  return j;
}

nlohmann::json overhead(const std::string& wire, int moves, unsigned seed,
                        const std::filesystem::path& dir) {
  const calib::Mechanism model = test::linear_delta();
  robotio::SafetyGuard guard(model, model.nominal_parameters(), test::delta_limits());
  guard.arm("bench");
  const std::string log = (dir / ("overhead_" + wire + ".jsonl")).string();
  robotio::SimControllerProcess sim(ROBOCAL_BINARY, test::sim_args(log, {}));
  auto link = connect_with_retries(guard, model, wire == "tcp" ? sim.tcp() : sim.pty());
  const std::vector<Eigen::VectorXd> targets = test::delta_targets(model, moves, seed + 200);
  std::vector<std::pair<std::vector<long>, double>> wall;
  double guard_s = 0.0;
  for (const Eigen::VectorXd& t : targets) {
    // The guard's share (path sampled every 2 mm of carriage travel, closure solved per sample),
    // timed on its own: it is part of the overhead below.
    const auto g0 = std::chrono::steady_clock::now();
    if (!guard.check_move(link->last_known(), t, kSpeed).allowed)
      throw std::runtime_error("overhead run: the guard refused a target");
    guard_s += std::chrono::duration<double>(std::chrono::steady_clock::now() - g0).count();
    const robotio::MoveResult r = link->move_actuators(t, kSpeed);
    if (!r.confirmed) throw std::runtime_error("overhead run: move not confirmed: " + r.reason);
    wall.emplace_back(r.readings.counts, r.seconds);
  }
  sim.stop();
  std::map<std::vector<long>, double> duration;
  for (const auto& m : test::events(test::read_sim_log(log), "motion_start"))
    duration[m["to"].get<std::vector<long>>()] = m["duration_s"].get<double>();
  std::vector<double> over_ms;
  double move_s = 0.0;
  for (const auto& [counts, s] : wall) {
    over_ms.push_back(1000.0 * (s - duration.at(counts)));
    move_s += duration.at(counts);
  }
  std::sort(over_ms.begin(), over_ms.end());
  const auto pct = [&](double p) {
    return over_ms[static_cast<std::size_t>(p * static_cast<double>(over_ms.size() - 1))];
  };
  nlohmann::json j;
  j["wire"] = wire;
  j["moves"] = moves;
  j["mean_simulated_move_ms"] = 1000.0 * move_s / static_cast<double>(moves);
  j["overhead_ms"] = {
      {"mean", std::accumulate(over_ms.begin(), over_ms.end(), 0.0) / static_cast<double>(moves)},
      {"median", pct(0.5)},
      {"p95", pct(0.95)},
      {"max", over_ms.back()}};
  j["guard_check_ms_mean"] = 1000.0 * guard_s / static_cast<double>(moves);
  j["limit_ms"] = 5.0;
  return j;
}

}  // namespace

int main(int argc, char** argv) {
  int moves = 200, overhead_moves = 100;
  double rate = 0.05;
  unsigned seed = 1;
  std::string only;
  for (int i = 1; i + 1 < argc; i += 2) {
    const std::string a = argv[i];
    if (a == "--moves") moves = std::atoi(argv[i + 1]);
    if (a == "--overhead-moves") overhead_moves = std::atoi(argv[i + 1]);
    if (a == "--rate") rate = std::atof(argv[i + 1]);
    if (a == "--seed") seed = static_cast<unsigned>(std::atoi(argv[i + 1]));
    if (a == "--only") only = argv[i + 1];  // soak | overhead | klipper
  }
  const auto dir = std::filesystem::temp_directory_path() / "robocal_bench_robotio_link";
  std::filesystem::create_directories(dir);
  nlohmann::json out;
  try {
    if (only != "klipper") {
      for (const std::string wire : {"tcp", "pty"}) {
        if (only != "soak") out["overhead"].push_back(overhead(wire, overhead_moves, seed, dir));
        if (only != "overhead") out["soak"].push_back(soak(wire, moves, rate, seed, dir));
      }
    }
    if (only.empty() || only == "klipper" || only == "soak")
      out["soak"].push_back(klipper_soak(moves, rate, seed, dir));
  } catch (const std::exception& e) {
    out["error"] = e.what();
    std::cout << out.dump(2) << "\n";
    return 1;
  }
  out["logs"] = dir.string();
  std::cout << out.dump(2) << "\n";
  return 0;
}
