#include "robocal/robotio/manual_link.hpp"

#include "robocal/robotio/link_error.hpp"
#include "robocal/robotio/motion_profile.hpp"

#include <poll.h>
#include <unistd.h>

#include <fmt/core.h>

#include <cerrno>
#include <cmath>
#include <sstream>

namespace robocal::robotio {
namespace {

constexpr const char* kDevice = "manual link (operator)";

std::string unit_of(const calib::Mechanism& model, std::size_t actuator) {
  // Readings in encoder counts (a scale other than 1) have no SI unit.
  const double scale =
      calib::encoder_scales(model, model.nominal_parameters())[static_cast<Eigen::Index>(actuator)];
  if (std::abs(scale - 1.0) > 1e-12) return "counts";
  return model.bodies[model.actuated[actuator]].joint == calib::JointType::kPrismatic ? "m" : "rad";
}

}  // namespace

std::optional<Eigen::VectorXd> parse_typed_readings(const std::string& text, int count) {
  std::string spaced = text;
  for (char& c : spaced)
    if (c == ',' || c == ';' || c == '\t') c = ' ';
  std::stringstream in(spaced);
  std::vector<double> values;
  std::string token;
  while (in >> token) {
    try {
      std::size_t used = 0;
      values.push_back(std::stod(token, &used));
      if (used != token.size()) return std::nullopt;
    } catch (const std::exception&) {
      return std::nullopt;
    }
  }
  if (static_cast<int>(values.size()) != count) return std::nullopt;
  return Eigen::Map<const Eigen::VectorXd>(values.data(), count);
}

ManualLink::ManualLink(SafetyGuard& guard, ManualLinkOptions options)
    : RobotLink(guard), options_(options) {
  status_.device = kDevice;
}

int ManualLink::actuator_count() const {
  return static_cast<int>(guard().model().actuated.size());
}

std::string ManualLink::describe(const Eigen::VectorXd& readings) const {
  std::string s;
  const calib::Mechanism& model = guard().model();
  for (Eigen::Index i = 0; i < readings.size(); ++i) {
    const auto k = static_cast<std::size_t>(i);
    s += fmt::format("  {:<16} {:>14.6f} {}\n", model.bodies[model.actuated[k]].name, readings[i],
                     unit_of(model, k));
  }
  return s;
}

std::string ManualLink::answer(const std::string& question, bool interruptible) {
  fmt::print(options_.out, "{} ", question);
  std::fflush(options_.out);
  for (;;) {
    if (const std::size_t eol = pending_.find('\n'); eol != std::string::npos) {
      std::string line = pending_.substr(0, eol);
      pending_.erase(0, eol + 1);
      if (!line.empty() && line.back() == '\r') line.pop_back();
      return line;
    }
    if (interruptible && guard().stop_requested()) {
      do_stop(StopKind::kControlled);
      interrupted("waiting for the operator");
    }
    pollfd p{options_.input_fd, POLLIN, 0};
    const int ready = ::poll(&p, 1, 50);  // the stop flag is looked at every 50 ms
    if (ready < 0 && errno != EINTR) throw LinkError(kDevice, "cannot read the operator's input");
    if (ready <= 0) continue;
    char buf[256];
    const ssize_t n = ::read(options_.input_fd, buf, sizeof buf);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) {
      status_.state = LinkState::kDisconnected;
      throw LinkError(kDevice, "the operator's input closed before an answer", pending_);
    }
    pending_.append(buf, static_cast<std::size_t>(n));
  }
}

void ManualLink::wait_for_done(const std::string& what) {
  for (;;) {
    const std::string a = answer(fmt::format("{}. Type done when it is there and still (stop to "
                                             "stop the session):",
                                             what),
                                 true);
    if (a == "done" || a == "yes" || a == "y") return;
    if (a == "stop") {
      guard().request_stop("the operator typed stop");
      interrupted(what);
    }
  }
}

FirmwareInfo ManualLink::connect() {
  fmt::print(options_.out,
             "Manual link: robocal shows each target as actuator readings; move the robot there "
             "with its own controls, type done, then type the readings its controller shows.\n");
  status_.firmware = {Firmware::kUnknown, "manual (operator)", "", ""};
  status_.state = LinkState::kIdle;
  set_last_known(do_read().values);
  return status_.firmware;
}

void ManualLink::do_home() {
  status_.state = LinkState::kMoving;
  wait_for_done("Home the robot with its controller");
  status_.state = LinkState::kIdle;
}

void ManualLink::do_move(const Eigen::VectorXd& target, const MoveSpeed& speed) {
  status_.state = LinkState::kMoving;
  ++status_.commands;
  fmt::print(options_.out,
             "Move the robot to (the path from the last pose was checked; at most {} per "
             "second):\n{}",
             speed.speed, describe(target));
}

void ManualLink::do_wait_settled(std::chrono::milliseconds /*timeout*/) {
  // An operator takes as long as they take: no deadline, but the stop flag is polled.
  wait_for_done("Move to the target above");
  status_.state = LinkState::kIdle;
}

ActuatorReadings ManualLink::do_read() {
  const int n = actuator_count();
  std::string last;
  for (int attempt = 0; attempt < options_.attempts; ++attempt) {
    last = answer(fmt::format("Type the {} actuator readings the controller shows, in the "
                              "order above:",
                              n),
                  false);
    if (const auto values = parse_typed_readings(last, n)) return {{}, *values, std::nullopt};
    fmt::print(options_.out, "That is not {} numbers.\n", n);
  }
  throw LinkError(kDevice, fmt::format("{} answers were not {} readings", options_.attempts, n),
                  last);
}

void ManualLink::do_stop(StopKind kind) {
  fmt::print(options_.out, "\nSTOP: {} the robot now.\n",
             kind == StopKind::kEmergency ? "emergency-stop" : "stop");
  std::fflush(options_.out);
  status_.state = kind == StopKind::kEmergency ? LinkState::kFault : LinkState::kStopped;
}

bool ManualLink::at_target(const ActuatorReadings& readings, const Eigen::VectorXd& target) const {
  if (readings.values.size() != target.size()) return false;
  const Eigen::VectorXd joint =
      (readings.values - target).cwiseAbs().cwiseProduct(guard().joint_per_reading());
  return joint.maxCoeff() <= options_.tolerance;
}

double ManualLink::expected_seconds(const Eigen::VectorXd& from, const Eigen::VectorXd& to,
                                    const MoveSpeed& speed) const {
  const double length = (to - from).cwiseProduct(guard().joint_per_reading()).norm();
  return trapezoid_seconds(length, speed.speed, speed.acceleration);
}

}  // namespace robocal::robotio
