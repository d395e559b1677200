// Linear-delta firmware settings fitted from the identified model (firmware_delta.hpp).
#include "robocal/calib/firmware_delta.hpp"

#include "robocal/calib/closure.hpp"
#include "robocal/calib/frame_placement.hpp"
#include "robocal/calib/kinematics.hpp"
#include "robocal/calib/mechanism_predictor.hpp"

#include <fmt/core.h>
#include <Eigen/Dense>

#include <cmath>
#include <numbers>
#include <random>
#include <stdexcept>

namespace robocal::calib {
namespace {

constexpr std::array<double, 3> kNominalAngleDeg = {210.0, 330.0, 90.0};  // towers A, B, C

double deg(double rad) {
  return rad * 180.0 / std::numbers::pi;
}

// A printed value without the sign of rounding noise ("-0.0000" reads like a correction).
double clean(double v) {
  return std::abs(v) < 5e-7 ? 0.0 : v;
}

// Degrees in (-180, 180].
double wrap_deg(double d) {
  d = std::fmod(d, 360.0);
  if (d > 180.0) d -= 360.0;
  if (d <= -180.0) d += 360.0;
  return d;
}

// Parameter vector of the fit: R, L (1 or 3), θ_a..c, c_a..c, frame x, y, roll, pitch.
struct Layout {
  bool shared_arm = false;  // Marlin: one diagonal rod for all towers
  int arms() const { return shared_arm ? 1 : 3; }
  int theta() const { return 1 + arms(); }
  int offset() const { return theta() + 3; }
  int frame() const { return offset() + 3; }
  int size() const { return frame() + 4; }
};

FirmwareDeltaModel unpack_model(const Layout& l, const Eigen::VectorXd& x,
                                const std::array<double, 3>& endstop_reading) {
  FirmwareDeltaModel m;
  m.delta_radius = x[0];
  for (int i = 0; i < 3; ++i) {
    m.arm_length[static_cast<std::size_t>(i)] = x[1 + (l.shared_arm ? 0 : i)];
    m.tower_angle[static_cast<std::size_t>(i)] = x[l.theta() + i];
    m.carriage_offset[static_cast<std::size_t>(i)] = x[l.offset() + i];
  }
  m.endstop_reading = endstop_reading;
  return m;
}

FirmwareFrame unpack_frame(const Layout& l, const Eigen::VectorXd& x) {
  return {x[l.frame()], x[l.frame() + 1], x[l.frame() + 2], x[l.frame() + 3]};
}

Eigen::Vector3d to_firmware_frame(const FirmwareFrame& f, const Eigen::Vector3d& p) {
  const Eigen::Matrix3d R = (Eigen::AngleAxisd(f.pitch, Eigen::Vector3d::UnitY()) *
                             Eigen::AngleAxisd(f.roll, Eigen::Vector3d::UnitX()))
                                .toRotationMatrix();
  return R * p + Eigen::Vector3d(f.x, f.y, 0.0);
}

// Stacked residuals firmware nozzle - tool (firmware frame); false if a pose does not assemble.
bool residuals(const Layout& l, const Eigen::VectorXd& x, const FirmwareDeltaFit& data,
               Eigen::VectorXd& out) {
  const FirmwareDeltaModel m = unpack_model(l, x, data.model.endstop_reading);
  const FirmwareFrame f = unpack_frame(l, x);
  out.resize(static_cast<Eigen::Index>(3 * data.readings.size()));
  for (std::size_t k = 0; k < data.readings.size(); ++k) {
    Eigen::Vector3d nozzle;
    if (!firmware_delta_position(m, data.readings[k], nozzle)) return false;
    out.segment<3>(static_cast<Eigen::Index>(3 * k)) =
        nozzle - to_firmware_frame(f, data.tool_in_base[k]);
  }
  return true;
}

// The root body the robot's geometry hangs from (the robot's base frame).
int root_of(const Mechanism& model, int body) {
  while (model.bodies[static_cast<std::size_t>(body)].parent >= 0)
    body = model.bodies[static_cast<std::size_t>(body)].parent;
  return body;
}

// Start of the fit: the robot file's closed form (nominal geometry).
Eigen::VectorXd initial_guess(const Layout& l, const Mechanism& model) {
  const ClosedFormSpec& s = model.closed_form;
  Eigen::VectorXd x = Eigen::VectorXd::Zero(l.size());
  double radius = 0.0, arm = 0.0;
  for (int i = 0; i < 3; ++i) {
    const auto k = static_cast<std::size_t>(i);
    const Eigen::Vector3d joint = s.rail_origin[k] - s.platform_offset[k];
    radius += joint.head<2>().norm() / 3.0;
    arm += s.link_length[k] / 3.0;
    if (!l.shared_arm) x[1 + i] = s.link_length[k];
    x[l.theta() + i] = std::atan2(joint.y(), joint.x());
    x[l.offset() + i] = joint.z();
  }
  x[0] = radius;
  if (l.shared_arm) x[1] = arm;
  return x;
}

// Levenberg-Marquardt with central-difference Jacobians (14 unknowns, a few hundred samples).
int least_squares(const Layout& l, const FirmwareDeltaFit& data, Eigen::VectorXd& x) {
  Eigen::VectorXd r;
  if (!residuals(l, x, data, r))
    throw std::runtime_error(
        "the firmware's delta model cannot reach the workspace samples from "
        "the robot file's nominal geometry");
  double cost = r.squaredNorm();
  double lambda = 1e-3;
  int iteration = 0;
  for (; iteration < 100; ++iteration) {
    Eigen::MatrixXd J(r.size(), x.size());
    for (Eigen::Index j = 0; j < x.size(); ++j) {
      const double h = 1e-7 * std::max(1.0, std::abs(x[j]));
      Eigen::VectorXd xp = x, xm = x, rp, rm;
      xp[j] += h;
      xm[j] -= h;
      if (!residuals(l, xp, data, rp) || !residuals(l, xm, data, rm))
        throw std::runtime_error("the firmware's delta model left its reach during the fit");
      J.col(j) = (rp - rm) / (2.0 * h);
    }
    const Eigen::MatrixXd JtJ = J.transpose() * J;
    const Eigen::VectorXd g = J.transpose() * r;
    bool improved = false;
    for (int attempt = 0; attempt < 20 && !improved; ++attempt) {
      Eigen::MatrixXd A = JtJ;
      A.diagonal() *= 1.0 + lambda;
      const Eigen::VectorXd step = A.ldlt().solve(-g);
      Eigen::VectorXd trial_r;
      const Eigen::VectorXd trial = x + step;
      if (residuals(l, trial, data, trial_r) && trial_r.squaredNorm() <= cost) {
        const double gain = cost - trial_r.squaredNorm();
        x = trial;
        r = trial_r;
        cost = r.squaredNorm();
        lambda = std::max(lambda / 10.0, 1e-12);
        improved = true;
        if (step.norm() < 1e-13 || gain <= 1e-30) return iteration + 1;
      } else {
        lambda *= 10.0;
      }
    }
    if (!improved) break;  // at the minimum to machine precision
  }
  return iteration;
}

}  // namespace

const char* to_string(DeltaFirmware firmware) {
  switch (firmware) {
    case DeltaFirmware::kKlipper:
      return "Klipper";
    case DeltaFirmware::kMarlin:
      return "Marlin";
    case DeltaFirmware::kReprapFirmware:
      return "RepRapFirmware";
  }
  return "?";
}

bool firmware_delta_position(const FirmwareDeltaModel& m, const Eigen::Vector3d& readings,
                             Eigen::Vector3d& nozzle) {
  // Trilateration: the nozzle is L_i from each carriage joint (tower point at height h_i).
  std::array<Eigen::Vector3d, 3> p;
  for (std::size_t i = 0; i < 3; ++i)
    p[i] = {m.delta_radius * std::cos(m.tower_angle[i]),
            m.delta_radius * std::sin(m.tower_angle[i]),
            readings[static_cast<Eigen::Index>(i)] + m.carriage_offset[i]};
  const Eigen::Vector3d p12 = p[1] - p[0], p13 = p[2] - p[0];
  const double d = p12.norm();
  const Eigen::Vector3d ex = p12 / d;
  const double i = ex.dot(p13);
  Eigen::Vector3d ey = p13 - i * ex;
  const double j = ey.norm();
  if (d <= 0.0 || j <= 0.0) return false;
  ey /= j;
  Eigen::Vector3d ez = ex.cross(ey);
  if (ez.z() > 0) ez = -ez;  // the solution below the carriages
  const double l1 = m.arm_length[0] * m.arm_length[0], l2 = m.arm_length[1] * m.arm_length[1],
               l3 = m.arm_length[2] * m.arm_length[2];
  const double x = (l1 - l2 + d * d) / (2.0 * d);
  const double y = (l1 - l3 + i * i + j * j) / (2.0 * j) - i * x / j;
  const double z2 = l1 - x * x - y * y;
  if (!(z2 >= 0.0)) return false;
  nozzle = p[0] + x * ex + y * ey + std::sqrt(z2) * ez;
  return true;
}

std::string firmware_delta_mismatch(const Mechanism& model, DeltaFirmware firmware) {
  const std::string who = fmt::format("'{}'", model.name);
  const std::string fw = to_string(firmware);
  const std::string needs =
      fmt::format("{}'s delta kinematics is for three linear towers (vertical carriages)", fw);
  switch (model.closed_form.kind) {
    case ClosedFormKind::kRotaryDelta:
      return fmt::format("{} has rotary arms (motors turn the shoulders); {}", who, needs);
    case ClosedFormKind::kGantryTau:
    case ClosedFormKind::kNone:
      return model.closures.empty()
                 ? fmt::format("{} is a serial arm (no closed loops); {}", who, needs)
                 : fmt::format(
                       "{} is not a linear delta (its robot file declares no rails "
                       "closed form); {}",
                       who, needs);
    case ClosedFormKind::kLinearDelta:
      break;
  }
  const ClosedFormSpec& s = model.closed_form;
  if (model.actuated.size() != 3 || s.rail_direction.size() != 3 || s.link_length.size() != 3)
    return fmt::format("{} has {} actuated carriages; {}", who, model.actuated.size(), needs);
  for (std::size_t i = 0; i < 3; ++i) {
    const Eigen::Vector3d v = s.rail_direction[i].normalized();
    if (v.z() < std::cos(5.0 * std::numbers::pi / 180.0))
      return fmt::format(
          "{}'s carriage {} runs along ({:.3g}, {:.3g}, {:.3g}), not a vertical "
          "tower (its rails are guideways); {}",
          who, i + 1, v.x(), v.y(), v.z(), needs);
    if (model.bodies[static_cast<std::size_t>(model.actuated[i])].joint != JointType::kPrismatic)
      return fmt::format("{}'s actuated joint {} is not a carriage (prismatic); {}", who, i + 1,
                         needs);
  }
  return "";
}

FirmwareDeltaFit fit_firmware_delta(const Mechanism& model, const Eigen::VectorXd& params,
                                    DeltaFirmware firmware, const FirmwareDeltaOptions& options) {
  if (const std::string why = firmware_delta_mismatch(model, firmware); !why.empty())
    throw std::invalid_argument(why);
  FirmwareDeltaFit fit;
  fit.firmware = firmware;
  for (std::size_t i = 0; i < 3; ++i) {
    const Body& carriage = model.bodies[static_cast<std::size_t>(model.actuated[i])];
    // Nominal encoder model: the controller's reading where the endstop sits.
    const double scale =
        carriage.encoder_scale_param >= 0
            ? model.parameters[static_cast<std::size_t>(carriage.encoder_scale_param)].value
            : 1.0;
    const double offset =
        carriage.encoder_offset_param >= 0
            ? model.parameters[static_cast<std::size_t>(carriage.encoder_offset_param)].value
            : 0.0;
    fit.model.endstop_reading[i] = std::isnan(options.endstop_reading)
                                       ? (carriage.limits.upper - offset) / scale
                                       : options.endstop_reading;
  }
  // Workspace: readings where the identified model assembles on its intended mode.
  const MechanismPredictor predictor(model, model.tool);
  std::mt19937 rng(options.seed);
  // Twice the samples wanted: poses a printer never takes are dropped below.
  const auto samples = sample_actuators(predictor, {params}, 2 * options.samples, rng);
  const int base = root_of(model, model.tool);
  // The base frame hangs from the world by fixed joints: its pose needs no closure.
  const Eigen::Isometry3d base_pose = frame_pose(
      model, params, make_joint_state(model, params, samples.front(), model.home_passive()), base);
  const Layout layout{firmware == DeltaFirmware::kMarlin};
  Eigen::VectorXd x = initial_guess(layout, model);
  for (std::size_t k = 0; k < samples.size() && fit.readings.size() < options.samples; ++k) {
    FramePrediction tool;
    std::string why;
    if (!predictor.predict(params, samples[k], static_cast<int>(k), false, tool, why)) continue;
    const Eigen::VectorXd& r = samples[k];
    const Eigen::Vector3d p = base_pose.inverse() * tool.pose.translation();
    // A printer works with every rod sloping down from its carriage (the firmwares' equation
    // h = z + sqrt(L² - d²) has no other branch): keep rods at least 10 % of their length
    // steep, by the nominal geometry.
    bool printer_pose = true;
    for (int i = 0; i < 3; ++i)
      printer_pose =
          printer_pose && r[i] + x[layout.offset() + i] - p.z() >=
                              0.1 * model.closed_form.link_length[static_cast<std::size_t>(i)];
    if (!printer_pose) continue;
    fit.readings.emplace_back(r[0], r[1], r[2]);
    fit.tool_in_base.push_back(p);
  }
  if (fit.readings.size() < 20)
    throw std::runtime_error(fmt::format(
        "only {} workspace positions of '{}' have every rod sloping down from its carriage: too "
        "few to fit the firmware's model",
        fit.readings.size(), model.name));
  // The uncorrected firmware (the drawing's numbers) against the calibrated model, for scale.
  Eigen::VectorXd r_nominal;
  if (residuals(layout, x, fit, r_nominal)) {
    double sum = 0.0;
    for (std::size_t k = 0; k < fit.readings.size(); ++k) {
      const double e = r_nominal.segment<3>(static_cast<Eigen::Index>(3 * k)).norm();
      sum += e * e;
      fit.nominal_max = std::max(fit.nominal_max, e);
    }
    fit.nominal_rms = std::sqrt(sum / static_cast<double>(fit.readings.size()));
  }
  fit.iterations = least_squares(layout, fit, x);
  fit.model = unpack_model(layout, x, fit.model.endstop_reading);
  fit.frame = unpack_frame(layout, x);
  Eigen::VectorXd r;
  residuals(layout, x, fit, r);
  double sum = 0.0;
  for (std::size_t k = 0; k < fit.readings.size(); ++k) {
    const double e = r.segment<3>(static_cast<Eigen::Index>(3 * k)).norm();
    sum += e * e;
    fit.residual_max = std::max(fit.residual_max, e);
  }
  fit.residual_rms = std::sqrt(sum / static_cast<double>(fit.readings.size()));
  return fit;
}

FirmwareController firmware_delta_controller(const Mechanism& model, const Eigen::VectorXd& params,
                                             const FirmwareDeltaFit& fit) {
  if (const std::string why = firmware_delta_mismatch(model, fit.firmware); !why.empty())
    throw std::invalid_argument(why);
  const auto refuse = [&](const std::string& why) {
    return std::invalid_argument(fmt::format(
        "'{}': the robot file's layout does not carry {}'s delta model ({}): compensate for the "
        "robot file's drawing instead",
        model.name, to_string(fit.firmware), why));
  };
  const auto set = [&](Eigen::VectorXd& p, const std::string& name, double value) {
    const int i = model.parameter_index(name);
    if (i < 0) throw refuse("no parameter " + name);
    p[i] = value;
  };
  const auto zero_body = [&](Eigen::VectorXd& p, int body) {
    for (std::size_t i = 0; i < model.parameters.size(); ++i)
      if (model.parameters[i].body == body &&
          model.parameters[i].group != ParamGroup::kEncoderScale)
        p[static_cast<Eigen::Index>(i)] = 0.0;
  };
  FirmwareController out;
  Eigen::VectorXd& c = out.controller;
  c = params;
  // The firmware's frame is the controller's world: the base at identity, the nozzle at the
  // effector's centre (every frame from the base to the tool at zero).
  for (int b = model.tool; b >= 0; b = model.bodies[static_cast<std::size_t>(b)].parent)
    zero_body(c, b);
  const FirmwareDeltaModel& m = fit.model;
  for (std::size_t i = 0; i < 3; ++i) {
    const int carriage = model.actuated[i];
    const Body& cb = model.bodies[static_cast<std::size_t>(carriage)];
    const int tower = cb.parent;
    if (tower <= 0 || model.bodies[static_cast<std::size_t>(tower)].parent != 0)
      throw refuse("carriage '" + cb.name + "' does not hang from a tower body on the base");
    int rod = -1, joint = -1;
    for (const Closure& cl : model.closures)
      if (cl.type == ClosureType::kDistance && (cl.body_a == carriage || cl.body_b == carriage)) {
        rod = cl.length_param;
        joint = cl.body_a == carriage ? cl.body_b : cl.body_a;
      }
    if (rod < 0) throw refuse("no rod from carriage '" + cb.name + "'");
    const std::string& tower_name = model.bodies[static_cast<std::size_t>(tower)].name;
    const std::string& joint_name = model.bodies[static_cast<std::size_t>(joint)].name;
    // The effector joint keeps its place in the effector's plane; the tower stands the firmware's
    // delta radius from it, at the tower's angle.
    zero_body(c, joint);
    const int jx = model.parameter_index(joint_name + ".x");
    const int jy = model.parameter_index(joint_name + ".y");
    if (jx < 0 || jy < 0)
      throw refuse("effector joint '" + joint_name + "' is not an xyz_rpy frame");
    c[jx] = params[jx];
    c[jy] = params[jy];
    zero_body(c, tower);
    set(c, tower_name + ".x", m.delta_radius * std::cos(m.tower_angle[i]) + c[jx]);
    set(c, tower_name + ".y", m.delta_radius * std::sin(m.tower_angle[i]) + c[jy]);
    zero_body(c, carriage);
    if (cb.encoder_offset_param < 0) throw refuse("carriage '" + cb.name + "' has no encoder");
    c[cb.encoder_offset_param] = m.carriage_offset[i];
    if (cb.encoder_scale_param >= 0) c[cb.encoder_scale_param] = 1.0;
    c[rod] = m.arm_length[i];
  }
  // The calibrated robot in the firmware's frame: p_firmware = Ry(pitch) Rx(roll) p_base + (x, y).
  out.calibrated = params;
  Eigen::Isometry3d firmware_T_base = Eigen::Isometry3d::Identity();
  firmware_T_base.linear() = (Eigen::AngleAxisd(fit.frame.pitch, Eigen::Vector3d::UnitY()) *
                              Eigen::AngleAxisd(fit.frame.roll, Eigen::Vector3d::UnitX()))
                                 .toRotationMatrix();
  firmware_T_base.translation() = Eigen::Vector3d(fit.frame.x, fit.frame.y, 0.0);
  const Eigen::VectorXd r0 = fit.readings.front();
  const Eigen::Isometry3d world_T_base = forward_kinematics(model, params, r0, 0).pose;
  set_fixed_frame_pose(model, out.calibrated, 0, r0, firmware_T_base * world_T_base);
  // The layout carried the firmware's model only if it computes the firmware's nozzle.
  for (std::size_t k = 0; k < fit.readings.size(); k += 10) {
    Eigen::Vector3d nozzle;
    if (!firmware_delta_position(m, fit.readings[k], nozzle)) continue;
    const ForwardResult fk = forward_kinematics(model, c, fit.readings[k], model.tool);
    if (!fk.closure.ok() || (fk.pose.translation() - nozzle).norm() > 1e-9)
      throw refuse(
          fmt::format("its forward kinematics with the settings is {:.3g} m from the "
                      "firmware's",
                      fk.closure.ok() ? (fk.pose.translation() - nozzle).norm() : 1.0));
  }
  return out;
}

std::vector<std::pair<std::string, double>> firmware_delta_settings(const FirmwareDeltaFit& fit) {
  const FirmwareDeltaModel& m = fit.model;
  const double R = m.delta_radius;
  std::array<double, 3> s{}, k{};  // sqrt(L² - R²); carriage height at the endstop minus s
  for (std::size_t i = 0; i < 3; ++i) {
    s[i] = std::sqrt(m.arm_length[i] * m.arm_length[i] - R * R);
    k[i] = m.carriage_offset[i] + m.endstop_reading[i] - s[i];
  }
  std::vector<std::pair<std::string, double>> out;
  const char* abc[] = {"a", "b", "c"};
  const char* xyz[] = {"X", "Y", "Z"};
  switch (fit.firmware) {
    case DeltaFirmware::kKlipper:
      out.emplace_back("delta_radius", R * 1e3);
      for (std::size_t i = 0; i < 3; ++i) {
        double a = std::fmod(deg(m.tower_angle[i]), 360.0);
        if (a < 0) a += 360.0;
        out.emplace_back(std::string("angle_") + abc[i], a);
        out.emplace_back(std::string("arm_length_") + abc[i], m.arm_length[i] * 1e3);
        // Klipper: carriage height at the endstop = position_endstop + sqrt(arm² - R²).
        out.emplace_back(std::string("position_endstop_") + abc[i], k[i] * 1e3);
      }
      break;
    case DeltaFirmware::kMarlin: {
      // Marlin: homed at (0, 0, H) after each carriage moved M666 adj_i (<= 0) from its
      // endstop, so the carriage height at the endstop is H + sqrt(L² - R²) - adj_i. (Marlin's
      // homeaxis() for a delta moves a carriage by its adjustment only when that points away from
      // the endstop and ignores positive values: H is the lowest k, so every adj_i <= 0 counts.)
      const double H = std::min({k[0], k[1], k[2]});
      out.emplace_back("L", m.arm_length[0] * 1e3);
      out.emplace_back("R", R * 1e3);
      out.emplace_back("H", H * 1e3);
      for (std::size_t i = 0; i < 3; ++i)
        out.emplace_back(xyz[i], wrap_deg(deg(m.tower_angle[i]) - kNominalAngleDeg[i]));
      for (std::size_t i = 0; i < 3; ++i)
        out.emplace_back(std::string("M666_") + xyz[i], (H - k[i]) * 1e3);
      break;
    }
    case DeltaFirmware::kReprapFirmware: {
      // RRF: homed carriage height = H + sqrt(L_i² - R²) + M666 e_i, e normalised to mean 0.
      const double H = (k[0] + k[1] + k[2]) / 3.0;
      for (std::size_t i = 0; i < 3; ++i)
        out.emplace_back(std::string("L_") + abc[i], m.arm_length[i] * 1e3);
      out.emplace_back("R", R * 1e3);
      out.emplace_back("H", H * 1e3);
      for (std::size_t i = 0; i < 3; ++i)
        out.emplace_back(xyz[i], wrap_deg(deg(m.tower_angle[i]) - kNominalAngleDeg[i]));
      for (std::size_t i = 0; i < 3; ++i)
        out.emplace_back(std::string("M666_") + xyz[i], (k[i] - H) * 1e3);
      break;
    }
  }
  for (auto& [name, value] : out) value = clean(value);
  return out;
}

std::string firmware_delta_text(const FirmwareDeltaFit& fit, const std::string& robot_name,
                                const FirmwareTextNotes& notes) {
  const auto settings = firmware_delta_settings(fit);
  const auto get = [&](const std::string& name) {
    for (const auto& [key, value] : settings)
      if (key == name) return value;
    throw std::logic_error("firmware setting " + name + " missing");
  };
  const char c = fit.firmware == DeltaFirmware::kKlipper ? '#' : ';';
  std::string t;
  t += fmt::format(
      "{} robocal: {} delta settings for '{}', fitted to the calibrated model over {} "
      "workspace positions\n",
      c, to_string(fit.firmware), robot_name, fit.readings.size());
  t += fmt::format(
      "{} residual of {}'s delta model against the calibrated model: RMS {:.1f} um, "
      "max {:.1f} um\n",
      c, to_string(fit.firmware), fit.residual_rms * 1e6, fit.residual_max * 1e6);
  t += fmt::format(
      "{} (what the firmware cannot represent: tower tilt, towers off one circle, "
      "per-tower effector offsets{})\n",
      c, fit.firmware == DeltaFirmware::kMarlin ? ", rod lengths that differ" : "");
  t += fmt::format(
      "{} what these settings keep: the firmware with the robot file's drawing is RMS {:.1f} um, "
      "max {:.1f} um from the calibrated model; with these settings RMS {:.1f} um, max {:.1f} um\n",
      c, fit.nominal_rms * 1e6, fit.nominal_max * 1e6, fit.residual_rms * 1e6,
      fit.residual_max * 1e6);
  if (std::isfinite(notes.model_rms))
    t += fmt::format(
        "{} robocal's full calibrated model follows the measurements to {:.1f} um RMS\n", c,
        notes.model_rms * 1e6);
  if (!notes.compensate.empty())
    t += fmt::format(
        "{} for the rest: {} rewrites G-code programs for the printer running these settings, "
        "so that it follows them with the full calibrated model's accuracy\n",
        c, notes.compensate);
  if (!notes.tool.empty()) t += fmt::format("{} nozzle: {}\n", c, notes.tool);
  if (!notes.measured.empty()) t += fmt::format("{} measured: {}\n", c, notes.measured);
  t += fmt::format(
      "{} assumes the endstops trigger at carriage readings {:.3f}, {:.3f}, {:.3f} mm\n", c,
      fit.model.endstop_reading[0] * 1e3, fit.model.endstop_reading[1] * 1e3,
      fit.model.endstop_reading[2] * 1e3);
  t += fmt::format(
      "{} heights are from the robot file's base plane: set the nozzle-to-bed height "
      "(Z offset) as usual after loading these\n",
      c);
  t += fmt::format(
      "{} the robot's base origin in the firmware frame: x {:+.3f} mm, y {:+.3f} mm; "
      "base tilted {:+.3f} / {:+.3f} mrad about x / y\n",
      c, clean(fit.frame.x * 1e3), clean(fit.frame.y * 1e3), clean(fit.frame.roll * 1e3),
      clean(fit.frame.pitch * 1e3));
  switch (fit.firmware) {
    case DeltaFirmware::kKlipper:
      t += fmt::format("[printer]\nkinematics: delta\ndelta_radius: {:.6f}\n", get("delta_radius"));
      for (const char* tower : {"a", "b", "c"})
        t += fmt::format(
            "\n[stepper_{0}]\nangle: {1:.6f}\narm_length: {2:.6f}\nposition_endstop: "
            "{3:.6f}\n",
            tower, get(std::string("angle_") + tower), get(std::string("arm_length_") + tower),
            get(std::string("position_endstop_") + tower));
      break;
    case DeltaFirmware::kMarlin:
      t += "; S (segments per second) is not geometry: keep yours; one diagonal rod L for all "
           "towers\n";
      t += fmt::format("M665 L{:.4f} R{:.4f} H{:.4f} X{:.4f} Y{:.4f} Z{:.4f}\n", get("L"), get("R"),
                       get("H"), get("X"), get("Y"), get("Z"));
      t += fmt::format("M666 X{:.4f} Y{:.4f} Z{:.4f}\nM500 ; store\n", get("M666_X"), get("M666_Y"),
                       get("M666_Z"));
      break;
    case DeltaFirmware::kReprapFirmware:
      t += "; B (printable radius) is not geometry: keep yours; endstop adjustments have mean 0\n";
      t += fmt::format("M665 L{:.4f}:{:.4f}:{:.4f} R{:.4f} H{:.4f} X{:.4f} Y{:.4f} Z{:.4f}\n",
                       get("L_a"), get("L_b"), get("L_c"), get("R"), get("H"), get("X"), get("Y"),
                       get("Z"));
      t += fmt::format("M666 X{:.4f} Y{:.4f} Z{:.4f}\n", get("M666_X"), get("M666_Y"),
                       get("M666_Z"));
      break;
  }
  return t;
}

}  // namespace robocal::calib
