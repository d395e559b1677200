#pragma once
// Moonraker's JSON-RPC 2.0 API over its WebSocket (ws://HOST:7125/websocket), the way a Klipper
// printer is reached on the network. From Moonraker's documentation (docs/external_api):
// - a request is {"jsonrpc": "2.0", "method": M, "params": P, "id": N}; its answer carries the
//   same id and either "result" or "error": {"code": C, "message": S};
// - `printer.gcode.script` {"script": "G28"} answers "ok" once the G-code has run; what the
//   G-code prints (`GET_POSITION`'s "// mcu: stepper_a:..." lines, "!! ..." errors) arrives as
//   `notify_gcode_response` notifications, {"method": ..., "params": ["text"]}, no id;
// - Klippy's state changes arrive as `notify_klippy_ready`, `notify_klippy_shutdown` and
//   `notify_klippy_disconnected`; `server.info` reports "klippy_state" (ready, startup, shutdown,
//   error, disconnected) and `printer.info` "state" and "state_message";
// - `printer.emergency_stop` halts the printer at once (Klippy goes to shutdown), answering "ok".
#include "robocal/robotio/link_error.hpp"
#include "robocal/robotio/websocket.hpp"

#include <nlohmann/json.hpp>

#include <deque>
#include <optional>
#include <string>

namespace robocal::robotio {

// A notification from Moonraker (a message with a method and no id).
struct MoonrakerNotification {
  std::string method;
  nlohmann::json params;
};

// A JSON-RPC error Moonraker answered (a G-code error, Klippy not ready, an unknown method):
// what() names the device, the method and Moonraker's message; code() is its error code.
class MoonrakerError final : public LinkError {
 public:
  MoonrakerError(const std::string& device, const std::string& method, int code,
                 const std::string& message);
  int code() const { return code_; }

 private:
  int code_;
};

// One JSON-RPC request's text; `params` null leaves the member out.
std::string jsonrpc_request(const std::string& method, const nlohmann::json& params, long id);

class MoonrakerClient {
 public:
  MoonrakerClient(std::string host, int port = 7125, std::string path = "/websocket");
  void open(Clock::time_point deadline) { ws_.open(deadline); }
  void close() { ws_.close(); }
  bool is_open() const { return ws_.is_open(); }
  std::string device() const { return ws_.device(); }

  // Sends the request and waits for the answer with its id. Notifications that arrive meanwhile
  // are kept (take_notifications). Throws MoonrakerError for an error answer, LinkError when no
  // answer comes before `deadline` or the connection is lost.
  nlohmann::json call(const std::string& method, const nlohmann::json& params,
                      Clock::time_point deadline);
  // The same in two halves, for a caller that must look at other things while it waits (a stop
  // request): sends the request and returns its id; then the answer to that id, or nullopt when
  // the deadline passes first (call again to keep waiting). Throws as call() does.
  long send(const std::string& method, const nlohmann::json& params);
  std::optional<nlohmann::json> answer(long id, const std::string& method,
                                       Clock::time_point deadline);
  // Notifications received so far, oldest first (and forgotten here).
  std::deque<MoonrakerNotification> take_notifications();
  // Waits until a notification arrives or the deadline passes; false on the deadline.
  bool wait_notification(Clock::time_point deadline);

 private:
  // One message off the socket: an answer is returned, a notification kept; nullopt on the
  // deadline.
  std::optional<nlohmann::json> receive(Clock::time_point deadline);

  WebSocketClient ws_;
  long next_id_ = 1;
  std::deque<MoonrakerNotification> notifications_;
};

}  // namespace robocal::robotio
