// The firmware dialects, on reply lines written as the firmwares' documentation shows them.
#include "robocal/robotio/gcode_dialect.hpp"
#include "robocal/robotio/motion_profile.hpp"
#include "robocal/robotio/sim_controller.hpp"

#include <gtest/gtest.h>

#include <cmath>

namespace robocal::robotio {
namespace {

TEST(GcodeDialect, ClassifiesMarlinAndRrfReplies) {
  EXPECT_EQ(classify_reply("ok").kind, ReplyKind::kOk);
  EXPECT_EQ(classify_reply("ok\r").kind, ReplyKind::kOk);
  EXPECT_EQ(classify_reply("ok T:210.0 /210.0").kind, ReplyKind::kOk);
  EXPECT_EQ(classify_reply("echo:busy: processing").kind, ReplyKind::kBusy);
  EXPECT_EQ(classify_reply("Error:checksum mismatch, Last Line: 3").kind, ReplyKind::kError);
  EXPECT_EQ(classify_reply("Error: G1: target position not reachable").kind, ReplyKind::kError);
  const Reply marlin = classify_reply("Resend: 4");
  EXPECT_EQ(marlin.kind, ReplyKind::kResend);
  EXPECT_EQ(marlin.resend_line, 4);
  const Reply rrf = classify_reply("rs 17");
  EXPECT_EQ(rrf.kind, ReplyKind::kResend);
  EXPECT_EQ(rrf.resend_line, 17);
  EXPECT_EQ(classify_reply("!! Shutdown due to MCU error").kind, ReplyKind::kFatal);
  EXPECT_EQ(classify_reply("Error:Printer halted. kill() called!").kind, ReplyKind::kFatal);
  EXPECT_EQ(classify_reply("echo:Unknown command: \"M9999\"").kind, ReplyKind::kEcho);
  EXPECT_EQ(classify_reply(" T:24.80 /0.00 B:25.10 /0.00 @:0 B@:0").kind, ReplyKind::kTemperature);
  EXPECT_EQ(classify_reply("X:1.00 Y:2.00 Z:3.00 E:0.00 Count X:80 Y:160 Z:240").kind,
            ReplyKind::kPosition);
  EXPECT_EQ(classify_reply("Cap:EMERGENCY_PARSER:1").kind, ReplyKind::kOther);
  EXPECT_EQ(classify_reply("Resend: abc").kind, ReplyKind::kOther);  // malformed: not a resend
}

TEST(GcodeDialect, ParsesMarlinM114StepperCounts) {
  const auto r =
      parse_position_report("X:10.00 Y:20.00 Z:5.00 E:0.00 Count X:800 Y:1600 Z:400", "XYZ");
  ASSERT_TRUE(r);
  EXPECT_EQ(r->positions, (std::vector<double>{10.0, 20.0, 5.0}));
  EXPECT_EQ(r->counts, (std::vector<long>{800, 1600, 400}));
}

TEST(GcodeDialect, ParsesMarlinsDeltaM114CountsNamedByTower) {
  // Marlin on a delta names the tower steppers A, B, C (its " Count A:" report).
  const std::string line = "X:0.00 Y:0.00 Z:250.00 E:0.00 Count A:28880 B:28880 C:28880";
  EXPECT_EQ(classify_reply(line).kind, ReplyKind::kPosition);
  const auto r = parse_position_report(line, "XYZ", "ABC");
  ASSERT_TRUE(r);
  EXPECT_EQ(r->counts, (std::vector<long>{28880, 28880, 28880}));
  EXPECT_DOUBLE_EQ(r->positions[2], 250.0);
  EXPECT_FALSE(parse_position_report(line, "XYZ"));  // no X: Y: Z: counts on a delta
}

TEST(GcodeDialect, ParsesRrfM114StepperCounts) {
  // RepRapFirmware's documented example reply.
  const auto r = parse_position_report(
      "X:10.000 Y:20.000 Z:5.000 E:51.000 E0:51.0 E1:0.0 Count 800 1600 2000 Machine 10.00 "
      "20.00 5.00 Bed comp 0.00",
      "XYZ");
  ASSERT_TRUE(r);
  EXPECT_EQ(r->counts, (std::vector<long>{800, 1600, 2000}));
  EXPECT_DOUBLE_EQ(r->positions[2], 5.0);
}

TEST(GcodeDialect, RejectsPartialOrMalformedPositionReports) {
  EXPECT_FALSE(parse_position_report("X:10.00 Y:20.00 Z:5.00 E:0.00", "XYZ"));  // no counts
  EXPECT_FALSE(parse_position_report("X:10.00 Y:20.0", "XYZ"));
  EXPECT_FALSE(parse_position_report("X:10.00 Y:20.00 Z:5.00 Count X:800 Y:16", "XYZ"));
  EXPECT_FALSE(parse_position_report("X:1 Y:2 Z:3 Count X:8.5 Y:16 Z:24", "XYZ"));
  EXPECT_FALSE(parse_position_report("X:1 Y:2 Z:3 Count 8 16", "XYZ"));
  EXPECT_FALSE(parse_position_report("garbage", "XYZ"));
}

TEST(GcodeDialect, IdentifiesFirmwareFromM115AndBanners) {
  const auto marlin = parse_firmware_line(
      "FIRMWARE_NAME:Marlin 2.1.2.1 (Github) SOURCE_CODE_URL:github.com/MarlinFirmware/Marlin "
      "PROTOCOL_VERSION:1.0 MACHINE_TYPE:Kossel EXTRUDER_COUNT:1");
  ASSERT_TRUE(marlin);
  EXPECT_EQ(marlin->firmware, Firmware::kMarlin);
  EXPECT_EQ(marlin->version, "2.1.2.1");
  const auto rrf = parse_firmware_line(
      "FIRMWARE_NAME: RepRapFirmware for Duet 3 MB6HC FIRMWARE_VERSION: 3.4.5 ELECTRONICS: Duet 3 "
      "MB6HC v1.01 FIRMWARE_DATE: 2022-11-30 14:37:10");
  ASSERT_TRUE(rrf);
  EXPECT_EQ(rrf->firmware, Firmware::kRepRapFirmware);
  EXPECT_EQ(rrf->version, "3.4.5");
  EXPECT_EQ(rrf->name, "RepRapFirmware for Duet 3 MB6HC");
  const auto banner = parse_firmware_line("echo:Marlin 2.0.9.3");
  ASSERT_TRUE(banner);
  EXPECT_EQ(banner->firmware, Firmware::kMarlin);
  const auto grbl = parse_firmware_line("FIRMWARE_NAME:Grbl 1.1h");
  ASSERT_TRUE(grbl);
  EXPECT_EQ(grbl->firmware, Firmware::kUnknown);
  EXPECT_FALSE(parse_firmware_line("ok"));
}

TEST(GcodeDialect, ChecksumIsTheXorOfTheLineBeforeTheStar) {
  // "N1 G28": 'N'=78 ^ '1'=49 ^ ' '=32 ^ 'G'=71 ^ '2'=50 ^ '8'=56 = 18, by hand.
  EXPECT_EQ(numbered_line(1, "G28"), "N1 G28*18");
  const ReceivedLine ok = split_received_line("N1 G28*18");
  EXPECT_TRUE(ok.valid);
  EXPECT_EQ(ok.number, 1);
  EXPECT_EQ(ok.command, "G28");
  EXPECT_FALSE(split_received_line("N1 G28*19").valid);
  EXPECT_FALSE(split_received_line("N1 G29*18").valid);  // one flipped character
  EXPECT_FALSE(split_received_line("N1 G28*").valid);
  const ReceivedLine plain = split_received_line("G1 X10 ; comment");
  EXPECT_FALSE(plain.has_number);
  EXPECT_EQ(plain.command, "G1 X10");
}

TEST(GcodeDialect, StopCommandsPerFirmware) {
  EXPECT_EQ(quick_stop_command(Firmware::kMarlin), "M410");
  EXPECT_EQ(quick_stop_command(Firmware::kRepRapFirmware), "");
  EXPECT_EQ(emergency_stop_command(), "M112");
  EXPECT_EQ(resend_request(Firmware::kMarlin, 5), "Resend: 5");
  EXPECT_EQ(resend_request(Firmware::kRepRapFirmware, 5), "rs 5");
}

TEST(MotionProfile, TrapezoidAndTriangleMatchTheClosedForms) {
  // 10 mm at 5 mm/s, 10 mm/s^2: 0.5 s ramps (1.25 mm each), 7.5 mm cruise at 5 mm/s -> 2.5 s.
  EXPECT_NEAR(trapezoid_seconds(10.0, 5.0, 10.0), 0.5 + 1.5 + 0.5, 1e-12);
  // 1 mm, same limits: never reaches 5 mm/s; t = 2 sqrt(d / a).
  EXPECT_NEAR(trapezoid_seconds(1.0, 5.0, 10.0), 2.0 * std::sqrt(0.1), 1e-12);
  // Halfway in time is halfway in distance (symmetric profile); ends are exact.
  const double T = trapezoid_seconds(10.0, 5.0, 10.0);
  EXPECT_NEAR(trapezoid_distance(10.0, 5.0, 10.0, T / 2), 5.0, 1e-12);
  EXPECT_NEAR(trapezoid_distance(10.0, 5.0, 10.0, 0.5), 1.25, 1e-12);
  EXPECT_DOUBLE_EQ(trapezoid_distance(10.0, 5.0, 10.0, T + 1), 10.0);
  EXPECT_DOUBLE_EQ(trapezoid_seconds(0.0, 5.0, 10.0), 0.0);
}

TEST(FaultSpec, ParsesRatesAndRefusesUnknownKinds) {
  const FaultPlan all = parse_fault_spec("all=0.05");
  for (double r : all.rate) EXPECT_DOUBLE_EQ(r, 0.05);
  const FaultPlan some = parse_fault_spec("drop=0.1,lost_ok=0.2");
  EXPECT_DOUBLE_EQ(some.rate[static_cast<std::size_t>(FaultKind::kDrop)], 0.1);
  EXPECT_DOUBLE_EQ(some.rate[static_cast<std::size_t>(FaultKind::kLostOk)], 0.2);
  EXPECT_DOUBLE_EQ(some.rate[static_cast<std::size_t>(FaultKind::kBusy)], 0.0);
  EXPECT_THROW(parse_fault_spec("explode=0.1"), std::invalid_argument);
  EXPECT_THROW(parse_fault_spec("drop=2"), std::invalid_argument);
  EXPECT_THROW(parse_fault_spec("drop"), std::invalid_argument);
}

}  // namespace
}  // namespace robocal::robotio
