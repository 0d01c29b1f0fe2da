// PortLock: flock(2) on /tmp/cnc_bridge-<device path with '/' replaced>.lock, and on the same name
// with ".want" appended while a transfer waits.
#include "cnc_bridge/common/port_lock.h"

#include <fcntl.h>
#include <sys/file.h>
#include <unistd.h>

#include <cerrno>
#include <climits>
#include <cstdlib>
#include <cstring>
#include <thread>

#include "cnc_bridge/common/error.h"

namespace cnc_bridge
{
namespace
{
int openLockFile(const std::string& path)
{
  const int fd = ::open(path.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0666);
  if (fd < 0)
  {
    throw LinkError("cannot open lock file " + path + ": " + std::strerror(errno));
  }
  return fd;
}
}  // namespace

PortLock::PortLock(const std::string& device, const std::string& lock_dir)
{
  char resolved[PATH_MAX];
  std::string name = ::realpath(device.c_str(), resolved) ? resolved : device;
  for (char& c : name)
  {
    if (c == '/')
      c = '_';
  }
  path_ = lock_dir + "/cnc_bridge-" + name + ".lock";
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
