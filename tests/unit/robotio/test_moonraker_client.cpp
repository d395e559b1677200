// Moonraker's JSON-RPC client against a loopback WebSocket server that answers the way
// Moonraker's documentation shows (docs/external_api: printer.md, jsonrpc_notifications.md,
// introduction.md): results and errors matched by id, G-code output as notify_gcode_response
// notifications sent before the script's "ok", an answer that never comes, a stale answer.
#include "loopback_listener.hpp"
#include "robocal/robotio/moonraker.hpp"

#include <gtest/gtest.h>

#include <sys/socket.h>
#include <unistd.h>

#include <functional>
#include <string>
#include <thread>
#include <vector>

namespace robocal::robotio {
namespace {

using nlohmann::json;

// Accepts one client and gives each JSON-RPC request to `answer`, which returns the messages to
// send back (in order; none for a request left unanswered).
class ScriptedMoonraker {
 public:
  using Answer = std::function<std::vector<json>(const json& request)>;
  explicit ScriptedMoonraker(Answer answer) : answer_(std::move(answer)) {
    const test::LoopbackListener listener = test::listen_on_loopback();
    listen_fd_ = listener.fd;
    port_ = listener.port;
    thread_ = std::thread([this] { serve(); });
  }
  ~ScriptedMoonraker() {
    thread_.join();
    ::close(listen_fd_);
  }
  int port() const { return port_; }

 private:
  bool fill(int fd, std::string& buffer) {
    char chunk[4096];
    const ssize_t n = ::recv(fd, chunk, sizeof chunk, 0);
    if (n <= 0) return false;
    buffer.append(chunk, static_cast<std::size_t>(n));
    return true;
  }
  void send_all(int fd, const std::string& data) {
    (void)::send(fd, data.data(), data.size(), MSG_NOSIGNAL);
  }
  void serve() {
    const int fd = ::accept(listen_fd_, nullptr, nullptr);
    ASSERT_GE(fd, 0);
    std::string buffer;
    while (buffer.find("\r\n\r\n") == std::string::npos)
      if (!fill(fd, buffer)) return;
    const std::size_t end = buffer.find("\r\n\r\n") + 4;
    const WsClientRequest request = ws_parse_client_request(buffer.substr(0, end));
    buffer.erase(0, end);
    send_all(fd, ws_server_response(request.key));
    for (;;) {
      std::optional<WsFrame> frame;
      while (!(frame = take_ws_frame(buffer, /*from_client=*/true)))
        if (!fill(fd, buffer)) {
          ::close(fd);
          return;
        }
      if (frame->opcode == WsOpcode::kClose) break;
      for (const json& reply : answer_(json::parse(frame->payload)))
        send_all(fd, encode_ws_frame({true, WsOpcode::kText, reply.dump()}, std::nullopt));
    }
    ::close(fd);
  }
  Answer answer_;
  int listen_fd_ = -1;
  int port_ = 0;
  std::thread thread_;
};

json result(const json& request, const json& value) {
  return {{"jsonrpc", "2.0"}, {"result", value}, {"id", request["id"]}};
}

TEST(MoonrakerClient, RequestTextIsJsonRpc2WithParamsOnlyWhenGiven) {
  EXPECT_EQ(jsonrpc_request("printer.info", json(), 5445),
            R"({"id":5445,"jsonrpc":"2.0","method":"printer.info"})");
  EXPECT_EQ(
      jsonrpc_request("printer.gcode.script", json{{"script", "G28"}}, 7466),
      R"({"id":7466,"jsonrpc":"2.0","method":"printer.gcode.script","params":{"script":"G28"}})");
}

TEST(MoonrakerClient, AnswersByIdNotificationsKeptInOrderErrorsNamed) {
  ScriptedMoonraker server([](const json& request) -> std::vector<json> {
    const std::string method = request["method"];
    if (method == "printer.info")
      return {result(request, {{"state", "ready"}, {"state_message", "Printer is ready"}})};
    if (method == "printer.gcode.script" && request["params"]["script"] == "GET_POSITION")
      // The G-code's output first, then an answer to an older request, then the script's "ok".
      return {{{"jsonrpc", "2.0"},
               {"method", "notify_gcode_response"},
               {"params", {"// mcu: stepper_a:1200 stepper_b:1210 stepper_c:1190"}}},
              {{"jsonrpc", "2.0"}, {"result", "stale"}, {"id", 1}},
              result(request, "ok")};
    if (method == "printer.gcode.script")
      return {{{"jsonrpc", "2.0"},
               {"error",
                {{"code", 400},
                 {"message",
                  "{'message': 'Must home axis first: 0.000 0.000 300.000 [0.000]', "
                  "'error': 'WebRequestError'}"}}},
               {"id", request["id"]}}};
    return {};  // printer.emergency_stop: never answered here
  });
  MoonrakerClient client("127.0.0.1", server.port());
  client.open(Clock::now() + std::chrono::seconds(5));
  const json info = client.call("printer.info", json(), Clock::now() + std::chrono::seconds(5));
  EXPECT_EQ(info["state"], "ready");
  EXPECT_EQ(client.call("printer.gcode.script", {{"script", "GET_POSITION"}},
                        Clock::now() + std::chrono::seconds(5)),
            "ok");
  const auto notes = client.take_notifications();
  ASSERT_EQ(notes.size(), 1u);
  EXPECT_EQ(notes[0].method, "notify_gcode_response");
  EXPECT_EQ(notes[0].params[0], "// mcu: stepper_a:1200 stepper_b:1210 stepper_c:1190");
  EXPECT_TRUE(client.take_notifications().empty());
  try {
    (void)client.call("printer.gcode.script", {{"script", "G1 X10"}},
                      Clock::now() + std::chrono::seconds(5));
    ADD_FAILURE() << "an error answer must throw";
  } catch (const MoonrakerError& e) {
    EXPECT_EQ(e.code(), 400);
    EXPECT_NE(e.controller_said().find("Must home axis first"), std::string::npos);
    EXPECT_NE(std::string(e.what()).find("printer.gcode.script answered error 400"),
              std::string::npos)
        << e.what();
  }
  try {
    (void)client.call("printer.emergency_stop", json(),
                      Clock::now() + std::chrono::milliseconds(300));
    ADD_FAILURE() << "a request never answered must time out";
  } catch (const MoonrakerError&) {
    ADD_FAILURE() << "a timeout is not an error answer";
  } catch (const LinkError& e) {
    EXPECT_NE(std::string(e.what()).find("no answer to printer.emergency_stop in time"),
              std::string::npos)
        << e.what();
  }
  client.close();
}

}  // namespace
}  // namespace robocal::robotio
