#include "cnc_bridge/cell/cycle_time.h"

#include <sys/stat.h>

#include <algorithm>
#include <cmath>
#include <sstream>
#include <utility>

#include "cnc_bridge/at_protocol/planner.h"
#include "cnc_bridge/common/error.h"
#include "cnc_bridge/common/program_dir.h"
#include "cnc_bridge/gcode/program_steps.h"

namespace cnc_bridge
{
namespace cell
{
namespace ap = at_protocol;

namespace
{
// As the planner's own test for a zero-length segment (pulses): such a move is merged, no time.
constexpr double kSamePoint = 1e-6;

void requirePositive(double value, const char* field)
{
  if (!(value > 0.0) || !std::isfinite(value))
    throw ConfigError(std::string("cycle profile: ") + field + " must be a positive number of its unit");
}

ap::Vec3 pulses(const gcode::Vec3& mm)
{
  return {mm.x * ap::kPulsesPerMm, mm.y * ap::kPulsesPerMm, mm.z * ap::kPulsesPerMm};
}

double distance(const ap::Vec3& a, const ap::Vec3& b)
{
  return std::sqrt((a[0] - b[0]) * (a[0] - b[0]) + (a[1] - b[1]) * (a[1] - b[1]) + (a[2] - b[2]) * (a[2] - b[2]));
}
}  // namespace

void CycleProfile::validate() const
{
  requirePositive(max_feed, "max_feed");
  requirePositive(rapid_rate, "rapid_rate");
  requirePositive(acceleration, "acceleration");
  if (!(tool_change_time >= 0.0) || !std::isfinite(tool_change_time))
    throw ConfigError("cycle profile: tool_change_time must be 0 or more seconds");
  if (!(corner_share > 0.0 && corner_share < 1.0))
    throw ConfigError("cycle profile: corner_share must lie between 0 and 1");
}

// Collects the moves of one operation (rest to rest: a dwell, a tool change or a stop ends it),
// plans them as one trajectory, and lays every block out on the cycle's time line.
class CyclePlan::Builder
{
 public:
  Builder(const CycleProfile& profile, const std::string& name) : profile_(profile), name_(name)
  {
    limits_.max_speed = {profile.rapid_rate, profile.rapid_rate, profile.rapid_rate};
    limits_.max_accel = {profile.acceleration, profile.acceleration, profile.acceleration};
    limits_.corner_share = profile.corner_share;
    limits_.profile = ap::Profile::kTrapezoid;
    limits_.validate();
  }

  void step(const gcode::ProgramStep& step)
  {
    using Kind = gcode::ProgramStep::Kind;
    if (step.kind == Kind::kMove)
    {
      move(step.move);
      return;
    }
    flush();
    double seconds = 0.0;
    if (step.kind == Kind::kDwell)
      seconds = step.dwell_s;
    else if (step.kind == Kind::kToolChange)
      seconds = profile_.tool_change_time;
    add(step.line, seconds);
  }

  CyclePlan finish()
  {
    flush();
    CyclePlan plan;
    plan.blocks_ = std::move(blocks_);
    plan.total_ = clock_;
    return plan;
  }

 private:
  void move(const gcode::Move& move)
  {
    double feed = 2.0 * profile_.rapid_rate;  // a rapid: the axes' rapid rate caps it
    if (move.motion != gcode::Motion::kRapid)
    {
      if (!(move.feed_mm_per_min > 0.0))
        throw ConfigError(name_ + " line " + std::to_string(move.line) +
                          ": a feed move with no feed programmed (F): its time is unknown");
      feed = std::min(move.feed_mm_per_min / 60.0, profile_.max_feed);
    }
    const ap::Vec3 start = pulses(move.start);
    if (points_.empty() || distance(points_.back(), start) >= kSamePoint)
    {
      if (!points_.empty())
        segment(start, feed, move.line);  // a jump in the program's positions: travelled too
      else
        points_.push_back(start);
    }
    segment(pulses(move.end), feed, move.line);
  }

  void segment(const ap::Vec3& to, double feed, uint32_t line)
  {
    points_.push_back(to);
    feeds_.push_back(feed);
    lines_.push_back(line);
  }

  // Plans the operation so far; each move takes the time of its segment of the trajectory. The
  // planner merges a segment shorter than kSamePoint from the last point it kept; so does this.
  void flush()
  {
    if (points_.size() > 1)
    {
      const ap::Trajectory trajectory(points_, feeds_, limits_);
      const auto& segments = trajectory.segments();
      std::vector<std::pair<uint32_t, size_t>> owners;  // line, segment index (npos: merged)
      ap::Vec3 kept = points_.front();
      size_t next = 0;
      for (size_t i = 1; i < points_.size(); ++i)
      {
        if (distance(points_[i], kept) < kSamePoint)
        {
          owners.emplace_back(lines_[i - 1], std::string::npos);
          continue;
        }
        owners.emplace_back(lines_[i - 1], next++);
        kept = points_[i];
      }
      if (next != segments.size())
        throw Error(name_ + ": the planner's segments do not match the program's moves");
      for (const auto& [line, index] : owners)
      {
        double seconds = 0.0;
        if (index != std::string::npos)
          seconds = (index + 1 < segments.size() ? segments[index + 1].t_start : trajectory.duration()) -
                    segments[index].t_start;
        add(line, seconds);
      }
    }
    const bool had = !points_.empty();
    const ap::Vec3 last = had ? points_.back() : ap::Vec3{};
    points_.clear();
    feeds_.clear();
    lines_.clear();
    if (had)
      points_.push_back(last);  // the next operation starts where this one rests
  }

  // Consecutive steps of one block (an arc's chords, a cycle's moves) make one planned block.
  void add(uint32_t line, double seconds)
  {
    if (!blocks_.empty() && blocks_.back().line == line)
      blocks_.back().duration += seconds;
    else
      blocks_.push_back(PlannedBlock{line, clock_, seconds});
    clock_ += seconds;
  }

  const CycleProfile& profile_;
  const std::string& name_;
  ap::PlannerLimits limits_;
  std::vector<ap::Vec3> points_;  // pulses
  std::vector<double> feeds_;     // mm/s per segment
  std::vector<uint32_t> lines_;   // source line per segment
  std::vector<PlannedBlock> blocks_;
  double clock_ = 0.0;
};

CyclePlan CyclePlan::plan(std::istream& program, const CycleProfile& profile, const std::string& name)
{
  profile.validate();
  gcode::ParserOptions options;
  options.dialect = profile.dialect;
  options.tool_table = profile.tool_table;
  gcode::ProgramSteps steps(program, options);
  Builder builder(profile, name);
  gcode::ProgramStep step;
  while (steps.next(step))
    builder.step(step);
  return builder.finish();
}

std::optional<size_t> CyclePlan::find(uint32_t line, size_t from) const
{
  for (size_t i = from; i < blocks_.size(); ++i)
    if (blocks_[i].line == line)
      return i;
  for (size_t i = from; i < blocks_.size(); ++i)
    if (blocks_[i].line > line)
      return i;
  return std::nullopt;
}

CycleCountdown::CycleCountdown(std::shared_ptr<const CyclePlan> plan, double start, bool running)
    : plan_(std::move(plan)), cap_(plan_->total()), run_since_(start), running_(running)
{
}

double CycleCountdown::runTime(double now) const
{
  return run_before_ + (running_ ? std::max(0.0, now - run_since_) : 0.0);
}

void CycleCountdown::setRunning(bool running, double now)
{
  if (running == running_)
    return;
  if (running_)
    run_before_ = runTime(now);
  else
    run_since_ = now;
  running_ = running;
}

bool CycleCountdown::reportBlock(uint32_t line, double now)
{
  if (block_ && plan_->blocks()[*block_].line == line)
    return true;  // the block still running
  const std::optional<size_t> found = plan_->find(line, block_.value_or(0));
  if (!found)
    return false;
  if (found == block_)
    return true;  // a line of no time before the next block: the machine is still in this one
  // The machine is inside this block: keep the clock's estimate where it falls inside it.
  const PlannedBlock& block = plan_->blocks()[*found];
  anchor_progress_ = std::clamp(progress(now), block.start, block.start + block.duration);
  cap_ = block.start + block.duration;
  run_before_ = 0.0;
  run_since_ = now;
  block_ = found;
  return true;
}

double CycleCountdown::progress(double now) const
{
  return std::min(cap_, anchor_progress_ + runTime(now));
}

double CycleCountdown::remaining(double now) const
{
  return std::max(0.0, plan_->total() - progress(now));
}

// A program as found in the folder: planned, or why not.
struct CycleWatch::Loaded
{
  std::string name;  // as the machine reports it
  std::string path;  // empty when not found
  struct timespec mtime = {};
  off_t size = 0;
  std::shared_ptr<const CyclePlan> plan;
  std::string error;
};

namespace
{
// A part program larger than this is not read: the prediction is then unknown.
constexpr off_t kMaxProgramBytes = 64 << 20;

std::string findProgram(const std::string& program, const std::string& folder)
{
  if (program.empty())
    throw ConfigError("the machine reports no program");
  checkRequestedName(program);
  const ProgramDirectory dir(folder);
  for (const std::string& candidate : {program, program + ".nc"})
  {
    try
    {
      return dir.resolveExisting(candidate);
    }
    catch (const ConfigError&)
    {
      continue;  // not this name: the next
    }
  }
  throw ConfigError("program '" + printableName(program) + "' is not in " + folder + " (as it is or with .nc)");
}
}  // namespace

CycleWatch::CycleWatch(CycleProfile profile, std::string program_dir)
    : profile_(std::move(profile)), program_dir_(std::move(program_dir))
{
  profile_.validate();
  if (program_dir_.empty())
    throw ConfigError("no program folder for the cycle time (program_dir)");
}

std::shared_ptr<const CycleWatch::Loaded> CycleWatch::load(const std::string& program)
{
  auto loaded = std::make_shared<Loaded>();
  loaded->name = program;
  try
  {
    loaded->path = findProgram(program, program_dir_);
    struct stat st;
    if (::stat(loaded->path.c_str(), &st) != 0)
      throw Error("cannot read " + loaded->path);
    loaded->mtime = st.st_mtim;
    loaded->size = st.st_size;
    if (cache_ && cache_->name == program && cache_->path == loaded->path && cache_->size == loaded->size &&
        cache_->mtime.tv_sec == loaded->mtime.tv_sec && cache_->mtime.tv_nsec == loaded->mtime.tv_nsec)
      return cache_;  // planned before, unchanged since
    if (st.st_size > kMaxProgramBytes)
      throw ConfigError(loaded->path + " is larger than 64 MiB: not planned");
    std::istringstream in(readRegularFile(loaded->path));
    loaded->plan = std::make_shared<const CyclePlan>(CyclePlan::plan(in, profile_, printableName(program)));
  }
  catch (const std::exception& e)
  {
    loaded->error = e.what();
  }
  cache_ = loaded;
  return loaded;
}

void CycleWatch::startCycle(const CycleObservation& observation, double now, bool start_known)
{
  in_cycle_ = true;
  loaded_ = load(observation.program);
  anchored_ = start_known;
  countdown_.reset();
  if (loaded_->plan)
    countdown_.emplace(loaded_->plan, now, observation.execution == Execution::Active);
}

void CycleWatch::observe(const CycleObservation& observation, double now)
{
  const bool up = observation.link == Link::Up;
  const bool running = observation.execution == Execution::Active;
  const bool in_cycle = running || observation.execution == Execution::Paused;
  if (in_cycle_ && (!up || !in_cycle))
  {
    in_cycle_ = false;
    loaded_.reset();
    countdown_.reset();
    anchored_ = false;
  }
  if (!up)
  {
    seen_ = false;  // a cycle under way when the link comes back has an unknown start
    return;
  }
  if (!in_cycle_)
  {
    if (!in_cycle)
    {
      seen_ = true;
      return;
    }
    startCycle(observation, now, seen_);
  }
  if (!countdown_)
    return;
  countdown_->setRunning(running, now);
  if (observation.block != 0 && countdown_->reportBlock(observation.block, now))
    anchored_ = anchored_ || countdown_->reportedBlock().has_value();
}

CyclePrediction CycleWatch::predict(double now) const
{
  CyclePrediction prediction;
  if (!in_cycle_)
  {
    prediction.reason = "no cycle running";
    return prediction;
  }
  prediction.program = loaded_->name;
  if (!loaded_->plan)
  {
    prediction.reason = loaded_->error;
    return prediction;
  }
  prediction.planned = loaded_->plan->total();
  if (!anchored_)
  {
    prediction.reason = "the cycle was under way before its start was seen, and no block is reported";
    return prediction;
  }
  prediction.remaining = countdown_->remaining(now);
  if (const auto block = countdown_->reportedBlock())
    prediction.block = loaded_->plan->blocks()[*block].line;
  return prediction;
}
}  // namespace cell
}  // namespace cnc_bridge
