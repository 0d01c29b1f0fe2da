// PtyMaster: openpty(3), raw slave, master wrapped in an Asio stream_descriptor.
#include "testing/pty.h"

#include <pty.h>
#include <termios.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <filesystem>

namespace cnc_bridge
{
namespace
{
/// Points \p link at \p target, making its folder if needed. The link is made beside its final
/// name and renamed over it, so the path never stops naming a device: whoever opens it gets the
/// old pty or the new one, never a missing file. \returns the reason of a failure, or "".
std::string linkAtomically(const std::string& target, const std::string& link)
{
  std::error_code ignored;  // a folder that cannot be made shows as the symlink's failure
  std::filesystem::create_directories(std::filesystem::path(link).parent_path(), ignored);
  const std::string temporary = link + ".new" + std::to_string(::getpid());
  ::unlink(temporary.c_str());
  if (::symlink(target.c_str(), temporary.c_str()) != 0)
  {
    return std::strerror(errno);
  }
  if (::rename(temporary.c_str(), link.c_str()) != 0)
  {
    std::string reason = std::strerror(errno);
    ::unlink(temporary.c_str());
    return reason;
  }
  return "";
}
}  // namespace

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
    const std::string error = linkAtomically(slave_path_, link_path);
    if (!error.empty())
    {
      close();
      ::close(slave_fd_);
      throw LinkError("cannot link " + link_path + " to " + slave_path_ + ": " + error);
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
