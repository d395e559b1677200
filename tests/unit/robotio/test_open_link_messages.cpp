// The open link's message parts (robotio/OPEN_LINK.md), pure: hello replies as the specification
// shows them, what is refused and how the refusal names it, error replies.
#include "robocal/calib/robot_file.hpp"
#include "robocal/robotio/open_link.hpp"

#include <gtest/gtest.h>

#include <string>

namespace robocal::robotio {
namespace {

using nlohmann::json;

json spec_hello() {
  return json::parse(R"({"id":1,"ok":true,"protocol":"robocal-open-link","version":[1,0],
    "controller":"Gantry-Tau lab controller 2.3",
    "capabilities":["counts","home","emergency_stop","settled_event"],
    "actuators":[{"name":"q1","unit":"m","resolution":1.25e-5},
                 {"name":"q2","unit":"m","resolution":1.25e-5},
                 {"name":"q3","unit":"m","resolution":1.25e-5}],
    "keepalive_s":1.0})");
}

calib::Mechanism robot(const std::string& name) {
  return calib::load_robot_file(std::string(ROBOCAL_TESTDATA_DIR) + "/robots/" + name + ".yaml");
}

TEST(OpenLinkHello, ReadsTheSpecificationsExample) {
  const OpenLinkHello h = parse_open_hello(spec_hello());
  EXPECT_EQ(h.protocol, "robocal-open-link");
  EXPECT_EQ(h.major, 1);
  EXPECT_EQ(h.minor, 0);
  EXPECT_EQ(h.controller, "Gantry-Tau lab controller 2.3");
  ASSERT_EQ(h.actuators.size(), 3u);
  EXPECT_EQ(h.actuators[1].name, "q2");
  EXPECT_DOUBLE_EQ(h.actuators[2].resolution, 1.25e-5);
  EXPECT_TRUE(h.has("counts"));
  EXPECT_FALSE(h.has("teleport"));
  EXPECT_DOUBLE_EQ(h.keepalive_s, 1.0);
}

TEST(OpenLinkHello, UnknownFieldsAndCapabilitiesAreIgnored) {
  json j = spec_hello();
  j["firmware_build"] = "2026-11-30";
  j["capabilities"].push_back("teleport");
  EXPECT_TRUE(parse_open_hello(j).has("teleport"));
  j.erase("keepalive_s");
  EXPECT_DOUBLE_EQ(parse_open_hello(j).keepalive_s, 0.0);  // optional: no keep-alives
}

TEST(OpenLinkHello, MissingOrMalformedFieldsAreNamed) {
  auto problem = [](json j) {
    try {
      parse_open_hello(j);
    } catch (const std::invalid_argument& e) {
      return std::string(e.what());
    }
    return std::string("accepted");
  };
  json j = spec_hello();
  j.erase("controller");
  EXPECT_EQ(problem(j), "no \"controller\"");
  j = spec_hello();
  j["version"] = "1.0";
  EXPECT_EQ(problem(j), "\"version\" is not [major, minor]");
  j = spec_hello();
  j["actuators"][1]["resolution"] = 0;
  EXPECT_EQ(problem(j), "actuator 2 'q2': \"resolution\" must be a positive number");
  j = spec_hello();
  j["actuators"] = json::array();
  EXPECT_EQ(problem(j), "\"actuators\" is not a non-empty list");
}

TEST(OpenLinkHello, ActuatorsMustFitTheRobotFile) {
  const OpenLinkHello h = parse_open_hello(spec_hello());
  EXPECT_EQ(open_hello_mismatch(h, robot("linear_delta")), "");
  EXPECT_EQ(open_hello_mismatch(h, robot("ur5")),
            "the controller reports 3 actuators (q1, q2, q3); the robot file 'ur5' has 6");
  const std::string revolute = open_hello_mismatch(h, robot("rotary_delta"));
  EXPECT_NE(revolute.find("actuator 1 'q1' is in 'm'"), std::string::npos) << revolute;
  EXPECT_NE(revolute.find("revolute joint there (expects 'rad')"), std::string::npos) << revolute;
}

TEST(OpenLinkReplies, ErrorCodeAndMessage) {
  EXPECT_EQ(open_reply_failure(json::parse(R"({"id":3,"ok":true})")).code, 0);
  const OpenLinkFailure f = open_reply_failure(json::parse(
      R"({"id":7,"ok":false,"error":{"code":201,"message":"target 2 outside 0.000..0.400 m"}})"));
  EXPECT_EQ(f.code, 201);
  EXPECT_EQ(f.message, "target 2 outside 0.000..0.400 m");
  EXPECT_EQ(open_reply_failure(json::parse(R"({"id":7,"ok":false})")).code, -1);
}

TEST(OpenLinkAddress, OnlyOpenHostPort) {
  EXPECT_TRUE(is_open_link_address("open:127.0.0.1:7001"));
  EXPECT_FALSE(is_open_link_address("tcp:127.0.0.1:7001"));
  EXPECT_FALSE(is_open_link_address("/dev/ttyACM0"));
  EXPECT_THROW(open_link_transport("open:127.0.0.1"), LinkError);
  EXPECT_THROW(open_link_transport("/dev/ttyACM0"), LinkError);
}

TEST(OpenLinkBeforeConnect, EveryCommandIsRefusedNamingTheDevice) {
  const calib::Mechanism model = robot("linear_delta");
  SafetyLimits limits;
  limits.max_speed = 1.0;
  limits.max_acceleration = 1.0;
  SafetyGuard guard(model, model.nominal_parameters(), limits);
  guard.arm("test");
  OpenLink link(guard, OpenLinkOptions{"open:127.0.0.1:1", std::chrono::milliseconds(100), 1, 0});
  try {
    link.read_actuators();
    FAIL() << "reading before connect must fail";
  } catch (const LinkError& e) {
    EXPECT_EQ(std::string(e.what()),
              "open link 127.0.0.1:1: not connected: the controller has not answered hello");
  }
  EXPECT_THROW(link.counts_for(Eigen::Vector3d(0.3, 0.3, 0.3)), LinkError);
}

}  // namespace
}  // namespace robocal::robotio
