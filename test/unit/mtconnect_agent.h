// The reference MTConnect agent for tests: mtconnect/cppagent v1.8.0.3, built by
// scripts/build_cppagent.sh (scripts/setup.sh runs it), started in the test's own folder with a
// Devices.xml and an agent.cfg the adapter's core generated, on loopback. Its log stays in that
// folder; it runs in a process group of its own and dies with the test.
//
// Where it is: $CNC_MTCONNECT_AGENT, else CNC_MTCONNECT_AGENT_DEFAULT (the setup's install path).
// A test that needs it and cannot find it fails, saying how to install it: a step that could not
// run is not a pass.
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
#include <cstdlib>
#include <fstream>
#include <functional>
#include <sstream>
#include <stdexcept>
#include <string>
#include <thread>

namespace cnc_bridge::test
{
class ReferenceAgent
{
 public:
  /// \returns the agent binary's path; \throws std::runtime_error saying how to install it.
  static std::string binary()
  {
    const char* env = std::getenv("CNC_MTCONNECT_AGENT");
    const std::string path = env && *env ? env : CNC_MTCONNECT_AGENT_DEFAULT;
    if (::access(path.c_str(), X_OK) != 0)
      throw std::runtime_error("the reference MTConnect agent (cppagent v1.8.0.3) is not at " + path +
                               ": run scripts/setup.sh (it builds the agent with scripts/build_cppagent.sh) "
                               "or set CNC_MTCONNECT_AGENT to an agent binary");
    return path;
  }

  /// Writes \p devices_xml and the configuration \p config_for makes for the agent's HTTP port
  /// (chosen here) to \p dir and starts the agent; returns once it serves HTTP.
  ReferenceAgent(const std::string& dir, const std::string& devices_xml,
                 const std::function<std::string(unsigned http_port)>& config_for)
      : dir_(dir)
  {
    const std::string agent = binary();
    http_port = freeLoopbackPort();
    std::ofstream(dir_ + "/Devices.xml") << devices_xml;
    const std::string config = config_for(http_port) +
                               "ServerIp = 127.0.0.1\nMonitorConfigFiles = false\n"
                               "logger_config {\n    output = file agent.log\n    logging_level = debug\n}\n";
    std::ofstream(dir_ + "/agent.cfg") << config;
    pid_ = ::fork();
    if (pid_ == 0)
    {
      ::setpgid(0, 0);
      ::prctl(PR_SET_PDEATHSIG, SIGKILL);  // a killed test leaves no agent behind
      // Not the test's sockets: an adapter's listening socket kept open here would stay bound
      // after the test closed it.
      ::close_range(3, ~0U, 0);
      if (::chdir(dir_.c_str()) != 0)
        ::_exit(126);
      const std::string out = dir_ + "/agent.out";
      std::freopen(out.c_str(), "a", stdout);
      std::freopen(out.c_str(), "a", stderr);
      ::execl(agent.c_str(), agent.c_str(), "run", "agent.cfg", nullptr);
      std::perror("exec the MTConnect agent");
      ::_exit(127);
    }
    ::setpgid(pid_, pid_);
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(30);
    while (!listensOnLoopback(http_port))
    {
      int status = 0;
      if (::waitpid(pid_, &status, WNOHANG) == pid_)
      {
        pid_ = -1;
        throw std::runtime_error("the MTConnect agent exited: " + log());
      }
      if (std::chrono::steady_clock::now() > deadline)
        throw std::runtime_error("the MTConnect agent does not serve port " + std::to_string(http_port) + ": " + log());
      std::this_thread::sleep_for(std::chrono::milliseconds(20));  // polling the port, not a wait for an event
    }
  }
  ~ReferenceAgent()
  {
    if (pid_ > 0)
    {
      ::kill(-pid_, SIGKILL);
      ::waitpid(pid_, nullptr, 0);
    }
  }
  ReferenceAgent(const ReferenceAgent&) = delete;
  ReferenceAgent& operator=(const ReferenceAgent&) = delete;

  /// The agent's own words (its log and what it printed), for failure messages.
  std::string log() const
  {
    std::string text;
    for (const char* name : {"/agent.out", "/agent.log"})
    {
      std::ifstream in(dir_ + name);
      std::string all, line;
      while (std::getline(in, line))
      {
        if (line.find(" DEBUG ") == std::string::npos)  // its heartbeats and rates
          all += line + "\n";
      }
      text += std::string(name + 1) + ": " + (all.size() > 4000 ? "..." + all.substr(all.size() - 4000) : all) + "\n";
    }
    return text;
  }

  unsigned http_port = 0;

 private:
  std::string dir_;
  pid_t pid_ = -1;
};
}  // namespace cnc_bridge::test
