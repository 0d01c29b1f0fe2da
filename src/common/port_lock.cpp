// PortLock: flock(2) on /tmp/cnc_bridge-<device path with '/' replaced>.lock.
#include "cnc_bridge/common/port_lock.h"

#include <fcntl.h>
#include <sys/file.h>
#include <unistd.h>

#include <cerrno>
#include <climits>
#include <cstdlib>
#include <cstring>

#include "cnc_bridge/common/error.h"

namespace cnc_bridge
{
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
  if (fd_ >= 0)
  {
    ::close(fd_);
  }
}

bool PortLock::tryLock()
{
  if (held_)
  {
    return true;
  }
  if (fd_ < 0)
  {
    fd_ = ::open(path_.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0666);
    if (fd_ < 0)
    {
      throw LinkError("cannot open lock file " + path_ + ": " + std::strerror(errno));
    }
  }
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
