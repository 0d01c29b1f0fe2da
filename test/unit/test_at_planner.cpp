// The trajectory planner: per-axis speed and acceleration limits at every 1 ms sample (corners
// included), the end point exact in pulses, the total time consistent with the feed, and a cancel
// that decelerates along the path without a jump.
#include <gtest/gtest.h>

#include <cmath>

#include "cnc_bridge/at_protocol/planner.h"
#include "cnc_bridge/common/error.h"

using namespace cnc_bridge;
using namespace cnc_bridge::at_protocol;

namespace
{
Vec3 mm(double x, double y, double z)
{
  return {x * kPulsesPerMm, y * kPulsesPerMm, z * kPulsesPerMm};
}

/// Every sample of the trajectory from t = 0 to the end, one per period.
std::vector<Sample> samples(const Trajectory& t)
{
  std::vector<Sample> out{t.at(0.0)};
  for (size_t k = 1; k <= t.steps(); ++k)
  {
    out.push_back(t.step(k));
  }
  return out;
}

/// Asserts the speed and acceleration limits between consecutive samples (exact derivatives).
void expectWithinLimits(const std::vector<Sample>& s, const PlannerLimits& limits)
{
  const double dt = limits.period;
  double worst_accel_ratio = 0.0;
  for (size_t k = 0; k < s.size(); ++k)
  {
    for (int i = 0; i < 3; ++i)
    {
      const double v_max = limits.max_speed[i] * kPulsesPerMm;
      ASSERT_LE(std::fabs(s[k].velocity[i]), v_max * (1 + 1e-9)) << "axis " << i << " sample " << k;
      if (k > 0)
      {
        const double a = std::fabs(s[k].velocity[i] - s[k - 1].velocity[i]) / dt;
        const double a_max = limits.max_accel[i] * kPulsesPerMm;
        worst_accel_ratio = std::max(worst_accel_ratio, a / a_max);
        ASSERT_LE(a, a_max * (1 + 1e-6)) << "axis " << i << " sample " << k;
        // No jump in position either: at most the top speed for one period.
        ASSERT_LE(std::fabs(s[k].position[i] - s[k - 1].position[i]), v_max * dt * (1 + 1e-9) + 1e-6);
      }
    }
  }
  EXPECT_GT(worst_accel_ratio, 0.5);  // the planner does use its acceleration
}
}  // namespace

TEST(AtPlanner, StraightLineTimeMatchesFeedAndAcceleration)
{
  PlannerLimits limits;  // X: 50 mm/s, 500 mm/s^2; the path may use 80 % of it between corners
  const Trajectory t({mm(0, 0, 0), mm(100, 0, 0)}, 20.0, limits);
  // Trapezoid from rest to rest: L/F + F/a with a = 0.8 * 500 mm/s^2.
  const double a = (1.0 - limits.corner_share) * 500.0;
  EXPECT_NEAR(t.duration(), 100.0 / 20.0 + 20.0 / a, 1e-9);
  EXPECT_EQ(t.steps(), 5050u);
  EXPECT_NEAR(t.length(), 100000.0, 1e-9);
  // Cruise at the feed: 20 mm/s of X's 50 mm/s is feed value 102 (255 * 0.4).
  const Setpoint cruise = t.toSetpoint(t.at(2.5));
  EXPECT_EQ(cruise.feed, (std::array<int, 3>{102, 0, 0}));
  EXPECT_NEAR(t.at(2.5).path_speed, 20000.0, 1e-6);
  expectWithinLimits(samples(t), limits);
}

TEST(AtPlanner, EndPointIsExactInPulsesAndAtRest)
{
  PlannerLimits limits;
  const Trajectory t({mm(0, 0, 0), {12345, -6789, 1011}, {-3, 77777, -22222}}, 33.3, limits);
  const Setpoint last = t.toSetpoint(t.step(t.steps()));
  EXPECT_EQ(last.position, (std::array<int32_t, 3>{-3, 77777, -22222}));
  EXPECT_EQ(last.feed, (std::array<int, 3>{0, 0, 0}));
  const Setpoint second_last = t.toSetpoint(t.step(t.steps() - 1));
  for (int i = 0; i < 3; ++i)
  {
    EXPECT_LE(std::abs(second_last.position[i] - last.position[i]), 2);
  }
}

TEST(AtPlanner, AxisLimitsHoldOnDiagonalsAndCorners)
{
  PlannerLimits limits;
  limits.max_speed = {40.0, 30.0, 10.0};
  limits.max_accel = {400.0, 300.0, 100.0};
  // A zigzag with 90 and 135 degree corners, a plunge and a 3-D diagonal.
  const Trajectory t(
      {mm(0, 0, 0), mm(20, 0, 0), mm(20, 15, 0), mm(0, 30, 0), mm(0, 30, -5), mm(10, 40, -10), mm(10, 40, -10)}, 100.0,
      limits);
  expectWithinLimits(samples(t), limits);
  // The X-only first segment is capped at X's 40 mm/s, though 100 mm/s was asked; the diagonal
  // (-0.8, 0.6) may go 50 mm/s along the path: 40 mm/s in X, 30 mm/s in Y, both at their limits.
  EXPECT_NEAR(t.segments()[0].v_cruise, 40000.0, 1e-6);
  EXPECT_NEAR(t.segments()[2].v_cruise, 50000.0, 1e-6);
}

TEST(AtPlanner, GentleCornersOfAnArcAreNotFullStops)
{
  PlannerLimits limits;
  std::vector<Vec3> arc;
  const double r = 20.0;
  for (int k = 0; k <= 180; ++k)  // a half circle in 1 degree chords
  {
    const double angle = M_PI * k / 180.0;
    arc.push_back(mm(r * std::cos(angle), r * std::sin(angle), 0));
  }
  const double feed = 10.0;
  const Trajectory t(arc, feed, limits);
  expectWithinLimits(samples(t), limits);
  // Stopping at 180 corners would take far longer than the length at the feed.
  EXPECT_LT(t.duration(), t.length() / kPulsesPerMm / feed * 1.2);
  EXPECT_GT(t.duration(), t.length() / kPulsesPerMm / feed);
}

TEST(AtPlanner, ShortSegmentNeverReachesTheFeed)
{
  PlannerLimits limits;
  const Trajectory t({mm(0, 0, 0), mm(0, 0.5, 0)}, 50.0, limits);
  // Triangle: peak speed sqrt(a L), time 2 sqrt(L / a), a = 400 mm/s^2, L = 0.5 mm.
  EXPECT_NEAR(t.duration(), 2.0 * std::sqrt(0.5 / 400.0), 1e-9);
  expectWithinLimits(samples(t), limits);
}

TEST(AtPlanner, StopDeceleratesAlongThePathWithoutAJump)
{
  PlannerLimits limits;
  const Trajectory t({mm(0, 0, 0), mm(50, 0, 0), mm(50, 50, 0)}, 40.0, limits);
  TrajectoryStream stream(t);
  Setpoint setpoint;
  std::vector<Sample> seen{t.at(0.0)};
  for (int k = 0; k < 600; ++k)  // into the cruise on the first segment
  {
    ASSERT_TRUE(stream.next(setpoint));
    seen.push_back(stream.current());
  }
  const double speed_at_cancel = stream.current().path_speed;
  ASSERT_NEAR(speed_at_cancel, 40000.0, 1e-6);
  stream.stop();
  while (stream.next(setpoint))
  {
    seen.push_back(stream.current());
    ASSERT_LE(stream.current().path_speed, seen[seen.size() - 2].path_speed + 1e-6);  // only slows down
  }
  expectWithinLimits(seen, limits);
  // v^2 / 2a with a = 400 mm/s^2: 2 mm, i.e. about 0.1 s; stopped well before the corner at 50 mm.
  const double stop_distance = seen.back().distance;  // the ramp counts from where it starts
  EXPECT_NEAR(stop_distance, 40000.0 * 40000.0 / (2 * 400000.0), 50.0);
  EXPECT_EQ(setpoint.feed, (std::array<int, 3>{0, 0, 0}));
  EXPECT_LT(setpoint.position[0], 50000);
  EXPECT_EQ(setpoint.position[1], 0);
  EXPECT_LT(stream.sent(), t.steps());
  EXPECT_EQ(stream.total(), stream.sent());
}

TEST(AtPlanner, StopJustBeforeACornerSlowsThroughItWithinLimits)
{
  PlannerLimits limits;
  const Trajectory t({mm(0, 0, 0), mm(30, 0, 0), mm(30, 30, 0)}, 40.0, limits);
  // The plan itself slows for the corner; cancel shortly before it.
  const size_t cancel_at = static_cast<size_t>((t.segments()[0].t_accel + t.segments()[0].t_cruise) / 0.001) - 5;
  TrajectoryStream stream(t);
  Setpoint setpoint;
  std::vector<Sample> seen{t.at(0.0)};
  for (size_t k = 0; k < cancel_at; ++k)
  {
    ASSERT_TRUE(stream.next(setpoint));
    seen.push_back(stream.current());
  }
  stream.stop();
  while (stream.next(setpoint))
  {
    seen.push_back(stream.current());
  }
  expectWithinLimits(seen, limits);
  EXPECT_EQ(seen.back().path_speed, 0.0);
}

TEST(AtPlanner, StopBeforeTheFirstStepOrAfterTheLastIsEmpty)
{
  PlannerLimits limits;
  const Trajectory t({mm(0, 0, 0), mm(1, 0, 0)}, 10.0, limits);
  TrajectoryStream early(t);
  early.stop();
  Setpoint setpoint;
  EXPECT_FALSE(early.next(setpoint));
  TrajectoryStream late(t);
  while (late.next(setpoint))
  {
  }
  late.stop();
  EXPECT_FALSE(late.next(setpoint));
  EXPECT_EQ(setpoint.position[0], 1000);
}

TEST(AtPlanner, InvalidInputIsRefused)
{
  PlannerLimits limits;
  EXPECT_THROW(Trajectory({}, 10.0, limits), ConfigError);
  EXPECT_THROW(Trajectory({mm(0, 0, 0), mm(1, 0, 0)}, 0.0, limits), ConfigError);
  EXPECT_THROW(Trajectory({mm(0, 0, 0), {NAN, 0, 0}}, 10.0, limits), ConfigError);
  limits.max_accel[1] = 0.0;
  EXPECT_THROW(Trajectory({mm(0, 0, 0), mm(1, 0, 0)}, 10.0, limits), ConfigError);
  PlannerLimits ok;
  const Trajectory point({mm(1, 2, 3)}, 10.0, ok);
  EXPECT_EQ(point.steps(), 0u);
  EXPECT_EQ(point.length(), 0.0);
}

TEST(AtPlanner, FeedPerSegmentAsAProgramsFWordsChange)
{
  PlannerLimits limits;
  const Trajectory t({mm(0, 0, 0), mm(20, 0, 0), mm(20, 20, 0)}, std::vector<double>{10.0, 40.0}, limits);
  EXPECT_NEAR(t.segments()[0].v_cruise, 10000.0, 1e-6);
  EXPECT_NEAR(t.segments()[1].v_cruise, 40000.0, 1e-6);
  expectWithinLimits(samples(t), limits);
  EXPECT_THROW(Trajectory({mm(0, 0, 0), mm(1, 0, 0)}, std::vector<double>{10.0, 10.0}, limits), ConfigError);
  EXPECT_THROW(Trajectory({mm(0, 0, 0), mm(1, 0, 0)}, std::vector<double>{-1.0}, limits), ConfigError);
}
