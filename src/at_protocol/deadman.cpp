// The renew-or-expire rule of a jog's deadman (see deadman.h).
#include "cnc_bridge/at_protocol/deadman.h"

#include <cmath>
#include <sstream>

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
}  // namespace at_protocol
}  // namespace cnc_bridge
