// Klipper's delta configuration and GET_POSITION as Moonraker shows them, read against texts and
// figures worked out by hand from Klipper's sources: configfile.settings (docs/Status_Reference.md;
// defaults of stepper_b/_c from stepper_a, angles 210/330/90, 200 full steps), the step distance
// rotation_distance / (full_steps * microsteps * gear ratio) (docs/Rotation_Distance.md), the
// endstop coordinate position_endstop + sqrt(arm^2 - R^2) (kinematics/delta.py), GET_POSITION's
// respond_info lines (extras/gcode_move.py, gcode.py) and the microcontroller count relation
// mcu = round((commanded + offset) / step distance) (stepper.py).
#include "robocal/robotio/klipper.hpp"

#include <gtest/gtest.h>

#include <cmath>

namespace robocal::robotio {
namespace {

using nlohmann::json;

// A printer.cfg's delta as Klipper reports it: only stepper_a carries arm_length and
// position_endstop, stepper_c turns its tower by 0.5 degrees, 40 mm per turn at 16 microsteps
// (80 steps/mm).
json delta_settings() {
  json s;
  s["printer"] = {{"kinematics", "delta"}, {"delta_radius", 140.0}, {"max_velocity", 300}};
  s["stepper_a"] = {{"rotation_distance", 40.0},
                    {"microsteps", 16},
                    {"arm_length", 270.0},
                    {"position_endstop", 221.5}};
  s["stepper_b"] = {{"rotation_distance", 40.0}, {"microsteps", 16}, {"position_endstop", 221.1}};
  s["stepper_c"] = {{"rotation_distance", 40.0}, {"microsteps", 16}, {"angle", 90.5}};
  return s;
}

TEST(KlipperSettings, ADeltaIsReadWithKlippersDefaults) {
  const KlipperPrinter p = klipper_printer_from_settings(delta_settings());
  ASSERT_TRUE(p.problem.empty()) << p.problem;
  ASSERT_TRUE(p.delta);
  EXPECT_EQ(p.kinematics, "delta");
  EXPECT_EQ(p.delta->firmware, Firmware::kKlipper);
  EXPECT_DOUBLE_EQ(p.steps_per_mm, 200.0 * 16.0 / 40.0);
  EXPECT_DOUBLE_EQ(p.delta->radius, 140.0);
  for (std::size_t i = 0; i < 3; ++i) EXPECT_DOUBLE_EQ(p.delta->diagonal_rod[i], 270.0);
  EXPECT_DOUBLE_EQ(p.delta->angle_trim[0], 0.0);
  EXPECT_DOUBLE_EQ(p.delta->angle_trim[2], 0.5);
  // The endstop coordinates: position_endstop + sqrt(270^2 - 140^2) = position_endstop + 230.8679.
  const double rise = std::sqrt(270.0 * 270.0 - 140.0 * 140.0);
  EXPECT_NEAR(endstop_coordinate(*p.delta, 0), 221.5 + rise, 1e-9);
  EXPECT_NEAR(endstop_coordinate(*p.delta, 1), 221.1 + rise, 1e-9);
  EXPECT_NEAR(endstop_coordinate(*p.delta, 2), 221.5 + rise, 1e-9);  // stepper_a's default
  EXPECT_DOUBLE_EQ(homing_backoff(*p.delta, 1), 0.0);                // Klipper stays on it
}

TEST(KlipperSettings, TheSimulatedPrintersSettingsReadBackToItsGeometry) {
  DeltaGeometry g;
  g.firmware = Firmware::kKlipper;
  g.diagonal_rod = {270.2, 269.9, 270.0};
  g.radius = 139.8;
  g.height = 221.5;
  g.angle_trim = {0.3, -0.2, 0.1};
  g.endstop_adjustment = {0.0, -0.4, 0.25};
  const KlipperPrinter p = klipper_printer_from_settings(klipper_delta_settings(g, 80.0));
  ASSERT_TRUE(p.problem.empty()) << p.problem;
  EXPECT_NEAR(p.steps_per_mm, 80.0, 1e-12);
  for (int i = 0; i < 3; ++i) {
    const auto k = static_cast<std::size_t>(i);
    EXPECT_NEAR(p.delta->diagonal_rod[k], g.diagonal_rod[k], 1e-12);
    EXPECT_NEAR(p.delta->angle_trim[k], g.angle_trim[k], 1e-12);
    EXPECT_NEAR(endstop_coordinate(*p.delta, i), endstop_coordinate(g, i), 1e-9);
  }
}

TEST(KlipperSettings, GearRatiosMultiplyTheStepsPerMillimetre) {
  json s = delta_settings();
  for (const char* name : {"stepper_a", "stepper_b", "stepper_c"})
    s[name]["gear_ratio"] = json::array({json::array({80, 20}), json::array({3, 2})});
  const KlipperPrinter p = klipper_printer_from_settings(s);
  ASSERT_TRUE(p.problem.empty()) << p.problem;
  EXPECT_DOUBLE_EQ(p.steps_per_mm, 200.0 * 16.0 * 4.0 * 1.5 / 40.0);
}

TEST(KlipperSettings, WhatCannotBeDrivenIsNamedBySectionAndOption) {
  json cartesian = delta_settings();
  cartesian["printer"]["kinematics"] = "cartesian";
  EXPECT_EQ(klipper_printer_from_settings(cartesian).problem,
            "the printer's kinematics is 'cartesian' ([printer] kinematics), not a linear delta");

  json no_radius = delta_settings();
  no_radius["printer"].erase("delta_radius");
  EXPECT_EQ(klipper_printer_from_settings(no_radius).problem,
            "the configuration has no [printer] delta_radius (a delta needs it)");

  json no_tower = delta_settings();
  no_tower.erase("stepper_c");
  EXPECT_NE(klipper_printer_from_settings(no_tower).problem.find("no [stepper_c] section"),
            std::string::npos);

  json text_rod = delta_settings();
  text_rod["stepper_a"]["arm_length"] = "270";
  EXPECT_NE(klipper_printer_from_settings(text_rod).problem.find(
                "[stepper_a] arm_length: \"270\" is not a number"),
            std::string::npos);

  json uneven = delta_settings();
  uneven["stepper_b"]["microsteps"] = 32;
  EXPECT_NE(
      klipper_printer_from_settings(uneven).problem.find("[stepper_b] moves 160.0000 steps/mm"),
      std::string::npos);

  EXPECT_EQ(klipper_printer_from_settings(json::object()).problem,
            "the configuration has no [printer] kinematics");
}

// GET_POSITION's answer as Klipper prints it, one G-code response with "// " before each line.
const char* kGetPosition =
    "// mcu: stepper_a:-184320 stepper_b:52117 stepper_c:9003\n"
    "// stepper: stepper_a:452.367900 stepper_b:451.967900 stepper_c:452.367900\n"
    "// kinematic: X:0.000000 Y:0.000000 Z:221.500000\n"
    "// toolhead: X:0.000000 Y:0.000000 Z:221.500000 E:0.000000\n"
    "// gcode: X:0.000000 Y:0.000000 Z:221.500000 E:0.000000\n"
    "// gcode base: X:0.000000 Y:0.000000 Z:0.000000 E:0.000000\n"
    "// gcode homing: X:0.000000 Y:0.000000 Z:0.000000";

TEST(KlipperGetPosition, CountsAndCommandedPositionsAreReadByStepperName) {
  const auto p = parse_get_position({kGetPosition}, {"stepper_a", "stepper_b", "stepper_c"});
  ASSERT_TRUE(p);
  EXPECT_EQ(p->mcu, (std::vector<long>{-184320, 52117, 9003}));
  EXPECT_DOUBLE_EQ(p->stepper[1], 451.9679);
  // In another order, and split over two responses.
  const auto q =
      parse_get_position({"// stepper: stepper_c:1.5 stepper_a:2.5 stepper_b:3.5",
                          "// mcu: stepper_c:7 stepper_b:8 stepper_a:9\n// kinematic: X:0 Y:0 Z:0"},
                         {"stepper_a", "stepper_b", "stepper_c"});
  ASSERT_TRUE(q);
  EXPECT_EQ(q->mcu, (std::vector<long>{9, 8, 7}));
  EXPECT_EQ(q->stepper, (std::vector<double>{2.5, 3.5, 1.5}));
}

TEST(KlipperGetPosition, AMissingOrGarbledFigureIsNotAPosition) {
  const std::vector<std::string> abc = {"stepper_a", "stepper_b", "stepper_c"};
  EXPECT_FALSE(parse_get_position({"// mcu: stepper_a:1 stepper_b:2"}, abc));
  EXPECT_FALSE(parse_get_position({"// mcu: stepper_a:1 stepper_b:2 stepper_c:3"}, abc));
  EXPECT_FALSE(parse_get_position(
      {"// mcu: stepper_a:1 stepper_b:2x stepper_c:3\n// stepper: stepper_a:1 stepper_b:2 "
       "stepper_c:3"},
      abc));
  EXPECT_FALSE(parse_get_position({"!! Printer is not ready"}, abc));
  // The simulator's text reads back.
  const auto p =
      parse_get_position({get_position_text({5, -6, 7}, {1.25, 2.5, 3.75}, Eigen::Vector3d(1, 2, 3),
                                            Eigen::Vector3d(1, 2, 3))},
                         abc);
  ASSERT_TRUE(p);
  EXPECT_EQ(p->mcu, (std::vector<long>{5, -6, 7}));
  EXPECT_EQ(p->stepper, (std::vector<double>{1.25, 2.5, 3.75}));
}

// The library linear delta's drawing in Klipper's terms: rods 270 mm, radius 140 mm,
// position_endstop 221.5 mm, 80 steps/mm.
CarriageFrame klipper_frame() {
  CarriageFrame f;
  f.geometry.firmware = Firmware::kKlipper;
  f.geometry.diagonal_rod = {270.0, 270.0, 270.0};
  f.geometry.radius = 140.0;
  f.geometry.height = 221.5;
  f.steps_per_mm = 80.0;
  return f;
}

// Klipper's steps lie on a grid through the endstop coordinate: with the endstop at 452.3679 mm
// (36189.43 steps at 80 steps/mm) the firmware counts 36189 there; a carriage commanded to 400.0
// mm is 4189.43 steps below it, so it stops 4189 steps below (count 32000); at 399.992 mm it is
// 4190.07 below (count 31999). At 400.0075 mm (32000.6 steps from zero) Marlin's grid,
// round(coordinate * 80), counts 32001; Klipper's, 4188.83 below the endstop, 32000.
TEST(KlipperGrid, StepsAreCountedFromTheEndstop) {
  CarriageFrame f = klipper_frame();
  const double endstop = 221.5 + std::sqrt(270.0 * 270.0 - 140.0 * 140.0);
  ASSERT_NEAR(endstop * 80.0, 36189.43, 0.01);
  EXPECT_EQ(endstop_count(f, 0), 36189);
  EXPECT_EQ(count_of_coordinate(f, 0, endstop), 36189);
  EXPECT_EQ(count_of_coordinate(f, 0, 400.0), 36189 - 4189);
  EXPECT_EQ(count_of_coordinate(f, 0, 399.992), 36189 - 4190);
  EXPECT_NEAR(coordinate_of_count(f, 0, 32000), endstop - 4189.0 / 80.0, 1e-12);
  EXPECT_EQ(count_of_coordinate(f, 0, 400.0075), 32000);
  // Marlin's grid is its coordinate's zero: the same coordinate, another count.
  f.geometry.firmware = Firmware::kMarlin;
  EXPECT_EQ(count_of_coordinate(f, 0, 400.0075), 32001);
}

TEST(KlipperGrid, TheMicrocontrollerCountAtTheEndstopFollowsFromAnyHomedPosition) {
  CarriageFrame f = klipper_frame();
  const double endstop = endstop_coordinate(f.geometry, 0);
  // The carriage commanded 10 mm (800 steps) and a fraction below the endstop: the mcu counts
  // 800 fewer than at the endstop.
  KlipperPosition p;
  p.mcu = {1000 - 800, 2000, 3000};
  p.stepper = {endstop - 10.0 - 0.2 / 80.0, endstop_coordinate(f.geometry, 1),
               endstop_coordinate(f.geometry, 2)};
  const std::array<long, 3> at_endstop = klipper_mcu_at_endstop(f, p);
  EXPECT_EQ(at_endstop, (std::array<long, 3>{1000, 2000, 3000}));
  const std::vector<long> counts = klipper_frame_counts(f, p, at_endstop);
  EXPECT_EQ(counts[0], endstop_count(f, 0) - 800);
  EXPECT_EQ(counts[1], endstop_count(f, 1));
}

}  // namespace
}  // namespace robocal::robotio
