// FakeTransport: an input queue and a record of writes behind one mutex.
#include "testing/fake_transport.h"

#include "cnc_bridge/common/error.h"

namespace cnc_bridge
{
void FakeTransport::feed(const std::vector<uint8_t>& bytes)
{
  {
    std::lock_guard<std::mutex> lock(mutex_);
    input_.insert(input_.end(), bytes.begin(), bytes.end());
  }
  changed_.notify_all();
}

void FakeTransport::feed(const std::string& text)
{
  feed(std::vector<uint8_t>(text.begin(), text.end()));
}

void FakeTransport::onWrite(WriteHook hook)
{
  std::lock_guard<std::mutex> lock(mutex_);
  hook_ = std::move(hook);
}

std::vector<uint8_t> FakeTransport::written() const
{
  std::lock_guard<std::mutex> lock(mutex_);
  return written_;
}

void FakeTransport::clearWritten()
{
  std::lock_guard<std::mutex> lock(mutex_);
  written_.clear();
}

void FakeTransport::disconnect()
{
  {
    std::lock_guard<std::mutex> lock(mutex_);
    disconnected_ = true;
  }
  changed_.notify_all();
}

void FakeTransport::setMaxReadChunk(size_t bytes)
{
  std::lock_guard<std::mutex> lock(mutex_);
  max_chunk_ = bytes;
}

bool FakeTransport::waitForWritten(size_t count, Milliseconds timeout) const
{
  std::unique_lock<std::mutex> lock(mutex_);
  return changed_.wait_for(lock, timeout, [&] { return written_.size() >= count; });
}

size_t FakeTransport::read(uint8_t* buffer, size_t size, Milliseconds timeout)
{
  std::unique_lock<std::mutex> lock(mutex_);
  const auto ready = [&] { return !input_.empty() || disconnected_ || closed_ || interrupted_; };
  if (timeout == kWaitForever)
  {
    changed_.wait(lock, ready);
  }
  else
  {
    changed_.wait_for(lock, timeout, ready);
  }
  if (interrupted_)
  {
    interrupted_ = false;
    throw CancelledError(name_ + ": cancelled");
  }
  if (closed_)
  {
    throw LinkError(name_ + ": not open");
  }
  if (input_.empty())
  {
    if (disconnected_)
    {
      throw LinkError(name_ + ": the peer closed the connection");
    }
    return 0;
  }
  size_t n = std::min(size, input_.size());
  if (max_chunk_ > 0)
  {
    n = std::min(n, max_chunk_);
  }
  std::copy(input_.begin(), input_.begin() + static_cast<std::ptrdiff_t>(n), buffer);
  input_.erase(input_.begin(), input_.begin() + static_cast<std::ptrdiff_t>(n));
  return n;
}

void FakeTransport::write(const uint8_t* data, size_t size, Milliseconds /*timeout*/)
{
  WriteHook hook;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (interrupted_)
    {
      interrupted_ = false;
      throw CancelledError(name_ + ": cancelled");
    }
    if (closed_ || disconnected_)
    {
      throw LinkError(name_ + ": the peer closed the connection");
    }
    written_.insert(written_.end(), data, data + size);
    hook = hook_;
  }
  changed_.notify_all();
  if (hook)
  {
    hook(*this, std::vector<uint8_t>(data, data + size));
  }
}

void FakeTransport::discardInput()
{
  std::lock_guard<std::mutex> lock(mutex_);
  input_.clear();
}

void FakeTransport::interrupt()
{
  {
    std::lock_guard<std::mutex> lock(mutex_);
    interrupted_ = true;
  }
  changed_.notify_all();
}

void FakeTransport::close()
{
  {
    std::lock_guard<std::mutex> lock(mutex_);
    closed_ = true;
  }
  changed_.notify_all();
}

bool FakeTransport::isOpen() const
{
  std::lock_guard<std::mutex> lock(mutex_);
  return !closed_;
}
}  // namespace cnc_bridge
