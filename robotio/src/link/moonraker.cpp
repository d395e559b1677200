#include "robocal/robotio/moonraker.hpp"

#include "robocal/robotio/link_error.hpp"

#include <fmt/format.h>

#include <utility>

namespace robocal::robotio {

MoonrakerError::MoonrakerError(const std::string& device, const std::string& method, int code,
                               const std::string& message)
    : LinkError(device, fmt::format("{} answered error {}", method, code), message), code_(code) {}

std::string jsonrpc_request(const std::string& method, const nlohmann::json& params, long id) {
  nlohmann::json request = {{"jsonrpc", "2.0"}, {"method", method}};
  if (!params.is_null()) request["params"] = params;
  request["id"] = id;
  return request.dump();
}

MoonrakerClient::MoonrakerClient(std::string host, int port, std::string path)
    : ws_(std::move(host), port, std::move(path)) {}

std::optional<nlohmann::json> MoonrakerClient::receive(Clock::time_point deadline) {
  for (;;) {
    const auto text = ws_.receive_text(deadline);
    if (!text) return std::nullopt;
    nlohmann::json message = nlohmann::json::parse(*text, nullptr, /*allow_exceptions=*/false);
    if (!message.is_object())
      throw LinkError(device(), "Moonraker sent a message that is not a JSON object",
                      text->substr(0, 200));
    if (message.contains("id") && (message.contains("result") || message.contains("error")))
      return message;
    if (message.contains("method") && message["method"].is_string()) {
      notifications_.push_back({message["method"].get<std::string>(),
                                message.contains("params") ? message["params"] : nlohmann::json()});
      continue;
    }
    throw LinkError(device(),
                    "Moonraker sent a message that is neither an answer nor a notification",
                    text->substr(0, 200));
  }
}

long MoonrakerClient::send(const std::string& method, const nlohmann::json& params) {
  const long id = next_id_++;
  ws_.send_text(jsonrpc_request(method, params, id));
  return id;
}

std::optional<nlohmann::json> MoonrakerClient::answer(long id, const std::string& method,
                                                      Clock::time_point deadline) {
  for (;;) {
    auto message = receive(deadline);
    if (!message) return std::nullopt;
    // An answer to an earlier request that timed out here: not this one's.
    if (!(*message)["id"].is_number_integer() || (*message)["id"].get<long>() != id) continue;
    if (message->contains("error")) {
      const nlohmann::json& e = (*message)["error"];
      const int code = e.is_object() && e.contains("code") && e["code"].is_number_integer()
                           ? e["code"].get<int>()
                           : 0;
      const std::string text = e.is_object() && e.contains("message") && e["message"].is_string()
                                   ? e["message"].get<std::string>()
                                   : e.dump();
      throw MoonrakerError(device(), method, code, text);
    }
    return (*message)["result"];
  }
}

nlohmann::json MoonrakerClient::call(const std::string& method, const nlohmann::json& params,
                                     Clock::time_point deadline) {
  const long id = send(method, params);
  auto result = answer(id, method, deadline);
  if (!result) throw LinkError(device(), fmt::format("no answer to {} in time", method));
  return *result;
}

std::deque<MoonrakerNotification> MoonrakerClient::take_notifications() {
  return std::exchange(notifications_, {});
}

bool MoonrakerClient::wait_notification(Clock::time_point deadline) {
  while (notifications_.empty()) {
    auto answer = receive(deadline);
    if (!answer && notifications_.empty()) return false;
    // An answer nobody waits for any more (its call timed out) is dropped.
  }
  return true;
}

}  // namespace robocal::robotio
