// WebSocket framing and handshake against the worked examples of RFC 6455 (section 1.3: the
// handshake's key and accept value; section 5.7: frame bytes), SHA-1 against FIPS 180-4's
// examples and base64 against RFC 4648's test vectors; and a client talking to a server made of
// the same pure functions over a real loopback socket.
#include "loopback_listener.hpp"
#include "robocal/robotio/link_error.hpp"
#include "robocal/robotio/websocket.hpp"

#include <gtest/gtest.h>

#include <sys/socket.h>
#include <unistd.h>

#include <string>
#include <thread>

namespace robocal::robotio {
namespace {

std::string bytes(std::initializer_list<int> values) {
  std::string out;
  for (const int v : values) out.push_back(static_cast<char>(v));
  return out;
}

std::string hex(const std::array<std::uint8_t, 20>& digest) {
  static constexpr char kDigits[] = "0123456789abcdef";
  std::string out;
  for (const std::uint8_t b : digest) {
    out.push_back(kDigits[b >> 4]);
    out.push_back(kDigits[b & 0xF]);
  }
  return out;
}

TEST(WebSocket, Sha1OfTheStandardsExamples) {
  EXPECT_EQ(hex(sha1("abc")), "a9993e364706816aba3e25717850c26c9cd0d89d");
  EXPECT_EQ(hex(sha1("")), "da39a3ee5e6b4b0d3255bfef95601890afd80709");
  // Two blocks: 56 bytes of message push the length into a second block.
  EXPECT_EQ(hex(sha1("abcdbcdecdefdefgefghfghighijhijkijkljklmklmnlmnomnopnopq")),
            "84983e441c3bd26ebaae4aa1f95129e5e54670f1");
}

TEST(WebSocket, Base64OfRfc4648Vectors) {
  EXPECT_EQ(base64(""), "");
  EXPECT_EQ(base64("f"), "Zg==");
  EXPECT_EQ(base64("fo"), "Zm8=");
  EXPECT_EQ(base64("foo"), "Zm9v");
  EXPECT_EQ(base64("foob"), "Zm9vYg==");
  EXPECT_EQ(base64("fooba"), "Zm9vYmE=");
  EXPECT_EQ(base64("foobar"), "Zm9vYmFy");
}

TEST(WebSocket, AcceptValueOfRfc6455Section1_3) {
  EXPECT_EQ(websocket_accept("dGhlIHNhbXBsZSBub25jZQ=="), "s3pPLMBiTxaQ9kYGzzhZRbK+xOo=");
}

TEST(WebSocket, FramesOfRfc6455Section5_7) {
  const std::array<std::uint8_t, 4> mask = {0x37, 0xfa, 0x21, 0x3d};
  // A single-frame unmasked text message "Hello", and the same masked.
  EXPECT_EQ(encode_ws_frame({true, WsOpcode::kText, "Hello"}, std::nullopt),
            bytes({0x81, 0x05, 0x48, 0x65, 0x6c, 0x6c, 0x6f}));
  EXPECT_EQ(encode_ws_frame({true, WsOpcode::kText, "Hello"}, mask),
            bytes({0x81, 0x85, 0x37, 0xfa, 0x21, 0x3d, 0x7f, 0x9f, 0x4d, 0x51, 0x58}));
  // A fragmented unmasked text message: "Hel", then "lo".
  EXPECT_EQ(encode_ws_frame({false, WsOpcode::kText, "Hel"}, std::nullopt),
            bytes({0x01, 0x03, 0x48, 0x65, 0x6c}));
  EXPECT_EQ(encode_ws_frame({true, WsOpcode::kContinuation, "lo"}, std::nullopt),
            bytes({0x80, 0x02, 0x6c, 0x6f}));
  // Unmasked ping, masked pong, each with "Hello".
  EXPECT_EQ(encode_ws_frame({true, WsOpcode::kPing, "Hello"}, std::nullopt),
            bytes({0x89, 0x05, 0x48, 0x65, 0x6c, 0x6c, 0x6f}));
  EXPECT_EQ(encode_ws_frame({true, WsOpcode::kPong, "Hello"}, mask),
            bytes({0x8a, 0x85, 0x37, 0xfa, 0x21, 0x3d, 0x7f, 0x9f, 0x4d, 0x51, 0x58}));
  // 256 bytes of binary data in a single unmasked frame: 16-bit length 0x0100.
  const std::string b256 =
      encode_ws_frame({true, WsOpcode::kBinary, std::string(256, 'x')}, std::nullopt);
  EXPECT_EQ(b256.substr(0, 4), bytes({0x82, 0x7e, 0x01, 0x00}));
  EXPECT_EQ(b256.size(), 4u + 256u);
  // 64 KiB in a single unmasked frame: 64-bit length 0x0000000000010000.
  const std::string b64k =
      encode_ws_frame({true, WsOpcode::kBinary, std::string(65536, 'y')}, std::nullopt);
  EXPECT_EQ(b64k.substr(0, 10), bytes({0x82, 0x7f, 0, 0, 0, 0, 0, 0x01, 0x00, 0x00}));
  EXPECT_EQ(b64k.size(), 10u + 65536u);
}

TEST(WebSocket, FramesAreTakenWholeAndOnlyWhenComplete) {
  // The masked "Hello" as a server receives it, one byte at a time.
  const std::string wire =
      bytes({0x81, 0x85, 0x37, 0xfa, 0x21, 0x3d, 0x7f, 0x9f, 0x4d, 0x51, 0x58});
  std::string buffer;
  for (std::size_t i = 0; i + 1 < wire.size(); ++i) {
    buffer.push_back(wire[i]);
    EXPECT_FALSE(take_ws_frame(buffer, /*from_client=*/true)) << "after " << i + 1 << " bytes";
  }
  buffer.push_back(wire.back());
  buffer += bytes({0x89, 0x80, 1, 2, 3, 4});  // and an empty masked ping behind it
  const auto hello = take_ws_frame(buffer, true);
  ASSERT_TRUE(hello);
  EXPECT_TRUE(hello->fin);
  EXPECT_EQ(hello->opcode, WsOpcode::kText);
  EXPECT_EQ(hello->payload, "Hello");
  const auto ping = take_ws_frame(buffer, true);
  ASSERT_TRUE(ping);
  EXPECT_EQ(ping->opcode, WsOpcode::kPing);
  EXPECT_TRUE(ping->payload.empty());
  EXPECT_TRUE(buffer.empty());
  // The 64 KiB frame round-trips.
  std::string big =
      encode_ws_frame({true, WsOpcode::kBinary, std::string(65536, 'y')}, std::nullopt);
  const auto taken = take_ws_frame(big, /*from_client=*/false);
  ASSERT_TRUE(taken);
  EXPECT_EQ(taken->payload, std::string(65536, 'y'));
}

TEST(WebSocket, FramesNoPeerMaySendAreRefusedByName) {
  const auto refused = [](std::string wire, bool from_client) {
    try {
      (void)take_ws_frame(wire, from_client, 1024);
    } catch (const std::runtime_error& e) {
      return std::string(e.what());
    }
    return std::string();
  };
  EXPECT_NE(refused(bytes({0xC1, 0x00}), false).find("reserved bits"), std::string::npos);
  EXPECT_NE(refused(bytes({0x83, 0x00}), false).find("unknown opcode 0x3"), std::string::npos);
  EXPECT_NE(refused(bytes({0x81, 0x05, 'H', 'e', 'l', 'l', 'o'}), true).find("without a mask"),
            std::string::npos);
  EXPECT_NE(refused(bytes({0x81, 0x80, 1, 2, 3, 4}), false).find("with a mask"), std::string::npos);
  EXPECT_NE(refused(bytes({0x09, 0x00}), false).find("control frame"), std::string::npos);
  EXPECT_NE(refused(bytes({0x89, 0x7e, 0x00, 0x7e}), false).find("control frame"),
            std::string::npos);
  EXPECT_NE(refused(bytes({0x82, 0x7f, 0x80, 0, 0, 0, 0, 0, 0, 1}), false).find("most significant"),
            std::string::npos);
  EXPECT_NE(refused(bytes({0x82, 0x7e, 0x10, 0x00}), false).find("4096 bytes (at most 1024"),
            std::string::npos);
}

TEST(WebSocket, HandshakeRequestAndAnswerCheckEachOther) {
  const std::string key = "dGhlIHNhbXBsZSBub25jZQ==";
  const std::string request = ws_client_request("printer.local", 7125, "/websocket", key);
  EXPECT_EQ(request,
            "GET /websocket HTTP/1.1\r\nHost: printer.local:7125\r\nUpgrade: websocket\r\n"
            "Connection: Upgrade\r\nSec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\n"
            "Sec-WebSocket-Version: 13\r\n\r\n");
  const WsClientRequest parsed = ws_parse_client_request(request);
  EXPECT_EQ(parsed.problem, "");
  EXPECT_EQ(parsed.path, "/websocket");
  EXPECT_EQ(parsed.key, key);
  const std::string answer = ws_server_response(key);
  EXPECT_NE(answer.find("Sec-WebSocket-Accept: s3pPLMBiTxaQ9kYGzzhZRbK+xOo=\r\n"),
            std::string::npos);
  EXPECT_EQ(ws_check_server_response(answer, key), "");
  // Header names and the Connection token list are case-insensitive (RFC 7230).
  EXPECT_EQ(ws_check_server_response("HTTP/1.1 101 Switching Protocols\r\nupgrade: WebSocket\r\n"
                                     "connection: keep-alive, upgrade\r\n"
                                     "sec-websocket-accept: s3pPLMBiTxaQ9kYGzzhZRbK+xOo=\r\n\r\n",
                                     key),
            "");
  EXPECT_NE(ws_check_server_response("HTTP/1.1 404 Not Found\r\n\r\n", key).find("404 Not Found"),
            std::string::npos);
  EXPECT_NE(ws_check_server_response(ws_server_response("AAAAAAAAAAAAAAAAAAAAAA=="), key)
                .find("does not answer our key"),
            std::string::npos);
  EXPECT_NE(
      ws_parse_client_request("GET /websocket HTTP/1.1\r\nHost: x\r\n\r\n").problem.find("Upgrade"),
      std::string::npos);
  EXPECT_NE(ws_parse_client_request("POST / HTTP/1.1\r\n\r\n").problem.find("not an HTTP/1.1 GET"),
            std::string::npos);
}

// A loopback server made of the pure functions: accepts one client, answers its upgrade, pings
// it, sends a message in two fragments, echoes one text message, then closes with a reason.
class OneClientServer {
 public:
  OneClientServer() {
    const test::LoopbackListener listener = test::listen_on_loopback();
    listen_fd_ = listener.fd;
    port_ = listener.port;
    thread_ = std::thread([this] { serve(); });
  }
  ~OneClientServer() {
    thread_.join();
    ::close(listen_fd_);
  }
  int port() const { return port_; }
  std::string pong;  // what the client answered to the ping

 private:
  void send_all(int fd, const std::string& data) {
    EXPECT_EQ(::send(fd, data.data(), data.size(), MSG_NOSIGNAL),
              static_cast<ssize_t>(data.size()));
  }
  std::optional<WsFrame> next_frame(int fd, std::string& buffer) {
    for (;;) {
      if (auto f = take_ws_frame(buffer, /*from_client=*/true)) return f;
      char chunk[4096];
      const ssize_t n = ::recv(fd, chunk, sizeof chunk, 0);
      if (n <= 0) return std::nullopt;
      buffer.append(chunk, static_cast<std::size_t>(n));
    }
  }
  void serve() {
    const int fd = ::accept(listen_fd_, nullptr, nullptr);
    ASSERT_GE(fd, 0);
    std::string buffer;
    char chunk[4096];
    while (buffer.find("\r\n\r\n") == std::string::npos) {
      const ssize_t n = ::recv(fd, chunk, sizeof chunk, 0);
      ASSERT_GT(n, 0);
      buffer.append(chunk, static_cast<std::size_t>(n));
    }
    const std::size_t end = buffer.find("\r\n\r\n") + 4;
    const WsClientRequest request = ws_parse_client_request(buffer.substr(0, end));
    buffer.erase(0, end);
    EXPECT_EQ(request.problem, "");
    EXPECT_EQ(request.path, "/websocket");
    // The answer and the first frames in one write: the client must keep what follows its answer.
    send_all(fd, ws_server_response(request.key) +
                     encode_ws_frame({true, WsOpcode::kPing, "are you there"}, std::nullopt) +
                     encode_ws_frame({false, WsOpcode::kText, "{\"part\":"}, std::nullopt));
    const auto pong_frame = next_frame(fd, buffer);
    ASSERT_TRUE(pong_frame);
    EXPECT_EQ(pong_frame->opcode, WsOpcode::kPong);
    pong = pong_frame->payload;
    send_all(fd, encode_ws_frame({true, WsOpcode::kContinuation, "2}"}, std::nullopt));
    const auto text = next_frame(fd, buffer);
    ASSERT_TRUE(text);
    send_all(fd, encode_ws_frame({true, WsOpcode::kText, "echo " + text->payload}, std::nullopt));
    send_all(fd,
             encode_ws_frame({true, WsOpcode::kClose, std::string("\x03\xe9", 2) + "going away"},
                             std::nullopt));
    ::close(fd);
  }
  int listen_fd_ = -1;
  int port_ = 0;
  std::thread thread_;
};

TEST(WebSocket, ClientAnswersPingsJoinsFragmentsAndNamesTheServersClose) {
  OneClientServer server;
  WebSocketClient client("127.0.0.1", server.port(), "/websocket");
  client.open(Clock::now() + std::chrono::seconds(5));
  ASSERT_TRUE(client.is_open());
  const auto first = client.receive_text(Clock::now() + std::chrono::seconds(5));
  ASSERT_TRUE(first);
  EXPECT_EQ(*first, "{\"part\":2}");
  client.send_text("hello server");
  const auto echo = client.receive_text(Clock::now() + std::chrono::seconds(5));
  ASSERT_TRUE(echo);
  EXPECT_EQ(*echo, "echo hello server");
  try {
    (void)client.receive_text(Clock::now() + std::chrono::seconds(5));
    ADD_FAILURE() << "a close frame must end the connection with a LinkError";
  } catch (const LinkError& e) {
    EXPECT_NE(std::string(e.what()).find("websocket 127.0.0.1:"), std::string::npos) << e.what();
    EXPECT_EQ(e.controller_said(), "going away");
  }
  EXPECT_FALSE(client.is_open());
  EXPECT_EQ(server.pong, "are you there");
}

TEST(WebSocket, AServerThatIsNotAWebSocketIsNamed) {
  // A plain HTTP server's refusal: the client reports the status line it got.
  const test::LoopbackListener listener = test::listen_on_loopback();
  const int listen_fd = listener.fd;
  std::thread server([&] {
    const int fd = ::accept(listen_fd, nullptr, nullptr);
    char chunk[4096];
    (void)::recv(fd, chunk, sizeof chunk, 0);
    const std::string answer = "HTTP/1.1 404 Not Found\r\nContent-Length: 0\r\n\r\n";
    (void)::send(fd, answer.data(), answer.size(), MSG_NOSIGNAL);
    ::close(fd);
  });
  WebSocketClient client("127.0.0.1", listener.port, "/websocket");
  try {
    client.open(Clock::now() + std::chrono::seconds(5));
    ADD_FAILURE() << "a 404 must not open the connection";
  } catch (const LinkError& e) {
    EXPECT_NE(std::string(e.what()).find("did not switch to WebSocket"), std::string::npos)
        << e.what();
    EXPECT_EQ(e.controller_said(), "HTTP/1.1 404 Not Found");
  }
  server.join();
  ::close(listen_fd);
}

}  // namespace
}  // namespace robocal::robotio
