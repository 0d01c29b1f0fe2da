// AtomicFileWriter: temporary file in the same directory, fsync, rename, fsync of the directory.
#include "cnc_bridge/common/atomic_file.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <random>

#include "cnc_bridge/common/error.h"

namespace cnc_bridge
{
namespace
{
std::string directoryOf(const std::string& path)
{
  const auto slash = path.find_last_of('/');
  if (slash == std::string::npos)
  {
    return ".";
  }
  return slash == 0 ? "/" : path.substr(0, slash);
}

std::string baseName(const std::string& path)
{
  const auto slash = path.find_last_of('/');
  return slash == std::string::npos ? path : path.substr(slash + 1);
}
}  // namespace

std::string AtomicFileWriter::tempShown() const
{
  return directoryOf(path_) + "/" + temp_name_;
}

AtomicFileWriter::AtomicFileWriter(std::string path, mode_t mode) : path_(std::move(path))
{
  // The destination's folder is the caller's (resolved already); only the names in it are guarded.
  dir_fd_ = ::open(directoryOf(path_).c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (dir_fd_ < 0)
    throw ConfigError("cannot create a temporary file beside " + path_ + ": " + std::strerror(errno));
  own_dir_fd_ = true;
  create(baseName(path_), mode);
}

AtomicFileWriter::AtomicFileWriter(int dir_fd, const std::string& name, std::string shown, mode_t mode)
    : path_(std::move(shown)), dir_fd_(dir_fd)
{
  create(name, mode);
}

void AtomicFileWriter::create(const std::string& name, mode_t mode)
{
  name_ = name;
  std::random_device random;
  static const char kLetters[] = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789";
  int error = EEXIST;
  for (int attempt = 0; attempt < 100 && error == EEXIST; ++attempt)
  {
    std::string temp = "." + name + ".partial.";
    for (int i = 0; i < 6; ++i)
      temp += kLetters[random() % (sizeof(kLetters) - 1)];
    // O_EXCL: never an existing file, nor the target of a link planted at the name.
    fd_ =
        ::openat(dir_fd_, temp.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_NOFOLLOW | O_CLOEXEC, mode & kProgramFileMode);
    if (fd_ >= 0)
    {
      temp_name_ = temp;
      return;
    }
    error = errno;
  }
  if (own_dir_fd_)
    ::close(dir_fd_);
  throw ConfigError("cannot create a temporary file beside " + path_ + ": " + std::strerror(error));
}

AtomicFileWriter::~AtomicFileWriter()
{
  if (!committed_)
  {
    discard();
  }
  if (own_dir_fd_)
  {
    ::close(dir_fd_);
  }
}

void AtomicFileWriter::write(const uint8_t* data, size_t size)
{
  if (fd_ < 0)
  {
    throw Error("write to " + path_ + " after commit or discard");
  }
  while (size > 0)
  {
    const ssize_t n = ::write(fd_, data, size);
    if (n < 0)
    {
      if (errno == EINTR)
      {
        continue;
      }
      throw Error("writing " + tempShown() + ": " + std::strerror(errno));
    }
    data += n;
    size -= static_cast<size_t>(n);
    bytes_written_ += static_cast<size_t>(n);
  }
  startWriteback();
}

void AtomicFileWriter::startWriteback()
{
  // Start writing what is written so far to disk, without waiting for it: the rest of the transfer
  // (the next chunk from the network) runs meanwhile, and commit()'s fsync only waits for the tail.
  // sync_file_range(2): SYNC_FILE_RANGE_WRITE starts writeback of dirty pages and returns.
  if (bytes_written_ - writeback_from_ < kWritebackStep)
    return;
  ::sync_file_range(fd_, static_cast<off_t>(writeback_from_), static_cast<off_t>(bytes_written_ - writeback_from_),
                    SYNC_FILE_RANGE_WRITE);
  writeback_from_ = bytes_written_;
}

void AtomicFileWriter::commit()
{
  if (fd_ < 0)
  {
    throw Error("commit of " + path_ + " after discard");
  }
  if (::fsync(fd_) != 0 || ::close(fd_) != 0)
  {
    const std::string reason = std::strerror(errno);
    fd_ = -1;
    discard();
    throw Error("flushing " + tempShown() + ": " + reason);
  }
  fd_ = -1;
  // renameat replaces a link at the destination itself, not the file it points to.
  if (::renameat(dir_fd_, temp_name_.c_str(), dir_fd_, name_.c_str()) != 0)
  {
    const std::string reason = std::strerror(errno);
    discard();
    throw Error("renaming " + tempShown() + " to " + path_ + ": " + reason);
  }
  committed_ = true;
  ::fsync(dir_fd_);  // makes the rename itself durable
}

void AtomicFileWriter::discard()
{
  if (fd_ >= 0)
  {
    ::close(fd_);
    fd_ = -1;
  }
  if (!committed_ && !temp_name_.empty())
  {
    ::unlinkat(dir_fd_, temp_name_.c_str(), 0);
    temp_name_.clear();
  }
}
}  // namespace cnc_bridge
