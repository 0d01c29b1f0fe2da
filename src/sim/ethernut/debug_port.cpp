// The simulated board's debug port (debug_port.h).
#include "sim/ethernut/debug_port.h"

#include "cnc_bridge/common/error.h"
#include "cnc_bridge/common/log.h"

namespace cnc_bridge
{
namespace ethernut
{
DebugPort::DebugPort(Transport& port, size_t max_queued) : port_(port), max_queued_(max_queued)
{
  writer_ = std::thread([this] { run(); });
}

DebugPort::~DebugPort()
{
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stopping_ = true;
  }
  queued_.notify_all();
  port_.interrupt();  // a write blocked on a full port
  writer_.join();
}

void DebugPort::print(const DebugMessage& message)
{
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (lines_.size() >= max_queued_)
    {
      ++dropped_;
      return;
    }
    lines_.push_back(debugLine(message) + "\r\n");
  }
  queued_.notify_one();
}

uint64_t DebugPort::dropped() const
{
  std::lock_guard<std::mutex> lock(mutex_);
  return dropped_;
}

void DebugPort::run()
{
  for (;;)
  {
    std::string line;
    {
      std::unique_lock<std::mutex> lock(mutex_);
      queued_.wait(lock, [this] { return stopping_ || !lines_.empty(); });
      if (stopping_)
      {
        return;
      }
      line = std::move(lines_.front());
      lines_.pop_front();
    }
    try
    {
      port_.write(line);
    }
    catch (const Error& e)
    {
      CNC_LOG_WARN("sim_ethernut: debug port: " << e.what());
      return;
    }
  }
}
}  // namespace ethernut
}  // namespace cnc_bridge
