#pragma once
// The printer firmwares' own delta calibration routines, for the bench only: written
// from their documentation (Klipper docs/Delta_Calibrate.md, RepRapFirmware's "calibrating a
// delta printer" / G32 least-squares auto-calibration, Marlin G33), not from their code.
//
// All of them fit the firmware's small delta model (firmware_delta.hpp: towers on one circle of
// radius R at angles θ_i, rods L_i, carriage offsets c_i) by least squares to what was probed:
// the firmware moved the nozzle to (x, y, 0) by its current model, so the carriage readings are
// known; the probe says how high above the bed the nozzle really was, so the model after
// calibration must place the nozzle at that height at those readings. Distances between printed
// positions (Klipper's extended calibration measures a printed object) enter the same way: the
// model must reproduce them at the readings that printed them. The routines differ in which
// factors they adjust:
//  - Klipper DELTA_CALIBRATE (basic): the three endstop positions, the delta radius and the
//    angles of towers A and B (tower C's angle fixes the frame): 6 factors, heights only.
//  - Klipper DELTA_CALIBRATE METHOD=extended (with the printed object's distances): the same plus
//    the three arm (diagonal rod) lengths: 9 factors.
//  - RepRapFirmware G32 least squares, S3 / S4 / S6 / S7: endstop corrections; + delta radius;
//    + the X and Y tower angle corrections; + the (common) diagonal rod length.
//  - Marlin G33: 4 factors (endstops + radius; tower angles off with T) and 7 (+ the three tower
//    angle trims, normalised: their common part is a turn about z that no height sees; here the
//    Gauss-Newton step is the minimum-norm one).
// The solver is Gauss–Newton on numerical derivatives (what RRF documents: linearised least
// squares, iterated; Klipper documents a least-squares fit of the same residuals).
#include "robocal/calib/firmware_delta.hpp"
#include "robocal/calib/mechanism.hpp"

#include <Eigen/Dense>

#include <cmath>
#include <string>
#include <utility>
#include <vector>

namespace robocal::bench {

enum class Factor {
  kEndstopA,
  kEndstopB,
  kEndstopC,
  kRadius,
  kAngleA,
  kAngleB,
  kAngleC,
  kArmA,
  kArmB,
  kArmC,
  kArm
};

struct FirmwareRoutine {
  std::string name;
  std::vector<Factor> factors;
};

inline std::vector<FirmwareRoutine> firmware_routines(bool with_distances) {
  using F = Factor;
  const std::vector<F> endstops = {F::kEndstopA, F::kEndstopB, F::kEndstopC};
  auto plus = [&](std::vector<F> more) {
    std::vector<F> f = endstops;
    f.insert(f.end(), more.begin(), more.end());
    return f;
  };
  if (with_distances)
    return {{"klipper_extended",
             plus({F::kRadius, F::kAngleA, F::kAngleB, F::kArmA, F::kArmB, F::kArmC})}};
  return {{"klipper_basic", plus({F::kRadius, F::kAngleA, F::kAngleB})},
          {"rrf_4", plus({F::kRadius})},
          {"rrf_6", plus({F::kRadius, F::kAngleA, F::kAngleB})},
          {"rrf_7", plus({F::kRadius, F::kAngleA, F::kAngleB, F::kArm})},
          {"marlin_g33_7", plus({F::kRadius, F::kAngleA, F::kAngleB, F::kAngleC})}};
}

// The firmware model a printer ships with: the robot file's drawing (its closed form).
inline calib::FirmwareDeltaModel nominal_firmware_model(const calib::Mechanism& model) {
  calib::FirmwareDeltaModel m;
  const calib::ClosedFormSpec& s = model.closed_form;
  for (std::size_t i = 0; i < 3; ++i) {
    const Eigen::Vector3d joint = s.rail_origin[i] - s.platform_offset[i];
    m.delta_radius += joint.head<2>().norm() / 3.0;
    m.arm_length[i] = s.link_length[i];
    m.tower_angle[i] = std::atan2(joint.y(), joint.x());
    m.carriage_offset[i] = joint.z();
  }
  return m;
}

inline calib::FirmwareDeltaModel apply_factors(calib::FirmwareDeltaModel m,
                                               const std::vector<Factor>& factors,
                                               const Eigen::VectorXd& x) {
  for (std::size_t k = 0; k < factors.size(); ++k) {
    const double v = x(static_cast<Eigen::Index>(k));
    switch (factors[k]) {
      case Factor::kEndstopA:
        m.carriage_offset[0] += v;
        break;
      case Factor::kEndstopB:
        m.carriage_offset[1] += v;
        break;
      case Factor::kEndstopC:
        m.carriage_offset[2] += v;
        break;
      case Factor::kRadius:
        m.delta_radius += v;
        break;
      case Factor::kAngleA:
        m.tower_angle[0] += v;
        break;
      case Factor::kAngleB:
        m.tower_angle[1] += v;
        break;
      case Factor::kAngleC:
        m.tower_angle[2] += v;
        break;
      case Factor::kArmA:
        m.arm_length[0] += v;
        break;
      case Factor::kArmB:
        m.arm_length[1] += v;
        break;
      case Factor::kArmC:
        m.arm_length[2] += v;
        break;
      case Factor::kArm:
        for (double& a : m.arm_length) a += v;
        break;
    }
  }
  return m;
}

// What was measured, in the firmware's terms: carriage readings with the probed height there;
// carriage readings of printed positions with distances between pairs of them.
struct FirmwareProbeData {
  std::vector<Eigen::Vector3d> probe_readings;
  std::vector<double> heights;
  std::vector<Eigen::Vector3d> printed_readings;
  std::vector<std::pair<int, int>> pairs;
  std::vector<double> distances;
};

inline bool firmware_residuals(const calib::FirmwareDeltaModel& m, const FirmwareProbeData& d,
                               Eigen::VectorXd& r) {
  r.resize(static_cast<Eigen::Index>(d.heights.size() + d.distances.size()));
  Eigen::Vector3d p;
  for (std::size_t k = 0; k < d.heights.size(); ++k) {
    if (!calib::firmware_delta_position(m, d.probe_readings[k], p)) return false;
    r(static_cast<Eigen::Index>(k)) = p.z() - d.heights[k];
  }
  std::vector<Eigen::Vector3d> printed;
  for (const auto& rd : d.printed_readings) {
    if (!calib::firmware_delta_position(m, rd, p)) return false;
    printed.push_back(p);
  }
  for (std::size_t k = 0; k < d.distances.size(); ++k) {
    const auto [a, b] = d.pairs[k];
    r(static_cast<Eigen::Index>(d.heights.size() + k)) =
        (printed[static_cast<std::size_t>(a)] - printed[static_cast<std::size_t>(b)]).norm() -
        d.distances[k];
  }
  return true;
}

// Gauss–Newton from the shipped model; the minimum-norm step when the factors are confounded.
inline calib::FirmwareDeltaModel run_firmware_routine(const calib::FirmwareDeltaModel& start,
                                                      const FirmwareRoutine& routine,
                                                      const FirmwareProbeData& data) {
  const auto n = static_cast<Eigen::Index>(routine.factors.size());
  Eigen::VectorXd x = Eigen::VectorXd::Zero(n);
  Eigen::VectorXd r;
  if (!firmware_residuals(start, data, r)) return start;
  for (int it = 0; it < 20; ++it) {
    Eigen::MatrixXd J(r.size(), n);
    for (Eigen::Index k = 0; k < n; ++k) {
      const double h = 1e-7;
      Eigen::VectorXd xp = x, xm = x, rp, rm;
      xp(k) += h;
      xm(k) -= h;
      if (!firmware_residuals(apply_factors(start, routine.factors, xp), data, rp) ||
          !firmware_residuals(apply_factors(start, routine.factors, xm), data, rm))
        return apply_factors(start, routine.factors, x);
      J.col(k) = (rp - rm) / (2.0 * h);
    }
    Eigen::CompleteOrthogonalDecomposition<Eigen::MatrixXd> cod;
    cod.setThreshold(1e-9);
    cod.compute(J);
    Eigen::VectorXd step = cod.solve(-r);
    // Marlin's normalisation: three tower angle trims carry a common turn about z that no
    // measurement sees; their mean is removed.
    std::vector<Eigen::Index> angles;
    for (Eigen::Index k = 0; k < n; ++k) {
      const Factor f = routine.factors[static_cast<std::size_t>(k)];
      if (f == Factor::kAngleA || f == Factor::kAngleB || f == Factor::kAngleC) angles.push_back(k);
    }
    if (angles.size() == 3) {
      double mean = 0.0;
      for (Eigen::Index k : angles) mean += (x(k) + step(k)) / 3.0;
      for (Eigen::Index k : angles) step(k) -= mean;
    }
    x += step;
    if (!firmware_residuals(apply_factors(start, routine.factors, x), data, r))
      return apply_factors(start, routine.factors, x - step);
    if (step.norm() < 1e-12) break;
  }
  return apply_factors(start, routine.factors, x);
}

}  // namespace robocal::bench
