// The process's time zone (TZ) set for the life of a test, and the previous one restored after
// it, so that local-time arithmetic is checked in a zone the test chooses and not the machine's.
#pragma once

#include <cstdlib>
#include <ctime>
#include <optional>
#include <string>

namespace cnc_bridge
{
namespace test
{
class ScopedTimeZone
{
 public:
  /// \param tz a POSIX TZ string, e.g. "UTC0" or "CET-1CEST,M3.5.0,M10.5.0/3".
  explicit ScopedTimeZone(const char* tz)
  {
    if (const char* previous = std::getenv("TZ"))
    {
      previous_ = previous;
    }
    ::setenv("TZ", tz, 1);
    ::tzset();
  }
  ~ScopedTimeZone()
  {
    if (previous_)
    {
      ::setenv("TZ", previous_->c_str(), 1);
    }
    else
    {
      ::unsetenv("TZ");
    }
    ::tzset();
  }
  ScopedTimeZone(const ScopedTimeZone&) = delete;
  ScopedTimeZone& operator=(const ScopedTimeZone&) = delete;

 private:
  std::optional<std::string> previous_;
};
}  // namespace test
}  // namespace cnc_bridge
