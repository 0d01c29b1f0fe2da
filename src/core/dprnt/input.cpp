// DPRNT inputs: reopened streams (serial, TCP) and a followed file.
#include "cnc_bridge/dprnt/input.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>

#include "cnc_bridge/common/error.h"
#include "cnc_bridge/common/log.h"

namespace cnc_bridge
{
namespace dprnt
{
namespace
{
constexpr size_t kChunk = 4096;
// A read returns at least this often so a stop request is seen even if interrupt() raced a reopen.
constexpr Milliseconds kReadSlice(200);
}  // namespace

// ---------------------------------------------------------------------------------------------
StreamInput::StreamInput(std::function<std::unique_ptr<Transport>()> open, std::string description, Backoff backoff)
    : open_(std::move(open)), description_(std::move(description)), backoff_(backoff)
{
}

StreamInput::~StreamInput()
{
  stop();
}

void StreamInput::start(BytesHandler on_bytes, StateHandler on_state, RestartHandler /*on_restart*/)
{
  on_bytes_ = std::move(on_bytes);
  link_ = std::make_unique<ReconnectingLink>(description_, open_, backoff_);
  link_->start([this](Transport& link) { session(link); }, std::move(on_state));
}

void StreamInput::session(Transport& link)
{
  uint8_t buffer[kChunk];
  while (!stopping_)
  {
    const size_t n = link.read(buffer, sizeof buffer, kReadSlice);
    if (n > 0)
      on_bytes_(buffer, n);
  }
}

void StreamInput::stop()
{
  stopping_ = true;
  if (link_)
    link_->stop();
}

unsigned StreamInput::reconnects() const
{
  return link_ ? link_->reconnects() : 0;
}

// ---------------------------------------------------------------------------------------------
FileInput::FileInput(std::string path, bool from_start, Milliseconds poll, Backoff backoff)
    : path_(std::move(path)), from_start_(from_start), poll_(poll), backoff_(backoff)
{
}

FileInput::~FileInput()
{
  stop();
  closeFile();
}

void FileInput::start(BytesHandler on_bytes, StateHandler on_state, RestartHandler on_restart)
{
  on_bytes_ = std::move(on_bytes);
  on_restart_ = std::move(on_restart);
  Reconnector::Callbacks callbacks;
  callbacks.connect = [this] { openFile(); };
  callbacks.session = [this] { session(); };
  on_state_ = on_state;
  callbacks.on_state = std::move(on_state);
  reconnector_ = std::make_unique<Reconnector>(describe(), std::move(callbacks), backoff_);
  reconnector_->start();
}

void FileInput::stop()
{
  stop_.stop();
  if (reconnector_)
  {
    reconnector_->stop();
    reconnector_.reset();
  }
}

unsigned FileInput::reconnects() const
{
  return reconnector_ ? reconnector_->reconnects() : 0;
}

void FileInput::closeFile()
{
  if (fd_ >= 0)
  {
    ::close(fd_);
    fd_ = -1;
  }
}

void FileInput::openFile()
{
  closeFile();
  tail_.clear();
  seen_size_ = -1;
  // Only a file that exists at the very first attempt has history to skip; a file created later,
  // or reopened after a failure, holds only what was written while we waited: read it all.
  const bool skip_history = first_attempt_ && !from_start_;
  first_attempt_ = false;
  fd_ = ::open(path_.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd_ < 0)
  {
    throw LinkError("file " + path_ + ": " + std::strerror(errno));
  }
  if (skip_history)
  {
    const off_t end = ::lseek(fd_, 0, SEEK_END);
    // The skipped history's last bytes are what a rewrite check compares against.
    const off_t from = std::max<off_t>(0, end - static_cast<off_t>(kVerifyWindow));
    std::string history(static_cast<size_t>(end - from), '\0');
    const ssize_t n = ::pread(fd_, history.data(), history.size(), from);
    if (n == static_cast<ssize_t>(history.size()))
      tail_ = std::move(history);
  }
}

void FileInput::keepTail(const uint8_t* data, size_t size)
{
  if (size >= kVerifyWindow)
  {
    tail_.assign(reinterpret_cast<const char*>(data) + size - kVerifyWindow, kVerifyWindow);
    return;
  }
  tail_.append(reinterpret_cast<const char*>(data), size);
  if (tail_.size() > kVerifyWindow)
    tail_.erase(0, tail_.size() - kVerifyWindow);
}

const char* FileInput::changedUnderneath()
{
  struct stat st;
  if (::fstat(fd_, &st) != 0)
  {
    throw LinkError("file " + path_ + ": " + std::strerror(errno));
  }
  const off_t position = ::lseek(fd_, 0, SEEK_CUR);
  if (st.st_size < position)
    return "truncated";
  const bool unchanged =
      st.st_size == seen_size_ && st.st_mtim.tv_sec == seen_mtime_.tv_sec && st.st_mtim.tv_nsec == seen_mtime_.tv_nsec;
  seen_size_ = st.st_size;
  seen_mtime_ = st.st_mtim;
  if (unchanged || tail_.empty() || position < static_cast<off_t>(tail_.size()))
    return nullptr;
  // Written since the last look: are the bytes before the read position still the ones read?
  std::string now(tail_.size(), '\0');
  const ssize_t n = ::pread(fd_, now.data(), now.size(), position - static_cast<off_t>(tail_.size()));
  if (n < 0)
  {
    throw LinkError("file " + path_ + ": " + std::strerror(errno));
  }
  return static_cast<size_t>(n) == now.size() && now == tail_ ? nullptr : "rewritten";
}

void FileInput::startOver(const std::string& why)
{
  ++restarts_;
  CNC_LOG_INFO("file " << path_ << " " << why);
  if (on_restart_)
    on_restart_(why);
  if (on_state_)
    on_state_(LinkState::kUp, why);
}

void FileInput::session()
{
  uint8_t buffer[kChunk];
  while (!stop_.stopped())
  {
    // Checked before every read, not only after a poll: the bytes handler may have taken a while.
    // One fstat per read; the file is compared only when it changed.
    if (const char* what = changedUnderneath())
    {
      ::lseek(fd_, 0, SEEK_SET);
      tail_.clear();
      seen_size_ = -1;
      startOver(std::string("file ") + what + ": reading from its start");
      continue;
    }
    const ssize_t n = ::read(fd_, buffer, sizeof buffer);
    if (n > 0)
    {
      keepTail(buffer, static_cast<size_t>(n));
      on_bytes_(buffer, static_cast<size_t>(n));
      continue;
    }
    if (n < 0 && errno != EINTR)
    {
      throw LinkError("file " + path_ + ": " + std::strerror(errno));
    }
    // At the end of what was written: truncated, rotated, or just nothing new yet?
    struct stat open_stat, path_stat;
    if (::fstat(fd_, &open_stat) != 0)
    {
      throw LinkError("file " + path_ + ": " + std::strerror(errno));
    }
    if (open_stat.st_size < ::lseek(fd_, 0, SEEK_CUR))
    {
      continue;  // truncated: changedUnderneath() tells it
    }
    if (::stat(path_.c_str(), &path_stat) == 0 &&
        (path_stat.st_ino != open_stat.st_ino || path_stat.st_dev != open_stat.st_dev))
    {
      // Everything of the old file has been read (read() returned 0 above): switch to the new one.
      openFile();
      startOver("file rotated: following the new file");
      continue;
    }
    stop_.waitFor(poll_);
  }
}
}  // namespace dprnt
}  // namespace cnc_bridge
