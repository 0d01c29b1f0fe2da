// A peer program (lrzsz sx/rx, the python3-xmodem peer) run as a child process on a pty slave,
// for the tests that put an independent implementation on the other end of a line.
#pragma once

#include <fcntl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <csignal>
#include <string>
#include <vector>

namespace cnc_bridge::test
{
/// In a forked child: runs \p argv (argv[0] a path, no PATH search) in place of this process, or
/// exits with 127 if it cannot.
[[noreturn]] inline void execOrExit(const std::vector<std::string>& argv)
{
  std::vector<char*> args;
  for (const auto& a : argv)
    args.push_back(const_cast<char*>(a.c_str()));
  args.push_back(nullptr);
  ::execv(args[0], args.data());
  ::_exit(127);
}

/// A peer process. With \p stdio_on set, its stdin and stdout are the pty slave (lrzsz style).
class Peer
{
 public:
  Peer(const std::vector<std::string>& argv, const std::string& cwd, const std::string& stdio_on)
  {
    pid_ = ::fork();
    if (pid_ == 0)
    {
      if (::chdir(cwd.c_str()) != 0)
        ::_exit(126);
      if (!stdio_on.empty())
      {
        const int fd = ::open(stdio_on.c_str(), O_RDWR | O_NOCTTY);
        if (fd < 0)
          ::_exit(126);
        ::dup2(fd, 0);
        ::dup2(fd, 1);
        ::close(fd);
      }
      const int null = ::open("/dev/null", O_WRONLY);
      ::dup2(null, 2);  // lrzsz chatters on stderr
      execOrExit(argv);
    }
  }
  /// Waits for the peer (its own timeouts bound the wait) and returns its exit status.
  int wait()
  {
    int status = 0;
    ::waitpid(pid_, &status, 0);
    pid_ = -1;
    return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
  }
  ~Peer()
  {
    if (pid_ > 0)
    {
      ::kill(pid_, SIGKILL);
      ::waitpid(pid_, nullptr, 0);
    }
  }

 private:
  pid_t pid_ = -1;
};
}  // namespace cnc_bridge::test
