#include "robocal/robotio/websocket.hpp"

#include "robocal/robotio/link_error.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cctype>
#include <random>
#include <stdexcept>
#include <utility>
#include <vector>

namespace robocal::robotio {
namespace {

constexpr std::string_view kWebSocketGuid = "258EAFA5-E914-47DA-95CA-C5AB0DC85B11";

std::uint32_t rotl(std::uint32_t v, int bits) {
  return (v << bits) | (v >> (32 - bits));
}

// One 64-byte block of SHA-1's compression (FIPS 180-4, section 6.1.2).
void sha1_block(std::array<std::uint32_t, 5>& h, const std::uint8_t* block) {
  std::array<std::uint32_t, 80> w{};
  for (std::size_t t = 0; t < 16; ++t)
    w[t] = (std::uint32_t{block[4 * t]} << 24) | (std::uint32_t{block[4 * t + 1]} << 16) |
           (std::uint32_t{block[4 * t + 2]} << 8) | std::uint32_t{block[4 * t + 3]};
  for (int t = 16; t < 80; ++t) w[t] = rotl(w[t - 3] ^ w[t - 8] ^ w[t - 14] ^ w[t - 16], 1);
  std::uint32_t a = h[0], b = h[1], c = h[2], d = h[3], e = h[4];
  for (int t = 0; t < 80; ++t) {
    std::uint32_t f = 0;
    std::uint32_t k = 0;
    if (t < 20) {
      f = (b & c) | (~b & d);
      k = 0x5A827999;
    } else if (t < 40) {
      f = b ^ c ^ d;
      k = 0x6ED9EBA1;
    } else if (t < 60) {
      f = (b & c) | (b & d) | (c & d);
      k = 0x8F1BBCDC;
    } else {
      f = b ^ c ^ d;
      k = 0xCA62C1D6;
    }
    const std::uint32_t temp = rotl(a, 5) + f + e + k + w[t];
    e = d;
    d = c;
    c = rotl(b, 30);
    b = a;
    a = temp;
  }
  h[0] += a;
  h[1] += b;
  h[2] += c;
  h[3] += d;
  h[4] += e;
}

std::string lower_case(std::string_view text) {
  std::string out(text);
  std::transform(out.begin(), out.end(), out.begin(),
                 [](unsigned char ch) { return static_cast<char>(std::tolower(ch)); });
  return out;
}

// Header lines of an HTTP message after its first line, names lower-cased, values trimmed.
std::vector<std::pair<std::string, std::string>> http_headers(std::string_view message) {
  std::vector<std::pair<std::string, std::string>> out;
  std::size_t pos = message.find("\r\n");
  while (pos != std::string_view::npos) {
    const std::size_t start = pos + 2;
    const std::size_t end = message.find("\r\n", start);
    if (end == std::string_view::npos || end == start) break;
    const std::string_view line = message.substr(start, end - start);
    const std::size_t colon = line.find(':');
    if (colon != std::string_view::npos) {
      std::string name = lower_case(line.substr(0, colon));
      std::string_view value = line.substr(colon + 1);
      while (!value.empty() && (value.front() == ' ' || value.front() == '\t'))
        value.remove_prefix(1);
      while (!value.empty() && (value.back() == ' ' || value.back() == '\t'))
        value.remove_suffix(1);
      out.emplace_back(std::move(name), std::string(value));
    }
    pos = end;
  }
  return out;
}

std::string header(const std::vector<std::pair<std::string, std::string>>& headers,
                   std::string_view name) {
  for (const auto& [n, v] : headers)
    if (n == name) return v;
  return "";
}

// A comma-separated header value holding `token`, case-insensitively ("keep-alive, Upgrade").
bool has_token(const std::string& header_value, std::string_view token) {
  const std::string value = lower_case(header_value);
  const std::string lower = lower_case(token);
  std::size_t start = 0;
  while (start <= value.size()) {
    std::size_t end = value.find(',', start);
    if (end == std::string::npos) end = value.size();
    std::string_view item(value.data() + start, end - start);
    while (!item.empty() && item.front() == ' ') item.remove_prefix(1);
    while (!item.empty() && item.back() == ' ') item.remove_suffix(1);
    if (item == lower) return true;
    start = end + 1;
  }
  return false;
}

bool is_control(WsOpcode op) {
  return (static_cast<std::uint8_t>(op) & 0x8) != 0;
}

bool known_opcode(std::uint8_t op) {
  return op == 0x0 || op == 0x1 || op == 0x2 || op == 0x8 || op == 0x9 || op == 0xA;
}

std::string random_key() {
  std::random_device device;
  std::string nonce(16, '\0');
  for (char& c : nonce) c = static_cast<char>(device() & 0xFF);
  return base64(nonce);
}

std::array<std::uint8_t, 4> random_mask() {
  static thread_local std::mt19937 engine{std::random_device{}()};
  std::array<std::uint8_t, 4> mask{};
  for (auto& m : mask) m = static_cast<std::uint8_t>(engine() & 0xFF);
  return mask;
}

}  // namespace

std::array<std::uint8_t, 20> sha1(std::string_view data) {
  std::array<std::uint32_t, 5> h = {0x67452301, 0xEFCDAB89, 0x98BADCFE, 0x10325476, 0xC3D2E1F0};
  // Padding (section 5.1.1): a 1 bit, zeros to 56 mod 64 bytes, the length in bits (64-bit BE).
  std::string padded(data);
  padded.push_back(static_cast<char>(0x80));
  while (padded.size() % 64 != 56) padded.push_back('\0');
  const std::uint64_t bits = static_cast<std::uint64_t>(data.size()) * 8;
  for (int i = 7; i >= 0; --i) padded.push_back(static_cast<char>((bits >> (8 * i)) & 0xFF));
  for (std::size_t i = 0; i < padded.size(); i += 64)
    sha1_block(h, reinterpret_cast<const std::uint8_t*>(padded.data() + i));
  std::array<std::uint8_t, 20> out{};
  for (int i = 0; i < 5; ++i)
    for (int j = 0; j < 4; ++j) out[4 * i + j] = static_cast<std::uint8_t>(h[i] >> (24 - 8 * j));
  return out;
}

std::string base64(std::string_view bytes) {
  static constexpr char kAlphabet[] =
      "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  out.reserve((bytes.size() + 2) / 3 * 4);
  for (std::size_t i = 0; i < bytes.size(); i += 3) {
    const std::size_t n = std::min<std::size_t>(3, bytes.size() - i);
    std::uint32_t v = 0;
    for (std::size_t j = 0; j < 3; ++j)
      v = (v << 8) | (j < n ? static_cast<std::uint8_t>(bytes[i + j]) : 0u);
    for (std::size_t j = 0; j < 4; ++j)
      out.push_back(j <= n ? kAlphabet[(v >> (18 - 6 * j)) & 0x3F] : '=');
  }
  return out;
}

std::string websocket_accept(std::string_view client_key) {
  const auto digest = sha1(std::string(client_key) + std::string(kWebSocketGuid));
  return base64(std::string_view(reinterpret_cast<const char*>(digest.data()), digest.size()));
}

std::string encode_ws_frame(const WsFrame& frame,
                            const std::optional<std::array<std::uint8_t, 4>>& mask) {
  std::string out;
  out.push_back(
      static_cast<char>((frame.fin ? 0x80 : 0x00) | static_cast<std::uint8_t>(frame.opcode)));
  const std::uint8_t mask_bit = mask ? 0x80 : 0x00;
  const std::uint64_t n = frame.payload.size();
  if (n <= 125) {
    out.push_back(static_cast<char>(mask_bit | n));
  } else if (n <= 0xFFFF) {
    out.push_back(static_cast<char>(mask_bit | 126));
    out.push_back(static_cast<char>((n >> 8) & 0xFF));
    out.push_back(static_cast<char>(n & 0xFF));
  } else {
    out.push_back(static_cast<char>(mask_bit | 127));
    for (int i = 7; i >= 0; --i) out.push_back(static_cast<char>((n >> (8 * i)) & 0xFF));
  }
  if (!mask) return out + frame.payload;
  for (const std::uint8_t m : *mask) out.push_back(static_cast<char>(m));
  for (std::size_t i = 0; i < frame.payload.size(); ++i)
    out.push_back(static_cast<char>(static_cast<std::uint8_t>(frame.payload[i]) ^ (*mask)[i % 4]));
  return out;
}

std::optional<WsFrame> take_ws_frame(std::string& buffer, bool from_client,
                                     std::size_t max_payload) {
  if (buffer.size() < 2) return std::nullopt;
  const auto byte = [&](std::size_t i) { return static_cast<std::uint8_t>(buffer[i]); };
  const std::uint8_t b0 = byte(0);
  const std::uint8_t b1 = byte(1);
  if ((b0 & 0x70) != 0) throw std::runtime_error("websocket frame with reserved bits set");
  if (!known_opcode(b0 & 0x0F))
    throw std::runtime_error(fmt::format("websocket frame with unknown opcode {:#x}", b0 & 0x0F));
  WsFrame frame;
  frame.fin = (b0 & 0x80) != 0;
  frame.opcode = static_cast<WsOpcode>(b0 & 0x0F);
  const bool masked = (b1 & 0x80) != 0;
  if (masked != from_client)
    throw std::runtime_error(from_client ? "websocket frame from a client without a mask"
                                         : "websocket frame from a server with a mask");
  std::size_t pos = 2;
  std::uint64_t n = b1 & 0x7F;
  if (n == 126) {
    if (buffer.size() < 4) return std::nullopt;
    n = (std::uint64_t{byte(2)} << 8) | byte(3);
    pos = 4;
  } else if (n == 127) {
    if (buffer.size() < 10) return std::nullopt;
    if ((byte(2) & 0x80) != 0)
      throw std::runtime_error("websocket frame length with its most significant bit set");
    n = 0;
    for (std::size_t i = 2; i < 10; ++i) n = (n << 8) | byte(i);
    pos = 10;
  }
  if (is_control(frame.opcode) && (n > 125 || !frame.fin))
    throw std::runtime_error("websocket control frame longer than 125 bytes or fragmented");
  if (n > max_payload)
    throw std::runtime_error(
        fmt::format("websocket frame of {} bytes (at most {} accepted)", n, max_payload));
  std::array<std::uint8_t, 4> mask{};
  if (masked) {
    if (buffer.size() < pos + 4) return std::nullopt;
    for (std::size_t i = 0; i < 4; ++i) mask[i] = byte(pos + i);
    pos += 4;
  }
  if (buffer.size() < pos + n) return std::nullopt;
  frame.payload = buffer.substr(pos, static_cast<std::size_t>(n));
  if (masked)
    for (std::size_t i = 0; i < frame.payload.size(); ++i)
      frame.payload[i] =
          static_cast<char>(static_cast<std::uint8_t>(frame.payload[i]) ^ mask[i % 4]);
  buffer.erase(0, pos + static_cast<std::size_t>(n));
  return frame;
}

std::string ws_client_request(const std::string& host, int port, const std::string& path,
                              const std::string& key) {
  return fmt::format(
      "GET {} HTTP/1.1\r\nHost: {}:{}\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
      "Sec-WebSocket-Key: {}\r\nSec-WebSocket-Version: 13\r\n\r\n",
      path, host, port, key);
}

std::string ws_check_server_response(std::string_view response, std::string_view key) {
  const std::size_t line_end = response.find("\r\n");
  const std::string_view status = response.substr(0, line_end);
  if (status.rfind("HTTP/1.1 101", 0) != 0)
    return fmt::format("the server did not switch to WebSocket (it answered \"{}\")", status);
  const auto headers = http_headers(response);
  if (!has_token(header(headers, "upgrade"), "websocket"))
    return "the server's answer has no \"Upgrade: websocket\"";
  if (!has_token(header(headers, "connection"), "upgrade"))
    return "the server's answer has no \"Connection: Upgrade\"";
  const std::string accept = header(headers, "sec-websocket-accept");
  if (accept != websocket_accept(key))
    return fmt::format("the server's Sec-WebSocket-Accept \"{}\" does not answer our key", accept);
  return "";
}

WsClientRequest ws_parse_client_request(std::string_view request) {
  WsClientRequest out;
  const std::string_view first = request.substr(0, request.find("\r\n"));
  if (first.rfind("GET ", 0) != 0 || first.size() < 14 ||
      first.substr(first.size() - 9) != " HTTP/1.1") {
    out.problem = fmt::format("not an HTTP/1.1 GET request: \"{}\"", first);
    return out;
  }
  out.path = std::string(first.substr(4, first.size() - 13));
  const auto headers = http_headers(request);
  if (!has_token(header(headers, "upgrade"), "websocket"))
    out.problem = "no \"Upgrade: websocket\" header";
  else if (!has_token(header(headers, "connection"), "upgrade"))
    out.problem = "no \"Connection: Upgrade\" header";
  else if (header(headers, "sec-websocket-version") != "13")
    out.problem = "Sec-WebSocket-Version is not 13";
  out.key = header(headers, "sec-websocket-key");
  if (out.problem.empty() && out.key.size() != 24) out.problem = "no 16-byte Sec-WebSocket-Key";
  return out;
}

std::string ws_server_response(std::string_view key) {
  return fmt::format(
      "HTTP/1.1 101 Switching Protocols\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
      "Sec-WebSocket-Accept: {}\r\n\r\n",
      websocket_accept(key));
}

WebSocketClient::WebSocketClient(std::string host, int port, std::string path,
                                 std::chrono::milliseconds connect_timeout)
    : host_(std::move(host)),
      port_(port),
      path_(std::move(path)),
      tcp_(host_, port_, connect_timeout) {}

std::string WebSocketClient::device() const {
  return fmt::format("websocket {}:{}{}", host_, port_, path_);
}

void WebSocketClient::open(Clock::time_point deadline) {
  close();
  tcp_.open();
  const std::string key = random_key();
  tcp_.write_bytes(ws_client_request(host_, port_, path_, key));
  std::string response;
  std::size_t end = std::string::npos;
  while ((end = response.find("\r\n\r\n")) == std::string::npos) {
    const auto got = tcp_.read_some(deadline);
    if (!got) throw LinkError(device(), "no answer to the WebSocket upgrade request in time");
    response += *got;
    if (response.size() > 65536)
      throw LinkError(device(), "the answer to the WebSocket upgrade request never ended");
  }
  const std::string problem = ws_check_server_response(response.substr(0, end + 4), key);
  if (!problem.empty()) {
    tcp_.close();
    throw LinkError(device(), problem, response.substr(0, response.find("\r\n")));
  }
  buffer_ = response.substr(end + 4);  // frames the server sent right after its answer
  partial_.clear();
  open_ = true;
}

void WebSocketClient::close() {
  if (tcp_.is_open() && open_) {
    try {
      tcp_.write_bytes(
          encode_ws_frame({true, WsOpcode::kClose, std::string("\x03\xe8", 2)}, random_mask()));
    } catch (const LinkError&) {  // NOLINT(bugprone-empty-catch): closing a connection already gone
    }
  }
  tcp_.close();
  buffer_.clear();
  partial_.clear();
  open_ = false;
}

void WebSocketClient::send_text(const std::string& text) {
  if (!is_open()) throw LinkError(device(), "not connected");
  tcp_.write_bytes(encode_ws_frame({true, WsOpcode::kText, text}, random_mask()));
}

std::optional<std::string> WebSocketClient::receive_text(Clock::time_point deadline) {
  if (!is_open()) throw LinkError(device(), "not connected");
  for (;;) {
    std::optional<WsFrame> frame;
    try {
      frame = take_ws_frame(buffer_, /*from_client=*/false);
    } catch (const std::runtime_error& e) {
      tcp_.close();
      open_ = false;
      throw LinkError(device(), e.what());
    }
    if (!frame) {
      const auto got = tcp_.read_some(deadline);
      if (!got) return std::nullopt;
      buffer_ += *got;
      continue;
    }
    switch (frame->opcode) {
      case WsOpcode::kPing:
        tcp_.write_bytes(encode_ws_frame({true, WsOpcode::kPong, frame->payload}, random_mask()));
        break;
      case WsOpcode::kPong:
        break;
      case WsOpcode::kClose: {
        const std::string reason = frame->payload.size() > 2 ? frame->payload.substr(2) : "";
        tcp_.close();
        open_ = false;
        throw LinkError(device(), "the server closed the WebSocket", reason);
      }
      case WsOpcode::kText:
      case WsOpcode::kBinary:
        if (frame->fin) return frame->payload;
        partial_ = frame->payload;
        break;
      case WsOpcode::kContinuation:
        partial_ += frame->payload;
        if (frame->fin) return std::exchange(partial_, std::string());
        break;
    }
  }
}

}  // namespace robocal::robotio
