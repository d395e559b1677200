#pragma once
// Assembly-mode sweep over the parallel robots of the library, shared by the coarse
// unit test (tests/unit/calib/test_assembly_mode.cpp) and the dense bench
// (bench/bench_assembly_modes.cpp).
//
// For every configuration of a grid spanning each actuator's whole range (limits included), the
// nominal model and perturbed draws (every free parameter, normal at `tolerance_factor` x its
// file tolerance): forward kinematics through the library (ClosureSolver, cold) gives an answer
// with a verdict; an INDEPENDENT reference written here gives the intended answer:
//  - nominal: closed forms written in this file (rotary Delta sphere intersection, rails
//    trilateration for the linear delta and Gantry-Tau, the four-bar's spatial parallelogram
//    q3 = q1, the wire branch's parallelogram q3 = -q2), never the library's closed_form.cpp;
//  - perturbed: parameter continuation from the nominal reference state to the perturbed
//    parameters at the same readings (damped Newton of the library's plain closure residual,
//    mode checks off), which follows the intended branch unless a singularity lies in between.
// Counted: answers with verdict `intended` that disagree with the reference (silent wrong mode;
// must be 0), the largest disagreement of the rest, refusals and ambiguous verdicts with where
// they lie (the reference's distance to the nearest mode boundary, when it exists).
#include "robocal/calib/assembly_mode.hpp"
#include "robocal/calib/closure.hpp"
#include "robocal/calib/kinematics.hpp"
#include "robocal/calib/robot_file.hpp"

#include <Eigen/Core>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <map>
#include <optional>
#include <random>
#include <string>
#include <vector>

namespace robocal::calib::sweep {

struct Counts {
  long configurations = 0;  // (model, readings) pairs swept
  long intended = 0;        // answered with verdict intended
  long ambiguous = 0;       // answered with verdict ambiguous
  long refused_other = 0;   // status other_assembly_mode
  long not_closed = 0;      // loops do not close (outside the reachable set)
  long silent_wrong = 0;    // verdict intended but > tolerance from the reference
  long no_reference = 0;    // intended answers without a reference (reference not closable)
  long compared = 0;        // intended answers compared with the reference
  double max_error = 0.0;   // largest |tool position - reference| over the compared answers
  // Refused / ambiguous answers binned by the reference's distance to the nearest mode boundary
  // (min |invariant| of the intended-mode reference state): <0.02, <0.05, <0.1, >=0.1, none
  // (no reference: the intended mode does not close there).
  std::map<std::string, long> refused_by_distance, ambiguous_by_distance;
  // Refused answers whose reference is clear of every boundary (>= 0.1): the solver missed an
  // intended answer that exists.
  long refused_with_clear_reference = 0;

  void add(const Counts& o) {
    configurations += o.configurations;
    intended += o.intended;
    ambiguous += o.ambiguous;
    refused_other += o.refused_other;
    not_closed += o.not_closed;
    silent_wrong += o.silent_wrong;
    no_reference += o.no_reference;
    compared += o.compared;
    max_error = std::max(max_error, o.max_error);
    for (const auto& [k, v] : o.refused_by_distance) refused_by_distance[k] += v;
    for (const auto& [k, v] : o.ambiguous_by_distance) ambiguous_by_distance[k] += v;
    refused_with_clear_reference += o.refused_with_clear_reference;
  }
};

inline std::string format(const Eigen::VectorXd& v) {
  std::string s;
  for (Eigen::Index i = 0; i < v.size(); ++i) {
    if (i > 0) s += ',';
    s += std::to_string(v[i]);
  }
  return s;
}

inline std::string distance_bin(std::optional<double> d) {
  if (!d) return "no_reference";
  if (*d < 0.02) return "<0.02";
  if (*d < 0.05) return "0.02-0.05";
  if (*d < 0.1) return "0.05-0.1";
  return ">=0.1";
}

inline Eigen::Vector3d rot_z(double phi, const Eigen::Vector3d& v) {
  const double c = std::cos(phi), s = std::sin(phi);
  return {c * v.x() - s * v.y(), s * v.x() + c * v.y(), v.z()};
}

// Intersection of three spheres on the side `below` (smaller z) or the +x side: written here
// independently of calib/src/closed_form.cpp.
inline std::optional<Eigen::Vector3d> three_spheres(const Eigen::Vector3d c[3], const double r[3],
                                                    const Eigen::Vector3d& prefer) {
  // Subtracting sphere 1 from spheres 2 and 3 gives two planes; their line meets sphere 1.
  const Eigen::Vector3d n1 = 2.0 * (c[1] - c[0]), n2 = 2.0 * (c[2] - c[0]);
  const double b1 = r[0] * r[0] - r[1] * r[1] + c[1].squaredNorm() - c[0].squaredNorm();
  const double b2 = r[0] * r[0] - r[2] * r[2] + c[2].squaredNorm() - c[0].squaredNorm();
  const Eigen::Vector3d dir = n1.cross(n2);
  if (dir.norm() < 1e-12) return std::nullopt;
  // A point on the line: minimum-norm solution of [n1 n2]^T x = [b1 b2].
  Eigen::Matrix<double, 2, 3> N;
  N.row(0) = n1.transpose();
  N.row(1) = n2.transpose();
  const Eigen::Vector3d x0 =
      N.transpose() * (N * N.transpose()).inverse() * Eigen::Vector2d(b1, b2);
  const Eigen::Vector3d u = dir.normalized();
  const Eigen::Vector3d w = x0 - c[0];
  const double bq = u.dot(w), cq = w.squaredNorm() - r[0] * r[0];
  const double disc = bq * bq - cq;
  if (disc < 0) return std::nullopt;
  const Eigen::Vector3d p1 = x0 + (-bq + std::sqrt(disc)) * u;
  const Eigen::Vector3d p2 = x0 + (-bq - std::sqrt(disc)) * u;
  return prefer.dot(p1) >= prefer.dot(p2) ? p1 : p2;
}

// Nominal reference: the tool position on the intended mode (nullopt: the intended mode does not
// close) and, for robots whose passive joints follow in closed form, the passive joints.
struct NominalReference {
  std::optional<Eigen::Vector3d> tool;
  Eigen::VectorXd passive;  // empty: take the library's nominal answer once it matches `tool`
};

inline NominalReference nominal_reference(const Mechanism& m, const Eigen::VectorXd& p,
                                          const Eigen::VectorXd& readings) {
  NominalReference out;
  auto qj = [&](std::size_t i) {  // actuator joint value
    const Body& b = m.bodies[static_cast<std::size_t>(m.actuated[i])];
    return p[b.encoder_scale_param] * readings[static_cast<Eigen::Index>(i)] +
           p[b.encoder_offset_param];
  };
  if (m.name == "rotary_delta") {
    // r_b 0.2805, n 0.6, m 0.9, r_n 0.196, arms at 0, -120, +120 deg; plate below the elbows.
    const double phi[3] = {0.0, -2 * M_PI / 3, 2 * M_PI / 3};
    Eigen::Vector3d c[3];
    const double r[3] = {0.9, 0.9, 0.9};
    for (std::size_t i = 0; i < 3; ++i)
      c[i] = rot_z(phi[i], Eigen::Vector3d(0.2805 + 0.6 * std::cos(qj(i)) - 0.196, 0.0,
                                           -0.6 * std::sin(qj(i))));
    out.tool = three_spheres(c, r, -Eigen::Vector3d::UnitZ());
  } else if (m.name == "linear_delta") {
    // Towers at 210, 330, 90 deg, carriage joints at 0.174, effector joints at 0.034, rods 0.27;
    // effector below the carriages.
    const double ang[3] = {210.0, 330.0, 90.0};
    Eigen::Vector3d c[3];
    const double r[3] = {0.27, 0.27, 0.27};
    for (std::size_t i = 0; i < 3; ++i) {
      const double a = ang[i] * M_PI / 180.0;
      c[i] = Eigen::Vector3d((0.174 - 0.034) * std::cos(a), (0.174 - 0.034) * std::sin(a), qj(i));
    }
    out.tool = three_spheres(c, r, -Eigen::Vector3d::UnitZ());
  } else if (m.name == "gantry_tau") {
    // ||A_i + q_i x - T|| = L_i, platform on the +x side.
    const Eigen::Vector3d A[3] = {{0.04, 0, 1.44}, {0.25, -1.31, 1.46}, {0, 0, 0}};
    const double r[3] = {2.05, 1.82, 1.81};
    Eigen::Vector3d c[3];
    for (std::size_t i = 0; i < 3; ++i) c[i] = A[i] + qj(i) * Eigen::Vector3d::UnitX();
    out.tool = three_spheres(c, r, Eigen::Vector3d::UnitX());
  } else if (m.name == "four_bar") {
    // Spatial parallelogram: the output link stays parallel to the crank, so the tool (the
    // output link's end) sits at (1, 0, 0) + (-sin q1, cos q1, 0).
    const double a = qj(0);
    out.tool = Eigen::Vector3d(1.0 - std::sin(a), std::cos(a), 0.0);
  } else if (m.name == "wire_robot_branch") {
    // Parallelogram: the forearm keeps the turntable's orientation, q3 = -q2.
    out.passive = Eigen::VectorXd::Constant(1, -qj(1));
    const JointState s = make_joint_state(m, p, readings, out.passive);
    out.tool = frame_pose(m, p, s, m.tool).translation();
  }
  return out;
}

// Parameter continuation from (p0, x0) to p1 at fixed readings with the plain closure residual
// (mode checks off): the reference for perturbed models.
inline std::optional<Eigen::VectorXd> continue_parameters(const Mechanism& m,
                                                          const Eigen::VectorXd& p0,
                                                          const Eigen::VectorXd& p1,
                                                          const Eigen::VectorXd& readings,
                                                          Eigen::VectorXd x, int steps = 8) {
  ClosureOptions plain;
  plain.enforce_mode = false;
  for (int k = 1; k <= steps; ++k) {
    const double t = static_cast<double>(k) / steps;
    const ClosureResult r = solve_closure(m, p0 + t * (p1 - p0), readings, x, plain);
    if (!r.ok()) return std::nullopt;
    x = r.passive;
  }
  return x;
}

inline std::vector<Eigen::VectorXd> grid(const Mechanism& m, const Eigen::VectorXd& nominal,
                                         int values) {
  const std::size_t A = m.actuated.size();
  std::vector<std::vector<double>> axes(A);
  for (std::size_t i = 0; i < A; ++i) {
    const Body& b = m.bodies[static_cast<std::size_t>(m.actuated[i])];
    const double lo = b.limits.lower > -1e299 ? b.limits.lower : -M_PI;
    const double hi = b.limits.upper < 1e299 ? b.limits.upper : M_PI;
    for (int k = 0; k < values; ++k) axes[i].push_back(lo + (hi - lo) * k / (values - 1));
  }
  std::vector<Eigen::VectorXd> out;
  std::vector<int> idx(A, 0);
  while (true) {
    Eigen::VectorXd q(static_cast<Eigen::Index>(A));
    for (std::size_t i = 0; i < A; ++i) q[static_cast<Eigen::Index>(i)] = axes[i][idx[i]];
    out.push_back(readings_from_joint_values(m, nominal, q));
    std::size_t i = 0;
    while (i < A && ++idx[i] == values) idx[i++] = 0;
    if (i == A) break;
  }
  return out;
}

// Perturbed draw: every free parameter, normal at factor x its file tolerance.
inline Eigen::VectorXd perturbed(const Mechanism& m, double factor, std::mt19937& rng) {
  Eigen::VectorXd p = m.nominal_parameters();
  std::normal_distribution<double> n(0.0, 1.0);
  for (std::size_t k = 0; k < m.parameters.size(); ++k)
    if (m.parameters[k].free)
      p[static_cast<Eigen::Index>(k)] += factor * m.parameters[k].sigma * n(rng);
  return p;
}

// Sweeps one robot: `values` per actuator, the nominal model and `draws` perturbed ones.
// warm: each perturbed model is solved warm-started from the design's intended answer at the same
// readings (as compensation and tracking callers seed), instead of cold.
inline Counts sweep_robot(const Mechanism& m, int values, int draws, double tolerance_factor,
                          double agreement = 1e-9, unsigned seed = 15, bool warm = false) {
  Counts total;
  const Eigen::VectorXd nominal = m.nominal_parameters();
  const std::vector<Eigen::VectorXd> configs = grid(m, nominal, values);
  std::mt19937 rng(seed);
  std::vector<Eigen::VectorXd> models = {nominal};
  for (int d = 0; d < draws; ++d) models.push_back(perturbed(m, tolerance_factor, rng));
  const ClosureSolver nominal_solver(m, nominal);
  ClosureOptions plain;
  plain.enforce_mode = false;
  const ClosureSolver nominal_plain(m, nominal, plain);
  // Nominal reference states (passive joints on the intended mode), per configuration.
  std::vector<std::optional<Eigen::VectorXd>> nominal_state(configs.size());
  std::vector<std::optional<Eigen::Vector3d>> nominal_tool(configs.size());
  for (std::size_t c = 0; c < configs.size(); ++c) {
    const NominalReference ref = nominal_reference(m, nominal, configs[c]);
    nominal_tool[c] = ref.tool;
    if (!ref.tool) continue;
    Eigen::VectorXd x = ref.passive;
    if (x.size() == 0) {
      // The passive joints of the closed-form robots: the library's answer, accepted only where
      // it reproduces the reference tool position; else a plain solve from the library's
      // closed-form seed (pinned to the reference position).
      ClosureResult r = nominal_plain.solve(configs[c]);
      const auto tool_of = [&](const Eigen::VectorXd& passive) -> Eigen::Vector3d {
        return frame_pose(m, nominal, make_joint_state(m, nominal, configs[c], passive), m.tool)
            .translation();
      };
      if (!r.ok() || (tool_of(r.passive) - *ref.tool).norm() > 1e-9)
        r = nominal_solver.solve(configs[c]);  // other seeds; still judged by the closed form
      if (!r.ok()) continue;
      x = r.passive;
    } else {
      const ClosureResult r = nominal_plain.solve(configs[c], x);  // polish (nominal: exact)
      if (!r.ok()) continue;
      x = r.passive;
    }
    const JointState s = make_joint_state(m, nominal, configs[c], x);
    if ((frame_pose(m, nominal, s, m.tool).translation() - *ref.tool).norm() > 1e-9) continue;
    nominal_state[c] = x;
  }
  for (std::size_t k = 0; k < models.size(); ++k) {
    const Eigen::VectorXd& p = models[k];
    const ClosureSolver solver(m, p);
    for (std::size_t c = 0; c < configs.size(); ++c) {
      const Eigen::VectorXd& q = configs[c];
      ++total.configurations;
      // Reference: nominal closed form, or parameter continuation from the nominal state.
      std::optional<Eigen::Vector3d> ref_tool;
      std::optional<double> ref_distance;
      if (nominal_state[c]) {
        std::optional<Eigen::VectorXd> x =
            k == 0 ? nominal_state[c] : continue_parameters(m, nominal, p, q, *nominal_state[c]);
        if (x) {
          const JointState s = make_joint_state(m, p, q, *x);
          ref_tool = k == 0 ? *nominal_tool[c] : frame_pose(m, p, s, m.tool).translation();
          const ModeCheck mc = check_assembly_mode(m, p, s);
          ref_distance = mc.distance;
          // A continuation that ended on another mode crossed a boundary: no reference.
          if (mc.verdict == ModeVerdict::kOther) {
            ref_tool.reset();
            ref_distance.reset();
          }
        }
      }
      const ClosureResult r =
          warm && k > 0 && nominal_state[c] ? solver.solve(q, *nominal_state[c]) : solver.solve(q);
      if (r.status == SolveStatus::kOtherMode) {
        ++total.refused_other;
        ++total.refused_by_distance[distance_bin(ref_distance)];
        if (ref_distance && *ref_distance >= 0.1) {
          ++total.refused_with_clear_reference;
          if (std::getenv("ROBOCAL_SWEEP_VERBOSE"))
            std::fprintf(stderr, "refused: model %zu q %s %s ref distance %.3g\n", k,
                         format(q).c_str(), r.mode.describe().c_str(), *ref_distance);
        }
        continue;
      }
      if (!r.ok()) {
        ++total.not_closed;
        continue;
      }
      if (r.mode.verdict == ModeVerdict::kAmbiguous) {
        ++total.ambiguous;
        ++total.ambiguous_by_distance[distance_bin(ref_distance)];
        continue;
      }
      ++total.intended;
      if (!ref_tool) {
        ++total.no_reference;
        if (std::getenv("ROBOCAL_SWEEP_VERBOSE"))
          std::fprintf(stderr, "no reference: model %zu q %s nominal state %d\n", k,
                       format(q).c_str(), nominal_state[c] ? 1 : 0);
        continue;
      }
      const JointState s = make_joint_state(m, p, q, r.passive);
      const double e = (frame_pose(m, p, s, m.tool).translation() - *ref_tool).norm();
      ++total.compared;
      if (e > agreement) {
        ++total.silent_wrong;
        if (std::getenv("ROBOCAL_SWEEP_VERBOSE"))
          std::fprintf(
              stderr,
              "silent: model %zu q %s error %.3g seed %s distance %.3g cond %.3g ref %.3g\n", k,
              format(q).c_str(), e, r.seed_used, r.mode.distance, r.mode.conditioning,
              ref_distance ? *ref_distance : -1.0);
      } else
        total.max_error = std::max(total.max_error, e);
    }
  }
  return total;
}

}  // namespace robocal::calib::sweep
