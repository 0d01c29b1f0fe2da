// DailyTimer (share_node's ~withdraw_at) on a clock the test moves: the action runs when the local
// clock reaches the time of day and not a second before, then on the next date; a clock set back
// after a run does not run it twice; without a recheck the timer finds the time by itself at its
// next look at the clock; an action that throws does not stop it. Time zone: UTC (TZ=UTC0).
#include <gtest/gtest.h>

#include <atomic>
#include <condition_variable>
#include <cstdlib>
#include <ctime>
#include <memory>
#include <mutex>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include "cnc_bridge/programs/daily_timer.h"
#include "scoped_time_zone.h"

using namespace cnc_bridge::programs;

namespace
{
class TestClock : public WallClock
{
 public:
  explicit TestClock(std::time_t start) : now_(start) {}
  std::time_t now() const override { return now_.load(); }
  void set(std::time_t when) { now_ = when; }

 private:
  std::atomic<std::time_t> now_;
};

/// Seconds since the epoch of a UTC date and time.
std::time_t utc(int year, int month, int day, int hour, int minute, int second = 0)
{
  std::tm t{};
  t.tm_year = year - 1900;
  t.tm_mon = month - 1;
  t.tm_mday = day;
  t.tm_hour = hour;
  t.tm_min = minute;
  t.tm_sec = second;
  return ::timegm(&t);
}

class DailyTimerTest : public ::testing::Test
{
 protected:
  /// The action: counts its runs and wakes waitForRuns().
  DailyTimer::Action counting()
  {
    return [this]
    {
      std::lock_guard<std::mutex> lock(mutex_);
      ++runs_;
      ran_.notify_all();
    };
  }
  bool waitForRuns(int runs)
  {
    std::unique_lock<std::mutex> lock(mutex_);
    return ran_.wait_for(lock, std::chrono::seconds(10), [&] { return runs_ >= runs; });
  }

  const cnc_bridge::test::ScopedTimeZone time_zone_{"UTC0"};
  std::mutex mutex_;
  std::condition_variable ran_;
  int runs_ = 0;
  const DailyTime six_pm_{18, 0};
};
}  // namespace

TEST_F(DailyTimerTest, RunsWhenTheClockReachesTheTimeThenOnTheNextDate)
{
  auto clock = std::make_shared<TestClock>(utc(2026, 11, 27, 17, 59));
  std::vector<std::time_t> scheduled;
  DailyTimer timer(
      six_pm_, counting(), [&](std::time_t next) { scheduled.push_back(next); }, clock);
  EXPECT_EQ(timer.next(), utc(2026, 11, 27, 18, 0));

  clock->set(utc(2026, 11, 27, 17, 59, 59));
  timer.recheck();
  EXPECT_EQ(timer.runs(), 0u);  // a second early: not yet

  clock->set(utc(2026, 11, 27, 18, 0));
  timer.recheck();  // returns once the action has run
  EXPECT_EQ(timer.runs(), 1u);
  EXPECT_EQ(runs_, 1);
  EXPECT_EQ(timer.next(), utc(2026, 11, 28, 18, 0));
  ASSERT_EQ(scheduled.size(), 2u);
  EXPECT_EQ(scheduled[0], utc(2026, 11, 27, 18, 0));
  EXPECT_EQ(scheduled[1], utc(2026, 11, 28, 18, 0));

  clock->set(utc(2026, 11, 28, 18, 0, 1));  // the next day, a second after: once more
  timer.recheck();
  EXPECT_EQ(timer.runs(), 2u);
  EXPECT_EQ(timer.next(), utc(2026, 11, 29, 18, 0));
}

TEST_F(DailyTimerTest, StartedAfterTheTimeWaitsForTheNextDay)
{
  auto clock = std::make_shared<TestClock>(utc(2026, 12, 31, 18, 0, 1));
  DailyTimer timer(six_pm_, counting(), nullptr, clock);
  timer.recheck();
  EXPECT_EQ(timer.runs(), 0u);
  EXPECT_EQ(timer.next(), utc(2027, 1, 1, 18, 0));  // across the year end
}

TEST_F(DailyTimerTest, AClockSetBackAfterARunDoesNotRunItTwice)
{
  auto clock = std::make_shared<TestClock>(utc(2026, 11, 27, 12, 0));
  DailyTimer timer(six_pm_, counting(), nullptr, clock);
  clock->set(utc(2026, 11, 27, 18, 0, 30));
  timer.recheck();
  EXPECT_EQ(timer.runs(), 1u);
  clock->set(utc(2026, 11, 27, 17, 59, 50));  // set back (a time server's correction)
  timer.recheck();
  clock->set(utc(2026, 11, 27, 18, 0, 10));
  timer.recheck();
  EXPECT_EQ(timer.runs(), 1u);
  EXPECT_EQ(timer.next(), utc(2026, 11, 28, 18, 0));
}

TEST_F(DailyTimerTest, FindsTheTimeByItselfAtItsNextLookAtTheClock)
{
  auto clock = std::make_shared<TestClock>(utc(2026, 11, 27, 17, 0));
  DailyTimer timer(six_pm_, counting(), nullptr, clock, std::chrono::milliseconds(20));
  clock->set(utc(2026, 11, 27, 18, 5));  // no recheck(): the timer's own wait ends
  ASSERT_TRUE(waitForRuns(1));
  timer.recheck();  // returns once the thread is past the run (its count and next time set)
  EXPECT_EQ(timer.runs(), 1u);
  EXPECT_EQ(timer.next(), utc(2026, 11, 28, 18, 0));
}

TEST_F(DailyTimerTest, AnActionThatThrowsDoesNotStopTheTimer)
{
  auto clock = std::make_shared<TestClock>(utc(2026, 11, 27, 17, 0));
  int calls = 0;
  DailyTimer timer(
      six_pm_,
      [&]
      {
        ++calls;
        throw std::runtime_error("share gone");
      },
      nullptr, clock);
  clock->set(utc(2026, 11, 27, 18, 0));
  timer.recheck();
  clock->set(utc(2026, 11, 28, 18, 0));
  timer.recheck();
  EXPECT_EQ(calls, 2);
  EXPECT_EQ(timer.runs(), 2u);
  EXPECT_EQ(timer.next(), utc(2026, 11, 29, 18, 0));
}
