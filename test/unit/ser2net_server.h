// A real serial device server for tests: ser2net (Debian package ser2net, 4.x) serving one device
// (a pty whose master the test holds, as a control's port) on two loopback ports at once: raw TCP
// and Telnet with COM Port Control (RFC 2217). Its configuration and log live in the test's own
// folder; it runs in the foreground in a process group of its own and dies with the test.
#pragma once

#include "loopback_port.h"

#include <netinet/in.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <fstream>
#include <sstream>
#include <stdexcept>
#include <string>
#include <thread>

namespace cnc_bridge::test
{
class Ser2netServer
{
 public:
  /// Writes the configuration for \p device with the server's own line settings \p line (ser2net's
  /// notation, "9600n81"); starts the server.
  Ser2netServer(const std::string& dir, const std::string& device, const std::string& line = "9600n81")
      : dir_(dir), device_(device), line_(line)
  {
    raw_port = freeLoopbackPort();
    rfc2217_port = freeLoopbackPort();
    start();
  }
  ~Ser2netServer() { stop(SIGKILL); }
  Ser2netServer(const Ser2netServer&) = delete;
  Ser2netServer& operator=(const Ser2netServer&) = delete;

  /// Starts ser2net and returns once both of its ports accept connections.
  void start()
  {
    writeConfig();
    pid_ = ::fork();
    if (pid_ == 0)
    {
      ::setpgid(0, 0);
      ::prctl(PR_SET_PDEATHSIG, SIGKILL);  // a killed test leaves no server behind
      const std::string out = dir_ + "/ser2net.log";
      std::freopen(out.c_str(), "a", stdout);
      std::freopen(out.c_str(), "a", stderr);
      // -n: stay in the foreground; -u: no UUCP lock files in /var/lock for the pty.
      ::execlp("ser2net", "ser2net", "-n", "-u", "-c", config().c_str(), "-P", (dir_ + "/ser2net.pid").c_str(),
               nullptr);
      std::perror("exec ser2net (Debian package ser2net)");
      ::_exit(127);
    }
    ::setpgid(pid_, pid_);
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(10);
    while (!listensOnLoopback(raw_port) || !listensOnLoopback(rfc2217_port))
    {
      int status = 0;
      if (::waitpid(pid_, &status, WNOHANG) == pid_)
      {
        pid_ = -1;
        throw std::runtime_error("ser2net exited: " + log());
      }
      if (std::chrono::steady_clock::now() > deadline)
        throw std::runtime_error("ser2net does not accept on ports " + std::to_string(raw_port) + " and " +
                                 std::to_string(rfc2217_port) + ": " + log());
      std::this_thread::sleep_for(std::chrono::milliseconds(10));  // polling the port, not a wait for an event
    }
  }

  /// Stops the server: SIGKILL for one that vanishes (a device server switched off), SIGTERM for a
  /// clean stop. Its clients' connections close.
  void stop(int signal = SIGTERM)
  {
    if (pid_ <= 0)
      return;
    ::kill(-pid_, signal);
    ::waitpid(pid_, nullptr, 0);
    pid_ = -1;
  }

  std::string rawUrl() const { return "tcp://127.0.0.1:" + std::to_string(raw_port); }
  std::string rfc2217Url() const { return "rfc2217://127.0.0.1:" + std::to_string(rfc2217_port); }
  std::string log() const
  {
    std::ifstream in(dir_ + "/ser2net.log");
    std::stringstream text;
    text << in.rdbuf();
    return text.str();
  }

  unsigned raw_port = 0;
  unsigned rfc2217_port = 0;

 private:
  std::string config() const { return dir_ + "/ser2net.yaml"; }

  void writeConfig() const
  {
    // One connection per port, both on the same device; a test uses one at a time. `local`:
    // ignore the modem lines (a pty has none).
    std::ofstream out(config());
    out << "%YAML 1.1\n---\n"
        << "connection: &raw\n"
        << "  accepter: tcp,127.0.0.1," << raw_port << "\n"
        << "  connector: serialdev," << device_ << "," << line_ << ",local\n"
        << "connection: &rfc2217\n"
        << "  accepter: telnet(rfc2217),tcp,127.0.0.1," << rfc2217_port << "\n"
        << "  connector: serialdev," << device_ << "," << line_ << ",local\n";
  }

  std::string dir_;
  std::string device_;
  std::string line_;
  pid_t pid_ = -1;
};
}  // namespace cnc_bridge::test
