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
  if (!(path_tolerance >= 0.0) || !std::isfinite(path_tolerance))
  {
    throw ConfigError("planner: the path tolerance must be a distance from 0 (mm)");
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
  holdPathTolerance(std::max(0.0, entry_speed));
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
    t += s.dwell + s.t_accel + s.t_cruise + s.t_decel;
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
    segment.dwell = segments_.size() < corner_dwells_.size() ? corner_dwells_[segments_.size()] : 0.0;
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
    junction[k] = k < corner_caps_.size() ? std::min(limit, corner_caps_[k]) : limit;
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

namespace
{
/// Distance from \p p to the segment \p s (pulses).
double distanceToSegment(const Vec3& p, const Trajectory::Segment& s)
{
  double along = 0.0;
  for (int i = 0; i < 3; ++i)
  {
    along += (p[i] - s.start[i]) * s.direction[i];
  }
  along = std::clamp(along, 0.0, s.length);
  Vec3 off;
  for (int i = 0; i < 3; ++i)
  {
    off[i] = p[i] - (s.start[i] + s.direction[i] * along);
  }
  return norm(off);
}

/// The segment holding \p distance along the path (the last one past its end).
size_t segmentAt(const std::vector<Trajectory::Segment>& segments, double distance)
{
  auto it = std::upper_bound(segments.begin(), segments.end(), distance,
                             [](double d, const Trajectory::Segment& s) { return d < s.s_start; });
  return it == segments.begin() ? 0 : static_cast<size_t>(std::prev(it) - segments.begin());
}
}  // namespace

std::vector<double> Trajectory::cornerDeviations(size_t window) const
{
  // The stream's moving average (TrajectoryStream::next) replayed: a ring of the last window
  // trapezoid samples, the start point before the start and the end point after the end.
  std::vector<double> worst(segments_.size(), 0.0);
  std::vector<Vec3> ring(window, start_);
  std::vector<double> ring_distance(window, 0.0);
  Vec3 sum{};
  for (int i = 0; i < 3; ++i)
  {
    sum[i] = start_[i] * static_cast<double>(window);
  }
  const size_t total = steps() + window - 1;
  for (size_t k = 1; k <= total; ++k)
  {
    const Sample raw = step(std::min(k, steps()));
    const size_t slot = k % window;
    for (int i = 0; i < 3; ++i)
    {
      sum[i] += raw.position[i] - ring[slot][i];
    }
    ring[slot] = raw.position;
    ring_distance[slot] = raw.distance;
    // The window spans [oldest, newest] along the path: a corner inside it is being mixed.
    const double newest = raw.distance;
    const double oldest = ring_distance[(k + 1) % window];
    const size_t first = segmentAt(segments_, oldest), last = segmentAt(segments_, newest);
    if (first == last)
    {
      continue;  // one segment: the mean of points on a line lies on it
    }
    Vec3 mean;
    for (int i = 0; i < 3; ++i)
    {
      mean[i] = sum[i] / static_cast<double>(window);
    }
    double deviation = kInf;
    for (size_t j = first; j <= last; ++j)
    {
      deviation = std::min(deviation, distanceToSegment(mean, segments_[j]));
    }
    // Charged to the corner nearest the window's middle (a point between two segments of one
    // direction, where a slow zone begins, is no corner).
    const double middle = (oldest + newest) / 2.0;
    size_t corner = 0;
    for (size_t j = first + 1; j <= last; ++j)
    {
      if (isCorner(j) &&
          (corner == 0 || std::fabs(segments_[j].s_start - middle) < std::fabs(segments_[corner].s_start - middle)))
      {
        corner = j;
      }
    }
    if (corner != 0)
    {
      worst[corner] = std::max(worst[corner], deviation);
    }
  }
  return worst;
}

bool Trajectory::isCorner(size_t k) const
{
  if (k == 0 || k >= segments_.size())
  {
    return false;
  }
  double change = 0.0;
  for (int i = 0; i < 3; ++i)
  {
    change += std::fabs(segments_[k].direction[i] - segments_[k - 1].direction[i]);
  }
  return change > 1e-9;
}

namespace
{
/// The polyline to plan: each corner k of \p base with a speed cap gets a slow zone, a stretch of
/// \p zone(k) on either side followed at the cap (so that the whole window of the moving average
/// around the corner moves at it, not only the corner point); \p dwells[k] marks an exact stop.
struct Refined
{
  std::vector<Vec3> points;
  std::vector<double> feeds;        ///< mm/s per segment
  std::vector<double> dwell_at;     ///< s held at each point
  std::vector<size_t> base_corner;  ///< the base corner each point is, or 0 for a zone's edge
};

Refined refine(const std::vector<Vec3>& base, const std::vector<double>& base_feeds, const std::vector<double>& caps,
               const std::vector<double>& dwells, double half_window)
{
  Refined out;
  auto add = [&out](const Vec3& point, double dwell, size_t corner)
  {
    out.points.push_back(point);
    out.dwell_at.push_back(dwell);
    out.base_corner.push_back(corner);
  };
  add(base[0], 0.0, 0);
  for (size_t k = 0; k + 1 < base.size(); ++k)
  {
    Vec3 delta;
    for (int i = 0; i < 3; ++i)
    {
      delta[i] = base[k + 1][i] - base[k][i];
    }
    const double length = norm(delta);
    // A zone long enough that the window around the corner stays in it: half a window at the
    // cap, and a quarter more.
    auto zone = [&](size_t c) { return std::isfinite(caps[c]) ? 1.25 * caps[c] * kPulsesPerMm * half_window : 0.0; };
    double lead = k > 0 ? zone(k) : 0.0, trail = k + 2 < base.size() ? zone(k + 1) : 0.0;
    if (lead + trail > length)
    {
      const double scale = length / (lead + trail);
      lead *= scale;
      trail *= scale;
    }
    auto at = [&](double along)
    {
      return Vec3{base[k][0] + delta[0] * along / length, base[k][1] + delta[1] * along / length,
                  base[k][2] + delta[2] * along / length};
    };
    const double lead_feed = std::min(base_feeds[k], caps[k]);
    const double trail_feed = trail > kSamePoint ? std::min(base_feeds[k], caps[k + 1]) : base_feeds[k];
    if (lead >= length - kSamePoint)
    {
      out.feeds.push_back(std::min(lead_feed, trail_feed));  // the whole segment is a slow zone
    }
    else
    {
      if (lead > kSamePoint)
      {
        add(at(lead), 0.0, 0);
        out.feeds.push_back(lead_feed);
      }
      if (length - trail > lead + kSamePoint && trail > kSamePoint)
      {
        add(at(length - trail), 0.0, 0);
        out.feeds.push_back(base_feeds[k]);
      }
      out.feeds.push_back(trail_feed);
    }
    add(base[k + 1], dwells[k + 1], k + 1);
  }
  return out;
}
}  // namespace

void Trajectory::holdPathTolerance(double entry_speed)
{
  const size_t window = limits_.smoothingWindow();
  if (window <= 1 || segments_.size() < 2)
  {
    return;
  }
  const double tolerance = limits_.path_tolerance * kPulsesPerMm;
  const double hold = static_cast<double>(window) * limits_.period;
  // The path as planned (identical points merged), each segment's feed as its speed limit.
  std::vector<Vec3> base;
  std::vector<double> base_feeds;
  for (const Segment& segment : segments_)
  {
    base.push_back(segment.start);
    base_feeds.push_back(segment.v_max / kPulsesPerMm);
  }
  base.push_back(end_);
  std::vector<double> caps(base.size(), kInf);  // mm/s through base corner k
  std::vector<double> dwells(base.size(), 0.0);
  // Each pass slows the corners still cut too far, in proportion (at a steady speed through the
  // corner the cut grows with it); a corner still too far after kSlowingPasses, or already slow,
  // becomes an exact stop held for a window. A few passes suffice in practice.
  constexpr int kSlowingPasses = 6;
  constexpr double kLowSpeed = 0.05;  // mm/s: slower than this is a stop
  for (int pass = 0; pass <= kSlowingPasses + 1; ++pass)
  {
    const std::vector<double> worst = cornerDeviations(window);
    bool changed = false;
    for (size_t k = 1; k < segments_.size(); ++k)
    {
      const size_t c = refined_corner_.empty() ? k : refined_corner_[k];
      if (c == 0 || worst[k] <= tolerance + 1e-9 || dwells[c] > 0.0)
      {
        continue;
      }
      const double speed = std::min(caps[c], segments_[k].v_entry / kPulsesPerMm);
      if (pass >= kSlowingPasses || tolerance <= 0.0 || speed < kLowSpeed)
      {
        caps[c] = 0.0;
        dwells[c] = hold;
      }
      else
      {
        caps[c] = speed * 0.9 * tolerance / worst[k];
      }
      changed = true;
    }
    if (!changed)
    {
      return;
    }
    const Refined path = refine(base, base_feeds, caps, dwells, hold / 2.0);
    corner_dwells_ = path.dwell_at;
    corner_caps_.assign(path.points.size(), kInf);
    for (size_t k = 0; k < path.points.size(); ++k)
    {
      corner_caps_[k] = path.dwell_at[k] > 0.0 ? 0.0 : kInf;
    }
    refined_corner_ = path.base_corner;
    segments_.clear();
    plan(path.points, path.feeds, entry_speed);
  }
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
  tau = std::max(0.0, tau - s.dwell);  // at rest on the start while it dwells
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
