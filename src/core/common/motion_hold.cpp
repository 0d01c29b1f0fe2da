#include "cnc_bridge/common/motion_hold.h"

namespace cnc_bridge
{
MotionHold::MotionHold(std::chrono::milliseconds cancel_poll) : cancel_poll_(cancel_poll) {}

void MotionHold::setGoalRunning(bool running)
{
  std::lock_guard<std::mutex> lock(mutex_);
  goal_running_ = running;
  hold_.clear();
}

bool MotionHold::disable(const std::string& what)
{
  std::lock_guard<std::mutex> lock(mutex_);
  if (goal_running_ && hold_.empty())
  {
    hold_ = what;
  }
  return goal_running_;
}

std::string MotionHold::hold() const
{
  std::lock_guard<std::mutex> lock(mutex_);
  return hold_;
}

MotionHold::Snapshot MotionHold::snapshot() const
{
  std::lock_guard<std::mutex> lock(mutex_);
  return Snapshot{hold_, resumes_};
}

std::string MotionHold::resume()
{
  std::string ended;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    ended.swap(hold_);
    ++resumes_;
  }
  resumed_.notify_all();
  return ended;
}

bool MotionHold::waitForResume(uint64_t resumes, const JobHold::Cancelled& cancelled)
{
  std::unique_lock<std::mutex> lock(mutex_);
  while (resumes_ == resumes)
  {
    lock.unlock();
    if (cancelled())
    {
      return false;
    }
    lock.lock();
    // A cancel comes without a notification: look again at least every poll period.
    resumed_.wait_for(lock, cancel_poll_, [&] { return resumes_ != resumes; });
  }
  return true;
}
}  // namespace cnc_bridge
