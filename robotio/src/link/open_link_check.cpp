// `robocal link-check`: the requirements of robotio/OPEN_LINK.md, each tried against the
// controller. Motion checks come last and only after the operator's confirmation.
#include "robocal/robotio/open_link_check.hpp"

#include "robocal/robotio/link_error.hpp"
#include "robocal/robotio/motion_profile.hpp"
#include "robocal/robotio/open_link.hpp"

#include <fmt/core.h>
#include <fmt/ranges.h>

#include <algorithm>
#include <cmath>
#include <optional>
#include <thread>

namespace robocal::robotio {
namespace {

using nlohmann::json;
using std::chrono::milliseconds;

class Checker {
 public:
  Checker(const std::string& address, const LinkCheckOptions& options)
      : options_(options),
        client_(open_link_transport(address),
                "open link " + address.substr(std::min<std::size_t>(5, address.size()))) {}

  std::vector<LinkCheckItem> run() {
    if (!connect()) return items_;
    const bool hello_ok = hello();
    if (hello_ok) {
      read_position();
      state();
      errors();
      repeated_id();
      wrong_count();
      older_version();
      motion();
    } else {
      skip_rest("no usable hello");
    }
    return items_;
  }

 private:
  void record(const std::string& requirement, bool pass, const std::string& detail) {
    items_.push_back({requirement, pass ? CheckVerdict::kPass : CheckVerdict::kFail, detail});
  }
  void skip(const std::string& requirement, const std::string& why) {
    items_.push_back({requirement, CheckVerdict::kSkip, why});
  }
  void skip_rest(const std::string& why) {
    for (const char* r : {"read", "state", "errors 100 and 101", "repeated id",
                          "move with the wrong actuator count", "older major version", "motion"})
      skip(r, why);
  }

  json ask(const json& request) {
    return client_.request(request, options_.reply_timeout, options_.reply_timeout * 3, 1);
  }

  bool connect() {
    try {
      client_.open();
      record("connection", true, "TCP connection accepted");
      return true;
    } catch (const LinkError& e) {
      record("connection", false, e.what());
      return false;
    }
  }

  bool hello() {
    json reply;
    try {
      reply = ask({{"cmd", "hello"},
                   {"protocol", kOpenLinkProtocol},
                   {"version", {kOpenLinkMajor, kOpenLinkMinor}},
                   {"client", "robocal link-check"}});
    } catch (const LinkError& e) {
      record("framing: a JSON object line answering the request's id", false, e.what());
      return false;
    }
    record("framing: a JSON object line answering the request's id", true,
           client_.garbage() > 0
               ? fmt::format("(after {} lines that were not JSON)", client_.garbage())
               : fmt::format("the reply carries id {}", reply.value("id", json()).dump()));
    const OpenLinkFailure f = open_reply_failure(reply);
    if (f.code != 0) {
      record("hello accepted", false, fmt::format("error {}: {}", f.code, f.message));
      return false;
    }
    try {
      hello_ = parse_open_hello(reply);
    } catch (const std::invalid_argument& e) {
      record("hello: protocol, version, controller, actuators", false, e.what());
      return false;
    }
    const bool protocol_ok = hello_.protocol == kOpenLinkProtocol && hello_.major == kOpenLinkMajor;
    record("hello: protocol robocal-open-link, same major version", protocol_ok,
           fmt::format("{} {}.{}", hello_.protocol, hello_.major, hello_.minor));
    std::string units_problem;
    for (const OpenLinkActuator& a : hello_.actuators)
      if (a.unit != "m" && a.unit != "rad")
        units_problem = fmt::format("actuator '{}' has unit '{}' (m or rad)", a.name, a.unit);
    record("hello: controller name, actuators with name, unit and resolution",
           units_problem.empty() && !hello_.controller.empty(),
           units_problem.empty()
               ? fmt::format("'{}', {} actuators, capabilities [{}]", hello_.controller,
                             hello_.actuators.size(), fmt::join(hello_.capabilities, ", "))
               : units_problem);
    return protocol_ok;
  }

  std::optional<std::vector<double>> position_of(const json& reply, std::string& problem) const {
    const std::size_t n = hello_.actuators.size();
    if (!reply.contains("position") || !reply["position"].is_array() ||
        reply["position"].size() != n) {
      problem = fmt::format("no \"position\" of {} numbers", n);
      return std::nullopt;
    }
    std::vector<double> p;
    for (const json& v : reply["position"]) {
      if (!v.is_number()) {
        problem = "a position is not a number";
        return std::nullopt;
      }
      p.push_back(v.get<double>());
    }
    if (hello_.has("counts")) {
      const json& c = reply.contains("counts") ? reply["counts"] : json();
      if (!c.is_array() || c.size() != n) {
        problem = "capability counts, but no \"counts\" list";
        return std::nullopt;
      }
      for (std::size_t i = 0; i < n; ++i) {
        const double expect = c[i].get<double>() * hello_.actuators[i].resolution;
        if (!c[i].is_number_integer() ||
            std::abs(expect - p[i]) > 0.5 * hello_.actuators[i].resolution + 1e-12) {
          problem = fmt::format("actuator {}: position {} is not counts {} x resolution {}", i + 1,
                                p[i], c[i].dump(), hello_.actuators[i].resolution);
          return std::nullopt;
        }
      }
    }
    return p;
  }

  std::optional<std::vector<double>> read_now(std::string& problem) {
    try {
      const json reply = ask({{"cmd", "read"}});
      const OpenLinkFailure f = open_reply_failure(reply);
      if (f.code != 0) {
        problem = fmt::format("error {}: {}", f.code, f.message);
        return std::nullopt;
      }
      return position_of(reply, problem);
    } catch (const LinkError& e) {
      problem = e.what();
      return std::nullopt;
    }
  }

  void read_position() {
    std::string problem;
    const auto p = read_now(problem);
    record("read: position (and counts = position / resolution)", p.has_value(),
           p ? fmt::format("[{}]", fmt::join(*p, ", ")) : problem);
    if (p) position_ = *p;
  }

  std::string state_now() {
    const json reply = ask({{"cmd", "state"}});
    if (open_reply_failure(reply).code != 0 || !reply.contains("state") ||
        !reply["state"].is_string())
      return "";
    return reply["state"].get<std::string>();
  }

  void state() {
    try {
      const std::string s = state_now();
      const bool known =
          s == "idle" || s == "moving" || s == "stopped" || s == "halted" || s == "fault";
      record("state: idle, moving, stopped, halted or fault", known,
             known ? s : client_.last_line());
    } catch (const LinkError& e) {
      record("state: idle, moving, stopped, halted or fault", false, e.what());
    }
  }

  // The error code of a reply read after a raw line, or -1.
  int raw_error(const std::string& line, json& reply) {
    client_.write_raw(line);
    const auto deadline = Clock::now() + options_.reply_timeout;
    while (const auto j = client_.read_json(deadline)) {
      if (j->contains("event")) continue;
      reply = *j;
      return open_reply_failure(*j).code;
    }
    return -1;
  }

  void errors() {
    try {
      json reply;
      const int malformed = raw_error("this is not json", reply);
      record("error 100 for a line that is not a JSON request (id null)",
             malformed == 100 && reply.contains("id") && reply["id"].is_null(),
             malformed < 0 ? "no reply" : reply.dump());
      const json unknown = ask({{"cmd", "no_such_command"}});
      const OpenLinkFailure f = open_reply_failure(unknown);
      record("error 101 for an unknown command, with a message",
             f.code == 101 && !f.message.empty(), unknown.dump());
    } catch (const LinkError& e) {
      record("errors 100 and 101", false, e.what());
    }
  }

  void repeated_id() {
    try {
      json first, second;
      const std::string line = R"({"id":900001,"cmd":"state"})";
      raw_error(line, first);
      raw_error(line, second);
      record("a repeated id gets the same reply again", !first.is_null() && first == second,
             fmt::format("{} / {}", first.dump(), second.dump()));
    } catch (const LinkError& e) {
      record("a repeated id gets the same reply again", false, e.what());
    }
  }

  void wrong_count() {
    try {
      const std::vector<double> target(hello_.actuators.size() + 1, 0.0);
      const json reply = ask({{"cmd", "move"},
                              {"target", target},
                              {"speed", options_.speed},
                              {"acceleration", options_.acceleration}});
      const OpenLinkFailure f = open_reply_failure(reply);
      std::string problem;
      const auto after = read_now(problem);
      const bool still = after && position_ == *after;
      record(
          "move with the wrong actuator count: error 102, nothing moves", f.code == 102 && still,
          f.code == 102 ? (still ? f.message : "the position changed: " + problem) : reply.dump());
    } catch (const LinkError& e) {
      record("move with the wrong actuator count: error 102, nothing moves", false, e.what());
    }
  }

  void older_version() {
    try {
      const json reply = ask({{"cmd", "hello"},
                              {"protocol", kOpenLinkProtocol},
                              {"version", {kOpenLinkMajor - 1, 9}},
                              {"client", "robocal link-check"}});
      const OpenLinkFailure f = open_reply_failure(reply);
      record("hello from an older major version: error 103 naming both versions",
             f.code == 103 && !f.message.empty(), reply.dump());
      // Leave the connection in the version it speaks.
      ask({{"cmd", "hello"},
           {"protocol", kOpenLinkProtocol},
           {"version", {kOpenLinkMajor, kOpenLinkMinor}}});
    } catch (const LinkError& e) {
      record("hello from an older major version: error 103 naming both versions", false, e.what());
    }
  }

  bool inside_box(const std::vector<double>& p) const {
    for (std::size_t i = 0; i < p.size(); ++i)
      if (p[i] < options_.lower[i] || p[i] > options_.upper[i]) return false;
    return true;
  }

  std::vector<double> box_point(double fraction) const {
    std::vector<double> p(options_.lower.size());
    for (std::size_t i = 0; i < p.size(); ++i)
      p[i] = options_.lower[i] + fraction * (options_.upper[i] - options_.lower[i]);
    return p;
  }

  double move_seconds(const std::vector<double>& from, const std::vector<double>& to) const {
    double d2 = 0.0;
    for (std::size_t i = 0; i < from.size(); ++i) d2 += (to[i] - from[i]) * (to[i] - from[i]);
    return trapezoid_seconds(std::sqrt(d2), options_.speed, options_.acceleration);
  }

  // The checks that move; returns the reason they cannot run, or "".
  std::string motion_precondition() const {
    const std::size_t n = hello_.actuators.size();
    if (options_.lower.empty() && options_.upper.empty())
      return "no --lower/--upper limits given: nothing moves";
    if (options_.lower.size() != n || options_.upper.size() != n)
      return fmt::format("--lower/--upper need {} values each (the controller's actuators)", n);
    for (std::size_t i = 0; i < n; ++i)
      if (!(options_.lower[i] < options_.upper[i]))
        return fmt::format("--lower must be below --upper (actuator {})", i + 1);
    if (position_.size() != n) return "the position could not be read";
    if (!inside_box(position_))
      return fmt::format("the robot is at [{}], outside the limits given: bring it inside first",
                         fmt::join(position_, ", "));
    return "";
  }

  void motion() {
    const char* kMove = "move inside the limits: accepted, settled, read back at the target";
    const char* kStop = "controlled stop during a move: acknowledged, the motion ends";
    if (const std::string why = motion_precondition(); !why.empty()) {
      skip(kMove, why);
      skip(kStop, why);
      return;
    }
    const std::vector<double> a = box_point(0.25), b = box_point(0.75);
    const std::string plan = fmt::format(
        "link-check moves the robot from [{}] to [{}], then towards [{}] and stops it on the way, "
        "at {} per second",
        fmt::join(position_, ", "), fmt::join(a, ", "), fmt::join(b, ", "), options_.speed);
    if (!options_.confirm_motion || !options_.confirm_motion(plan)) {
      skip(kMove, "the operator did not confirm motion");
      skip(kStop, "the operator did not confirm motion");
      return;
    }
    try {
      move_and_verify(kMove, a);
      stop_midway(kStop, a, b);
    } catch (const LinkError& e) {
      record("motion", false, e.what());
    }
  }

  json move_request(const std::vector<double>& target) const {
    return {{"cmd", "move"},
            {"target", target},
            {"speed", options_.speed},
            {"acceleration", options_.acceleration}};
  }

  milliseconds wait_budget(const std::vector<double>& from, const std::vector<double>& to) const {
    return milliseconds(static_cast<long>(1000.0 * (2.0 * move_seconds(from, to) + 5.0)));
  }

  void move_and_verify(const char* requirement, const std::vector<double>& target) {
    const json accepted = ask(move_request(target));
    if (const OpenLinkFailure f = open_reply_failure(accepted); f.code != 0) {
      record(requirement, false, fmt::format("move refused: error {}: {}", f.code, f.message));
      return;
    }
    const milliseconds budget = wait_budget(position_, target);
    const json settled = client_.request({{"cmd", "wait_settled"}}, budget, budget, 1);
    if (const OpenLinkFailure f = open_reply_failure(settled); f.code != 0) {
      record(requirement, false, fmt::format("wait_settled: error {}: {}", f.code, f.message));
      return;
    }
    std::string problem;
    const auto p = read_now(problem);
    bool at = p.has_value();
    for (std::size_t i = 0; at && i < target.size(); ++i)
      at = std::abs((*p)[i] - target[i]) <= 0.5 * hello_.actuators[i].resolution + 1e-12;
    const bool event_ok = !hello_.has("settled_event") || !client_.last_settled().is_null();
    record(requirement, at && event_ok,
           !p         ? problem
           : !at      ? fmt::format("read [{}] after settling at [{}]", fmt::join(*p, ", "),
                                    fmt::join(target, ", "))
           : event_ok ? fmt::format("at [{}]", fmt::join(*p, ", "))
                      : "capability settled_event, but no settled notification came");
    if (p) position_ = *p;
  }

  void stop_midway(const char* requirement, const std::vector<double>& from,
                   const std::vector<double>& to) {
    const json accepted = ask(move_request(to));
    if (open_reply_failure(accepted).code != 0) {
      record(requirement, false, "move refused: " + accepted.dump());
      return;
    }
    std::this_thread::sleep_for(
        milliseconds(static_cast<long>(1000.0 * 0.3 * move_seconds(from, to))));
    const json stopped = ask({{"cmd", "stop"}, {"kind", "controlled"}});
    const milliseconds budget = wait_budget(from, to);
    const json settled = client_.request({{"cmd", "wait_settled"}}, budget, budget, 1);
    const std::string s = state_now();
    std::string problem;
    const auto p = read_now(problem);
    const bool ok = open_reply_failure(stopped).code == 0 &&
                    open_reply_failure(settled).code == 0 && (s == "stopped" || s == "idle") &&
                    p.has_value();
    record(requirement, ok,
           ok ? fmt::format("state {}, stopped at [{}]", s, fmt::join(*p, ", "))
              : fmt::format("stop: {}; state '{}'; {}", stopped.dump(), s, problem));
  }

  LinkCheckOptions options_;
  OpenLinkClient client_;
  OpenLinkHello hello_;
  std::vector<double> position_;
  std::vector<LinkCheckItem> items_;
};

}  // namespace

const char* to_string(CheckVerdict verdict) {
  switch (verdict) {
    case CheckVerdict::kPass:
      return "PASS";
    case CheckVerdict::kFail:
      return "FAIL";
    case CheckVerdict::kSkip:
      return "SKIP";
  }
  return "?";
}

std::vector<LinkCheckItem> check_open_link(const std::string& address,
                                           const LinkCheckOptions& options) {
  try {
    return Checker(address, options).run();
  } catch (const LinkError& e) {
    return {{"open:HOST:PORT address", CheckVerdict::kFail, e.what()}};
  }
}

}  // namespace robocal::robotio
