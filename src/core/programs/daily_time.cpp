#include "cnc_bridge/programs/daily_time.h"

#include <cstdio>
#include <regex>

#include "cnc_bridge/common/error.h"

namespace cnc_bridge::programs
{
std::optional<DailyTime> DailyTime::parse(const std::string& text, const std::string& what)
{
  if (text.empty())
    return std::nullopt;
  static const std::regex kForm("([0-9]{1,2}):([0-9]{2})");
  std::smatch match;
  DailyTime time;
  if (std::regex_match(text, match, kForm))
  {
    time.hour = std::stoi(match[1]);
    time.minute = std::stoi(match[2]);
    if (time.hour < 24 && time.minute < 60)
      return time;
  }
  throw ConfigError(what + " \"" + text +
                    "\" is not a time of day: give HH:MM, 00:00 to 23:59 (local time), or "
                    "\"\" for never");
}

std::string DailyTime::str() const
{
  char text[8];
  std::snprintf(text, sizeof text, "%02d:%02d", hour, minute);
  return text;
}

std::time_t nextDailyTime(const DailyTime& at, std::time_t now, bool done_today)
{
  std::tm today{};
  ::localtime_r(&now, &today);
  // Dates are counted on a struct tm and normalised by mktime, which also picks the UTC offset in
  // force on that date and time (tm_isdst = -1): a day is not always 24 h.
  for (int day = done_today ? 1 : 0;; ++day)
  {
    std::tm candidate{};
    candidate.tm_year = today.tm_year;
    candidate.tm_mon = today.tm_mon;
    candidate.tm_mday = today.tm_mday + day;
    candidate.tm_hour = at.hour;
    candidate.tm_min = at.minute;
    candidate.tm_isdst = -1;
    const std::time_t when = std::mktime(&candidate);
    if (when > now)
      return when;
  }
}
}  // namespace cnc_bridge::programs
