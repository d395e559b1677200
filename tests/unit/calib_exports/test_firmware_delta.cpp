// Delta firmware exports, checked against the firmwares' documented equations written
// here independently of calib/identify/firmware_delta.cpp:
//   Klipper (klippy/kinematics/delta.py, config reference): towers at delta_radius, angle_i; the
//     carriage height at the endstop is position_endstop_i + sqrt(arm_length_i² - delta_radius²).
//   Marlin (M665 L R H X Y Z tower angle trims from 210/330/90, M666 X Y Z <= 0): homed at
//     (0, 0, H) after each carriage moved adj_i from its endstop: carriage height at the endstop
//     H + sqrt(L² - R²) - adj_i, one rod length L. (Marlin's homeaxis(), delta branch of
//     src/module/motion.cpp: after the endstop triggers, a carriage whose adjustment points away
//     from the endstop, adj * Z_HOME_DIR < 0, moves by adj; positive values are ignored. Then all
//     three are set to the position of (0, 0, delta_height).)
//   RepRapFirmware (M665 L a:b:c R H X Y Z, M666 X Y Z): homed carriage height
//     H + sqrt(L_i² - R²) + e_i (its M666 reference: a positive adjustment moves the head closer
//     to the bed near that tower, i.e. the firmware believes the carriage higher than it is).
// and for all: carriage height h_i = z + sqrt(L_i² - (x - x_i)² - (y - y_i)²), solved here for
// the nozzle by Newton's method (the library uses closed-form trilateration).
#include "../calib/calib_test_support.hpp"
#include "robocal/calib/closure.hpp"
#include "robocal/calib/firmware_delta.hpp"
#include "robocal/calib/kinematics.hpp"

#include <fmt/core.h>
#include <gtest/gtest.h>
#include <Eigen/Dense>

#include <cmath>
#include <map>
#include <numbers>

namespace robocal::calib {
namespace {

constexpr double kPi = std::numbers::pi;

struct Tower {
  double x, y, arm, endstop_height;  // mm; carriage height at the endstop
};

std::map<std::string, double> settings_map(const FirmwareDeltaFit& fit) {
  std::map<std::string, double> m;
  for (const auto& [k, v] : firmware_delta_settings(fit)) m[k] = v;
  return m;
}

// The firmware's towers from its own settings (mm, degrees), by its documentation.
std::array<Tower, 3> towers_of(DeltaFirmware firmware, std::map<std::string, double> s) {
  const double nominal[3] = {210.0, 330.0, 90.0};
  const char* abc[] = {"a", "b", "c"};
  const char* xyz[] = {"X", "Y", "Z"};
  std::array<Tower, 3> t{};
  for (int i = 0; i < 3; ++i) {
    double R = 0, angle = 0, arm = 0, endstop = 0;
    if (firmware == DeltaFirmware::kKlipper) {
      R = s["delta_radius"];
      angle = s[std::string("angle_") + abc[i]];
      arm = s[std::string("arm_length_") + abc[i]];
      endstop = s[std::string("position_endstop_") + abc[i]] + std::sqrt(arm * arm - R * R);
    } else if (firmware == DeltaFirmware::kMarlin) {
      R = s["R"];
      angle = nominal[i] + s[xyz[i]];
      arm = s["L"];
      const double adj = s[std::string("M666_") + xyz[i]];
      endstop = s["H"] + std::sqrt(arm * arm - R * R) - adj;
    } else {
      R = s["R"];
      angle = nominal[i] + s[xyz[i]];
      arm = s[std::string("L_") + abc[i]];
      endstop = s["H"] + std::sqrt(arm * arm - R * R) + s[std::string("M666_") + xyz[i]];
    }
    t[static_cast<std::size_t>(i)] = {R * std::cos(angle * kPi / 180),
                                      R * std::sin(angle * kPi / 180), arm, endstop};
  }
  return t;
}

// Nozzle (mm) for carriage heights h (mm): Newton on h_i = z + sqrt(L² - dx² - dy²).
Eigen::Vector3d nozzle_of(const std::array<Tower, 3>& t, const Eigen::Vector3d& h) {
  const auto equations = [&](const Eigen::Vector3d& p, Eigen::Vector3d& f, Eigen::Matrix3d& J) {
    for (int i = 0; i < 3; ++i) {
      const auto& w = t[static_cast<std::size_t>(i)];
      const double dx = p.x() - w.x, dy = p.y() - w.y;
      const double root = std::sqrt(w.arm * w.arm - dx * dx - dy * dy);
      f[i] = p.z() + root - h[i];
      J.row(i) << -dx / root, -dy / root, 1.0;
    }
    return f.allFinite();
  };
  Eigen::Vector3d p(0, 0, h.minCoeff() - t[0].arm);
  Eigen::Vector3d f;
  Eigen::Matrix3d J;
  EXPECT_TRUE(equations(p, f, J));
  for (int it = 0; it < 100 && f.norm() > 1e-11; ++it) {
    const Eigen::Vector3d step = J.lu().solve(f);
    // Backtrack while the step leaves the rods' reach or does not reduce the mismatch.
    double scale = 1.0;
    Eigen::Vector3d f_new;
    Eigen::Matrix3d J_new;
    while (scale > 1e-6 && !(equations(p - scale * step, f_new, J_new) && f_new.norm() < f.norm()))
      scale /= 2;
    p -= scale * step;
    f = f_new;
    J = J_new;
  }
  EXPECT_LT(f.norm(), 1e-9);
  return p;
}

struct Residual {
  double rms = 0, max = 0;
};

// The firmware's error over the fit's readings against the robot model's tool (computed here by
// the model's forward kinematics), in the firmware frame the fit reports. mm.
Residual firmware_residual(const Mechanism& model, const Eigen::VectorXd& params,
                           const FirmwareDeltaFit& fit, const std::array<Tower, 3>& towers) {
  const Eigen::Matrix3d R = (Eigen::AngleAxisd(fit.frame.pitch, Eigen::Vector3d::UnitY()) *
                             Eigen::AngleAxisd(fit.frame.roll, Eigen::Vector3d::UnitX()))
                                .toRotationMatrix();
  Residual r;
  for (const Eigen::Vector3d& reading : fit.readings) {
    const Eigen::VectorXd q = reading;
    // Seed the passive effector slides (x, y, z) below the carriages: the printer's branch.
    const Eigen::VectorXd seed = Eigen::Vector3d(0, 0, reading.minCoeff() - 0.2);
    const ForwardResult fk = forward_kinematics(model, params, q, model.tool, seed);
    EXPECT_TRUE(fk.closure.ok());
    EXPECT_LT(fk.pose.translation().z(), reading.minCoeff());  // every rod slopes down
    // linear_delta's base frame is the world (base.* nominal 0).
    const Eigen::Vector3d tool =
        (R * fk.pose.translation() + Eigen::Vector3d(fit.frame.x, fit.frame.y, 0)) * 1e3;
    Eigen::Vector3d h;
    for (int i = 0; i < 3; ++i)
      h[i] = towers[static_cast<std::size_t>(i)].endstop_height -
             (fit.model.endstop_reading[static_cast<std::size_t>(i)] - reading[i]) * 1e3;
    const double e = (nozzle_of(towers, h) - tool).norm();
    r.rms += e * e;
    r.max = std::max(r.max, e);
  }
  r.rms = std::sqrt(r.rms / static_cast<double>(fit.readings.size()));
  return r;
}

// A linear delta built exactly as the firmware's model: towers on one circle of radius R at the
// given angles (effector joints at their nominal offsets), rods L_i, endstop offsets off_i.
Eigen::VectorXd firmware_shaped(const Mechanism& m, double R,
                                const std::array<double, 3>& angle_deg,
                                const std::array<double, 3>& arm,
                                const std::array<double, 3>& offset) {
  Eigen::VectorXd p = m.nominal_parameters();
  const char* abc[] = {"a", "b", "c"};
  const auto set = [&](const std::string& name, double v) {
    const int i = m.parameter_index(name);
    ASSERT_GE(i, 0) << name;
    p[i] = v;
  };
  const auto get = [&](const std::string& name) { return p[m.parameter_index(name)]; };
  for (std::size_t i = 0; i < 3; ++i) {
    const std::string t = abc[i];
    const double a = angle_deg[i] * kPi / 180;
    set("tower_" + t + ".x", R * std::cos(a) + get("eff_joint_" + t + ".x"));
    set("tower_" + t + ".y", R * std::sin(a) + get("eff_joint_" + t + ".y"));
    set("rod_" + t + ".length", arm[i]);
    set("carriage_" + t + ".encoder_offset", offset[i]);
  }
  return p;
}

TEST(FirmwareDelta, AModelWithinTheFirmwaresParametersIsFittedBackExactly) {
  const Mechanism m = testing::load("linear_delta.yaml");
  const double R = 0.1412;
  const std::array<double, 3> angles = {209.6, 330.3, 90.0}, arms = {0.2712, 0.2695, 0.2703},
                              offsets = {0.0012, -0.0007, 0.0004};
  const Eigen::VectorXd p = firmware_shaped(m, R, angles, arms, offsets);
  const FirmwareDeltaFit fit = fit_firmware_delta(m, p, DeltaFirmware::kKlipper);
  ASSERT_GE(fit.readings.size(), 300u);
  EXPECT_LT(fit.residual_rms, 1e-9);
  EXPECT_LT(fit.residual_max, 1e-9);
  auto s = settings_map(fit);
  EXPECT_NEAR(s["delta_radius"], R * 1e3, 1e-6);
  const char* abc[] = {"a", "b", "c"};
  for (std::size_t i = 0; i < 3; ++i) {
    const std::string t = abc[i];
    EXPECT_NEAR(s["angle_" + t], angles[i], 1e-6) << t;
    EXPECT_NEAR(s["arm_length_" + t], arms[i] * 1e3, 1e-6) << t;
    // Carriage joint height = reading + offset; endstop at reading 0.45 (the tower's top limit).
    const double expected = (offsets[i] + 0.45 - std::sqrt(arms[i] * arms[i] - R * R)) * 1e3;
    EXPECT_NEAR(s["position_endstop_" + t], expected, 1e-6) << t;
  }
  // The firmware's documented equations reproduce the model from these numbers.
  const Residual r = firmware_residual(m, p, fit, towers_of(DeltaFirmware::kKlipper, s));
  EXPECT_LT(r.max, 1e-6);  // mm

  // RRF keeps per-tower rods too: exact; Marlin has one rod, so equal rods are exact for it.
  const FirmwareDeltaFit rrf = fit_firmware_delta(m, p, DeltaFirmware::kReprapFirmware);
  EXPECT_LT(rrf.residual_max, 1e-9);
  EXPECT_LT(
      firmware_residual(m, p, rrf, towers_of(DeltaFirmware::kReprapFirmware, settings_map(rrf)))
          .max,
      1e-6);
  const Eigen::VectorXd equal_rods =
      firmware_shaped(m, R, angles, {0.2704, 0.2704, 0.2704}, offsets);
  const FirmwareDeltaFit marlin = fit_firmware_delta(m, equal_rods, DeltaFirmware::kMarlin);
  EXPECT_LT(marlin.residual_max, 1e-9);
  auto ms = settings_map(marlin);
  EXPECT_NEAR(ms["L"], 270.4, 1e-6);
  EXPECT_NEAR(ms["X"], angles[0] - 210.0, 1e-6);
  EXPECT_NEAR(ms["Y"], angles[1] - 330.0, 1e-6);
  EXPECT_LT(firmware_residual(m, equal_rods, marlin, towers_of(DeltaFirmware::kMarlin, ms)).max,
            1e-6);
  // ...and different rods are what Marlin's one L cannot represent.
  const FirmwareDeltaFit marlin_unequal = fit_firmware_delta(m, p, DeltaFirmware::kMarlin);
  EXPECT_GT(marlin_unequal.residual_rms, 20e-6);
}

TEST(FirmwareDelta, TheReportedResidualIsTheFirmwaresOwnErrorOutsideItsModel) {
  const Mechanism m = testing::load("linear_delta.yaml");
  Eigen::VectorXd p = m.nominal_parameters();
  p[m.parameter_index("tower_a.roll")] += 0.004;    // tower A leans 4 mrad
  p[m.parameter_index("eff_joint_b.x")] += 0.0005;  // effector joint B 0.5 mm off
  p[m.parameter_index("rod_c.length")] += 0.0003;
  for (const DeltaFirmware fw :
       {DeltaFirmware::kKlipper, DeltaFirmware::kMarlin, DeltaFirmware::kReprapFirmware}) {
    const FirmwareDeltaFit fit = fit_firmware_delta(m, p, fw);
    const auto s = settings_map(fit);
    const Residual r = firmware_residual(m, p, fit, towers_of(fw, s));
    SCOPED_TRACE(to_string(fw));
    if (fw == DeltaFirmware::kMarlin) {
      for (const char* axis : {"M666_X", "M666_Y", "M666_Z"}) {
        EXPECT_LE(s.at(axis), 0.0) << "Marlin's endstop adjustments are <= 0";
      }
    }
    EXPECT_GT(fit.residual_rms, 5e-6);  // a tilt is not representable: a real residual
    EXPECT_NEAR(r.rms, fit.residual_rms * 1e3, 1e-6);
    EXPECT_NEAR(r.max, fit.residual_max * 1e3, 1e-6);
    // Least squares: no single firmware setting moved either way lowers the error.
    for (const auto& [name, value] : s) {
      for (const double step : {-1e-3, 1e-3}) {
        auto moved = s;
        moved[name] = value + step;
        EXPECT_GE(firmware_residual(m, p, fit, towers_of(fw, moved)).rms, r.rms - 1e-9) << name;
      }
    }
    const std::string text = firmware_delta_text(fit, m.name);
    EXPECT_NE(text.find(fmt::format("RMS {:.1f} um", fit.residual_rms * 1e6)), std::string::npos)
        << text;
  }
}

TEST(FirmwareDelta, RobotsThatAreNotLinearDeltasAreRefusedWithTheReason) {
  const auto why = [](const std::string& file) {
    return firmware_delta_mismatch(testing::load(file), DeltaFirmware::kKlipper);
  };
  EXPECT_EQ(why("linear_delta.yaml"), "");
  EXPECT_NE(why("rotary_delta.yaml").find("rotary arms"), std::string::npos);
  EXPECT_NE(why("rotary_delta.yaml").find("Klipper's delta kinematics is for three linear towers"),
            std::string::npos);
  EXPECT_NE(why("ur5.yaml").find("serial arm"), std::string::npos);
  EXPECT_NE(why("gantry_tau.yaml").find("not a vertical tower"), std::string::npos);
  const Mechanism tau = testing::load("gantry_tau.yaml");
  EXPECT_THROW(fit_firmware_delta(tau, tau.nominal_parameters(), DeltaFirmware::kMarlin),
               std::invalid_argument);
}

}  // namespace
}  // namespace robocal::calib
