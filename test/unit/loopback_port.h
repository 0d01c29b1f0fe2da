// Loopback ports for the tests that start a real server of their own (smbd, ser2net, the MTConnect
// agent): a free port to give it, and whether it listens yet, read from /proc/net/tcp rather than by
// connecting (a connection would be a client of the server: ser2net would open its device, and turn
// away a second client while it still closes that one).
#pragma once

#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cstdio>
#include <fstream>
#include <sstream>
#include <string>

namespace cnc_bridge::test
{
/// A TCP port of 127.0.0.1 free a moment ago (the kernel's choice for a socket bound to port 0).
inline unsigned freeLoopbackPort()
{
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in address{};
  address.sin_family = AF_INET;
  address.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  socklen_t size = sizeof address;
  ::bind(fd, reinterpret_cast<sockaddr*>(&address), sizeof address);
  ::getsockname(fd, reinterpret_cast<sockaddr*>(&address), &size);
  ::close(fd);
  return ntohs(address.sin_port);
}

/// Whether something listens on 127.0.0.1:\p port.
inline bool listensOnLoopback(unsigned port)
{
  std::ifstream table("/proc/net/tcp");
  std::string line;
  std::getline(table, line);  // the header
  char wanted[32];
  std::snprintf(wanted, sizeof wanted, "0100007F:%04X", port);
  while (std::getline(table, line))
  {
    std::istringstream fields(line);
    std::string slot, local, remote, state;
    fields >> slot >> local >> remote >> state;
    if (local == wanted && state == "0A")  // TCP_LISTEN
      return true;
  }
  return false;
}
}  // namespace cnc_bridge::test
