// A real Samba server for tests: smbd (Debian package samba) on 127.0.0.1 on a free high port,
// with everything it writes (configuration, password database, locks, state, logs, the shared
// folders) inside the test's own folder, so that tests run side by side and leave nothing behind.
// Two shares: [guest] open to guests, [secure] for one user whose password is set with smbpasswd
// in the private password database. smbd must be started as root (it becomes the user it serves).
#pragma once

#include "loopback_port.h"

#include <arpa/inet.h>
#include <netinet/in.h>
#include <pwd.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <stdexcept>
#include <string>
#include <thread>

#include "temp_dir.h"

// libsmbclient keeps some talloc allocations of each context until the process exits (about a
// hundred bytes each); the sanitizer build's leak check is told so, for this library only. Each
// test executable includes this header once.
extern "C" const char* __lsan_default_suppressions()
{
  return "leak:libtalloc.so\nleak:libsmbclient.so\n";
}

namespace cnc_bridge::test
{
class SambaServer
{
 public:
  /// Writes the configuration (with \p extra sections appended) and the user's password; does not
  /// start smbd.
  explicit SambaServer(const std::string& dir, const std::string& extra = "") : dir_(dir)
  {
    if (::geteuid() != 0)
      throw std::runtime_error("the Samba tests start smbd, which must run as root");
    const passwd* me = ::getpwuid(::geteuid());
    user = me ? me->pw_name : "root";
    for (const char* sub : {"private", "lock", "state", "cache", "pid", "ncalrpc", "guest", "secure"})
      std::filesystem::create_directories(dir_ + "/" + sub);
    port = freeLoopbackPort();
    std::ofstream conf(config());
    conf << "[global]\n"
         << "  server role = standalone server\n"
         << "  smb ports = " << port << "\n"
         << "  interfaces = 127.0.0.1\n  bind interfaces only = yes\n  disable netbios = yes\n"
         << "  passdb backend = tdbsam:" << dir_ << "/private/passdb.tdb\n"
         << "  private dir = " << dir_ << "/private\n  lock directory = " << dir_ << "/lock\n"
         << "  state directory = " << dir_ << "/state\n  cache directory = " << dir_ << "/cache\n"
         << "  pid directory = " << dir_ << "/pid\n  ncalrpc dir = " << dir_ << "/ncalrpc\n"
         << "  log file = " << dir_ << "/smbd.log\n  log level = 1\n  max log size = 0\n"
         << "  map to guest = Bad User\n"
         << "  load printers = no\n  printing = bsd\n  printcap name = /dev/null\n  disable spoolss = yes\n"
         << "[guest]\n  path = " << dir_ << "/guest\n  guest ok = yes\n  read only = no\n"
         << "  force user = " << user << "\n"
         << "[secure]\n  path = " << dir_ << "/secure\n  valid users = " << user << "\n  read only = no\n"
         << extra;
    conf.close();
    const std::string command = "smbpasswd -c " + config() + " -s -a " + user + " >" + dir_ + "/smbpasswd.log 2>&1";
    FILE* pipe = ::popen(command.c_str(), "w");
    if (pipe == nullptr)
      throw std::runtime_error("cannot run smbpasswd");
    std::fprintf(pipe, "%s\n%s\n", password.c_str(), password.c_str());
    if (::pclose(pipe) != 0)
      throw std::runtime_error("smbpasswd failed: " + readFile(dir_ + "/smbpasswd.log"));
  }
  ~SambaServer() { stop(); }
  SambaServer(const SambaServer&) = delete;
  SambaServer& operator=(const SambaServer&) = delete;

  /// Starts smbd in a process group of its own and returns once its port accepts connections.
  void start()
  {
    pid_ = ::fork();
    if (pid_ == 0)
    {
      ::setpgid(0, 0);
      ::prctl(PR_SET_PDEATHSIG, SIGKILL);  // a killed test leaves no server behind
      const std::string out = dir_ + "/smbd.out";
      std::freopen(out.c_str(), "a", stdout);
      std::freopen(out.c_str(), "a", stderr);
      ::execlp("smbd", "smbd", "--foreground", "--no-process-group", "-s", config().c_str(), nullptr);
      std::perror("exec smbd");
      ::_exit(127);
    }
    ::setpgid(pid_, pid_);
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(30);
    while (!answers())
    {
      int status = 0;
      if (::waitpid(pid_, &status, WNOHANG) == pid_)
      {
        pid_ = -1;
        throw std::runtime_error("smbd exited: " + readFile(dir_ + "/smbd.out") + readFile(dir_ + "/smbd.log"));
      }
      if (std::chrono::steady_clock::now() > deadline)
        throw std::runtime_error("smbd does not answer on port " + std::to_string(port));
      std::this_thread::sleep_for(std::chrono::milliseconds(20));  // polling the port, not a wait for an event
    }
  }

  /// Stops smbd and every child it forked (one per client connection): SIGKILL for a server that
  /// vanishes mid-transfer, SIGTERM for a clean stop.
  void stop(int signal = SIGTERM)
  {
    if (pid_ <= 0)
      return;
    ::kill(-pid_, signal);
    int status = 0;
    ::waitpid(pid_, &status, 0);
    ::kill(-pid_, SIGKILL);  // children that outlive the parent
    pid_ = -1;
  }
  bool running() const { return pid_ > 0; }

  std::string url(const std::string& share) const { return "smb://127.0.0.1:" + std::to_string(port) + "/" + share; }
  std::string folder(const std::string& share) const { return dir_ + "/" + share; }
  /// An smbclient authentication file with \p pass (the right password by default), mode 0600.
  std::string credentials(const std::string& name, const std::string& pass = "") const
  {
    const std::string path = dir_ + "/" + name;
    std::ofstream(path) << "username = " << user << "\npassword = " << (pass.empty() ? password : pass) << "\n";
    ::chmod(path.c_str(), 0600);
    return path;
  }
  std::string config() const { return dir_ + "/smb.conf"; }

  std::string user;
  std::string password = "cnc-Bridge-7";
  unsigned port = 0;

 private:
  bool answers() const
  {
    const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
    sockaddr_in address{};
    address.sin_family = AF_INET;
    address.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    address.sin_port = htons(static_cast<uint16_t>(port));
    const bool ok = ::connect(fd, reinterpret_cast<sockaddr*>(&address), sizeof(address)) == 0;
    ::close(fd);
    return ok;
  }

  std::string dir_;
  pid_t pid_ = -1;
};
}  // namespace cnc_bridge::test
