// PortLock: flock(2) on <lock dir>/cnc_bridge-<device path with '/' replaced>.lock, and on the same
// name with ".want" appended while a transfer waits. The lock directory defaults to
// /run/lock/cnc_bridge (port_lock.h, lockDirectory()).
#include "cnc_bridge/common/port_lock.h"

#include <fcntl.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <climits>
#include <cstdlib>
#include <cstring>
#include <thread>

#include "cnc_bridge/common/error.h"
#include "cnc_bridge/common/log.h"
#include "cnc_bridge/common/regular_file.h"

namespace cnc_bridge
{
namespace
{
int openLockFile(const std::string& path)
{
  // No O_TRUNC and no following links: a link planted at this path (to a file the node's user may
  // write) must not be truncated or written through. O_NONBLOCK: a FIFO there must not block.
  const int fd = ::open(path.c_str(), O_RDWR | O_CREAT | O_NOFOLLOW | O_NONBLOCK | O_NOCTTY | O_CLOEXEC, 0640);
  if (fd < 0)
  {
    if (errno == ELOOP)
    {
      throw LinkError("refused lock file " + path +
                      ": it is a symbolic link, which is never followed; remove it (and check who put it there)");
    }
    throw LinkError("cannot open lock file " + path + ": " + std::strerror(errno));
  }
  struct stat info;
  const bool known = ::fstat(fd, &info) == 0;
  if (!known || !S_ISREG(info.st_mode))
  {
    const std::string what = known ? "it is " + fileKind(info.st_mode) + ", not a regular file" : std::strerror(errno);
    ::close(fd);
    throw LinkError("refused lock file " + path + ": " + what + "; remove it");
  }
  return fd;
}

/// Why \p dir cannot hold the locks ("" if it can): it must be a directory itself (not a link), of
/// this user or root, and no other user may write to it (unless sticky, as /run/lock is).
std::string unsafeLockDir(const std::string& dir)
{
  struct stat info;
  if (::lstat(dir.c_str(), &info) != 0)
    return std::strerror(errno);
  if (!S_ISDIR(info.st_mode))
    return "it is " + fileKind(info.st_mode) + ", not a directory";
  if (info.st_uid != ::geteuid() && info.st_uid != 0)
    return "it belongs to another user (uid " + std::to_string(info.st_uid) + ")";
  if ((info.st_mode & S_IWOTH) && !(info.st_mode & S_ISVTX))
    return "every user may write to it";
  return "";
}

/// Creates \p dir with \p mode unless it exists; \returns why it cannot be used ("" if it can).
std::string makeLockDir(const std::string& dir, mode_t mode)
{
  if (::mkdir(dir.c_str(), mode) == 0)
  {
    ::chmod(dir.c_str(), mode);  // exactly, whatever the umask
  }
  else if (errno != EEXIST)
  {
    return std::string("cannot create it: ") + std::strerror(errno);
  }
  return unsafeLockDir(dir);
}
}  // namespace

std::string lockName(const std::string& device)
{
  std::string name;
  const size_t scheme_end = device.find("://");
  if (scheme_end != std::string::npos)
  {
    // A device server's port (tcp://host:port, rfc2217://host:port): no file to resolve; the same
    // host:port is the same line whichever protocol reaches it.
    name = "net-" + device.substr(scheme_end + 3);
  }
  else
  {
    char resolved[PATH_MAX];
    name = ::realpath(device.c_str(), resolved) ? resolved : device;
  }
  for (char& c : name)
  {
    if (c == '/')
      c = '_';
  }
  return name;
}

std::string lockDirectory(const std::string& requested)
{
  if (requested != kDefaultLockDir)
    return requested;
  const std::string why = makeLockDir(requested, 0755);
  if (why.empty())
    return requested;
  std::string fallback = "/tmp/cnc_bridge-" + std::to_string(::geteuid());
  const std::string fallback_why = makeLockDir(fallback, 0700);
  if (!fallback_why.empty())
  {
    throw ConfigError("no directory for the serial-port lock: " + requested + ": " + why + "; " + fallback + ": " +
                      fallback_why + "; set ~lock_dir (or fix the directory)");
  }
  CNC_LOG_WARN("port lock directory " << requested << " cannot be used (" << why << "); using " << fallback
                                      << " instead: every node on the line must run as this user or share ~lock_dir");
  return fallback;
}

PortLock::PortLock(const std::string& device, const std::string& lock_dir_requested)
{
  const std::string lock_dir = lockDirectory(lock_dir_requested);
  path_ = lock_dir + "/cnc_bridge-" + lockName(device) + ".lock";
}

PortLock::~PortLock()
{
  unlock();
  for (int fd : {fd_, want_fd_})
  {
    if (fd >= 0)
    {
      ::close(fd);
    }
  }
}

void PortLock::open()
{
  if (fd_ < 0)
  {
    fd_ = openLockFile(path_);
  }
  if (want_fd_ < 0)
  {
    want_fd_ = openLockFile(path_ + ".want");
  }
}

bool PortLock::tryLock()
{
  if (held_)
  {
    return true;
  }
  open();
  held_ = ::flock(fd_, LOCK_EX | LOCK_NB) == 0;
  return held_;
}

void PortLock::unlock()
{
  if (held_ && fd_ >= 0)
  {
    ::flock(fd_, LOCK_UN);
  }
  held_ = false;
}

bool PortLock::wantedElsewhere()
{
  open();
  // A shared probe: fails while a transfer holds the want lock exclusively.
  if (::flock(want_fd_, LOCK_SH | LOCK_NB) != 0)
  {
    return true;
  }
  ::flock(want_fd_, LOCK_UN);
  return false;
}

bool PortLock::tryLockForQuery()
{
  if (held_)
  {
    return true;
  }
  // A transfer that arrives between this check and tryLock() waits for one query: bounded.
  return !wantedElsewhere() && tryLock();
}

bool PortLock::lockForTransfer(std::chrono::milliseconds patience, const std::function<bool()>& cancelled)
{
  open();
  const auto deadline = std::chrono::steady_clock::now() + patience;
  bool wanting = false;
  bool locked = false;
  for (;;)
  {
    // Announce the wait (retried: a poller's shared probe can hold the want lock for an instant).
    wanting = wanting || ::flock(want_fd_, LOCK_EX | LOCK_NB) == 0;
    if (tryLock())
    {
      locked = true;
      break;
    }
    // flock(2) has no timeout: poll it.
    if ((cancelled && cancelled()) || std::chrono::steady_clock::now() >= deadline)
    {
      break;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  if (wanting)
  {
    ::flock(want_fd_, LOCK_UN);
  }
  if (locked)
  {
    const std::string next = std::to_string(generation() + 1);
    if (::ftruncate(fd_, 0) != 0 || ::pwrite(fd_, next.data(), next.size(), 0) != static_cast<ssize_t>(next.size()))
    {
      // Pollers then miss one settings refresh; the transfer itself is not affected.
    }
  }
  return locked;
}

uint64_t PortLock::generation()
{
  open();
  char text[32] = {};
  const ssize_t n = ::pread(fd_, text, sizeof text - 1, 0);
  if (n <= 0)
  {
    return 0;
  }
  return std::strtoull(text, nullptr, 10);
}

bool PortLock::heldElsewhere()
{
  if (held_)
  {
    return false;
  }
  if (tryLock())
  {
    unlock();
    return false;
  }
  return true;
}

ScopedPortLock::ScopedPortLock(PortLock& lock) : lock_(lock)
{
  if (!lock_.tryLock())
  {
    throw LinkError("serial port is busy: another cnc_bridge node holds " + lock_.lockFile());
  }
}
}  // namespace cnc_bridge
