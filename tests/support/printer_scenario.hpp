#pragma once
// What printer and delta users measure, simulated on the library linear delta with a
// known truth:
//  - bed probing: the firmware moves the nozzle to (x, y, 0) by its NOMINAL model and the probe
//    reports how far above the bed (plane z = 0, or a tilted plane) the nozzle really is there;
//    the pattern firmwares use: centre plus six points on a circle;
//  - a printed part measured with a caliper: distances between positions printed at commanded
//    (x, y, z) by the nominal model, positions that have no other observation.
// Shared by the tests and bench/printer_identify_bench.cpp.
#include "robocal/calib/identification.hpp"
#include "robocal/calib/inverse_kinematics.hpp"
#include "robocal/calib/mechanism_predictor.hpp"
#include "robocal/calib/robot_file.hpp"

#include <fmt/core.h>

#include <cmath>
#include <random>
#include <stdexcept>
#include <string>
#include <vector>

namespace robocal::test {

// The parameters a printer firmware's 9-factor calibration adjusts, in this model's names:
// three endstop offsets, three diagonal rods, three tower positions (radius / angle).
inline const std::vector<std::string>& printer_parameters() {
  static const std::vector<std::string> names = {"carriage_a.encoder_offset",
                                                 "carriage_b.encoder_offset",
                                                 "carriage_c.encoder_offset",
                                                 "rod_a.length",
                                                 "rod_b.length",
                                                 "rod_c.length",
                                                 "tower_a.x",
                                                 "tower_b.x",
                                                 "tower_c.y"};
  return names;
}

// Centre plus `count` points on a circle of `radius` (the firmwares' 7-point pattern: count 6).
inline std::vector<Eigen::Vector2d> probe_pattern(double radius, int count = 6) {
  std::vector<Eigen::Vector2d> pts = {Eigen::Vector2d::Zero()};
  for (int k = 0; k < count; ++k) {
    const double a = 2.0 * M_PI * k / count + M_PI / 2.0;
    pts.emplace_back(radius * std::cos(a), radius * std::sin(a));
  }
  return pts;
}

// Readings the nominal model commands for the nozzle at `target`.
inline Eigen::VectorXd commanded_readings(const calib::Mechanism& model,
                                          const Eigen::Vector3d& target) {
  calib::TaskTarget t;
  t.pose.translation() = target;
  const auto ik = calib::solve_ik(model, model.nominal_parameters(), t);
  if (!ik.ok())
    throw std::runtime_error(
        fmt::format("IK failed at ({}, {}, {})", target.x(), target.y(), target.z()));
  return ik.actuator_readings;
}

struct PrinterData {
  calib::Measurements measurements;
  std::vector<Eigen::Vector3d> true_positions;  // nozzle per pose (truth)
};

// Probe heights at `xy` on the bed plane z = tilt_x·x + tilt_y·y + bed_z (world), σ `sigma`.
inline void add_probe_heights(const calib::Mechanism& model, const Eigen::VectorXd& truth,
                              const std::vector<Eigen::Vector2d>& xy, double sigma,
                              std::mt19937& rng, PrinterData& out, double bed_z = 0.0,
                              double tilt_x = 0.0, double tilt_y = 0.0,
                              const std::string& prefix = "probe") {
  const calib::MechanismPredictor pred(model);
  std::normal_distribution<double> n01(0.0, 1.0);
  for (std::size_t k = 0; k < xy.size(); ++k) {
    calib::PoseMeasurement m;
    m.id = fmt::format("{}{}", prefix, k);
    m.actuators = commanded_readings(model, Eigen::Vector3d(xy[k].x(), xy[k].y(), 0.0));
    calib::FramePrediction fp;
    std::string why;
    if (!pred.predict(truth, m.actuators, -1, false, fp, why)) throw std::runtime_error(why);
    const Eigen::Vector3d p = fp.pose.translation();
    calib::ProbeHeightObservation h;
    h.sigma = sigma;
    h.measured_height = p.z() - (bed_z + tilt_x * p.x() + tilt_y * p.y()) + sigma * n01(rng);
    m.observations.emplace_back(h);
    out.true_positions.push_back(p);
    out.measurements.poses.push_back(std::move(m));
  }
}

// A printed part: points printed at `printed` (commanded), distances between the listed pairs
// measured with σ `sigma`. The printed positions get no other observation.
inline void add_printed_distances(const calib::Mechanism& model, const Eigen::VectorXd& truth,
                                  const std::vector<Eigen::Vector3d>& printed,
                                  const std::vector<std::pair<int, int>>& pairs, double sigma,
                                  std::mt19937& rng, PrinterData& out) {
  const calib::MechanismPredictor pred(model);
  std::normal_distribution<double> n01(0.0, 1.0);
  std::vector<Eigen::Vector3d> truth_pts;
  for (std::size_t k = 0; k < printed.size(); ++k) {
    calib::PoseMeasurement m;
    m.id = fmt::format("print{}", k);
    m.actuators = commanded_readings(model, printed[k]);
    calib::FramePrediction fp;
    std::string why;
    if (!pred.predict(truth, m.actuators, -1, false, fp, why)) throw std::runtime_error(why);
    truth_pts.push_back(fp.pose.translation());
    out.true_positions.push_back(fp.pose.translation());
    out.measurements.poses.push_back(std::move(m));
  }
  for (const auto& [a, b] : pairs) {
    calib::DistanceMeasurement d;
    d.first = fmt::format("print{}", a);
    d.second = fmt::format("print{}", b);
    d.observation.sigma = sigma;
    d.observation.measured_distance =
        (truth_pts[static_cast<std::size_t>(a)] - truth_pts[static_cast<std::size_t>(b)]).norm() +
        sigma * n01(rng);
    out.measurements.distances.push_back(d);
  }
}

// The printed part: eight points on a circle of radius 0.09 m one layer above the bed, twelve
// caliper distances (the eight neighbours and four diameters).
inline std::vector<Eigen::Vector3d> printed_points() {
  std::vector<Eigen::Vector3d> pts;
  for (int k = 0; k < 8; ++k) {
    const double a = 2.0 * M_PI * k / 8.0;
    pts.emplace_back(0.09 * std::cos(a), 0.09 * std::sin(a), 0.005);
  }
  return pts;
}
inline std::vector<std::pair<int, int>> printed_pairs() {
  std::vector<std::pair<int, int>> pairs;
  for (int k = 0; k < 8; ++k) pairs.emplace_back(k, (k + 1) % 8);
  for (int k = 0; k < 4; ++k) pairs.emplace_back(k, k + 4);
  return pairs;
}

// Truth: nominal with the printer parameters perturbed (σ 0.3 mm; endstops σ 1 mm).
inline Eigen::VectorXd printer_truth(const calib::Mechanism& model, std::mt19937& rng) {
  std::normal_distribution<double> n01(0.0, 1.0);
  Eigen::VectorXd truth = model.nominal_parameters();
  for (const auto& name : printer_parameters()) {
    const int i = model.parameter_index(name);
    if (i < 0) throw std::runtime_error("no parameter " + name);
    const double s = name.find("encoder_offset") != std::string::npos ? 1e-3 : 0.3e-3;
    truth(i) += s * n01(rng);
  }
  return truth;
}

// Indices of the printer parameters (SolveOptions::candidates).
inline std::vector<std::size_t> printer_candidates(const calib::Mechanism& model) {
  std::vector<std::size_t> c;
  for (const auto& name : printer_parameters())
    c.push_back(static_cast<std::size_t>(model.parameter_index(name)));
  return c;
}

}  // namespace robocal::test
