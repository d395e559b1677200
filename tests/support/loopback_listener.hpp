#pragma once
// A TCP socket listening on 127.0.0.1 at a port the kernel picks: the server side of tests that
// talk to a client over a real socket.
#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <stdexcept>

namespace robocal::test {

struct LoopbackListener {
  int fd = -1;
  int port = 0;
};

// Throws std::runtime_error when no socket can listen.
inline LoopbackListener listen_on_loopback(int backlog = 1) {
  LoopbackListener out;
  out.fd = ::socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  socklen_t len = sizeof addr;
  if (out.fd < 0 || ::bind(out.fd, reinterpret_cast<sockaddr*>(&addr), sizeof addr) != 0 ||
      ::listen(out.fd, backlog) != 0 ||
      ::getsockname(out.fd, reinterpret_cast<sockaddr*>(&addr), &len) != 0) {
    if (out.fd >= 0) ::close(out.fd);
    throw std::runtime_error("cannot listen on a loopback port");
  }
  out.port = ntohs(addr.sin_port);
  return out;
}

}  // namespace robocal::test
