// ~withdraw_at's schedule on a fixed clock: the next HH:MM after now, across midnight and the year
// end, on the days clocks go forward (23 h) and back (25 h, the repeated hour run once), and the
// parser's refusals. The time zone is a POSIX TZ rule (central Europe), so no tz database is needed.
#include <gtest/gtest.h>

#include <cstdlib>
#include <ctime>

#include "cnc_bridge/common/error.h"
#include "cnc_bridge/programs/daily_time.h"
#include "scoped_time_zone.h"

using namespace cnc_bridge;
using namespace cnc_bridge::programs;

namespace
{
class DailyTimeTest : public ::testing::Test
{
 protected:
  /// A local time; \p dst -1 lets mktime choose, 0/1 picks one of a repeated hour.
  static std::time_t local(int year, int month, int day, int hour, int minute, int dst = -1)
  {
    std::tm t{};
    t.tm_year = year - 1900;
    t.tm_mon = month - 1;
    t.tm_mday = day;
    t.tm_hour = hour;
    t.tm_min = minute;
    t.tm_isdst = dst;
    return std::mktime(&t);
  }

  // 2026: CEST from 29 March 02:00 to 25 October 03:00.
  const cnc_bridge::test::ScopedTimeZone time_zone_{"CET-1CEST,M3.5.0,M10.5.0/3"};
};

DailyTime at(const std::string& text)
{
  return *DailyTime::parse(text, "~withdraw_at");
}
}  // namespace

TEST_F(DailyTimeTest, LaterTodayOrTomorrow)
{
  EXPECT_EQ(nextDailyTime(at("18:00"), local(2026, 6, 10, 12, 0)), local(2026, 6, 10, 18, 0));
  EXPECT_EQ(nextDailyTime(at("18:00"), local(2026, 6, 10, 18, 0)), local(2026, 6, 11, 18, 0));  // strictly after
  EXPECT_EQ(nextDailyTime(at("18:00"), local(2026, 6, 10, 17, 59) + 59), local(2026, 6, 10, 18, 0));
  EXPECT_EQ(nextDailyTime(at("0:15"), local(2026, 6, 10, 23, 30)), local(2026, 6, 11, 0, 15));        // midnight
  EXPECT_EQ(nextDailyTime(at("00:00"), local(2026, 12, 31, 23, 59)), local(2027, 1, 1, 0, 0));        // year end
  EXPECT_EQ(nextDailyTime(at("06:00"), local(2026, 2, 28, 7, 0)), local(2026, 3, 1, 6, 0));           // month end
  EXPECT_EQ(nextDailyTime(at("18:00"), local(2026, 6, 10, 12, 0), true), local(2026, 6, 11, 18, 0));  // done today
}

TEST_F(DailyTimeTest, DaylightSavingChanges)
{
  // Clocks forward on 29 March: from 18:00 to 18:00 is 23 h; back on 25 October: 25 h.
  EXPECT_EQ(nextDailyTime(at("18:00"), local(2026, 3, 28, 18, 0)) - local(2026, 3, 28, 18, 0), 23 * 3600);
  EXPECT_EQ(nextDailyTime(at("18:00"), local(2026, 10, 24, 18, 0)) - local(2026, 10, 24, 18, 0), 25 * 3600);
  // 02:30 does not exist on 29 March: it comes when the clock has passed it, 03:30 CEST.
  EXPECT_EQ(nextDailyTime(at("02:30"), local(2026, 3, 29, 1, 0)), local(2026, 3, 29, 3, 30));
  // 02:30 comes twice on 25 October: once, then not again until the next day.
  const std::time_t first = nextDailyTime(at("02:30"), local(2026, 10, 25, 1, 0));
  EXPECT_TRUE(first == local(2026, 10, 25, 2, 30, 1) || first == local(2026, 10, 25, 2, 30, 0));
  EXPECT_EQ(nextDailyTime(at("02:30"), first, true), local(2026, 10, 26, 2, 30));
}

TEST_F(DailyTimeTest, ParsesHoursAndMinutesAndRefusesTheRest)
{
  EXPECT_FALSE(DailyTime::parse("", "~withdraw_at").has_value());
  EXPECT_EQ(at("7:05").str(), "07:05");
  EXPECT_EQ(at("23:59").hour, 23);
  EXPECT_EQ(at("23:59").minute, 59);
  for (const char* bad : {"24:00", "12:60", "noon", "12:5", "12:05:00", " 12:05", "-1:00", "12h05"})
    EXPECT_THROW(DailyTime::parse(bad, "~withdraw_at"), ConfigError) << bad;
  try
  {
    DailyTime::parse("25:00", "~withdraw_at");
  }
  catch (const ConfigError& e)
  {
    EXPECT_NE(std::string(e.what()).find("~withdraw_at \"25:00\""), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("HH:MM"), std::string::npos) << e.what();
  }
}
