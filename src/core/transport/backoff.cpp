// Backoff, StopSignal and the Reconnector loop.
#include "cnc_bridge/transport/backoff.h"

#include <algorithm>

#include "cnc_bridge/common/error.h"
#include "cnc_bridge/common/log.h"

namespace cnc_bridge
{
Backoff::Backoff(Milliseconds initial, Milliseconds maximum, double factor)
    : initial_(initial), maximum_(std::max(initial, maximum)), factor_(std::max(1.0, factor)), current_(initial)
{
}

Milliseconds Backoff::next()
{
  const Milliseconds delay = current_;
  ++failures_;
  const auto grown = static_cast<Milliseconds::rep>(static_cast<double>(current_.count()) * factor_);
  current_ = std::min(maximum_, Milliseconds(std::max<Milliseconds::rep>(grown, 1)));
  return delay;
}

void Backoff::reset()
{
  current_ = initial_;
  failures_ = 0;
}

void StopSignal::stop()
{
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stopped_ = true;
  }
  cv_.notify_all();
}

bool StopSignal::waitFor(Milliseconds timeout)
{
  std::unique_lock<std::mutex> lock(mutex_);
  return cv_.wait_for(lock, timeout, [this] { return stopped_.load(); });
}

Reconnector::Reconnector(std::string name, Callbacks callbacks, Backoff backoff)
    : name_(std::move(name)), callbacks_(std::move(callbacks)), backoff_(backoff)
{
}

Reconnector::~Reconnector()
{
  stop();
}

void Reconnector::start()
{
  if (!thread_.joinable())
  {
    thread_ = std::thread([this] { run(); });
  }
}

void Reconnector::stop()
{
  stop_.stop();
  if (callbacks_.disconnect)
  {
    callbacks_.disconnect();
  }
  if (thread_.joinable())
  {
    thread_.join();
  }
}

void Reconnector::run()
{
  const auto report = [this](LinkState state, const std::string& why)
  {
    if (callbacks_.on_state)
    {
      callbacks_.on_state(state, why);
    }
  };
  bool was_up = false;
  while (!stop_.stopped())
  {
    report(LinkState::kConnecting, "");
    try
    {
      callbacks_.connect();
      if (was_up || failures_ > 0)
      {
        ++reconnects_;
        CNC_LOG_INFO(name_ << ": link up again");
      }
      backoff_.reset();
      was_up = true;
      report(LinkState::kUp, "");
      callbacks_.session();
      if (stop_.stopped())
      {
        break;
      }
      throw LinkError("session ended");
    }
    catch (const std::exception& e)
    {
      if (callbacks_.disconnect)
      {
        callbacks_.disconnect();
      }
      if (stop_.stopped())
      {
        break;
      }
      ++failures_;
      const unsigned attempt = backoff_.failures();
      if (attempt == 0)
      {
        CNC_LOG_ERROR(name_ << ": " << e.what());
      }
      else if (attempt % 10 == 0)
      {
        CNC_LOG_WARN(name_ << ": still failing after " << attempt << " attempts: " << e.what());
      }
      report(LinkState::kDown, e.what());
      stop_.waitFor(backoff_.next());
    }
  }
  report(LinkState::kDown, "stopped");
}
}  // namespace cnc_bridge
