#include "cnc_bridge/common/job_hold.h"

#include <algorithm>
#include <utility>

namespace cnc_bridge
{
JobHold::JobHold(std::chrono::milliseconds cancel_poll) : cancel_poll_(cancel_poll) {}

void JobHold::hold(std::string what)
{
  std::lock_guard<std::mutex> lock(mutex_);
  held_ = std::move(what);
  resumed_ = false;
}

bool JobHold::waitForResume(const Cancelled& cancelled)
{
  std::unique_lock<std::mutex> lock(mutex_);
  while (!resumed_)
  {
    const uint64_t wakes = wakes_;
    lock.unlock();  // the predicate may take the caller's locks (an action server's)
    const bool gave_up = cancelled();
    lock.lock();
    if (gave_up && !resumed_)
    {
      break;
    }
    changed_.wait_for(lock, cancel_poll_, [&] { return resumed_ || wakes_ != wakes; });
  }
  const bool resumed = resumed_;
  held_.clear();
  resumed_ = false;
  return resumed;
}

bool JobHold::waitFor(std::chrono::duration<double> time, const Cancelled& cancelled)
{
  using Clock = std::chrono::steady_clock;
  const Clock::time_point deadline = Clock::now() + std::chrono::duration_cast<Clock::duration>(time);
  std::unique_lock<std::mutex> lock(mutex_);
  while (Clock::now() < deadline)
  {
    const uint64_t wakes = wakes_;
    lock.unlock();
    if (cancelled())
    {
      return false;
    }
    lock.lock();
    changed_.wait_until(lock, std::min(deadline, Clock::now() + cancel_poll_), [&] { return wakes_ != wakes; });
  }
  return true;
}

std::optional<std::string> JobHold::resume()
{
  std::string what;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (held_.empty())
    {
      return std::nullopt;
    }
    resumed_ = true;
    what = held_;
  }
  changed_.notify_all();
  return what;
}

std::string JobHold::held() const
{
  std::lock_guard<std::mutex> lock(mutex_);
  return held_;
}

void JobHold::wake()
{
  {
    std::lock_guard<std::mutex> lock(mutex_);
    ++wakes_;
  }
  changed_.notify_all();
}
}  // namespace cnc_bridge
