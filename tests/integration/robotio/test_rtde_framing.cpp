// RTDE framing (robotio/rtde.hpp) checked byte for byte against packages written out by hand from
// Universal Robots' RTDE guide: header = uint16 package size (header included) + uint8 type, all
// big-endian; 'V' carries a uint16 protocol version; 'O' (protocol 2) a double frequency and the
// comma-separated names, answered by a uint8 recipe id and the comma-separated types; data
// packages a uint8 recipe id and the fields in recipe order. The expected bytes below are not
// produced by robocal's encoder: each is typed from the guide's layout.
#include "robocal/robotio/link_error.hpp"
#include "robocal/robotio/rtde.hpp"
#include "robocal/robotio/ur_link.hpp"
#include "robocal/robotio/ur_primary.hpp"

#include <gtest/gtest.h>

#include <cstdint>
#include <string>
#include <vector>

namespace robocal::test {
namespace {

namespace rtde = robotio::rtde;

std::string bytes(std::initializer_list<int> b) {
  std::string s;
  for (int v : b) s.push_back(static_cast<char>(v));
  return s;
}

TEST(RtdeFraming, RequestProtocolVersionTwoIsFiveBytes) {
  // size 5 (3 header + uint16 version), 'V' = 0x56, version 2.
  EXPECT_EQ(rtde::encode_request_protocol_version(2), bytes({0x00, 0x05, 0x56, 0x00, 0x02}));
}

TEST(RtdeFraming, EmptyRequestsAreTheHeaderAlone) {
  EXPECT_EQ(rtde::encode_get_urcontrol_version(), bytes({0x00, 0x03, 0x76}));  // 'v'
  EXPECT_EQ(rtde::encode_start(), bytes({0x00, 0x03, 0x53}));                  // 'S'
  EXPECT_EQ(rtde::encode_pause(), bytes({0x00, 0x03, 0x50}));                  // 'P'
}

TEST(RtdeFraming, SetupOutputsCarriesTheFrequencyAsBigEndianDoubleAndTheNames) {
  // 125.0 = 1.953125 * 2^6: sign 0, exponent 1023 + 6 = 0x405, mantissa 0.953125 = 0xF4 << 44
  // -> 0x405F400000000000. Names "actual_q,robot_mode" are 19 bytes: size 3 + 8 + 19 = 30.
  std::string expect = bytes({0x00, 0x1E, 0x4F, 0x40, 0x5F, 0x40, 0x00, 0x00, 0x00, 0x00, 0x00});
  expect += "actual_q,robot_mode";
  EXPECT_EQ(rtde::encode_setup_outputs(125.0, {"actual_q", "robot_mode"}), expect);
}

TEST(RtdeFraming, ControllerVersionReplyDecodesFourUint32) {
  // size 19 = 3 + 4 * 4; 5.11.0.108 (108 = 0x6C).
  std::string wire =
      bytes({0x00, 0x13, 0x76, 0, 0, 0, 5, 0, 0, 0, 0x0B, 0, 0, 0, 0, 0, 0, 0, 0x6C});
  const auto p = rtde::take_package(wire);
  ASSERT_TRUE(p.has_value());
  EXPECT_TRUE(wire.empty());
  const rtde::ControllerVersion v = rtde::decode_controller_version(*p);
  EXPECT_EQ(v.text(), "5.11.0.108");
}

TEST(RtdeFraming, RecipeReplyNamesTheFieldsTheControllerDoesNotKnow) {
  // id 1, then "VECTOR6D,NOT_FOUND" (18 bytes): size 3 + 1 + 18 = 22 = 0x16.
  std::string wire = bytes({0x00, 0x16, 0x4F, 0x01}) + "VECTOR6D,NOT_FOUND";
  const auto p = rtde::take_package(wire);
  ASSERT_TRUE(p.has_value());
  const rtde::OutputRecipe r = rtde::decode_output_recipe(*p);
  EXPECT_EQ(r.id, 1);
  ASSERT_EQ(r.types.size(), 2u);
  EXPECT_EQ(rtde::unknown_outputs({"actual_q", "speed_slider_of_1999"}, r),
            std::vector<std::string>{"speed_slider_of_1999"});
  EXPECT_THROW(rtde::unknown_outputs({"actual_q"}, r), rtde::RtdeFormatError);
}

TEST(RtdeFraming, DataPackageFieldsAreBigEndianInRecipeOrder) {
  // Recipe DOUBLE, INT32, UINT32, VECTOR3D: 1.5 = 0x3FF8000000000000, -1 = 0xFFFFFFFF,
  // 7 = 0x00000007, (0, -2, 0.25): -2 = 0xC000000000000000, 0.25 = 0x3FD0000000000000.
  // size 3 + 1 + 8 + 4 + 4 + 24 = 44 = 0x2C.
  const std::vector<std::string> types = {"DOUBLE", "INT32", "UINT32", "VECTOR3D"};
  const std::string wire =
      bytes({0x00, 0x2C, 0x55, 0x01, 0x3F, 0xF8, 0,    0,    0, 0, 0, 0, 0xFF, 0xFF, 0xFF,
             0xFF, 0,    0,    0,    7,    0,    0,    0,    0, 0, 0, 0, 0,    0xC0, 0,
             0,    0,    0,    0,    0,    0,    0x3F, 0xD0, 0, 0, 0, 0, 0,    0});
  std::string stream = wire;
  const auto p = rtde::take_package(stream);
  ASSERT_TRUE(p.has_value());
  const rtde::DataPackage d = rtde::decode_data_package(*p, types);
  EXPECT_EQ(d.recipe_id, 1);
  ASSERT_EQ(d.fields.size(), 4u);
  EXPECT_EQ(d.fields[0][0], 1.5);
  EXPECT_EQ(d.fields[1][0], -1.0);
  EXPECT_EQ(d.fields[2][0], 7.0);
  EXPECT_EQ(d.fields[3], (std::vector<double>{0.0, -2.0, 0.25}));
  // The simulator's encoder writes the same bytes.
  EXPECT_EQ(rtde::encode_data_package(1, types, {{1.5}, {-1.0}, {7.0}, {0.0, -2.0, 0.25}}), wire);
}

TEST(RtdeFraming, PackagesAreCutFromAStreamOnlyWhenComplete) {
  std::string stream = bytes({0x00, 0x04, 0x53, 0x01, 0x00, 0x04});  // 'S' accepted, half of next
  auto p = rtde::take_package(stream);
  ASSERT_TRUE(p.has_value());
  EXPECT_TRUE(rtde::decode_accepted(*p));
  EXPECT_FALSE(rtde::take_package(stream).has_value()) << "3 bytes of a 4-byte package";
  stream += bytes({0x50, 0x01});  // the rest: 'P' accepted
  p = rtde::take_package(stream);
  ASSERT_TRUE(p.has_value());
  EXPECT_EQ(p->type, 'P');
  EXPECT_TRUE(stream.empty());
}

TEST(RtdeFraming, ASizeSmallerThanTheHeaderIsRefused) {
  std::string stream = bytes({0x00, 0x02, 0x55});
  EXPECT_THROW(rtde::take_package(stream), rtde::RtdeFormatError);
}

TEST(RtdeFraming, ADataPackageShorterThanItsRecipeNamesTheField) {
  std::string stream = bytes({0x00, 0x08, 0x55, 0x01, 0x3F, 0xF8, 0x00, 0x00});
  const auto p = rtde::take_package(stream);
  ASSERT_TRUE(p.has_value());
  try {
    rtde::decode_data_package(*p, {"DOUBLE"});
    FAIL() << "4 bytes cannot hold a double";
  } catch (const rtde::RtdeFormatError& e) {
    EXPECT_NE(std::string(e.what()).find("DOUBLE"), std::string::npos) << e.what();
  }
}

TEST(RtdeFraming, TextMessageOfProtocolTwo) {
  // length 2 "hi", length 4 "RTDE", level 1 (error): size 3 + 1 + 2 + 1 + 4 + 1 = 12.
  std::string stream = bytes({0x00, 0x0C, 0x4D, 0x02, 'h', 'i', 0x04, 'R', 'T', 'D', 'E', 0x01});
  const auto p = rtde::take_package(stream);
  ASSERT_TRUE(p.has_value());
  const rtde::TextMessage m = rtde::decode_text_message(*p);
  EXPECT_EQ(m.message, "hi");
  EXPECT_EQ(m.source, "RTDE");
  EXPECT_EQ(m.level, 1);
}

TEST(UrAddress, StandardPortsOrAllThreeGiven) {
  const robotio::UrAddress a = robotio::parse_ur_address("ur:10.0.0.5");
  EXPECT_EQ(a.host, "10.0.0.5");
  EXPECT_EQ(a.rtde_port, 30004);
  EXPECT_EQ(a.secondary_port, 30002);
  EXPECT_EQ(a.dashboard_port, 29999);
  const robotio::UrAddress b = robotio::parse_ur_address("ur:localhost:1:2:3");
  EXPECT_EQ(b.rtde_port, 1);
  EXPECT_EQ(b.secondary_port, 2);
  EXPECT_EQ(b.dashboard_port, 3);
  EXPECT_THROW(robotio::parse_ur_address("ur:host:1:2"), robotio::LinkError);
  try {
    robotio::parse_ur_address("ur:host:1:x:3");
    FAIL();
  } catch (const robotio::LinkError& e) {
    EXPECT_NE(std::string(e.what()).find("port 'x'"), std::string::npos) << e.what();
  }
}

TEST(UrScript, MovejAndStopjAsTheUrScriptManualWritesThem) {
  Eigen::VectorXd q(6);
  q << 0.0, -1.5, 1.25, 0.5, -0.25, 3.0;
  EXPECT_EQ(robotio::urscript_movej(q, 1.2, 0.5),
            "movej([0.000000000,-1.500000000,1.250000000,0.500000000,-0.250000000,3.000000000], "
            "a=1.200000, v=0.500000)");
  EXPECT_EQ(robotio::urscript_stopj(2.0), "stopj(2.000000)");
}

}  // namespace
}  // namespace robocal::test

// ---- the client interface's robot messages (ur_primary.hpp), bytes written out by hand from the
// published layout: int32 size (whole package), uint8 type 20, uint64 timestamp, int8 source,
// uint8 message type, then the message's fields; all big-endian.

namespace robocal::test {
namespace {

namespace up = robotio::ur_primary;

// A runtime exception (type 10): line 3, column 7, the text "name 'movx' is not defined".
std::string runtime_exception_bytes() {
  const std::string text = "name 'movx' is not defined";
  std::string b;
  const std::size_t size = 4 + 1 + 8 + 1 + 1 + 4 + 4 + text.size();  // 23 + 26 = 49
  b += std::string("\x00\x00\x00", 3) + static_cast<char>(size);
  b += '\x14';                                              // 20: robot message
  b += std::string("\x00\x00\x00\x00\x00\x01\xe2\x40", 8);  // timestamp 123456
  b += '\xfe';                                              // source -2
  b += '\x0a';                                              // 10: runtime exception
  b += std::string("\x00\x00\x00\x03", 4);                  // line 3
  b += std::string("\x00\x00\x00\x07", 4);                  // column 7
  return b + text;
}

TEST(UrPrimaryMessages, RuntimeExceptionDecodesFromThePublishedLayout) {
  std::string stream = runtime_exception_bytes();
  ASSERT_EQ(stream.size(), 49U);
  const std::optional<up::Package> p = up::take_package(stream);
  ASSERT_TRUE(p.has_value());
  EXPECT_TRUE(stream.empty());
  EXPECT_EQ(p->type, 20);
  const std::optional<up::RobotMessage> m = up::decode_robot_message(*p);
  ASSERT_TRUE(m.has_value());
  EXPECT_EQ(m->timestamp, 123456U);
  EXPECT_EQ(m->source, -2);
  EXPECT_EQ(m->type, up::MessageType::kRuntimeException);
  EXPECT_EQ(m->line, 3);
  EXPECT_EQ(m->column, 7);
  EXPECT_EQ(m->text, "name 'movx' is not defined");
  EXPECT_TRUE(up::matters(*m));
  EXPECT_EQ(up::describe(*m),
            "runtime exception at line 3, column 7: \"name 'movx' is not defined\"");
  // The simulator's encoder writes the same bytes (apart from the timestamp given).
  EXPECT_EQ(up::encode_runtime_exception(123456, 3, 7, "name 'movx' is not defined"),
            runtime_exception_bytes());
}

TEST(UrPrimaryMessages, ErrorCodeCarriesCodeArgumentLevelAndText) {
  const std::string text = "Protective Stop: Collision detected by joint 3";
  std::string b;
  const std::size_t size = 4 + 1 + 8 + 1 + 1 + 4 + 4 + 4 + 1 + 4 + text.size();
  b += std::string("\x00\x00\x00", 3) + static_cast<char>(size);
  b += '\x14';
  b += std::string(8, '\0');                // timestamp 0
  b += '\x00';                              // source 0
  b += '\x06';                              // 6: error code
  b += std::string("\x00\x00\x00\xcc", 4);  // code 204
  b += std::string("\x00\x00\x00\x03", 4);  // argument 3
  b += std::string("\x00\x00\x00\x03", 4);  // report level 3: violation
  b += '\x00';                              // data type
  b += std::string("\x00\x00\x00\x00", 4);  // data
  b += text;
  std::string stream = b;
  const std::optional<up::RobotMessage> m =
      up::decode_robot_message(up::take_package(stream).value());
  ASSERT_TRUE(m.has_value());
  EXPECT_EQ(m->type, up::MessageType::kErrorCode);
  EXPECT_EQ(m->code, 204);
  EXPECT_EQ(m->argument, 3);
  EXPECT_EQ(m->report_level, 3);
  EXPECT_EQ(m->text, text);
  EXPECT_EQ(up::describe(*m), "error C204A3 (violation): \"" + text + "\"");
  EXPECT_TRUE(up::matters(*m));
}

TEST(UrPrimaryMessages, RobotStatesAreFramedAndSkippedAndPartialPackagesWait) {
  // A robot state (type 16) of 9 bytes: header and 4 bytes of sub-package, then the exception
  // split in two reads.
  std::string stream = std::string("\x00\x00\x00\x09\x10\x00\x00\x00\x00", 9);
  const std::string message = runtime_exception_bytes();
  stream += message.substr(0, 20);
  const std::optional<up::Package> state = up::take_package(stream);
  ASSERT_TRUE(state.has_value());
  EXPECT_EQ(state->type, 16);
  EXPECT_FALSE(up::decode_robot_message(*state).has_value());
  EXPECT_FALSE(up::take_package(stream).has_value()) << "only 20 of 49 bytes are there";
  stream += message.substr(20);
  const std::optional<up::Package> p = up::take_package(stream);
  ASSERT_TRUE(p.has_value());
  EXPECT_EQ(up::decode_robot_message(*p)->line, 3);
}

TEST(UrPrimaryMessages, ASizeBelowTheHeaderOrAShortBodyIsRefused) {
  std::string bad = std::string("\x00\x00\x00\x04\x14", 5);
  EXPECT_THROW((void)up::take_package(bad), std::runtime_error);
  // A runtime exception cut before its column number.
  std::string cut = std::string("\x00\x00\x00\x15\x14", 5) + std::string(8, '\0') + '\x00' +
                    '\x0a' + std::string("\x00\x00\x00\x03", 4) + std::string("\x00\x00", 2);
  ASSERT_EQ(cut.size(), 21U);  // 5 + 8 + 1 + 1 + 4 + 2
  const std::optional<up::Package> p = up::take_package(cut);
  ASSERT_TRUE(p.has_value());
  EXPECT_THROW((void)up::decode_robot_message(*p), std::runtime_error);
}

}  // namespace
}  // namespace robocal::test
