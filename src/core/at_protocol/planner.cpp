// The trajectory planner of the '@'-protocol node (see planner.h for the model).
#include "cnc_bridge/at_protocol/planner.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "cnc_bridge/common/error.h"

namespace cnc_bridge
{
namespace at_protocol
{
namespace
{
constexpr double kInf = std::numeric_limits<double>::infinity();
// Below this many pulses two points are the same point (a thousandth of a micrometre).
constexpr double kSamePoint = 1e-6;

double norm(const Vec3& v)
{
  return std::sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
}
}  // namespace

void PlannerLimits::validate() const
{
  if (!(period > 0.0))
  {
    throw ConfigError("planner: the period must be positive");
  }
  for (int i = 0; i < 3; ++i)
  {
    if (!(max_speed[i] > 0.0) || !(max_accel[i] > 0.0))
    {
      throw ConfigError(std::string("planner: max speed and acceleration of axis ") + "XYZ"[i] + " must be positive");
    }
  }
  if (!(corner_share > 0.0 && corner_share < 1.0))
  {
    throw ConfigError("planner: corner_share must be between 0 and 1");
  }
  for (int i = 0; i < 3; ++i)
  {
    if (!(max_jerk[i] > 0.0))
    {
      throw ConfigError(std::string("planner: max jerk of axis ") + "XYZ"[i] + " must be positive");
    }
  }
}

size_t PlannerLimits::smoothingWindow() const
{
  if (profile != Profile::kSCurve)
  {
    return 1;
  }
  double n = 1.0;
  for (int i = 0; i < 3; ++i)
  {
    n = std::max(n, std::ceil(2.0 * max_accel[i] / (max_jerk[i] * period) - 1e-9));
  }
  return static_cast<size_t>(std::min(n, 100000.0));
}

double timeOptimalJerkLimited(double length, double v, double a, double j)
{
  if (!(length > 0.0))
  {
    return 0.0;
  }
  // Ramp from rest to speed w: with a reached (w >= a^2/j) it takes w/a + a/j and covers
  // w (w/a + a/j) / 2; without, 2 sqrt(w/j) and covers w sqrt(w/j).
  auto ramp_time = [&](double w) { return w * j >= a * a ? w / a + a / j : 2.0 * std::sqrt(w / j); };
  auto ramp_distance = [&](double w) { return w * ramp_time(w) / 2.0; };
  if (2.0 * ramp_distance(v) <= length)
  {
    return 2.0 * ramp_time(v) + (length - 2.0 * ramp_distance(v)) / v;  // cruise at v
  }
  // The peak speed w below v with 2 ramp_distance(w) = length (increasing in w): bisection.
  double lo = 0.0, hi = v;
  for (int k = 0; k < 200; ++k)
  {
    const double mid = (lo + hi) / 2.0;
    (2.0 * ramp_distance(mid) <= length ? lo : hi) = mid;
  }
  return 2.0 * ramp_time(lo);
}

Trajectory::Trajectory(const std::vector<Vec3>& points, double feed, const PlannerLimits& limits, double entry_speed)
    : Trajectory(points, std::vector<double>(points.empty() ? 0 : points.size() - 1, feed), limits, entry_speed)
{
  if (!(feed > 0.0) || std::isnan(feed))
  {
    throw ConfigError("planner: the feed must be a positive number of mm/s");
  }
}

Trajectory::Trajectory(const std::vector<Vec3>& points, const std::vector<double>& feeds, const PlannerLimits& limits,
                       double entry_speed)
    : limits_(limits)
{
  limits_.validate();
  if (points.empty())
  {
    throw ConfigError("planner: a path needs at least one point");
  }
  if (feeds.size() + 1 != points.size())
  {
    throw ConfigError("planner: " + std::to_string(feeds.size()) + " feeds for " + std::to_string(points.size()) +
                      " points (one per segment needed)");
  }
  for (double feed : feeds)
  {
    if (!(feed > 0.0) || std::isnan(feed))
    {
      throw ConfigError("planner: the feed must be a positive number of mm/s");
    }
  }
  for (const auto& point : points)
  {
    for (double coordinate : point)
    {
      if (!std::isfinite(coordinate))
      {
        throw ConfigError("planner: a path point is not a finite number");
      }
    }
  }
  plan(points, feeds, std::max(0.0, entry_speed));
}

void Trajectory::plan(const std::vector<Vec3>& points, const std::vector<double>& feeds, double entry_speed)
{
  start_ = points.front();
  end_ = points.back();
  buildSegments(points, feeds);
  const size_t n = segments_.size();
  if (n == 0)
  {
    entry_feasible_ = entry_speed <= 1e-9;
    return;
  }
  const std::vector<double> entry_max = entryLimits(junctionLimits());
  // Forward pass: the fastest each segment can be left given how fast it was entered.
  if (entry_speed > entry_max[0] * (1.0 + 1e-9) + 1e-9)
  {
    entry_feasible_ = false;
    entry_speed = entry_max[0];
  }
  double v = entry_speed;
  double t = 0.0;
  double s_total = 0.0;
  for (size_t k = 0; k < n; ++k)
  {
    Segment& s = segments_[k];
    const double exit_max = k + 1 < n ? entry_max[k + 1] : 0.0;
    s.v_entry = v;
    s.v_exit = std::min(exit_max, std::sqrt(v * v + 2.0 * s.accel * s.length));
    profileSegment(s);
    s.t_start = t;
    s.s_start = s_total;
    t += s.t_accel + s.t_cruise + s.t_decel;
    s_total += s.length;
    v = s.v_exit;
  }
  duration_ = t;
  length_ = s_total;
}

// Segments with their own speed and acceleration limits along the path; points closer than
// kSamePoint to the last one are left out (end_ is the last point kept).
void Trajectory::buildSegments(const std::vector<Vec3>& points, const std::vector<double>& feeds)
{
  const double share = limits_.corner_share;
  Vec3 from = points.front();
  for (size_t p = 1; p < points.size(); ++p)
  {
    Vec3 delta;
    for (int i = 0; i < 3; ++i)
    {
      delta[i] = points[p][i] - from[i];
    }
    const double length = norm(delta);
    if (length < kSamePoint)
    {
      continue;
    }
    Segment segment;
    segment.start = from;
    segment.length = length;
    double v_max = feeds[p - 1] * kPulsesPerMm;
    double accel = kInf;
    for (int i = 0; i < 3; ++i)
    {
      segment.direction[i] = delta[i] / length;
      const double share_of_axis = std::fabs(segment.direction[i]);
      if (share_of_axis > 1e-12)
      {
        v_max = std::min(v_max, limits_.max_speed[i] * kPulsesPerMm / share_of_axis);
        accel = std::min(accel, limits_.max_accel[i] * kPulsesPerMm / share_of_axis);
      }
    }
    segment.v_max = v_max;
    segment.accel = (1.0 - share) * accel;
    segments_.push_back(segment);
    from = points[p];
  }
  end_ = from;
}

// Junction speed limits: the axis velocity may jump by share * max_accel * period at a corner.
// junction[k]: speed at the start of segment k; [n]: at the end (rest).
std::vector<double> Trajectory::junctionLimits() const
{
  const size_t n = segments_.size();
  std::vector<double> junction(n + 1, 0.0);
  junction[0] = kInf;
  for (size_t k = 1; k < n; ++k)
  {
    double limit = std::min(segments_[k - 1].v_max, segments_[k].v_max);
    for (int i = 0; i < 3; ++i)
    {
      const double jump = std::fabs(segments_[k].direction[i] - segments_[k - 1].direction[i]);
      if (jump > 1e-12)
      {
        limit = std::min(limit, limits_.corner_share * limits_.max_accel[i] * kPulsesPerMm * limits_.period / jump);
      }
    }
    junction[k] = limit;
  }
  junction[n] = 0.0;  // end at rest
  return junction;
}

// Backward pass: the fastest each segment may be entered and still slow down in time.
std::vector<double> Trajectory::entryLimits(const std::vector<double>& junction) const
{
  const size_t n = segments_.size();
  std::vector<double> entry_max(n);
  double exit = 0.0;
  for (size_t k = n; k-- > 0;)
  {
    const Segment& s = segments_[k];
    entry_max[k] = std::min(junction[k], std::sqrt(exit * exit + 2.0 * s.accel * s.length));
    exit = entry_max[k];
  }
  return entry_max;
}

// The speed profile of one segment between its entry and exit speeds: accelerate, cruise,
// decelerate.
void Trajectory::profileSegment(Segment& s)
{
  const double v_top = std::max({s.v_max, s.v_entry, s.v_exit});
  const double peak = std::sqrt((2.0 * s.accel * s.length + s.v_entry * s.v_entry + s.v_exit * s.v_exit) / 2.0);
  s.v_cruise = std::max({std::min(v_top, peak), s.v_entry, s.v_exit});
  const double d_accel = (s.v_cruise * s.v_cruise - s.v_entry * s.v_entry) / (2.0 * s.accel);
  const double d_decel = (s.v_cruise * s.v_cruise - s.v_exit * s.v_exit) / (2.0 * s.accel);
  const double d_cruise = std::max(0.0, s.length - d_accel - d_decel);
  s.t_accel = (s.v_cruise - s.v_entry) / s.accel;
  s.t_decel = (s.v_cruise - s.v_exit) / s.accel;
  s.t_cruise = s.v_cruise > 0.0 ? d_cruise / s.v_cruise : 0.0;
}

size_t Trajectory::steps() const
{
  if (duration_ <= 0.0)
  {
    return 0;
  }
  return static_cast<size_t>(std::ceil(duration_ / limits_.period - 1e-9));
}

Sample Trajectory::sampleSegment(const Segment& s, double tau)
{
  double distance = 0.0;
  double speed = 0.0;
  const double a = s.accel;
  if (tau <= s.t_accel)
  {
    distance = s.v_entry * tau + 0.5 * a * tau * tau;
    speed = s.v_entry + a * tau;
  }
  else if (tau <= s.t_accel + s.t_cruise)
  {
    distance = (s.v_cruise * s.v_cruise - s.v_entry * s.v_entry) / (2.0 * a) + s.v_cruise * (tau - s.t_accel);
    speed = s.v_cruise;
  }
  else
  {
    const double td = std::min(tau - s.t_accel - s.t_cruise, s.t_decel);
    distance = (s.v_cruise * s.v_cruise - s.v_entry * s.v_entry) / (2.0 * a) + s.v_cruise * s.t_cruise +
               s.v_cruise * td - 0.5 * a * td * td;
    speed = s.v_cruise - a * td;
  }
  distance = std::clamp(distance, 0.0, s.length);
  Sample sample;
  for (int i = 0; i < 3; ++i)
  {
    sample.position[i] = s.start[i] + s.direction[i] * distance;
    sample.velocity[i] = s.direction[i] * speed;
  }
  sample.path_speed = speed;
  sample.distance = s.s_start + distance;
  return sample;
}

Sample Trajectory::at(double t) const
{
  if (segments_.empty() || t >= duration_)
  {
    Sample sample;
    sample.position = end_;
    sample.distance = length_;
    return sample;  // at rest on the end point, exactly
  }
  t = std::max(0.0, t);
  auto it = std::upper_bound(segments_.begin(), segments_.end(), t,
                             [](double time, const Segment& s) { return time < s.t_start; });
  const Segment& segment = *std::prev(it);
  return sampleSegment(segment, t - segment.t_start);
}

Setpoint Trajectory::toSetpoint(const Sample& sample) const
{
  Setpoint setpoint;
  for (int i = 0; i < 3; ++i)
  {
    setpoint.position[i] = static_cast<int32_t>(std::llround(sample.position[i]));
    // Feed value: the protocol's -255..255, read as a fraction of the axis' top speed.
    const double scaled = sample.velocity[i] / (limits_.max_speed[i] * kPulsesPerMm) * kMaxFeed;
    setpoint.feed[i] = static_cast<int>(std::clamp<long>(std::lround(scaled), -kMaxFeed, kMaxFeed));
  }
  return setpoint;
}

Trajectory Trajectory::stopFrom(const Sample& from) const
{
  const double v = from.path_speed;
  if (segments_.empty() || v <= 1e-9 || from.distance >= length_)
  {
    return Trajectory({from.position}, 1.0, limits_);
  }
  // The rest of the path from the current point.
  auto it = std::upper_bound(segments_.begin(), segments_.end(), from.distance,
                             [](double d, const Segment& s) { return d < s.s_start; });
  const size_t current = static_cast<size_t>(std::prev(it) - segments_.begin());
  double slowest = kInf;
  for (size_t k = current; k < segments_.size(); ++k)
  {
    slowest = std::min(slowest, segments_[k].accel);
  }
  const double remaining = length_ - from.distance;
  // Never faster than now: the ramp cruises at most at the current speed, then decelerates.
  const double feed_mm = v / kPulsesPerMm;
  double distance = v * v / (2.0 * slowest) * 1.001 + 1e-6;
  for (;;)
  {
    distance = std::min(distance, remaining);
    std::vector<Vec3> points{from.position};
    const double until = from.distance + distance;
    for (size_t k = current; k < segments_.size(); ++k)
    {
      const Segment& s = segments_[k];
      const double segment_end = s.s_start + s.length;
      if (segment_end >= until)
      {
        const double along = until - s.s_start;
        points.push_back({s.start[0] + s.direction[0] * along, s.start[1] + s.direction[1] * along,
                          s.start[2] + s.direction[2] * along});
        break;
      }
      points.push_back({s.start[0] + s.direction[0] * s.length, s.start[1] + s.direction[1] * s.length,
                        s.start[2] + s.direction[2] * s.length});
    }
    // Rest on whole pulses: the controller's positions are integers.
    for (double& c : points.back())
    {
      c = std::round(c);
    }
    Trajectory ramp(points, feed_mm, limits_, v);
    if (ramp.entryFeasible() || distance >= remaining)
    {
      return ramp;
    }
    distance *= 2.0;  // a corner ahead needs a lower speed: stop over a longer stretch
  }
}

TrajectoryStream::TrajectoryStream(Trajectory trajectory)
    : trajectory_(std::move(trajectory)),
      current_(trajectory_.at(0.0)),
      raw_(current_),
      window_(trajectory_.limits().smoothingWindow())
{
  if (window_ > 1)
  {
    ring_.assign(window_, current_.position);  // before the start: at the start point
    tail_ = trajectory_.steps() > 0 ? window_ - 1 : 0;
  }
}

bool TrajectoryStream::nextRaw(Sample& sample)
{
  const Trajectory& trajectory = active();
  if (index_ >= trajectory.steps())
  {
    return false;
  }
  ++index_;
  sample = trajectory.step(index_);
  return true;
}

bool TrajectoryStream::next(Setpoint& setpoint)
{
  if (window_ <= 1)
  {
    if (!nextRaw(raw_))
    {
      return false;
    }
    current_ = raw_;
    setpoint = active().toSetpoint(current_);
    ++sent_;
    return true;
  }
  // S-curve: the mean of the last window_ trapezoid samples; after the trapezoid's end, the end
  // point comes in until the window holds nothing else.
  if (!raw_done_ && !nextRaw(raw_))
  {
    raw_done_ = true;
  }
  if (raw_done_)
  {
    if (tail_ == 0)
    {
      return false;
    }
    --tail_;
    raw_ = active().at(active().duration());
  }
  ring_[ring_next_] = raw_.position;
  ring_next_ = (ring_next_ + 1) % window_;
  Sample smoothed;
  const Vec3 before = current_.position;
  bool all_equal = true;
  for (int i = 0; i < 3; ++i)
  {
    double sum = 0.0;
    for (const Vec3& p : ring_)
    {
      sum += p[i];
      all_equal = all_equal && p[i] == ring_[0][i];
    }
    smoothed.position[i] = sum / static_cast<double>(window_);
  }
  if (all_equal)
  {
    smoothed.position = ring_[0];  // at rest on a point: exactly that point, no rounding of the mean
  }
  const double dt = active().limits().period;
  double speed2 = 0.0;
  for (int i = 0; i < 3; ++i)
  {
    smoothed.velocity[i] = (smoothed.position[i] - before[i]) / dt;
    speed2 += smoothed.velocity[i] * smoothed.velocity[i];
  }
  smoothed.path_speed = std::sqrt(speed2);
  smoothed.distance = raw_.distance;
  current_ = smoothed;
  setpoint = active().toSetpoint(current_);
  ++sent_;
  return true;
}

void TrajectoryStream::stop()
{
  if (stopping_)
  {
    return;
  }
  stopping_ = true;
  // The trapezoid behind the setpoints decelerates from where it is; the moving average follows
  // it, so the S-curve stops within its limits too.
  stop_.emplace(trajectory_.stopFrom(raw_));
  stop_offset_ = raw_.distance;
  index_ = 0;
}

PathRest restOfPath(const std::vector<Vec3>& points, const std::vector<double>& feeds, double distance,
                    const Vec3& from)
{
  if (points.empty() || feeds.size() + 1 != points.size())
  {
    throw ConfigError("planner: " + std::to_string(feeds.size()) + " feeds for " + std::to_string(points.size()) +
                      " points (one per segment needed)");
  }
  PathRest rest;
  rest.points.push_back(from);
  double along = 0.0;  // pulses from points[0] to points[p]
  for (size_t p = 1; p < points.size(); ++p)
  {
    Vec3 delta;
    for (int i = 0; i < 3; ++i)
    {
      delta[i] = points[p][i] - points[p - 1][i];
    }
    along += norm(delta);
    if (along > distance + 1e-3)
    {
      // A corner still ahead: the segment that reaches it keeps its feed.
      rest.points.push_back(points[p]);
      rest.feeds.push_back(feeds[p - 1]);
    }
  }
  if (rest.feeds.empty())
  {
    return rest;
  }
  // A stop that rests exactly on the next corner (or the end): that corner is not repeated.
  Vec3 first;
  for (int i = 0; i < 3; ++i)
  {
    first[i] = rest.points[1][i] - from[i];
  }
  if (norm(first) < kSamePoint)
  {
    rest.points.erase(rest.points.begin() + 1);
    rest.feeds.erase(rest.feeds.begin());
  }
  return rest;
}
}  // namespace at_protocol
}  // namespace cnc_bridge
