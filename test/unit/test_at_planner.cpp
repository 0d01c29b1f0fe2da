// The trajectory planner: per-axis speed and acceleration limits at every 1 ms sample (corners
// included), the end point exact in pulses, the total time consistent with the feed, and a cancel
// that decelerates along the path without a jump.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <iostream>
#include <limits>

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

// ---- S-curve (jerk-limited) profile ----

namespace
{
PlannerLimits scurveLimits()
{
  PlannerLimits limits;
  limits.profile = Profile::kSCurve;
  limits.max_jerk = {10000.0, 10000.0, 5000.0};
  return limits;
}

struct Streamed
{
  std::vector<Vec3> positions;  // pulses, the setpoints' exact (unrounded) positions, start first
  std::vector<Setpoint> setpoints;
};

// Streams \p stream to the end; calls stop() after \p stop_after setpoints (0: never).
Streamed stream(TrajectoryStream& s, size_t stop_after = 0)
{
  Streamed out;
  out.positions.push_back(s.current().position);
  Setpoint sp;
  while (s.next(sp))
  {
    out.positions.push_back(s.current().position);
    out.setpoints.push_back(sp);
    if (stop_after && out.setpoints.size() == stop_after)
    {
      s.stop();
    }
  }
  return out;
}

struct Ratios
{
  double speed = 0, accel = 0, jerk = 0;
};

// Worst ratio to the limits of the speed, acceleration and jerk of every axis, from the
// positions' differences (the start is at rest before the first setpoint).
Ratios worstRatios(const std::vector<Vec3>& p, const PlannerLimits& limits)
{
  Ratios r;
  const double dt = limits.period;
  std::vector<Vec3> ext{p.front(), p.front()};
  ext.insert(ext.end(), p.begin(), p.end());
  ext.push_back(p.back());
  ext.push_back(p.back());
  for (size_t k = 3; k < ext.size(); ++k)
  {
    for (int i = 0; i < 3; ++i)
    {
      const double v0 = (ext[k][i] - ext[k - 1][i]) / dt, v1 = (ext[k - 1][i] - ext[k - 2][i]) / dt,
                   v2 = (ext[k - 2][i] - ext[k - 3][i]) / dt;
      const double a0 = (v0 - v1) / dt, a1 = (v1 - v2) / dt;
      r.speed = std::max(r.speed, std::fabs(v0) / (limits.max_speed[i] * kPulsesPerMm));
      r.accel = std::max(r.accel, std::fabs(a0) / (limits.max_accel[i] * kPulsesPerMm));
      r.jerk = std::max(r.jerk, std::fabs(a0 - a1) / dt / (limits.max_jerk[i] * kPulsesPerMm));
    }
  }
  return r;
}
}  // namespace

TEST(AtPlannerSCurve, TimeOptimalReferenceMatchesTheClosedFormCases)
{
  // Long move: cruise at v; time L/v + v/a + a/j.
  EXPECT_NEAR(timeOptimalJerkLimited(100.0, 50.0, 500.0, 10000.0), 100.0 / 50 + 50.0 / 500 + 500.0 / 10000, 1e-12);
  // Short move where a is never reached (pure jerk): four phases of t with L = 2 j t^3.
  const double t = std::cbrt(0.001 / (2 * 10000.0));
  EXPECT_NEAR(timeOptimalJerkLimited(0.001, 50.0, 500.0, 10000.0), 4 * t, 1e-9);
  EXPECT_EQ(timeOptimalJerkLimited(0.0, 50, 500, 10000), 0.0);
}

TEST(AtPlannerSCurve, SpeedAccelerationAndJerkHoldOnRandomPaths)
{
  const PlannerLimits limits = scurveLimits();
  uint32_t state = 12345;
  auto rnd = [&state](double lo, double hi)
  {
    state = state * 1664525u + 1013904223u;
    return lo + (hi - lo) * (state >> 8) / double(1u << 24);
  };
  Ratios worst;
  for (int path = 0; path < 40; ++path)
  {
    std::vector<Vec3> points{{0, 0, 0}};
    std::vector<double> feeds;
    const int n = 2 + static_cast<int>(rnd(0, 12));
    for (int k = 0; k < n; ++k)
    {
      points.push_back({std::round(rnd(-40000, 40000)), std::round(rnd(-40000, 40000)), std::round(rnd(-5000, 5000))});
      feeds.push_back(rnd(1.0, 80.0));
    }
    TrajectoryStream s(Trajectory(points, feeds, limits));
    const Streamed out = stream(s);
    const Ratios r = worstRatios(out.positions, limits);
    SCOPED_TRACE(path);
    ASSERT_LE(r.speed, 1.0 + 1e-9);
    ASSERT_LE(r.accel, 1.0 + 1e-6);
    ASSERT_LE(r.jerk, 1.0 + 1e-6);
    EXPECT_EQ(
        out.setpoints.back().position,
        (std::array<int32_t, 3>{int32_t(points.back()[0]), int32_t(points.back()[1]), int32_t(points.back()[2])}));
    EXPECT_EQ(out.setpoints.back().feed, (std::array<int, 3>{0, 0, 0}));
    worst.accel = std::max(worst.accel, r.accel);
    worst.jerk = std::max(worst.jerk, r.jerk);
  }
  // The limits are used, not just respected.
  std::cout << "worst ratios over 40 random paths: acceleration " << worst.accel << ", jerk " << worst.jerk << "\n";
  EXPECT_GT(worst.accel, 0.5);
  EXPECT_GT(worst.jerk, 0.3);
}

TEST(AtPlannerSCurve, SingleSegmentTimeIsWithinAFactorOfTheTimeOptimalProfile)
{
  const PlannerLimits limits = scurveLimits();
  for (double length_mm : {0.5, 5.0, 20.0, 100.0, 500.0})
  {
    SCOPED_TRACE(length_mm);
    const double feed = 40.0;
    TrajectoryStream s(Trajectory({mm(0, 0, 0), mm(length_mm, 0, 0)}, feed, limits));
    const double ours = static_cast<double>(s.total()) * limits.period;
    const double best = timeOptimalJerkLimited(length_mm, feed, 500.0, 10000.0);
    // docs/at_controller_node.md: within 1.6x of the time-optimal double S (the factor is largest
    // on short moves, where the average's extra n - 1 periods weigh most).
    EXPECT_LE(ours / best, 1.6) << ours << " s vs " << best << " s";
    std::cout << length_mm << " mm at " << feed << " mm/s: S-curve " << ours << " s, time-optimal " << best
              << " s, ratio " << ours / best << "\n";
    EXPECT_GE(ours, best * (1 - 1e-9));
    const Streamed out = stream(s);
    EXPECT_EQ(out.setpoints.back().position[0], int32_t(length_mm * 1000));
  }
}

TEST(AtPlannerSCurve, ArcStaysWithinTheChordTolerance)
{
  // A circle of 20 mm radius as chords with a sagitta of 0.01 mm, as the G-code parser cuts it.
  const double r = 20000.0, tol = 10.0;  // pulses
  const int n = static_cast<int>(std::ceil(2 * M_PI / (2 * std::acos(1 - tol / r))));
  std::vector<Vec3> points;
  for (int k = 0; k <= n; ++k)
  {
    points.push_back({std::round(r * std::cos(2 * M_PI * k / n)), std::round(r * std::sin(2 * M_PI * k / n)), 0});
  }
  const PlannerLimits limits = scurveLimits();
  TrajectoryStream s(Trajectory(points, 30.0, limits));
  const Streamed out = stream(s);
  double worst = 0;
  for (const Vec3& p : out.positions)
  {
    worst = std::max(worst, std::fabs(std::hypot(p[0], p[1]) - r));
  }
  EXPECT_LE(worst, 2 * tol) << "pulses off the circle";
  std::cout << "S-curve on a chorded 20 mm circle: at most " << worst << " um off the circle, " << s.total()
            << " setpoints\n";
  const Ratios ratios = worstRatios(out.positions, limits);
  EXPECT_LE(ratios.jerk, 1.0 + 1e-6);
}

TEST(AtPlannerSCurve, CancelDeceleratesWithinTheLimitsAndStopsShortOfTheEnd)
{
  const PlannerLimits limits = scurveLimits();
  TrajectoryStream s(Trajectory({mm(0, 0, 0), mm(100, 0, 0), mm(100, 50, 0)}, 40.0, limits));
  const Streamed out = stream(s, 1500);  // at full speed along X
  const Ratios r = worstRatios(out.positions, limits);
  EXPECT_LE(r.speed, 1.0 + 1e-9);
  EXPECT_LE(r.accel, 1.0 + 1e-6);
  EXPECT_LE(r.jerk, 1.0 + 1e-6);
  EXPECT_LT(out.positions.back()[0], 100000.0);
  EXPECT_EQ(out.positions.back()[1], 0.0);
  EXPECT_EQ(out.setpoints.back().feed, (std::array<int, 3>{0, 0, 0}));
  // The stop takes the deceleration ramp plus the average's window, no more.
  EXPECT_LT(out.setpoints.size(), 1500u + 200u + limits.smoothingWindow());
}

// A path stopped part-way (as motion disabled mid-path stops it) goes on from rest: the rest of
// the path starts at the stop point, keeps every corner beyond it with its feed, and ends exactly
// on the path's end point; stop and restart together stay within the limits at every sample.
TEST(AtPlanner, TheRestOfAStoppedPathGoesOnFromTheStopPointToTheExactEnd)
{
  for (const PlannerLimits& limits : {PlannerLimits{}, scurveLimits()})
  {
    SCOPED_TRACE(limits.profile == Profile::kSCurve ? "scurve" : "trapezoid");
    const std::vector<Vec3> points{mm(0, 0, 0), mm(20, 0, 0), mm(20, 10, -1), mm(5, 10, -1)};
    const std::vector<double> feeds{40.0, 10.0, 25.0};
    TrajectoryStream first(Trajectory(points, feeds, limits));
    const Streamed before = stream(first, 400);  // stopped at speed on the first segment
    const Vec3 stop = before.positions.back();
    ASSERT_EQ(stop[1], 0.0);
    ASSERT_LT(stop[0], 20000.0);
    // Where it rests, along the path: the stop point's own distance from the start.
    EXPECT_NEAR(first.distance(), stop[0], 1.0);

    const PathRest rest = restOfPath(points, feeds, first.distance(), stop);
    ASSERT_EQ(rest.points.size(), 4u);
    EXPECT_EQ(rest.points[0], stop);
    EXPECT_EQ(rest.points[1], points[1]);
    EXPECT_EQ(rest.points[3], points[3]);
    EXPECT_EQ(rest.feeds, feeds);

    TrajectoryStream second(Trajectory(rest.points, rest.feeds, limits));  // from rest: entry speed 0
    const Streamed after = stream(second);
    EXPECT_EQ(after.setpoints.back().position, (std::array<int32_t, 3>{5000, 10000, -1000}));
    EXPECT_EQ(after.setpoints.back().feed, (std::array<int, 3>{0, 0, 0}));
    std::vector<Vec3> whole = before.positions;
    whole.insert(whole.end(), after.positions.begin() + 1, after.positions.end());
    const Ratios r = worstRatios(whole, limits);
    EXPECT_LE(r.speed, 1.0 + 1e-9);
    EXPECT_LE(r.accel, 1.0 + 1e-6);
    if (limits.profile == Profile::kSCurve)
    {
      EXPECT_LE(r.jerk, 1.0 + 1e-6);
    }
  }
}

TEST(AtPlanner, TheRestOfAPathStoppedAtACornerOrAtItsEnd)
{
  const std::vector<Vec3> points{mm(0, 0, 0), mm(20, 0, 0), mm(20, 10, 0)};
  const std::vector<double> feeds{40.0, 10.0};
  // Resting on the corner: the corner is not repeated, the last segment keeps its feed.
  const PathRest at_corner = restOfPath(points, feeds, 20000.0, mm(20, 0, 0));
  EXPECT_EQ(at_corner.points, (std::vector<Vec3>{mm(20, 0, 0), mm(20, 10, 0)}));
  EXPECT_EQ(at_corner.feeds, std::vector<double>{10.0});
  // Resting at the end: nothing left.
  const PathRest at_end = restOfPath(points, feeds, 30000.0, mm(20, 10, 0));
  EXPECT_TRUE(at_end.empty());
  EXPECT_EQ(at_end.points, std::vector<Vec3>{mm(20, 10, 0)});
  EXPECT_THROW(restOfPath(points, {40.0}, 0.0, mm(0, 0, 0)), ConfigError);
}

// ---- The path tolerance: corners within it, the jerk limit held ----

namespace
{
/// The furthest any streamed position passes from the polyline \p corners (pulses).
double worstDistanceFromPath(const std::vector<Vec3>& positions, const std::vector<Vec3>& corners)
{
  double worst = 0.0;
  for (const Vec3& p : positions)
  {
    double nearest = 1e300;
    for (size_t k = 1; k < corners.size(); ++k)
    {
      const Vec3& a = corners[k - 1];
      const Vec3& b = corners[k];
      double ab2 = 0, t = 0;
      for (int i = 0; i < 3; ++i)
      {
        ab2 += (b[i] - a[i]) * (b[i] - a[i]);
        t += (p[i] - a[i]) * (b[i] - a[i]);
      }
      t = ab2 > 0 ? std::clamp(t / ab2, 0.0, 1.0) : 0.0;
      double d2 = 0;
      for (int i = 0; i < 3; ++i)
      {
        const double d = p[i] - (a[i] + t * (b[i] - a[i]));
        d2 += d * d;
      }
      nearest = std::min(nearest, std::sqrt(d2));
    }
    worst = std::max(worst, nearest);
  }
  return worst;
}

/// A corner: from the origin 10 mm along X, then 10 mm turned by \p degrees.
std::vector<Vec3> corner(double degrees)
{
  const double turn = degrees * M_PI / 180.0;
  return {mm(0, 0, 0), mm(10, 0, 0), mm(10 + 10 * std::cos(turn), 10 * std::sin(turn), 0)};
}

/// The limits of the square that cut its corners by 86 um: jerk 10 m/s^3, 0.5 m/s^2.
PlannerLimits squareLimits(double tolerance_mm)
{
  PlannerLimits limits = scurveLimits();
  limits.max_accel = {500.0, 500.0, 250.0};
  limits.max_jerk = {10000.0, 10000.0, 5000.0};
  limits.path_tolerance = tolerance_mm;
  return limits;
}

const std::vector<Vec3> kSquare = {mm(0, 0, 0), mm(20, 0, 0), mm(20, 20, 0), mm(0, 20, 0), mm(0, 0, 0)};
}  // namespace

TEST(AtPlannerPathTolerance, TheSquaresCornersArePassedWithinTheToleranceWithTheJerkLimitHeld)
{
  for (const double tolerance : {0.01, 0.002, 0.0})
  {
    const PlannerLimits limits = squareLimits(tolerance);
    TrajectoryStream s(Trajectory(kSquare, 40.0, limits));
    const Streamed out = stream(s);
    const double worst = worstDistanceFromPath(out.positions, kSquare);
    EXPECT_LE(worst, tolerance * kPulsesPerMm + 1e-6) << "tolerance " << tolerance << " mm";
    const Ratios r = worstRatios(out.positions, limits);
    EXPECT_LE(r.jerk, 1.0 + 1e-6) << "tolerance " << tolerance;
    EXPECT_LE(r.accel, 1.0 + 1e-6) << "tolerance " << tolerance;
    EXPECT_EQ(out.positions.back(), kSquare.back());
  }
}

TEST(AtPlannerPathTolerance, WithoutItTheMovingAverageCutsTheSquaresCornersFarOutside)
{
  // What the tolerance is for: a tolerance so loose that no corner is held shows the cut.
  TrajectoryStream s(Trajectory(kSquare, 40.0, squareLimits(1000.0)));
  EXPECT_GT(worstDistanceFromPath(stream(s).positions, kSquare), 50.0) << "pulses: the cut the tolerance prevents";
}

TEST(AtPlannerPathTolerance, CornersOfEveryAngleAtSeveralFeedsStayWithinIt)
{
  for (const double degrees : {10.0, 30.0, 60.0, 90.0, 120.0, 150.0, 175.0})
  {
    for (const double feed : {5.0, 20.0, 40.0})
    {
      const PlannerLimits limits = squareLimits(0.01);
      const std::vector<Vec3> path = corner(degrees);
      TrajectoryStream s(Trajectory(path, feed, limits));
      const Streamed out = stream(s);
      EXPECT_LE(worstDistanceFromPath(out.positions, path), 10.0 + 1e-6) << degrees << " deg at " << feed << " mm/s";
      EXPECT_LE(worstRatios(out.positions, limits).jerk, 1.0 + 1e-6) << degrees << " deg at " << feed << " mm/s";
    }
  }
}

TEST(AtPlannerPathTolerance, AGentleCornerIsSlowedThroughAZoneNotStoppedOn)
{
  // 10 degrees at 20 mm/s: taken slower (as slow as the corner's own acceleration rule asks, or
  // slower through a zone around it), never a stop and a hold; the legs away from it at the feed.
  const Trajectory t(corner(10.0), 20.0, squareLimits(0.01));
  const auto& segments = t.segments();
  const auto at_corner = std::find_if(segments.begin(), segments.end(),
                                      [](const Trajectory::Segment& s) {
                                        return std::fabs(s.start[0] - 10000.0) < 1e-6 && std::fabs(s.start[1]) < 1e-6;
                                      });
  ASSERT_NE(at_corner, segments.end());
  EXPECT_EQ(at_corner->dwell, 0.0);
  EXPECT_GT(at_corner->v_entry, 100.0) << "pulses/s through the corner: not stopped";
  double fastest = 0;
  for (const auto& s : segments)
  {
    fastest = std::max(fastest, s.v_cruise);
  }
  EXPECT_NEAR(fastest, 20000.0, 1.0) << "the legs away from the corner at the feed";
}

TEST(AtPlannerPathTolerance, ANegativeOrNoNumberToleranceIsRefused)
{
  for (const double tolerance : {-0.01, std::nan(""), std::numeric_limits<double>::infinity()})
  {
    PlannerLimits limits = scurveLimits();
    limits.path_tolerance = tolerance;
    EXPECT_THROW(limits.validate(), ConfigError) << tolerance;
  }
}
