// A time of day something is done every day (share_node's ~withdraw_at), in the local time zone,
// and when it next comes: across midnight, month and year ends and daylight saving changes.
#pragma once

#include <ctime>
#include <optional>
#include <string>

namespace cnc_bridge::programs
{
/// \brief A local time of day, "HH:MM" (24 h).
struct DailyTime
{
  int hour = 0;
  int minute = 0;

  /// \brief Parses "HH:MM" or "H:MM" (00:00 to 23:59); "" is none. Anything else throws a
  /// ConfigError naming \p what (the parameter or option) and the expected form.
  static std::optional<DailyTime> parse(const std::string& text, const std::string& what);
  std::string str() const;  ///< "HH:MM"
};

/// \brief The first time after \p now (strictly) at which the local clock (TZ) reads \p at, on
/// the local date of \p now or a later one; with \p done_today, not before the next date (so
/// that the hour repeated when clocks go back does not run it twice). A time the clocks skip
/// that day (clocks going forward) comes when the clock has passed it: as mktime(3) normalises
/// it (02:30 on a day 02:00 becomes 03:00 is 03:30).
std::time_t nextDailyTime(const DailyTime& at, std::time_t now, bool done_today = false);
}  // namespace cnc_bridge::programs
