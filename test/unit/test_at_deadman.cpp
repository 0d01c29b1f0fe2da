// The jog deadman's rule on a clock the test sets: a renewal lasts the timeout, renewing pushes
// the expiry out, the expiry is reported once, and a timeout of 0 never arms. Its timer thread:
// checks at start, on a poke and once the time a check asked for has passed (waited on with a
// deadline, not slept).
#include <gtest/gtest.h>

#include <cmath>
#include <condition_variable>
#include <mutex>
#include <vector>

#include "cnc_bridge/at_protocol/deadman.h"
#include "cnc_bridge/common/error.h"

using namespace cnc_bridge;
using namespace cnc_bridge::at_protocol;
using namespace std::chrono_literals;

TEST(AtDeadman, ExpiresOnceTheTimeoutAfterTheLastRenewal)
{
  Deadman deadman(0.5);
  const auto t0 = Deadman::Clock::time_point{} + 100s;
  EXPECT_FALSE(deadman.expire(t0 + 10s));  // never armed: nothing to expire
  deadman.renew(t0);
  EXPECT_TRUE(deadman.armed());
  Deadman::Clock::duration remaining{};
  EXPECT_FALSE(deadman.expire(t0 + 499ms, &remaining));
  EXPECT_EQ(remaining, 1ms);
  EXPECT_TRUE(deadman.expire(t0 + 500ms));
  EXPECT_FALSE(deadman.armed());
  EXPECT_FALSE(deadman.expire(t0 + 600ms, &remaining));  // reported once
  EXPECT_EQ(remaining, Deadman::Clock::duration::zero());
}

TEST(AtDeadman, RenewingKeepsItAliveAsLongAsTheCommandsComeInTime)
{
  Deadman deadman(0.5);
  const auto t0 = Deadman::Clock::time_point{} + 100s;
  // A client at 10 Hz for 2 s: never expires, though 2 s is four timeouts.
  for (int k = 0; k <= 20; ++k)
  {
    deadman.renew(t0 + k * 100ms);
    EXPECT_FALSE(deadman.expire(t0 + k * 100ms + 99ms)) << k;
  }
  const auto last = t0 + 2000ms;
  EXPECT_FALSE(deadman.expire(last + 499ms));
  EXPECT_TRUE(deadman.expire(last + 500ms));
}

TEST(AtDeadman, DisarmedOrDisabledNeverExpires)
{
  Deadman deadman(0.5);
  const auto t0 = Deadman::Clock::time_point{} + 100s;
  deadman.renew(t0);
  deadman.disarm();
  EXPECT_FALSE(deadman.expire(t0 + 10s));

  Deadman off(0.0);
  EXPECT_FALSE(off.enabled());
  off.renew(t0);
  EXPECT_FALSE(off.armed());
  EXPECT_FALSE(off.expire(t0 + 1000s));
}

TEST(AtDeadman, DescribesItsTimeoutAndRefusesANegativeOne)
{
  EXPECT_EQ(Deadman(0.5).describe("jog command"), "no jog command for 0.5 s");
  EXPECT_THROW(Deadman(-1.0), ConfigError);
  EXPECT_THROW(Deadman(std::nan("")), ConfigError);
}

TEST(AtDeadman, TheTimerChecksAtStartOnAPokeAndWhenTheTimeACheckAskedForHasPassed)
{
  std::mutex mutex;
  std::condition_variable checked;
  std::vector<Deadman::Clock::time_point> checks;
  Deadman::Clock::duration next = Deadman::Clock::duration::zero();  // what the next check returns
  DeadmanTimer timer(
      [&]
      {
        std::lock_guard<std::mutex> lock(mutex);
        checks.push_back(Deadman::Clock::now());
        const Deadman::Clock::duration wait = next;
        next = Deadman::Clock::duration::zero();
        checked.notify_all();
        return wait;
      });
  std::unique_lock<std::mutex> lock(mutex);
  timer.start();
  ASSERT_TRUE(checked.wait_for(lock, 10s, [&] { return checks.size() == 1; }));  // at start; zero: until a poke
  next = 50ms;
  timer.poke();
  ASSERT_TRUE(checked.wait_for(lock, 10s, [&] { return checks.size() == 2; }));  // the poke
  ASSERT_TRUE(checked.wait_for(lock, 10s, [&] { return checks.size() == 3; }));  // 50 ms later
  EXPECT_GE(checks[2] - checks[1], 50ms);
  lock.unlock();
  timer.stop();
  EXPECT_EQ(checks.size(), 3u);  // the last check returned zero and nothing poked it since
}
