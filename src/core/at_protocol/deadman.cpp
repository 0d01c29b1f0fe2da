// The renew-or-expire rule of a jog's deadman and its timer thread (see deadman.h).
#include "cnc_bridge/at_protocol/deadman.h"

#include <cmath>
#include <sstream>
#include <utility>

#include "cnc_bridge/common/error.h"

namespace cnc_bridge
{
namespace at_protocol
{
Deadman::Deadman(double timeout_s)
{
  if (!(timeout_s >= 0.0) || !std::isfinite(timeout_s))
  {
    throw ConfigError("deadman timeout must be 0 (off) or a positive number of seconds, not " +
                      std::to_string(timeout_s));
  }
  timeout_ = std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(timeout_s));
}

void Deadman::renew(Clock::time_point now)
{
  if (!enabled())
  {
    return;
  }
  std::lock_guard<std::mutex> lock(mutex_);
  armed_ = true;
  deadline_ = now + timeout_;
}

void Deadman::disarm()
{
  std::lock_guard<std::mutex> lock(mutex_);
  armed_ = false;
}

bool Deadman::armed() const
{
  std::lock_guard<std::mutex> lock(mutex_);
  return armed_;
}

bool Deadman::expire(Clock::time_point now, Clock::duration* remaining)
{
  std::lock_guard<std::mutex> lock(mutex_);
  if (armed_ && now >= deadline_)
  {
    armed_ = false;
    if (remaining)
    {
      *remaining = Clock::duration::zero();
    }
    return true;
  }
  if (remaining)
  {
    *remaining = armed_ ? deadline_ - now : Clock::duration::zero();
  }
  return false;
}

std::string Deadman::describe(const std::string& what) const
{
  std::ostringstream text;
  text << "no " << what << " for " << std::chrono::duration<double>(timeout_).count() << " s";
  return text.str();
}

DeadmanTimer::DeadmanTimer(Check check) : check_(std::move(check)) {}

DeadmanTimer::~DeadmanTimer()
{
  stop();
}

void DeadmanTimer::start()
{
  std::lock_guard<std::mutex> lock(mutex_);
  if (!thread_.joinable() && !stopping_)
  {
    thread_ = std::thread([this] { run(); });
  }
}

void DeadmanTimer::stop()
{
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stopping_ = true;
  }
  changed_.notify_all();
  if (thread_.joinable())
  {
    thread_.join();
  }
}

void DeadmanTimer::poke()
{
  {
    std::lock_guard<std::mutex> lock(mutex_);
    poked_ = true;
  }
  changed_.notify_all();
}

void DeadmanTimer::run()
{
  std::unique_lock<std::mutex> lock(mutex_);
  while (!stopping_)
  {
    poked_ = false;  // a poke from here on checks again
    lock.unlock();
    const Deadman::Clock::duration wait = check_();
    lock.lock();
    const auto woken = [this] { return poked_ || stopping_; };
    if (wait > Deadman::Clock::duration::zero())
    {
      // wait_for measures on the steady clock (libstdc++ waits with CLOCK_MONOTONIC).
      changed_.wait_for(lock, wait, woken);
    }
    else
    {
      changed_.wait(lock, woken);
    }
  }
}
}  // namespace at_protocol
}  // namespace cnc_bridge
