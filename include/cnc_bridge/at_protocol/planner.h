// Trajectory planning for the '@'-protocol (docs/protocols/at_protocol.md; the ESPRIT paper's section 4.1):
// the add-in, not the controller, turns a tool path into "the required speed and position for each
// axis at each time loop" of 1 ms, with acceleration and deceleration. This file holds that planner:
// a polyline in pulses becomes a time-parametrised trapezoidal velocity profile along the path,
// sampled every period into the integer feed values and pulse positions of the protocol.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <vector>

#include "cnc_bridge/at_protocol/codec.h"

namespace cnc_bridge
{
namespace at_protocol
{
using Vec3 = std::array<double, 3>;

/// Velocity profile along the path.
enum class Profile : uint8_t
{
  kTrapezoid,  ///< constant acceleration phases: the acceleration jumps (infinite jerk)
  kSCurve      ///< jerk-limited: the trapezoid smoothed by a moving average (see TrajectoryStream)
};

/// \brief Machine limits and timing of the planner. Lengths in millimetres (the machinist's unit;
/// the ROS layer converts from metres), times in seconds.
struct PlannerLimits
{
  double period = 0.001;                ///< s, the controller's time loop (1 ms)
  Vec3 max_speed{50.0, 50.0, 25.0};     ///< mm/s per axis; also the speed a feed value of 255 means
  Vec3 max_accel{500.0, 500.0, 250.0};  ///< mm/s^2 per axis
  /// Share of each axis' acceleration budget kept for the change of direction at a corner. Along a
  /// segment the path accelerates with (1 - share) of the limit; at a corner the axis velocity may
  /// jump by at most share * max_accel * period. A sample straddling a corner then sees both, and
  /// the sum stays within max_accel: the limit holds at every sample, corners included.
  double corner_share = 0.2;
  Profile profile = Profile::kTrapezoid;
  Vec3 max_jerk{10000.0, 10000.0, 5000.0};  ///< mm/s^3 per axis (held by the S-curve profile)
  /// mm: how far the S-curve's path may pass from a corner (LinuxCNC's G64 P). The moving average
  /// mixes the two legs of a corner over its window; a corner whose mix would pass further is taken
  /// slower, or, where no speed is slow enough, stopped on and held for a window, so that the
  /// average never mixes its legs (an exact stop). 0: every corner so. The trapezoid follows the
  /// polyline itself and ignores it.
  double path_tolerance = 0.01;

  /// \throws ConfigError if a value is not positive, corner_share is not in (0, 1) or
  /// path_tolerance is negative or not finite.
  void validate() const;
  /// \brief Samples the S-curve averages over: n = max over the axes of ceil(2 a / (j period)), so
  /// that a moving average of n samples of a trapezoid that keeps acceleration a keeps jerk j (a
  /// sample's velocity change is at most a period; the average's acceleration is the difference of
  /// two such changes n samples apart over n: at most 2 a / (n period) per period). 1 for the
  /// trapezoid.
  size_t smoothingWindow() const;
};

/// \brief The shortest time to travel \p length from rest to rest with speed, acceleration and jerk
/// at most \p v, \p a, \p j (the time-optimal jerk-limited "double S" profile; closed form, see
/// Biagiotti and Melchiorri, Trajectory Planning for Automatic Machines and Robots, section 3.4).
double timeOptimalJerkLimited(double length, double v, double a, double j);

/// \brief The state of the path at one instant, in pulses (1/1000 mm) and pulses per second.
struct Sample
{
  Vec3 position{};
  Vec3 velocity{};
  double path_speed = 0.0;  ///< pulses/s along the path
  double distance = 0.0;    ///< pulses travelled along the path
};

/// \brief A planned move along a polyline: trapezoidal speed along each segment, junction speeds
/// limited so that every axis stays within its speed and acceleration limits. Immutable after
/// planning, so thread-safe for concurrent readers.
///
/// Speeds: the path speed on a segment with unit direction u is at most min(feed, max_speed_i/|u_i|);
/// its acceleration is (1 - corner_share) * min(max_accel_i/|u_i|). Speeds at the junctions come from
/// a backward and a forward pass (the classic look-ahead of CNC interpolators), so the path never
/// needs more deceleration than it has room for and ends at rest.
class Trajectory
{
 public:
  /// \brief Plans a path through \p points (pulses), starting at \p entry_speed.
  /// \param feed path speed wanted, mm/s (capped by the axis limits).
  /// \param entry_speed pulses/s at the first point, in the direction of the first segment (0 from rest).
  /// \throws ConfigError on fewer than one point, a non-positive feed, or invalid limits.
  /// Consecutive identical points are merged; a path of one point is a trajectory of zero length.
  Trajectory(const std::vector<Vec3>& points, double feed, const PlannerLimits& limits, double entry_speed = 0.0);

  /// \brief As above with a feed per segment: \p feeds[i] (mm/s) from points[i] to points[i + 1]
  /// (G-code F words change along a program; a rapid may pass a very large feed: the axis limits cap it).
  /// \throws ConfigError if feeds.size() != points.size() - 1 or a feed is not positive.
  Trajectory(const std::vector<Vec3>& points, const std::vector<double>& feeds, const PlannerLimits& limits,
             double entry_speed = 0.0);

  /// \returns false if \p entry_speed was too high to stop within the path (the profile then
  /// starts slower than asked); true for every path planned from rest.
  bool entryFeasible() const { return entry_feasible_; }
  /// Seconds from the first point to rest at the last.
  double duration() const { return duration_; }
  /// Pulses along the path.
  double length() const { return length_; }
  /// Setpoints this trajectory is streamed as: one per period, the last exactly at duration().
  size_t steps() const;
  const PlannerLimits& limits() const { return limits_; }
  const Vec3& start() const { return start_; }
  const Vec3& end() const { return end_; }

  /// \brief The state at time \p t (clamped to [0, duration()]).
  Sample at(double t) const;
  /// \brief The state after \p k periods (k = 1..steps(); the last is the end point at rest).
  Sample step(size_t k) const { return at(static_cast<double>(k) * limits_.period); }

  /// \brief The protocol's setpoint for a sample: positions rounded to whole pulses, feed values
  /// scaled so that 255 is the axis' max_speed, with the sign of the direction.
  Setpoint toSetpoint(const Sample& sample) const;

  /// \brief A trajectory that continues from \p from along the rest of this path, decelerating at
  /// the path's limits until it stops (a cancel: never a jump in position or speed).
  Trajectory stopFrom(const Sample& from) const;

  struct Segment
  {
    Vec3 start{};
    Vec3 direction{};  ///< unit vector
    double length = 0.0;
    double accel = 0.0;  ///< pulses/s^2 along the path
    double v_max = 0.0;  ///< pulses/s
    double v_entry = 0.0, v_cruise = 0.0, v_exit = 0.0;
    double t_accel = 0.0, t_cruise = 0.0, t_decel = 0.0;
    double t_start = 0.0;  ///< s from the start of the trajectory (the start of its dwell)
    double s_start = 0.0;  ///< pulses from the start of the trajectory
    double dwell = 0.0;    ///< s at rest on start before moving: an exact stop at a corner
  };
  const std::vector<Segment>& segments() const { return segments_; }

 private:
  void plan(const std::vector<Vec3>& points, const std::vector<double>& feeds, double entry_speed);
  // The steps of plan(): the segments, the speed limits at their junctions, the backward pass,
  // one segment's speed profile.
  void buildSegments(const std::vector<Vec3>& points, const std::vector<double>& feeds);
  std::vector<double> junctionLimits() const;
  std::vector<double> entryLimits(const std::vector<double>& junction) const;
  static void profileSegment(Segment& segment);
  /// S-curve: plans again, slower through (or stopping on) each corner whose moving average passes
  /// further from the path than limits_.path_tolerance.
  void holdPathTolerance(double entry_speed);
  /// For each corner k (the start of segment k), the furthest the moving average of \p window
  /// samples passes from the path while its window holds that corner (pulses).
  std::vector<double> cornerDeviations(size_t window) const;
  /// Whether segment \p k starts with a change of direction.
  bool isCorner(size_t k) const;
  static Sample sampleSegment(const Segment& segment, double tau);

  PlannerLimits limits_;
  std::vector<Segment> segments_;
  std::vector<double> corner_caps_;     ///< pulses/s at corner k at most (holdPathTolerance())
  std::vector<double> corner_dwells_;   ///< s held at corner k
  std::vector<size_t> refined_corner_;  ///< for each point planned, the corner of the path it is (0: none)
  Vec3 start_{};
  Vec3 end_{};
  double duration_ = 0.0;
  double length_ = 0.0;
  bool entry_feasible_ = true;
};

/// \brief The rest of a path after a stop on it: what is left to follow when a path that stopped
/// part-way (a cancel's deceleration, see Trajectory::stopFrom) goes on from rest.
struct PathRest
{
  std::vector<Vec3> points;   ///< the stop point, then every corner beyond it, to the path's end
  std::vector<double> feeds;  ///< mm/s per segment, as the path had them
  /// Nothing left: the stop point is the path's end.
  bool empty() const { return feeds.empty(); }
};

/// \brief The polyline \p points (with \p feeds per segment, as Trajectory takes them) from
/// \p distance pulses along it on, starting at \p from (where the stop rests: on the path, up to
/// the rounding to whole pulses). A corner within a thousandth of a pulse of \p distance counts
/// as passed.
/// \throws ConfigError if feeds.size() != points.size() - 1.
PathRest restOfPath(const std::vector<Vec3>& points, const std::vector<double>& feeds, double distance,
                    const Vec3& from);

/// \brief Streams a trajectory one setpoint per call, and switches to a deceleration ramp on
/// request. Used by the sender thread only: not thread-safe.
///
/// With Profile::kSCurve every setpoint is the mean of the last PlannerLimits::smoothingWindow()
/// samples of the trapezoid (the samples before the start are the start point, after the end the
/// end point): a moving average of n samples turns each constant-acceleration phase into a
/// jerk-limited ramp and the velocity jumps at corners into ramps over n periods, while speed and
/// acceleration stay within what the trapezoid keeps. The stream is n - 1 periods longer and ends
/// exactly on the end point. Velocities of S-curve setpoints are the differences of consecutive
/// positions over the period.
class TrajectoryStream
{
 public:
  explicit TrajectoryStream(Trajectory trajectory);

  /// \brief The next setpoint. \returns false when the trajectory (or its stop ramp) is done.
  bool next(Setpoint& setpoint);
  /// \brief From the next call on, decelerate to a stop along the path. Idempotent.
  void stop();
  bool stopping() const { return stopping_; }
  /// Setpoints handed out so far.
  size_t sent() const { return sent_; }
  /// Setpoints in all (changes once when stop() shortens the stream).
  size_t total() const { return sent_ - index_ + active().steps() + tail_; }
  /// The sample of the last setpoint handed out (pulses; the smoothed one for an S-curve).
  const Sample& current() const { return current_; }
  /// Pulses along the streamed trajectory (not its stop ramp) of the trapezoid's sample behind the
  /// last setpoint: once the stream is done, where along the path it came to rest.
  double distance() const { return stop_offset_ + raw_.distance; }

 private:
  const Trajectory& active() const { return stop_ ? *stop_ : trajectory_; }
  bool nextRaw(Sample& sample);

  Trajectory trajectory_;
  std::optional<Trajectory> stop_;
  double stop_offset_ = 0.0;  // pulses along trajectory_ where stop_ starts
  size_t index_ = 0;          // steps of *active_ streamed
  size_t sent_ = 0;
  bool stopping_ = false;
  Sample current_;
  Sample raw_;  // the trapezoid's sample behind the last setpoint
  // S-curve: the last `window` trapezoid samples (a ring) and how many flush steps remain.
  size_t window_ = 1;
  std::vector<Vec3> ring_;
  size_t ring_next_ = 0;
  size_t tail_ = 0;
  bool raw_done_ = false;
};
}  // namespace at_protocol
}  // namespace cnc_bridge
