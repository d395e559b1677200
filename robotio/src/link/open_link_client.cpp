// The open link protocol's client side (robotio/OPEN_LINK.md): request ids, JSON lines,
// deadlines, and the parts of a hello and an error reply.
#include "robocal/robotio/link_error.hpp"
#include "robocal/robotio/open_link.hpp"

#include <fmt/core.h>

#include <algorithm>
#include <stdexcept>
#include <utility>

namespace robocal::robotio {
namespace {

using nlohmann::json;
using std::chrono::milliseconds;

const json& field(const json& reply, const char* name) {
  if (!reply.contains(name)) throw std::invalid_argument(fmt::format("no \"{}\"", name));
  return reply[name];
}

std::string string_field(const json& object, const char* name) {
  const json& v = field(object, name);
  if (!v.is_string()) throw std::invalid_argument(fmt::format("\"{}\" is not a string", name));
  return v.get<std::string>();
}

OpenLinkActuator parse_actuator(const json& a, std::size_t index) {
  if (!a.is_object())
    throw std::invalid_argument(fmt::format("actuator {} is not an object", index + 1));
  OpenLinkActuator out;
  out.name = string_field(a, "name");
  out.unit = string_field(a, "unit");
  const json& r = field(a, "resolution");
  if (!r.is_number() || !(r.get<double>() > 0.0))
    throw std::invalid_argument(fmt::format(
        "actuator {} '{}': \"resolution\" must be a positive number", index + 1, out.name));
  out.resolution = r.get<double>();
  return out;
}

}  // namespace

bool OpenLinkHello::has(const std::string& capability) const {
  return std::find(capabilities.begin(), capabilities.end(), capability) != capabilities.end();
}

OpenLinkHello parse_open_hello(const json& reply) {
  OpenLinkHello h;
  h.protocol = string_field(reply, "protocol");
  const json& v = field(reply, "version");
  if (!v.is_array() || v.size() != 2 || !v[0].is_number_integer() || !v[1].is_number_integer())
    throw std::invalid_argument("\"version\" is not [major, minor]");
  h.major = v[0].get<int>();
  h.minor = v[1].get<int>();
  h.controller = string_field(reply, "controller");
  if (reply.contains("capabilities") && reply["capabilities"].is_array())
    for (const json& c : reply["capabilities"])
      if (c.is_string()) h.capabilities.push_back(c.get<std::string>());
  const json& actuators = field(reply, "actuators");
  if (!actuators.is_array() || actuators.empty())
    throw std::invalid_argument("\"actuators\" is not a non-empty list");
  for (std::size_t i = 0; i < actuators.size(); ++i)
    h.actuators.push_back(parse_actuator(actuators[i], i));
  if (reply.contains("keepalive_s") && reply["keepalive_s"].is_number())
    h.keepalive_s = std::max(0.0, reply["keepalive_s"].get<double>());
  return h;
}

std::string open_hello_mismatch(const OpenLinkHello& hello, const calib::Mechanism& model) {
  if (hello.actuators.size() != model.actuated.size()) {
    std::string names;
    for (const OpenLinkActuator& a : hello.actuators) names += (names.empty() ? "" : ", ") + a.name;
    return fmt::format("the controller reports {} actuators ({}); the robot file '{}' has {}",
                       hello.actuators.size(), names, model.name, model.actuated.size());
  }
  for (std::size_t i = 0; i < hello.actuators.size(); ++i) {
    const bool prismatic = model.bodies[model.actuated[i]].joint == calib::JointType::kPrismatic;
    const std::string expect = prismatic ? "m" : "rad";
    if (hello.actuators[i].unit != expect)
      return fmt::format(
          "actuator {} '{}' is in '{}'; the robot file '{}' has a {} joint there (expects '{}')",
          i + 1, hello.actuators[i].name, hello.actuators[i].unit, model.name,
          prismatic ? "prismatic" : "revolute", expect);
  }
  return "";
}

OpenLinkFailure open_reply_failure(const json& reply) {
  if (reply.value("ok", false) == true) return {};
  OpenLinkFailure f{-1, "error reply without code"};
  if (reply.contains("error") && reply["error"].is_object()) {
    const json& e = reply["error"];
    if (e.contains("code") && e["code"].is_number_integer()) f.code = e["code"].get<int>();
    if (e.contains("message") && e["message"].is_string()) f.message = e["message"];
  }
  return f;
}

OpenLinkClient::OpenLinkClient(std::unique_ptr<Transport> transport, std::string device)
    : transport_(std::move(transport)), device_(std::move(device)) {}

void OpenLinkClient::open() {
  try {
    transport_->open();
  } catch (const LinkError& e) {
    throw LinkError(device_, e.what());
  }
  transport_->drain();
  restart_ids();
}

std::optional<json> OpenLinkClient::read_json(Clock::time_point deadline) {
  for (;;) {
    std::optional<std::string> text;
    try {
      text = transport_->read_line(deadline);
    } catch (const LinkError&) {
      throw LinkError(device_, "connection lost", last_line_);
    }
    if (!text) return std::nullopt;
    last_line_ = *text;
    json j = json::parse(*text, nullptr, false);
    if (j.is_object()) return j;
    ++garbage_;
  }
}

json OpenLinkClient::request(json request, milliseconds silence, milliseconds total, int attempts,
                             const std::function<void()>& tick, Clock::time_point quiet_until) {
  const long id = next_id_++;
  request["id"] = id;
  const std::string cmd = request.value("cmd", "?");
  const std::string line = request.dump();
  auto write = [&] {
    try {
      transport_->write_line(line);
    } catch (const LinkError&) {
      throw LinkError(device_, fmt::format("connection lost sending '{}'", cmd), last_line_);
    }
  };
  write();
  int sent = 1;
  const auto total_deadline = Clock::now() + total;
  auto silence_deadline = std::max(Clock::now(), quiet_until) + silence;
  const long garbage_before = garbage_;
  auto what_came = [&] {
    const long g = garbage_ - garbage_before;
    return g > 0 ? fmt::format(" ({} lines that were not JSON objects)", g) : std::string();
  };
  for (;;) {
    if (tick) tick();
    const auto slice =
        std::min({silence_deadline, total_deadline, Clock::now() + milliseconds(50)});
    const std::optional<json> reply = read_json(slice);
    if (!reply) {
      if (Clock::now() >= total_deadline)
        throw OpenLinkTimeout(device_,
                              fmt::format("no reply to '{}' within {:.1f} s{}", cmd,
                                          static_cast<double>(total.count()) / 1000.0, what_came()),
                              last_line_);
      if (Clock::now() >= silence_deadline) {
        if (sent >= attempts)
          throw LinkError(
              device_, fmt::format("no reply to '{}' after {} attempts{}", cmd, sent, what_came()),
              last_line_);
        ++sent;
        ++repeats_;
        write();  // the same id: a controller that executed it only repeats its reply
        silence_deadline = Clock::now() + silence;
      }
      continue;
    }
    silence_deadline = std::max(silence_deadline, Clock::now() + silence);
    if (reply->contains("event")) {
      ++notifications_;
      if ((*reply)["event"] == "settled") last_settled_ = *reply;
      continue;
    }
    if (!reply->contains("id") || (*reply)["id"] != id) {
      ++stale_;  // the reply to an earlier request sent again, or a confused controller
      continue;
    }
    return *reply;
  }
}

bool is_open_link_address(const std::string& address) {
  return address.rfind("open:", 0) == 0;
}

std::unique_ptr<Transport> open_link_transport(const std::string& address) {
  if (!is_open_link_address(address))
    throw LinkError(address, "expected open:HOST:PORT for the open link");
  return make_transport("tcp:" + address.substr(5));
}

}  // namespace robocal::robotio
