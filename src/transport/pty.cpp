// PtyMaster: openpty(3), raw slave, master wrapped in an Asio stream_descriptor.
#include "cnc_bridge/transport/pty.h"

#include <pty.h>
#include <termios.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>

namespace cnc_bridge
{
PtyMaster::PtyMaster(const std::string& link_path)
{
  int master_fd = -1;
  char name[256] = {0};
  struct termios raw;
  std::memset(&raw, 0, sizeof(raw));
  ::cfmakeraw(&raw);
  raw.c_cflag |= CLOCAL | CREAD;
  if (::openpty(&master_fd, &slave_fd_, name, &raw, nullptr) != 0)
  {
    throw LinkError(std::string("cannot allocate a pty: ") + std::strerror(errno));
  }
  slave_path_ = name;
  stream_.assign(master_fd);
  if (!link_path.empty())
  {
    // Made beside the link and renamed over it: the path never stops naming a device, and
    // whoever opens it gets the old pty or the new one, never a missing file.
    const std::string temporary = link_path + ".new" + std::to_string(::getpid());
    ::unlink(temporary.c_str());
    if (::symlink(slave_path_.c_str(), temporary.c_str()) != 0 || ::rename(temporary.c_str(), link_path.c_str()) != 0)
    {
      ::unlink(temporary.c_str());
      const std::string reason = std::strerror(errno);
      close();
      ::close(slave_fd_);
      throw LinkError("cannot link " + link_path + " to " + slave_path_ + ": " + reason);
    }
    link_path_ = link_path;
  }
}

PtyMaster::~PtyMaster()
{
  close();
  if (slave_fd_ >= 0)
  {
    ::close(slave_fd_);
  }
  if (!link_path_.empty())
  {
    ::unlink(link_path_.c_str());
  }
}

void PtyMaster::drain()
{
  // A pty has no wire: data is in the slave's input queue as soon as write() returns.
}

void PtyMaster::discardInput()
{
  if (isOpen())
  {
    ::tcflush(stream_.native_handle(), TCIFLUSH);
  }
}
}  // namespace cnc_bridge
