// Delta firmware geometry: the reply lines exactly as Marlin 2.x (M503's M665/M666 lines, M114 on
// a delta) and RepRapFirmware 3.x (M665/M666 without parameters) print them, and the firmware's
// kinematics against closed forms written here.
#include "robocal/calib/robot_file.hpp"
#include "robocal/robotio/delta_firmware.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>

namespace robocal::robotio {
namespace {

TEST(DeltaFirmware, ReadsMarlinsM503DeltaLines) {
  const std::string heading =
      "echo:; Delta (L<diagonal rod> R<radius> H<height> S<segments per sec> XYZ<tower angle "
      "trim> ABC<rod trim>):";
  const std::vector<std::string> m503 = {
      "echo:; Steps per unit:",
      "echo:  M92 X80.00 Y80.00 Z80.00 E93.00",
      "echo:; Endstop adjustment:",
      "echo:  M666 X-0.41 Y0.00 Z-1.20",
      heading,
      "echo:  M665 L215.00 R105.20 H250.50 S200.00 X0.30 Y-0.20 Z0.00 A0.00 B0.50 C-0.25"};
  const auto g = parse_marlin_delta_settings(m503);
  ASSERT_TRUE(g);
  EXPECT_DOUBLE_EQ(g->diagonal_rod[0], 215.0);
  EXPECT_DOUBLE_EQ(g->diagonal_rod[1], 215.5);  // L + B trim
  EXPECT_DOUBLE_EQ(g->diagonal_rod[2], 214.75);
  EXPECT_DOUBLE_EQ(g->radius, 105.2);
  EXPECT_DOUBLE_EQ(g->height, 250.5);
  EXPECT_DOUBLE_EQ(g->angle_trim[0], 0.3);
  EXPECT_DOUBLE_EQ(g->angle_trim[1], -0.2);
  EXPECT_DOUBLE_EQ(g->endstop_adjustment[0], -0.41);
  EXPECT_DOUBLE_EQ(g->endstop_adjustment[2], -1.2);
  // Older Marlin without rod trims: one rod for all towers.
  const auto old = parse_marlin_delta_settings({"echo:  M665 L250.00 R124.00 H250.00 S200.00"});
  ASSERT_TRUE(old);
  EXPECT_DOUBLE_EQ(old->diagonal_rod[2], 250.0);
}

TEST(DeltaFirmware, AMarlinWithoutM665IsNotADelta) {
  EXPECT_FALSE(parse_marlin_delta_settings(
      {"echo:; Steps per unit:", "echo:  M92 X80.00 Y80.00 Z400.00 E93.00"}));
  EXPECT_FALSE(parse_marlin_delta_settings({"echo:  M665 Lfoo R124.00 H250.00"}));
}

TEST(DeltaFirmware, ReadsRepRapFirmwaresM665AndM666Replies) {
  const auto g = parse_rrf_delta_settings(
      {"Diagonals 215.000:215.500:214.750, delta radius 105.200, homed height 250.500, bed "
       "radius 85.0, X 0.300\u00b0, Y -0.200\u00b0, Z 0.000\u00b0"},
      {"Endstop adjustments X0.35 Y-0.95 Z0.60, tilt X0.10% Y-0.20%"});
  ASSERT_TRUE(g);
  EXPECT_DOUBLE_EQ(g->diagonal_rod[1], 215.5);
  EXPECT_DOUBLE_EQ(g->radius, 105.2);
  EXPECT_DOUBLE_EQ(g->height, 250.5);
  EXPECT_DOUBLE_EQ(g->angle_trim[0], 0.3);
  EXPECT_DOUBLE_EQ(g->angle_trim[1], -0.2);
  EXPECT_DOUBLE_EQ(g->endstop_adjustment[0], 0.35);
  EXPECT_DOUBLE_EQ(g->endstop_adjustment[1], -0.95);
  EXPECT_DOUBLE_EQ(g->endstop_adjustment[2], 0.6);
  EXPECT_DOUBLE_EQ(g->tilt_x, 0.001);
  EXPECT_DOUBLE_EQ(g->tilt_y, -0.002);
  // A Cartesian RRF refuses the query in its own words.
  EXPECT_FALSE(
      parse_rrf_delta_settings({"Error: M665 parameters do not apply to Cartesian kinematics"},
                               {"Error: M666 parameters do not apply to Cartesian kinematics"}));
}

TEST(DeltaFirmware, TheSimulatorsRepliesReadBack) {
  DeltaGeometry g;
  g.firmware = Firmware::kRepRapFirmware;
  g.diagonal_rod = {270.0, 270.5, 269.75};
  g.radius = 140.0;
  g.height = 221.5;
  g.angle_trim = {0.3, -0.2, 0.1};
  g.endstop_adjustment = {0.4, -0.1, 0.0};
  const auto rrf = parse_rrf_delta_settings({rrf_m665_reply(g)}, {rrf_m666_reply(g)});
  ASSERT_TRUE(rrf);
  EXPECT_EQ(rrf->diagonal_rod, g.diagonal_rod);
  EXPECT_EQ(rrf->angle_trim, g.angle_trim);
  g.firmware = Firmware::kMarlin;
  g.endstop_adjustment = {-0.4, -0.1, 0.0};
  const auto marlin = parse_marlin_delta_settings(marlin_m503_lines(g, 80.0));
  ASSERT_TRUE(marlin);
  for (std::size_t i = 0; i < 3; ++i) {
    EXPECT_NEAR(marlin->diagonal_rod[i], g.diagonal_rod[i], 1e-9);
    EXPECT_NEAR(marlin->endstop_adjustment[i], g.endstop_adjustment[i], 1e-9);
  }
}

// Closed form: carriage i at z + sqrt(L_i^2 - |xy - T_i|^2), T_i on radius R at 210/330/90 deg
// plus the trims; the forward kinematics inverts it.
TEST(DeltaFirmware, InverseAndForwardKinematicsAgreeWithTheClosedForm) {
  DeltaGeometry g;
  g.diagonal_rod = {215.0, 215.5, 214.75};
  g.radius = 105.2;
  g.height = 250.0;
  g.angle_trim = {0.3, -0.2, 0.1};
  const Eigen::Vector3d p(12.5, -30.25, 40.0);
  const auto c = carriage_coordinates(g, p);
  ASSERT_TRUE(c);
  for (int i = 0; i < 3; ++i) {
    const double a = (std::array<double, 3>{210.0, 330.0, 90.0}[static_cast<std::size_t>(i)] +
                      g.angle_trim[static_cast<std::size_t>(i)]) *
                     std::numbers::pi / 180.0;
    const double dx = p.x() - g.radius * std::cos(a), dy = p.y() - g.radius * std::sin(a);
    const double l = g.diagonal_rod[static_cast<std::size_t>(i)];
    EXPECT_NEAR((*c)[i], p.z() + std::sqrt(l * l - dx * dx - dy * dy), 1e-9);
  }
  const auto back = nozzle_position(g, *c);
  ASSERT_TRUE(back);
  EXPECT_LT((*back - p).norm(), 1e-9);
  // RRF's bed tilt adds x tilt_x + y tilt_y to every carriage; the forward form takes it off.
  g.tilt_x = 0.002;
  g.tilt_y = -0.001;
  const auto tilted = carriage_coordinates(g, p);
  ASSERT_TRUE(tilted);
  EXPECT_NEAR((*tilted)[0] - (*c)[0], p.x() * 0.002 - p.y() * 0.001, 1e-9);
  const auto tilted_back = nozzle_position(g, *tilted);
  ASSERT_TRUE(tilted_back);
  EXPECT_LT((*tilted_back - p).norm(), 1e-6);
  EXPECT_FALSE(carriage_coordinates(g, Eigen::Vector3d(400.0, 0.0, 0.0)));  // rods too short
}

TEST(DeltaFirmware, CountsRoundTripThroughTheFirmwaresCartesianTarget) {
  CarriageFrame f;
  f.geometry.diagonal_rod = {270.0, 270.0, 270.0};
  f.geometry.radius = 140.0;
  f.geometry.height = 219.0;
  f.geometry.endstop_adjustment = {-0.4, -0.1, 0.0};
  f.endstop_reading = {0.45, 0.45, 0.45};
  // Endstop: H + sqrt(L^2 - R^2) + |M666| (Marlin): the reading 0.45 is there.
  const double endstop = 219.0 + std::sqrt(270.0 * 270.0 - 140.0 * 140.0) + 0.4;
  // ... tied to the whole step counted there: a homed carriage reads the limit exactly.
  EXPECT_EQ(endstop_count(f, 0), std::lround(endstop * 80.0));
  EXPECT_NEAR(carriage_coordinate_of_reading(f, 0, 0.45), endstop, 0.5 / 80.0);
  EXPECT_EQ(delta_readings(f, {endstop_count(f, 0), endstop_count(f, 1), endstop_count(f, 2)}),
            (Eigen::Vector3d(0.45, 0.45, 0.45)));
  EXPECT_NEAR(reading_of_carriage_coordinate(f, 0, carriage_coordinate_of_reading(f, 0, 0.35)),
              0.35, 1e-12);
  Eigen::VectorXd readings(3);
  readings << 0.351234, 0.332101, 0.369876;
  const std::vector<long> counts = delta_counts(f, readings);
  const auto xyz = cartesian_for_counts(f, counts);
  ASSERT_TRUE(xyz);
  const auto again = counts_for_cartesian(f, *xyz);
  ASSERT_TRUE(again);
  EXPECT_EQ(*again, counts);
}

TEST(DeltaFirmware, NamesEachFigureThatDisagreesWithTheRobotFileBeyondItsTolerance) {
  const calib::Mechanism model =
      calib::load_robot_file(std::string(ROBOCAL_TESTDATA_DIR) + "/robots/linear_delta.yaml");
  const RobotFileDelta file = robot_file_delta(model);
  ASSERT_TRUE(file.problem.empty()) << file.problem;
  EXPECT_NEAR(file.radius, 140.0, 1e-9);  // 174 - 34 mm
  EXPECT_NEAR(file.diagonal_rod[0], 270.0, 1e-9);
  EXPECT_NEAR(file.rod_tolerance, 1.5, 1e-9);  // 3 x the file's 0.5 mm
  DeltaGeometry g = drawing_geometry(file, Firmware::kMarlin);
  EXPECT_TRUE(geometry_disagreements(g, file).empty());
  g.diagonal_rod[0] = 272.0;
  g.angle_trim[2] = 2.0;
  const std::vector<std::string> d = geometry_disagreements(g, file);
  ASSERT_EQ(d.size(), 2U);
  EXPECT_EQ(d[0],
            "tower A diagonal rod: the firmware says 272.00 mm, the robot file 270.00 mm "
            "(tolerance 1.50 mm)");
  EXPECT_NE(d[1].find("tower C angle: the firmware says 92.00 deg, the robot file 90.00 deg"),
            std::string::npos)
      << d[1];
  const calib::Mechanism arm =
      calib::load_robot_file(std::string(ROBOCAL_TESTDATA_DIR) + "/robots/ur5.yaml");
  EXPECT_NE(robot_file_delta(arm).problem.find("not a linear delta"), std::string::npos);
}

TEST(DeltaFirmware, DeltaSettingsAreSetByNameAndAnUnknownNameIsRefused) {
  DeltaGeometry g;
  apply_delta_setting(g, "L=217");
  apply_delta_setting(g, "M666_Y=-0.5");
  EXPECT_DOUBLE_EQ(g.diagonal_rod[2], 217.0);
  EXPECT_DOUBLE_EQ(g.endstop_adjustment[1], -0.5);
  EXPECT_THROW(apply_delta_setting(g, "Q=1"), std::invalid_argument);
  EXPECT_THROW(apply_delta_setting(g, "L"), std::invalid_argument);
}

TEST(DeltaFirmware, AFrameReadsBackFromItsTextExactlyAndBrokenTextIsRefused) {
  CarriageFrame f;
  f.geometry.firmware = Firmware::kKlipper;
  f.geometry.diagonal_rod = {270.1, 269.9, 270.0 + 1.0 / 3.0};
  f.geometry.radius = 140.0 / 7.0;
  f.geometry.height = 219.25;
  f.geometry.angle_trim = {0.1, -0.2, 0.0};
  f.geometry.endstop_adjustment = {-0.4, -0.1, 0.0};
  f.geometry.tilt_x = 1e-4;
  f.geometry.tilt_y = -2e-4;
  f.steps_per_mm = 80.0;
  f.endstop_reading = {0.45, 0.45, 0.45 + 1e-9};
  const std::string text = carriage_frame_text(f);
  const auto back = carriage_frame_from_text(text);
  ASSERT_TRUE(back) << text;
  EXPECT_EQ(back->geometry.firmware, Firmware::kKlipper);
  EXPECT_EQ(back->geometry.diagonal_rod, f.geometry.diagonal_rod);  // exact, not near
  EXPECT_EQ(back->geometry.radius, f.geometry.radius);
  EXPECT_EQ(back->geometry.height, f.geometry.height);
  EXPECT_EQ(back->geometry.angle_trim, f.geometry.angle_trim);
  EXPECT_EQ(back->geometry.endstop_adjustment, f.geometry.endstop_adjustment);
  EXPECT_EQ(back->geometry.tilt_x, f.geometry.tilt_x);
  EXPECT_EQ(back->geometry.tilt_y, f.geometry.tilt_y);
  EXPECT_EQ(back->steps_per_mm, f.steps_per_mm);
  EXPECT_EQ(back->endstop_reading, f.endstop_reading);
  // A figure missing, one of three numbers missing, a word that is not a number, an unknown
  // firmware, an empty text: none is a frame.
  const auto without = [&](const std::string& part, const std::string& with) {
    std::string t = text;
    t.replace(t.find(part), part.size(), with);
    return t;
  };
  EXPECT_FALSE(carriage_frame_from_text(without(" height=219.25", "")));
  EXPECT_FALSE(carriage_frame_from_text(without("angle_trim=0.1,-0.2,0", "angle_trim=0.1,-0.2")));
  EXPECT_FALSE(carriage_frame_from_text(without("radius=20", "radius=twenty")));
  EXPECT_FALSE(carriage_frame_from_text(without("firmware=Klipper", "firmware=Smoothie")));
  EXPECT_FALSE(carriage_frame_from_text(without(" height=219.25", " radius=20")));
  EXPECT_FALSE(carriage_frame_from_text(""));
}

}  // namespace
}  // namespace robocal::robotio
