#pragma once
// The WebSocket protocol (RFC 6455) as a controller link needs it: the opening handshake (HTTP/1.1
// Upgrade with Sec-WebSocket-Key and its SHA-1 accept value), frames (FIN, opcode, 7/16/64-bit
// lengths, the client's masking), and a client that carries text messages over a TCP connection
// with a deadline on every read. Klipper printers are reached this way, through Moonraker's
// JSON-RPC endpoint (ws://HOST:7125/websocket); the simulated Moonraker serves the same frames.
//
// The framing and handshake functions are pure (bytes in, bytes out) so that they are tested
// against the RFC's own worked examples.
#include "robocal/robotio/transport.hpp"

#include <array>
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>

namespace robocal::robotio {

// SHA-1 (FIPS 180-4) of `data`, 20 bytes: only for the handshake's accept value.
std::array<std::uint8_t, 20> sha1(std::string_view data);
// Base64 (RFC 4648, with padding).
std::string base64(std::string_view bytes);

// The Sec-WebSocket-Accept value a server answers to a client's Sec-WebSocket-Key (RFC 6455
// section 4.2.2): base64(SHA-1(key + "258EAFA5-E914-47DA-95CA-C5AB0DC85B11")).
std::string websocket_accept(std::string_view client_key);

enum class WsOpcode : std::uint8_t {
  kContinuation = 0x0,
  kText = 0x1,
  kBinary = 0x2,
  kClose = 0x8,
  kPing = 0x9,
  kPong = 0xA,
};

struct WsFrame {
  bool fin = true;
  WsOpcode opcode = WsOpcode::kText;
  std::string payload;  // unmasked
};

// One frame's bytes. A client masks every frame it sends (section 5.3) with `mask`; a server
// sends without one (nullopt).
std::string encode_ws_frame(const WsFrame& frame,
                            const std::optional<std::array<std::uint8_t, 4>>& mask);

// Takes the first complete frame off the front of `buffer` (bytes received and not yet used);
// nullopt when the buffer does not hold a whole frame yet. `from_client`: frames must be masked
// (a server's view) or must not be (a client's view). Throws std::runtime_error naming what is
// wrong for a frame no peer may send: reserved bits set, an unknown opcode, masking the wrong
// way, a control frame longer than 125 bytes or fragmented, a 64-bit length with its top bit set,
// or a payload over `max_payload` bytes.
std::optional<WsFrame> take_ws_frame(std::string& buffer, bool from_client,
                                     std::size_t max_payload = std::size_t{16} << 20);

// The client's opening request for ws://host:port/path with the given Sec-WebSocket-Key.
std::string ws_client_request(const std::string& host, int port, const std::string& path,
                              const std::string& key);
// Checks a server's answer to that request (status 101, Upgrade: websocket, Connection:
// Upgrade, the accept value for `key`); the problem in words, or "" when it is a valid upgrade.
std::string ws_check_server_response(std::string_view response, std::string_view key);

// A server's view of a client's opening request: the request path and key, or the problem.
struct WsClientRequest {
  std::string path;
  std::string key;
  std::string problem;  // "" when the request is a valid WebSocket upgrade
};
WsClientRequest ws_parse_client_request(std::string_view request);
// The server's 101 answer for a client's key.
std::string ws_server_response(std::string_view key);

// A WebSocket client over TCP carrying text messages: answers pings, joins fragments, and
// reports a close or a lost connection as LinkError naming the device
// ("websocket 127.0.0.1:7125/websocket").
class WebSocketClient {
 public:
  WebSocketClient(std::string host, int port, std::string path,
                  std::chrono::milliseconds connect_timeout = std::chrono::milliseconds(2000));
  // Connects and completes the opening handshake before `deadline`. Throws LinkError.
  void open(Clock::time_point deadline);
  void close();
  bool is_open() const { return tcp_.is_open() && open_; }
  void send_text(const std::string& text);
  // The next complete text message, or nullopt when the deadline passes first.
  std::optional<std::string> receive_text(Clock::time_point deadline);
  std::string device() const;

 private:
  std::string host_;
  int port_;
  std::string path_;
  TcpTransport tcp_;
  std::string buffer_;
  std::string partial_;  // a fragmented text message so far
  bool open_ = false;
};

}  // namespace robocal::robotio
