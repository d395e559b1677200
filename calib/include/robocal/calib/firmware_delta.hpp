#pragma once
// Linear-delta printer firmware settings fitted from an identified robot model.
//
// The firmwares (Klipper `kinematics: delta`, Marlin and RepRapFirmware M665/M666) know a smaller
// delta model than robocal's: three vertical towers on one circle of radius R (delta radius = the
// horizontal distance carriage joint -> effector joint with the effector centred) at angles θ_i,
// one rod length L_i per tower (Marlin: one for all), and per-tower carriage height offsets. The
// firmware places the nozzle (x, y, z) where, for every tower,
//     h_i = z + sqrt(L_i² - (x - R cos θ_i)² - (y - R sin θ_i)²)
// with h_i the carriage height in the firmware's frame. The firmware's carriage height is the
// controller's carriage reading r_i shifted by a constant, h_i = r_i + c_i; what the firmwares call
// endstop position / homed height / endstop adjustment are c_i written relative to the carriage
// reading at which the endstop triggers (see each writer).
//
// fit_firmware_delta fits (R, L_i, θ_i, c_i) by least squares so that the firmware model's forward
// kinematics reproduces the identified model's tool positions at the same carriage readings over
// the workspace, up to where the firmware frame sits in the robot's base frame (a translation in x,
// y and a tilt: the firmware frame is the towers', the printer's prints are placed relative to
// its bed, so these are not errors of the printer; z is carried by c_i and the turn about z by
// θ_i). What remains — tower tilts, a non-circular tower placement, effector joint offsets that
// differ per tower, encoder scale errors — is what the firmware cannot represent: the residual.
#include "robocal/calib/mechanism.hpp"

#include <Eigen/Core>

#include <array>
#include <cstdint>
#include <limits>
#include <string>
#include <utility>
#include <vector>

namespace robocal::calib {

enum class DeltaFirmware : std::uint8_t { kKlipper, kMarlin, kReprapFirmware };

const char* to_string(DeltaFirmware firmware);

// The common smaller model, SI units (m, rad). Towers in the order A, B, C of the robot file's
// actuated joints (Klipper stepper_a/b/c, Marlin/RRF X/Y/Z towers).
struct FirmwareDeltaModel {
  double delta_radius = 0.0;
  std::array<double, 3> arm_length{};
  std::array<double, 3> tower_angle{};      // θ_i, rad, about the firmware's z
  std::array<double, 3> carriage_offset{};  // c_i: h_i = reading_i + c_i
  std::array<double, 3> endstop_reading{};  // reading at which tower i's endstop triggers
};

// Where the firmware frame sits in the robot's base frame: p_firmware = R_y(pitch)·R_x(roll)·p_base
// + (x, y, 0).
struct FirmwareFrame {
  double x = 0.0, y = 0.0, roll = 0.0, pitch = 0.0;
};

// The firmware's forward kinematics: nozzle position (firmware frame) for carriage readings (the
// solution below the carriages). false when the rods cannot reach (no real solution).
bool firmware_delta_position(const FirmwareDeltaModel& model, const Eigen::Vector3d& readings,
                             Eigen::Vector3d& nozzle);

struct FirmwareDeltaFit {
  DeltaFirmware firmware = DeltaFirmware::kKlipper;
  FirmwareDeltaModel model;
  FirmwareFrame frame;
  // The workspace samples: carriage readings and the identified model's tool position in the
  // robot's base frame at each (the ground truth the firmware model is fitted to).
  std::vector<Eigen::Vector3d> readings;
  std::vector<Eigen::Vector3d> tool_in_base;
  // Residual of the firmware's model: |firmware nozzle - tool| in the firmware frame, m.
  double residual_rms = 0.0;
  double residual_max = 0.0;
  // The same distance with the firmware set to the robot file's drawing (the closed form's
  // radius, rods, tower angles and endstops; the firmware frame on the base frame): how far the
  // uncorrected firmware is from the calibrated model, m.
  double nominal_rms = 0.0;
  double nominal_max = 0.0;
  int iterations = 0;
};

struct FirmwareDeltaOptions {
  std::size_t samples = 400;  // workspace samples (sample_actuators, intended mode)
  unsigned seed = 1;
  // Reading at which each endstop triggers; NaN = the actuated joint's upper limit in the robot
  // file (the endstops sit at the top of the towers).
  double endstop_reading = std::numeric_limits<double>::quiet_NaN();
};

// Why `model` cannot be written as delta firmware settings, or "" when it can: it must be a
// linear delta (closed_form rails) with three actuated prismatic carriages on vertical rails.
std::string firmware_delta_mismatch(const Mechanism& model, DeltaFirmware firmware);

// Fits the firmware's model to `model` at parameter vector `params` (throws std::invalid_argument
// with firmware_delta_mismatch's reason when it does not map, std::runtime_error when too few
// workspace samples assemble).
FirmwareDeltaFit fit_firmware_delta(const Mechanism& model, const Eigen::VectorXd& params,
                                    DeltaFirmware firmware,
                                    const FirmwareDeltaOptions& options = {});

// A printer running the fitted settings, as parameter vectors of the robot's own mechanism, for
// compensation (compensation.hpp) against the firmware instead of the robot file's drawing:
// `controller` is the firmware's model (towers on its circle at its angles, its rods, carriage
// offsets c_i, the nozzle at the effector's centre) in the firmware's frame; `calibrated` is
// `params` (the calibrated robot in its own base frame) moved into the firmware's frame. Both
// put tool positions in the firmware's coordinates, the ones a program for it is written in.
// Throws std::invalid_argument when the robot file's layout does not carry the firmware's model
// (each carriage on a fixed tower body hanging from the base, a rod from the carriage to an
// effector joint, xyz_rpy frames): checked by reproducing the firmware's forward kinematics at
// the fit's workspace samples to 1 nm.
struct FirmwareController {
  Eigen::VectorXd controller;
  Eigen::VectorXd calibrated;
};
FirmwareController firmware_delta_controller(const Mechanism& model, const Eigen::VectorXd& params,
                                             const FirmwareDeltaFit& fit);

// What the settings' comments say besides the fit itself (all optional).
struct FirmwareTextNotes {
  std::string tool;      // where the nozzle is, e.g. "the robot file's tool 'tool' (nozzle)"
  std::string measured;  // the frame the calibration measured instead, in words
  // How closely robocal's calibrated model follows the measurements (RMS, m; NaN: unknown).
  double model_rms = std::numeric_limits<double>::quiet_NaN();
  // The command that carries what the firmware cannot, for a printer running these settings
  // ("" = none named).
  std::string compensate;
};

// The firmware's settings as the user pastes them, with the residual and the assumptions in
// comments: Klipper printer.cfg sections; Marlin M665/M666; RepRapFirmware M665/M666.
std::string firmware_delta_text(const FirmwareDeltaFit& fit, const std::string& robot_name,
                                const FirmwareTextNotes& notes = {});

// The firmware's own numbers (mm, degrees) by the names it uses, for JSON and tests: Klipper
// delta_radius, arm_length_a.., angle_a.., position_endstop_a..; Marlin L R H X Y Z (tower angle
// trims) and M666 X Y Z; RRF L_a.. R H X Y Z and M666 X Y Z.
std::vector<std::pair<std::string, double>> firmware_delta_settings(const FirmwareDeltaFit& fit);

}  // namespace robocal::calib
