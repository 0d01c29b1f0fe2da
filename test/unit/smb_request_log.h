// What an SMB client sends, for tests: a proxy on 127.0.0.1 that forwards every connection to a
// server on another local port and records the SMB2 command of each request the client sends
// (each one of a compound request too), so that a test can check the requests a store spends on an
// operation. Frames are read whole (the 4-byte length of the SMB2 direct-TCP transport, then the
// message) and forwarded unchanged; the server's answers are copied back as they come.
#pragma once

#include <arpa/inet.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cstdint>
#include <mutex>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

namespace cnc_bridge::test
{
class SmbRequestLog
{
 public:
  /// Listens on a free port of 127.0.0.1 (\ref port) and forwards to \p server_port there.
  explicit SmbRequestLog(unsigned server_port) : server_port_(server_port)
  {
    listener_ = ::socket(AF_INET, SOCK_STREAM, 0);
    sockaddr_in address = loopback(0);
    if (::bind(listener_, reinterpret_cast<sockaddr*>(&address), sizeof(address)) != 0 || ::listen(listener_, 8) != 0)
      throw std::runtime_error("the SMB request log cannot listen on 127.0.0.1");
    socklen_t length = sizeof(address);
    ::getsockname(listener_, reinterpret_cast<sockaddr*>(&address), &length);
    port = ntohs(address.sin_port);
    acceptor_ = std::thread([this] { acceptConnections(); });
  }

  ~SmbRequestLog()
  {
    ::shutdown(listener_, SHUT_RDWR);  // wakes accept()
    acceptor_.join();
    {
      std::lock_guard<std::mutex> lock(mutex_);
      for (const int fd : sockets_)
        ::shutdown(fd, SHUT_RDWR);  // wakes the pumps
    }
    for (std::thread& pump : pumps_)
      pump.join();
    for (const int fd : sockets_)
      ::close(fd);
    ::close(listener_);
  }
  SmbRequestLog(const SmbRequestLog&) = delete;
  SmbRequestLog& operator=(const SmbRequestLog&) = delete;

  std::string url(const std::string& share) const { return "smb://127.0.0.1:" + std::to_string(port) + "/" + share; }

  /// The commands sent since the start or the last clear(), in order ("CREATE", "WRITE", ...).
  std::vector<std::string> commands() const
  {
    std::lock_guard<std::mutex> lock(mutex_);
    return commands_;
  }
  void clear()
  {
    std::lock_guard<std::mutex> lock(mutex_);
    commands_.clear();
  }

  unsigned port = 0;

 private:
  static sockaddr_in loopback(unsigned port)
  {
    sockaddr_in address{};
    address.sin_family = AF_INET;
    address.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    address.sin_port = htons(static_cast<uint16_t>(port));
    return address;
  }

  static bool readExactly(int fd, char* data, size_t size)
  {
    for (size_t done = 0; done < size;)
    {
      const ssize_t n = ::read(fd, data + done, size - done);
      if (n <= 0)
        return false;
      done += static_cast<size_t>(n);
    }
    return true;
  }

  static bool writeAll(int fd, const char* data, size_t size)
  {
    for (size_t done = 0; done < size;)
    {
      const ssize_t n = ::send(fd, data + done, size - done, MSG_NOSIGNAL);  // a closed peer is an error, not a signal
      if (n <= 0)
        return false;
      done += static_cast<size_t>(n);
    }
    return true;
  }

  void acceptConnections()
  {
    for (;;)
    {
      const int client = ::accept(listener_, nullptr, nullptr);
      if (client < 0)
        return;
      const int server = ::socket(AF_INET, SOCK_STREAM, 0);
      // Without this every forwarded request waits for the delayed acknowledgement of the one
      // before (Nagle's algorithm): 40 ms a request.
      const int on = 1;
      ::setsockopt(client, IPPROTO_TCP, TCP_NODELAY, &on, sizeof(on));
      ::setsockopt(server, IPPROTO_TCP, TCP_NODELAY, &on, sizeof(on));
      const sockaddr_in address = loopback(server_port_);
      std::lock_guard<std::mutex> lock(mutex_);
      sockets_.push_back(client);
      sockets_.push_back(server);
      if (::connect(server, reinterpret_cast<const sockaddr*>(&address), sizeof(address)) != 0)
      {
        ::shutdown(client, SHUT_RDWR);  // as the server would: the client sees the refusal
        continue;
      }
      pumps_.emplace_back([this, client, server] { forwardRequests(client, server); });
      pumps_.emplace_back([client, server] { copy(server, client); });
    }
  }

  /// Client to server, frame by frame.
  void forwardRequests(int from, int to)
  {
    std::string frame(4, '\0');  // the length, then the message: forwarded in one piece
    while (readExactly(from, frame.data(), 4))
    {
      const auto byte = [&frame](int i) { return static_cast<size_t>(static_cast<unsigned char>(frame[i])); };
      frame.resize(4 + (byte(1) << 16 | byte(2) << 8 | byte(3)));
      if (!readExactly(from, frame.data() + 4, frame.size() - 4))
        break;
      record(frame.substr(4));
      if (!writeAll(to, frame.data(), frame.size()))
        break;
    }
    ::shutdown(to, SHUT_WR);
  }

  static void copy(int from, int to)
  {
    char buffer[65536];
    ssize_t n = 0;
    while ((n = ::read(from, buffer, sizeof(buffer))) > 0)
    {
      if (!writeAll(to, buffer, static_cast<size_t>(n)))
        break;
    }
    ::shutdown(to, SHUT_WR);
  }

  /// The SMB2 header (MS-SMB2 2.2.1): "\xFESMB", the command at byte 12, the offset of the next
  /// request of a compound at byte 20.
  void record(const std::string& frame)
  {
    static const char* const names[] = {"NEGOTIATE",     "SESSION_SETUP", "LOGOFF",   "TREE_CONNECT", "TREE_DISCONNECT",
                                        "CREATE",        "CLOSE",         "FLUSH",    "READ",         "WRITE",
                                        "LOCK",          "IOCTL",         "CANCEL",   "ECHO",         "QUERY_DIRECTORY",
                                        "CHANGE_NOTIFY", "QUERY_INFO",    "SET_INFO", "OPLOCK_BREAK"};
    const auto at = [&frame](size_t i) { return static_cast<uint32_t>(static_cast<unsigned char>(frame[i])); };
    std::lock_guard<std::mutex> lock(mutex_);
    for (size_t start = 0; start + 64 <= frame.size();)
    {
      if (frame.compare(start, 4, "\xfeSMB") != 0)
      {
        commands_.emplace_back("not SMB2");
        return;
      }
      const uint32_t command = at(start + 12) | at(start + 13) << 8;
      commands_.emplace_back(command < sizeof(names) / sizeof(names[0]) ? names[command] : "unknown");
      const uint32_t next = at(start + 20) | at(start + 21) << 8 | at(start + 22) << 16 | at(start + 23) << 24;
      if (next == 0)
        break;
      start += next;
    }
  }

  unsigned server_port_;
  int listener_ = -1;
  std::thread acceptor_;
  mutable std::mutex mutex_;
  std::vector<int> sockets_;
  std::vector<std::thread> pumps_;
  std::vector<std::string> commands_;
};
}  // namespace cnc_bridge::test
