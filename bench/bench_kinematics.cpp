// Kinematics speed on the rotary Delta (library file, 30 bodies, 15 passive joints):
//   FK through the generic closure solver, warm-started along a path with 1 mm steps (<= 10 us),
//   FK cold from the closed-form seed, the closed-form sphere intersection itself (the floor),
//   FK cold on a perturbed model (from the design's answer by parameter continuation),
//   IK on a perturbed (non-closed-form) model warm-started along the path (<= 20 us), one-shot
//   (solve_ik) and through one IkSolver,
//   the parameter Jacobian of the tool position w.r.t. every parameter (<= 50 us).
// Run: build/release/bench/bench_kinematics --benchmark_repetitions=5
//      --benchmark_report_aggregates_only=true
#include "robocal/calib/closed_form.hpp"
#include "robocal/calib/closure.hpp"
#include "robocal/calib/inverse_kinematics.hpp"
#include "robocal/calib/kinematics.hpp"
#include "robocal/calib/robot_file.hpp"

#include <benchmark/benchmark.h>

#include <cmath>
#include <random>
#include <stdexcept>
#include <vector>

namespace {

using namespace robocal::calib;

const Mechanism& delta() {
  static const Mechanism m =
      load_robot_file(std::string(ROBOCAL_TESTDATA_DIR) + "/robots/rotary_delta.yaml");
  return m;
}

// Plate positions on a helix through the working volume, 1 mm apart.
std::vector<Eigen::Vector3d> path_points() {
  std::vector<Eigen::Vector3d> pts;
  const double radius = 0.15, pitch = 0.05;
  const double arc_per_turn = std::hypot(2 * M_PI * radius, pitch);
  const double dphi = 2 * M_PI * 0.001 / arc_per_turn;
  for (int k = 0; k < 2000; ++k) {
    const double phi = k * dphi;
    pts.emplace_back(radius * std::cos(phi), radius * std::sin(phi),
                     -0.95 + pitch * phi / (2 * M_PI));
  }
  return pts;
}

std::vector<Eigen::VectorXd> path_actuators() {
  std::vector<Eigen::VectorXd> q;
  for (const auto& p : path_points()) {
    const auto t = delta_inverse(delta().closed_form, p);
    if (!t) throw std::runtime_error("path leaves the workspace");
    q.emplace_back(*t);
  }
  return q;
}

void BM_DeltaFkWarm(benchmark::State& state) {
  const Mechanism& m = delta();
  const ClosureSolver solver(m, m.nominal_parameters());
  const auto q = path_actuators();
  Eigen::VectorXd passive = solver.solve(q[0]).passive;
  std::size_t k = 1;
  int iterations = 0;
  for (auto _ : state) {
    const ClosureResult r = solver.solve(q[k], passive);
    if (!r.ok()) state.SkipWithError("closure failed");
    passive = r.passive;
    iterations += r.iterations;
    benchmark::DoNotOptimize(passive.data());
    if (++k == q.size()) {
      k = 1;
      passive = solver.solve(q[0]).passive;
    }
  }
  state.counters["newton_iters"] =
      benchmark::Counter(iterations, benchmark::Counter::kAvgIterations);
}
BENCHMARK(BM_DeltaFkWarm);

void BM_DeltaFkCold(benchmark::State& state) {
  const Mechanism& m = delta();
  const ClosureSolver solver(m, m.nominal_parameters());
  const auto q = path_actuators();
  std::size_t k = 0;
  for (auto _ : state) {
    const ClosureResult r = solver.solve(q[k]);
    if (!r.ok()) state.SkipWithError("closure failed");
    benchmark::DoNotOptimize(r.passive.data());
    k = (k + 37) % q.size();
  }
}
BENCHMARK(BM_DeltaFkCold);

void BM_DeltaFkClosedForm(benchmark::State& state) {
  const Mechanism& m = delta();
  const auto q = path_actuators();
  std::size_t k = 0;
  for (auto _ : state) {
    auto T = delta_forward(m.closed_form, q[k]);
    benchmark::DoNotOptimize(T);
    k = (k + 1) % q.size();
  }
}
BENCHMARK(BM_DeltaFkClosedForm);

Eigen::VectorXd perturbed_parameters() {
  const Mechanism& m = delta();
  Eigen::VectorXd p = m.nominal_parameters();
  std::mt19937 rng(4);
  std::normal_distribution<double> n(0.0, 1.0);
  for (std::size_t k = 0; k < m.parameters.size(); ++k)
    if (m.parameters[k].group == ParamGroup::kJointGeometry)
      p[static_cast<Eigen::Index>(k)] += 5e-4 * n(rng);
  return p;
}

// FK cold on a perturbed model (a model whose loops differ from the robot file's design
// is solved from the design's answer by continuation in the parameters).
void BM_DeltaFkColdPerturbed(benchmark::State& state) {
  const Mechanism& m = delta();
  const ClosureSolver solver(m, perturbed_parameters());
  const auto q = path_actuators();
  std::size_t k = 0;
  for (auto _ : state) {
    const ClosureResult r = solver.solve(q[k]);
    if (!r.ok()) state.SkipWithError("closure failed");
    benchmark::DoNotOptimize(r.passive.data());
    k = (k + 37) % q.size();
  }
}
BENCHMARK(BM_DeltaFkColdPerturbed);

// IK along the helix on the perturbed model, each target warm-started from the previous answer;
// `solve(target, seed)` is the solver under test.
template <class Solve>
void ik_along_the_path(benchmark::State& state, Solve solve) {
  const auto pts = path_points();
  TaskTarget target;
  target.pose.translation() = pts[0];
  const IkResult first = solve(target, IkSeed{});
  IkSeed seed{first.actuator_q, first.passive};
  std::size_t k = 1;
  int iterations = 0;
  for (auto _ : state) {
    target.pose.translation() = pts[k];
    const IkResult r = solve(target, seed);
    if (!r.ok()) state.SkipWithError("ik failed");
    seed.actuator_q = r.actuator_q;
    seed.passive = r.passive;
    iterations += r.iterations;
    if (++k == pts.size()) {
      k = 1;
      seed = {first.actuator_q, first.passive};
    }
  }
  state.counters["newton_iters"] =
      benchmark::Counter(iterations, benchmark::Counter::kAvgIterations);
}

void BM_DeltaIkWarmPerturbed(benchmark::State& state) {
  const Eigen::VectorXd p = perturbed_parameters();
  ik_along_the_path(state, [&](const TaskTarget& target, const IkSeed& seed) {
    return solve_ik(delta(), p, target, seed);
  });
}
BENCHMARK(BM_DeltaIkWarmPerturbed);

// The same path through one IkSolver (its state kept across the solves, as a planner or a path
// check uses it).
void BM_DeltaIkSolverWarmPerturbed(benchmark::State& state) {
  IkSolver solver(delta(), perturbed_parameters());
  ik_along_the_path(state, [&](const TaskTarget& target, const IkSeed& seed) {
    return solver.solve(target, seed);
  });
}
BENCHMARK(BM_DeltaIkSolverWarmPerturbed);

void BM_DeltaParameterJacobian(benchmark::State& state) {
  const Mechanism& m = delta();
  const Eigen::VectorXd p = m.nominal_parameters();
  const Eigen::Vector3d q(0.2, 0.4, 0.1);
  const ClosureResult r = solve_closure(m, p, q);
  const JointState s = make_joint_state(m, p, q, r.passive);
  for (auto _ : state) {
    auto J = parameter_jacobian(m, p, s, q, m.tool);
    benchmark::DoNotOptimize(J.data());
  }
  state.counters["parameters"] = static_cast<double>(m.parameters.size());
}
BENCHMARK(BM_DeltaParameterJacobian);

}  // namespace

BENCHMARK_MAIN();
