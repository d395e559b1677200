#include "robocal/robotio/sim_truth.hpp"

#include "robocal/robotio/link_error.hpp"

#include <nlohmann/json.hpp>

#include <cmath>
#include <stdexcept>

namespace robocal::robotio {
namespace {

Eigen::Vector3d vector3(const nlohmann::json& array) {
  return {array.at(0).get<double>(), array.at(1).get<double>(), array.at(2).get<double>()};
}

}  // namespace

TruePoseReading parse_true_pose_reply(const std::string& line, const std::string& source) {
  const nlohmann::json reply = nlohmann::json::parse(line, nullptr, false);
  const auto fail = [&](const std::string& why) {
    return std::runtime_error(source + ": " + why + " in reply '" + line + "'");
  };
  if (!reply.is_object()) {
    throw fail("not a JSON object");
  }
  if (reply.contains("error")) {
    throw fail("the true robot has no pose: " + reply["error"].dump());
  }
  TruePoseReading reading;
  try {
    reading.t = reply.at("t").get<double>();
    reading.moving = reply.at("moving").get<bool>();
    reading.motion = reply.at("motion").get<long>();
    reading.frame = reply.value("frame", "");
    const auto& q = reply.at("quaternion_wxyz");
    const Eigen::Quaterniond rotation(q.at(0).get<double>(), q.at(1).get<double>(),
                                      q.at(2).get<double>(), q.at(3).get<double>());
    if (std::abs(rotation.norm() - 1.0) > 1e-6) {
      throw fail("quaternion is not of unit length");
    }
    reading.base_T_task = Eigen::Translation3d(vector3(reply.at("position"))) * rotation;
    reading.actuators_true = reply.value("actuators_true", std::vector<double>{});
  } catch (const nlohmann::json::exception& missing) {
    throw fail(std::string("missing or mistyped field (") + missing.what() + ")");
  }
  return reading;
}

SimControllerTruth::SimControllerTruth(const std::string& address, const BoardMounting& mounting,
                                       std::chrono::milliseconds timeout)
    : channel_(make_transport("tcp:" + address, 0)), mounting_(mounting), timeout_(timeout) {
  channel_->open();
}

TruePoseReading SimControllerTruth::read() {
  const std::lock_guard lock(mutex_);
  channel_->write_line("pose");
  const auto line = channel_->read_line(Clock::now() + timeout_);
  if (!line) {
    throw LinkError(channel_->device(), "true-pose channel: no answer within " +
                                            std::to_string(timeout_.count()) + " ms");
  }
  return parse_true_pose_reply(*line, "true-pose channel " + channel_->device());
}

Eigen::Isometry3d SimControllerTruth::world_T_board() {
  return mounting_.world_T_base * read().base_T_task * mounting_.task_T_board;
}

}  // namespace robocal::robotio
