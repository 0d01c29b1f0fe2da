#include "cnc_bridge/programs/daily_timer.h"

#include <algorithm>
#include <exception>
#include <utility>

#include "cnc_bridge/common/log.h"

namespace cnc_bridge::programs
{
namespace
{
class SystemClock : public WallClock
{
 public:
  std::time_t now() const override { return std::time(nullptr); }
};
}  // namespace

std::shared_ptr<const WallClock> WallClock::system()
{
  static const auto kClock = std::make_shared<const SystemClock>();
  return kClock;
}

DailyTimer::DailyTimer(DailyTime at, Action action, Scheduled scheduled, std::shared_ptr<const WallClock> clock,
                       std::chrono::milliseconds recheck)
    : at_(at),
      action_(std::move(action)),
      scheduled_(std::move(scheduled)),
      clock_(std::move(clock)),
      recheck_(std::max(recheck, std::chrono::milliseconds(1))),
      next_(nextDailyTime(at_, clock_->now()))
{
  if (scheduled_)
    scheduled_(next_);
  thread_ = std::thread([this] { loop(); });
}

DailyTimer::~DailyTimer()
{
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stop_ = true;
  }
  wake_.notify_all();
  checked_.notify_all();
  thread_.join();
}

std::time_t DailyTimer::next() const
{
  std::lock_guard<std::mutex> lock(mutex_);
  return next_;
}

uint64_t DailyTimer::runs() const
{
  std::lock_guard<std::mutex> lock(mutex_);
  return runs_;
}

void DailyTimer::recheck()
{
  std::unique_lock<std::mutex> lock(mutex_);
  const uint64_t wanted = ++requested_;
  wake_.notify_all();
  checked_.wait(lock, [&] { return served_ >= wanted || stop_; });
}

void DailyTimer::loop()
{
  std::unique_lock<std::mutex> lock(mutex_);
  while (!stop_)
  {
    const uint64_t serving = requested_;
    if (clock_->now() >= next_)
    {
      lock.unlock();
      try
      {
        action_();
      }
      catch (const std::exception& e)
      {
        CNC_LOG_ERROR("the action at " << at_.str() << " failed: " << e.what());
      }
      const std::time_t next = nextDailyTime(at_, clock_->now(), true);
      if (scheduled_)
        scheduled_(next);
      lock.lock();
      next_ = next;
      ++runs_;
    }
    served_ = serving;
    checked_.notify_all();
    // Whole seconds to the time, at most recheck_: a clock changed meanwhile is seen at the next look.
    const auto until_next = std::chrono::seconds(std::max<std::time_t>(0, next_ - clock_->now()));
    const auto wait = std::min<std::chrono::milliseconds>(
        std::max<std::chrono::milliseconds>(until_next, std::chrono::milliseconds(1)), recheck_);
    wake_.wait_for(lock, wait, [&] { return stop_ || requested_ != served_; });
  }
}
}  // namespace cnc_bridge::programs
