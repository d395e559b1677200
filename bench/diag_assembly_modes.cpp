// Diagnostic for the assembly-mode sweep: lists every "silent wrong-mode" case of
// tests/support/mode_sweep.hpp (library verdict intended, > 1e-9 m from the reference) with the
// library answer, the reference answer (parameter continuation, 8 steps as in the sweep), a fine
// continuation (512 steps), both verdicts, closure residuals, conditioning, and every distinct
// closed configuration an independent brute-force multi-start finds (random passive seeds, plain
// closure, clustered by tool position and plate orientation).
// Run: build/release/bench/diag_assembly_modes [values] [draws] [robot file] [seeds]
#include "mode_sweep.hpp"

#include <cstdio>
#include <cstdlib>
#include <random>
#include <string>
#include <vector>

using namespace robocal::calib;

namespace {

struct State {
  Eigen::VectorXd passive;
  Eigen::Vector3d tool;
  Eigen::Matrix3d R;  // orientation of the tool frame
  ModeCheck check;
  double residual = 0.0;
};

// Delta constraint-singularity measure: det of the unit normals of the three parallelogram planes
// (elbow bar x mean rod direction); 0 where the couples of the pairs cannot hold the plate level.
double normals_det(const Mechanism& m, const Eigen::VectorXd& p, const Eigen::VectorXd& q,
                   const Eigen::VectorXd& x) {
  std::vector<Eigen::Isometry3d> T;
  body_poses(m, p, make_joint_state(m, p, q, x), T);
  const int arms[3][4] = {{6, 16, 7, 17}, {19, 22, 20, 23}, {25, 28, 26, 29}};
  auto pos = [&](int b) {
    return Eigen::Vector3d(
        T[static_cast<std::size_t>(m.body_index("body" + std::to_string(b)))].translation());
  };
  Eigen::Matrix3d N;
  for (int i = 0; i < 3; ++i) {
    const Eigen::Vector3d e = pos(arms[i][1]) - pos(arms[i][0]);
    const Eigen::Vector3d u =
        (pos(arms[i][2]) - pos(arms[i][0]) + pos(arms[i][3]) - pos(arms[i][1])) / 2;
    N.col(i) = e.cross(u).normalized();
  }
  return N.determinant();
}

State describe(const Mechanism& m, const Eigen::VectorXd& p, const Eigen::VectorXd& q,
               const Eigen::VectorXd& x) {
  State s;
  s.passive = x;
  const JointState js = make_joint_state(m, p, q, x);
  const Eigen::Isometry3d T = frame_pose(m, p, js, m.tool);
  s.tool = T.translation();
  s.R = T.linear();
  s.check = check_assembly_mode(m, p, js);
  s.residual = closure_residual(m, p, js).cwiseAbs().maxCoeff();
  return s;
}

void print(const char* tag, const State& s) {
  std::printf(
      "  %-12s tool (%.9f %.9f %.9f) tilt %.3f deg verdict %s [%s] margin %.4f distance %.4f "
      "cond %.3g residual %.2g\n",
      tag, s.tool.x(), s.tool.y(), s.tool.z(),
      std::acos(std::clamp(s.R(2, 2), -1.0, 1.0)) * 180 / M_PI, to_string(s.check.verdict),
      s.check.invariant.c_str(), s.check.margin, s.check.distance, s.check.conditioning,
      s.residual);
}

}  // namespace

int main(int argc, char** argv) {
  const int values = argc > 1 ? std::atoi(argv[1]) : 10;
  const int draws = argc > 2 ? std::atoi(argv[2]) : 20;
  const std::string file = argc > 3 ? argv[3] : "rotary_delta.yaml";
  const int seeds = argc > 4 ? std::atoi(argv[4]) : 2000;
  const bool stats = std::getenv("DIAG_STATS") != nullptr;
  const Mechanism m = load_robot_file(std::string(ROBOCAL_TESTDATA_DIR) + "/robots/" + file);
  const Eigen::VectorXd nominal = m.nominal_parameters();
  const auto configs = sweep::grid(m, nominal, values);
  std::mt19937 rng(15);
  std::vector<Eigen::VectorXd> models = {nominal};
  for (int d = 0; d < draws; ++d) models.push_back(sweep::perturbed(m, 5.0, rng));
  ClosureOptions plain;
  plain.enforce_mode = false;
  const ClosureSolver nominal_solver(m, nominal);
  long cases = 0;
  for (std::size_t k = 1; k < models.size(); ++k) {
    const Eigen::VectorXd& p = models[k];
    const ClosureSolver solver(m, p);
    const ClosureSolver plain_solver(m, p, plain);
    for (const Eigen::VectorXd& q : configs) {
      const auto nref = sweep::nominal_reference(m, nominal, q);
      if (!nref.tool) continue;
      const ClosureResult r = solver.solve(q);
      if (!r.ok() || r.mode.verdict != ModeVerdict::kIntended) continue;
      // Nominal state as in the sweep (the library's nominal answer matching the closed form).
      ClosureResult rn = nominal_solver.solve(q);
      if (!rn.ok()) continue;
      const State ns = describe(m, nominal, q, rn.passive);
      if ((ns.tool - *nref.tool).norm() > 1e-9) continue;
      const auto x8 = sweep::continue_parameters(m, nominal, p, q, rn.passive, 8);
      if (!x8) continue;
      const State ref = describe(m, p, q, *x8);
      if (ref.check.verdict == ModeVerdict::kOther) continue;
      const State lib = describe(m, p, q, r.passive);
      if (stats) {  // one line per compared answer: silent, conditioning of each side, margins
        std::printf("S %d %zu %.3e %.4g %.4g %.4g %.4g %.4g %s %.4g %.4g\n",
                    (lib.tool - ref.tool).norm() > 1e-9 ? 1 : 0, k, (lib.tool - ref.tool).norm(),
                    lib.check.conditioning, ref.check.conditioning, ns.check.conditioning,
                    lib.check.distance, r.mode.conditioning, to_string(ref.check.verdict),
                    normals_det(m, p, q, r.passive), normals_det(m, nominal, q, rn.passive));
        continue;
      }
      if ((lib.tool - ref.tool).norm() <= 1e-9) continue;
      ++cases;
      std::printf("case %ld: draw %zu q %s |lib-ref| %.4g m, seed %s, library cond est %.3g\n",
                  cases, k, sweep::format(q).c_str(), (lib.tool - ref.tool).norm(), r.seed_used,
                  r.mode.conditioning);
      print("nominal", ns);
      print("library", lib);
      print("ref(8)", ref);
      const auto x512 = sweep::continue_parameters(m, nominal, p, q, rn.passive, 512);
      if (x512)
        print("ref(512)", describe(m, p, q, *x512));
      else
        std::printf("  ref(512)     failed\n");
      // Brute force: random seeds, plain closure, distinct configurations.
      std::mt19937 srng(1234);
      std::uniform_real_distribution<double> u(-M_PI, M_PI);
      std::vector<std::pair<State, int>> found;
      for (int s = 0; s < seeds; ++s) {
        Eigen::VectorXd seed = m.home_passive();
        if (s == 0)
          seed = r.passive;
        else if (s == 1)
          seed = *x8;
        else
          for (Eigen::Index i = 0; i < seed.size(); ++i) seed[i] += u(srng);
        const ClosureResult b = plain_solver.solve(q, seed);
        if (!b.ok()) continue;
        const State st = describe(m, p, q, b.passive);
        bool dup = false;
        for (auto& [f, n] : found)
          if ((f.tool - st.tool).norm() < 1e-7 && (f.R - st.R).norm() < 1e-6) {
            ++n;
            dup = true;
            break;
          }
        if (!dup) found.emplace_back(st, 1);
      }
      std::printf("  brute force: %zu distinct closed configurations from %d seeds\n", found.size(),
                  seeds);
      for (const auto& [f, n] : found) {
        if (f.check.verdict == ModeVerdict::kOther) continue;
        char tag[32];
        std::snprintf(tag, sizeof tag, "bf x%d", n);
        print(tag, f);
      }
      long other = 0;
      for (const auto& [f, n] : found) other += f.check.verdict == ModeVerdict::kOther;
      std::printf("  (+ %ld on other modes)\n", other);
      std::fflush(stdout);
    }
  }
  std::printf("%ld cases\n", cases);
  return 0;
}
