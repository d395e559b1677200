#pragma once
// Internal: evaluation of assembly-mode invariants over any pose source (the public
// Eigen::Isometry3d poses of kinematics.hpp, or the solver's cached detail::Rigid poses), so the
// solvers check every answer without converting or recomputing poses.
#include "robocal/calib/assembly_mode.hpp"
#include "robocal/calib/kinematics.hpp"
#include "tree_evaluator.hpp"

#include <algorithm>
#include <cmath>
#include <sstream>

namespace robocal::calib::detail {

inline Eigen::Vector3d unit_or_zero(const Eigen::Vector3d& v) {
  const double n = v.norm();
  return n > 1e-300 ? Eigen::Vector3d(v / n) : Eigen::Vector3d::Zero();
}

// position(b) -> world origin of body b; rotation(b) -> world rotation of body b; q = per-body
// joint values.
template <class Position, class Rotation>
double invariant_value(const ModeInvariant& inv, const Mechanism& m, const Eigen::VectorXd& q,
                       const Position& position, const Rotation& rotation) {
  const std::vector<int>& b = inv.bodies;
  auto p = [&](std::size_t k) -> Eigen::Vector3d { return position(b[k]); };
  switch (inv.kind) {
    case InvariantKind::kSide:
      return (rotation(b[0]) * inv.axis).dot(unit_or_zero(p(1) - p(0)));
    case InvariantKind::kTurn: {
      const Eigen::Vector3d axis = rotation(b[0]).col(2);
      return axis.dot(unit_or_zero(p(1) - p(0)).cross(unit_or_zero(p(2) - p(0))));
    }
    case InvariantKind::kParallel:
      return unit_or_zero(p(1) - p(0)).dot(unit_or_zero(p(3) - p(2)));
    case InvariantKind::kTriple: {
      Eigen::Matrix3d M;
      M.col(0) = unit_or_zero(p(1) - p(0));
      M.col(1) = unit_or_zero(p(3) - p(2));
      M.col(2) = unit_or_zero(p(5) - p(4));
      return M.determinant();
    }
    case InvariantKind::kTilt: {
      const double c = (rotation(b[0]) * inv.axis).dot(rotation(b[1]) * inv.axis);
      const double c0 = std::cos(inv.max_angle);
      return std::clamp((c - c0) / (1.0 - c0), -1.0, 1.0);
    }
    case InvariantKind::kJoint: {
      const Body& body = m.bodies[static_cast<std::size_t>(b[0])];
      const double v = q[b[0]];
      return body.joint == JointType::kRevolute ? std::sin(v) : std::tanh(v);
    }
  }
  return 0.0;
}

// conditioning: sigma_min / sigma_max of the closure Jacobian at the state, < 0 if unknown.
template <class Position, class Rotation>
ModeCheck check_mode(const Mechanism& m, const Eigen::VectorXd& q, const Position& position,
                     const Rotation& rotation, double conditioning = -1.0) {
  ModeCheck out;
  out.conditioning = conditioning;
  const AssemblyModeSpec& spec = m.assembly_mode;
  if (spec.invariants.empty()) return out;
  out.margin = 1e300;
  out.distance = 1e300;
  std::size_t nearest = 0;
  double flipped_margin = 0.0;
  for (std::size_t k = 0; k < spec.invariants.size(); ++k) {
    const ModeInvariant& inv = spec.invariants[k];
    const double v = invariant_value(inv, m, q, position, rotation);
    const double signed_v = inv.sign * v;
    if (!std::isfinite(signed_v)) {
      out.margin = -1.0;
      out.distance = 0.0;
      out.verdict = ModeVerdict::kAmbiguous;
      out.invariant = inv.name;
      return out;
    }
    out.margin = std::min(out.margin, signed_v);
    if (std::abs(v) < out.distance) {
      out.distance = std::abs(v);
      nearest = k;
    }
    if (signed_v <= -spec.ambiguity) {
      if (!out.invariant.empty()) out.invariant += ",";
      out.invariant += inv.name;
      flipped_margin = std::min(flipped_margin, signed_v);
    }
  }
  if (!out.invariant.empty()) {
    out.verdict = ModeVerdict::kOther;
  } else if (out.distance < spec.ambiguity) {
    out.verdict = ModeVerdict::kAmbiguous;
    out.invariant = spec.invariants[nearest].name;
  } else if (conditioning >= 0.0 && conditioning < spec.min_conditioning) {
    out.verdict = ModeVerdict::kAmbiguous;
    out.invariant = "closure_conditioning";
  } else {
    out.verdict = ModeVerdict::kIntended;
  }
  return out;
}

// `p` with the base frames (fixed bodies hanging from the world) and the task frame at the robot
// file's values: neither enters a closure, so these are the parameters of the loops alone.
inline Eigen::VectorXd loop_parameters(const Mechanism& m, const Eigen::VectorXd& p) {
  Eigen::VectorXd out = p;
  if (p.size() != static_cast<Eigen::Index>(m.parameters.size())) return out;
  for (std::size_t i = 0; i < m.parameters.size(); ++i) {
    const int b = m.parameters[i].body;
    if (b < 0) continue;
    const Body& body = m.bodies[static_cast<std::size_t>(b)];
    const bool base_frame = body.parent < 0 && body.joint == JointType::kFixed;
    const bool task_frame = b == m.task.frame && body.joint == JointType::kFixed;
    if (base_frame || task_frame) out[static_cast<Eigen::Index>(i)] = m.parameters[i].value;
  }
  return out;
}

// A perturbed model's loops close in several nearby configurations that all satisfy the declared
// invariants only near a singularity of the design (the design's one configuration split by the
// perturbation); the split configurations seen in the dense sweep had closure conditioning 1.0-1.8
// times the ambiguity threshold. Answers under this multiple of it are checked against the cold
// forward kinematics (closure.cpp, inverse_kinematics.cpp); away from it the invariants suffice
// and the hot paths pay nothing. 2.5 keeps 1.4x over the largest split seen. At 3 the perturbed
// Delta of bench_kinematics spent half its IK time in this check along an ordinary path
// (conditioning 0.025-0.04 there). The dense sweeps (bench_assembly_modes, 20 values per
// actuator, 20 draws at 5x the tolerances) answer the same at 2.5 as at 3 when cold, on all five
// parallel robots; warm-started from the design's answer, 92 of the Delta's 168,000 answers are
// intended at 2.5 where 3 called them ambiguous, each within 1e-11 m of the reference. Neither
// gives a silent wrong-mode answer.
constexpr double kDesignCheckMargin = 2.5;

// The design check's band of robot `m`, and whether a known conditioning (>= 0) lies in it.
inline double design_check_band(const Mechanism& m) {
  return kDesignCheckMargin * m.assembly_mode.min_conditioning;
}
inline bool in_design_check_band(const Mechanism& m, double conditioning) {
  return conditioning >= 0.0 && conditioning < design_check_band(m);
}

// The closure conditioning of an inverse-kinematics answer (IkSolver, the Compensator's fast
// path), from the passive columns J of the closure Jacobian (v, w: scratch): as the closure
// solver's (closure.cpp, conditioning), the estimate trusted from twice the design check's band,
// the thresholds the ambiguity gate and, for a model whose loops differ from the design, the band;
// bounds carried along a path of warm solves by `path`.
inline double inverse_answer_conditioning(PathConditioning& path, const Eigen::MatrixXd& J,
                                          Eigen::VectorXd& v, Eigen::VectorXd& w,
                                          const Mechanism& m, bool differs_from_design) {
  const double gate = m.assembly_mode.min_conditioning;
  return path(nullptr, J, v, w, 2.0 * design_check_band(m), gate,
              differs_from_design ? design_check_band(m) : gate);
}

// The design-branch check's comparison (inverse kinematics, the Compensator): the task frame where
// forward kinematics puts it for the answer's readings and where the answer has it are the same
// pose, within 1e-9 m and rad (the same passive values are not asked: a rod's idle turn about its
// own axis, or a turn of 2 pi, changes those and nothing else).
inline bool same_task_pose(const Eigen::Vector3d& p_a, const Eigen::Matrix3d& R_a,
                           const Eigen::Vector3d& p_b, const Eigen::Matrix3d& R_b) {
  constexpr double kSamePose = 1e-9;
  return (p_a - p_b).norm() <= kSamePose && rotation_log(R_a.transpose() * R_b).norm() <= kSamePose;
}

// A warm answer Newton reached in more than this many steps travelled from its seed and is
// checked like a nearly singular one (closure.cpp, check_warm_against_design, says why).
constexpr int kWarmNewtonSteps = 5;

// Whether the loops of `p` differ from the robot file's design (closure.hpp: cold solves of such
// a model follow the design's answer).
// (As loop_parameters(m, p) != m.nominal_parameters(), without building either: a one-shot
// solve asks this once.)
inline bool loops_differ_from_design(const Mechanism& m, const Eigen::VectorXd& p) {
  if (p.size() != static_cast<Eigen::Index>(m.parameters.size())) return false;
  for (std::size_t i = 0; i < m.parameters.size(); ++i) {
    const Parameter& par = m.parameters[i];
    if (p[static_cast<Eigen::Index>(i)] == par.value) continue;
    if (par.body >= 0) {
      const Body& body = m.bodies[static_cast<std::size_t>(par.body)];
      const bool base_frame = body.parent < 0 && body.joint == JointType::kFixed;
      const bool task_frame = par.body == m.task.frame && body.joint == JointType::kFixed;
      if (base_frame || task_frame) continue;
    }
    return true;
  }
  return false;
}

}  // namespace robocal::calib::detail
