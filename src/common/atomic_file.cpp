// AtomicFileWriter: temporary file in the same directory, fsync, rename, fsync of the directory.
#include "cnc_bridge/common/atomic_file.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <vector>

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

AtomicFileWriter::AtomicFileWriter(std::string path) : path_(std::move(path))
{
  std::string pattern = directoryOf(path_) + "/." + baseName(path_) + ".partial.XXXXXX";
  std::vector<char> buffer(pattern.begin(), pattern.end());
  buffer.push_back('\0');
  fd_ = ::mkstemp(buffer.data());
  if (fd_ < 0)
  {
    throw ConfigError("cannot create a temporary file beside " + path_ + ": " + std::strerror(errno));
  }
  temp_path_ = buffer.data();
  ::fchmod(fd_, 0644);
}

AtomicFileWriter::~AtomicFileWriter()
{
  if (!committed_)
  {
    discard();
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
      throw Error("writing " + temp_path_ + ": " + std::strerror(errno));
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
    throw Error("flushing " + temp_path_ + ": " + reason);
  }
  fd_ = -1;
  if (::rename(temp_path_.c_str(), path_.c_str()) != 0)
  {
    const std::string reason = std::strerror(errno);
    discard();
    throw Error("renaming " + temp_path_ + " to " + path_ + ": " + reason);
  }
  committed_ = true;
  // Make the rename itself durable.
  const int dir_fd = ::open(directoryOf(path_).c_str(), O_RDONLY | O_DIRECTORY);
  if (dir_fd >= 0)
  {
    ::fsync(dir_fd);
    ::close(dir_fd);
  }
}

void AtomicFileWriter::discard()
{
  if (fd_ >= 0)
  {
    ::close(fd_);
    fd_ = -1;
  }
  if (!committed_ && !temp_path_.empty())
  {
    ::unlink(temp_path_.c_str());
    temp_path_.clear();
  }
}
}  // namespace cnc_bridge
