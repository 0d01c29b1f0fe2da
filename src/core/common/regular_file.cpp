// RegularFile: open with O_NONBLOCK (a FIFO must not block the open), fstat, refuse anything but a
// regular file, then read with pread (see regular_file.h).
#include "cnc_bridge/common/regular_file.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>

#include "cnc_bridge/common/error.h"

namespace cnc_bridge
{
std::string fileKind(unsigned mode)
{
  if (S_ISREG(mode))
    return "a regular file";
  if (S_ISDIR(mode))
    return "a directory";
  if (S_ISFIFO(mode))
    return "a FIFO";
  if (S_ISLNK(mode))
    return "a symbolic link";
  if (S_ISCHR(mode))
    return "a character device";
  if (S_ISBLK(mode))
    return "a block device";
  if (S_ISSOCK(mode))
    return "a socket";
  return "not a regular file";
}

// O_NONBLOCK: opening a FIFO for reading would otherwise wait for a writer. It changes nothing for
// the regular file that is read afterwards.
RegularFile::RegularFile(const std::string& path)
    : path_(path), fd_(::open(path.c_str(), O_RDONLY | O_NONBLOCK | O_CLOEXEC | O_NOCTTY))
{
  if (fd_ < 0)
    throw ConfigError("cannot read " + path + ": " + std::strerror(errno));
  struct stat info;
  if (::fstat(fd_, &info) != 0)
  {
    const int error = errno;
    ::close(fd_);
    throw ConfigError("cannot read " + path + ": " + std::strerror(error));
  }
  if (!S_ISREG(info.st_mode))
  {
    ::close(fd_);
    throw ConfigError("refused: " + path + " is " + fileKind(info.st_mode) +
                      ", not a program file; only regular files are read or sent");
  }
  size_ = static_cast<uint64_t>(info.st_size);
}

RegularFile::~RegularFile()
{
  ::close(fd_);
}

size_t readFully(int fd, uint64_t offset, char* data, size_t size, const std::string& path)
{
  size_t got = 0;
  while (got < size)
  {
    const ssize_t n = ::pread(fd, data + got, size - got, static_cast<off_t>(offset + got));
    if (n < 0 && errno == EINTR)
      continue;
    if (n < 0)
      throw Error("reading " + path + ": " + std::strerror(errno));
    if (n == 0)
      break;
    got += static_cast<size_t>(n);
  }
  return got;
}

size_t RegularFile::readAt(uint64_t offset, char* data, size_t size) const
{
  return readFully(fd_, offset, data, size, path_);
}

size_t RegularFile::read(char* data, size_t size)
{
  const size_t got = readAt(offset_, data, size);
  offset_ += got;
  return got;
}

std::string RegularFile::readAll(uint64_t max_bytes, const std::string& limit_name)
{
  if (size_ > max_bytes)
  {
    throw ConfigError("refused: " + path_ + " holds " + std::to_string(size_) + " bytes, more than " + limit_name +
                      " (" + std::to_string(max_bytes) + ")");
  }
  std::string contents;
  char buffer[65536];
  for (size_t n = read(buffer, sizeof buffer); n > 0; n = read(buffer, sizeof buffer))
  {
    if (contents.size() + n > max_bytes)  // it grew since it was opened
      throw ConfigError("refused: " + path_ + " grew past " + limit_name + " (" + std::to_string(max_bytes) +
                        " bytes) while it was read");
    contents.append(buffer, n);
  }
  return contents;
}
}  // namespace cnc_bridge
