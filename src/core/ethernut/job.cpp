#include "cnc_bridge/ethernut/job.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <utility>

#include "cnc_bridge/common/error.h"

namespace cnc_bridge
{
namespace ethernut
{
namespace
{
constexpr size_t kSkippedLinesNamed = 5;

gcode::ParserOptions withSeparateMachineMoves(gcode::ParserOptions options)
{
  options.separate_machine_moves = true;  // a skipped G53 move leaves the program position alone
  return options;
}
}  // namespace

// ------------------------------------------------------------------------- GcodeJob
GcodeJob::GcodeJob(std::unique_ptr<std::istream> in, const gcode::ParserOptions& options, G53Policy g53)
    : in_(std::move(in)), steps_(*in_, withSeparateMachineMoves(options)), g53_(std::move(g53))
{
}

bool GcodeJob::next(gcode::Move& move)
{
  step_.reset();
  gcode::ProgramStep step;
  while (steps_.next(step))
  {
    if (step.kind != gcode::ProgramStep::Kind::kMove)
    {
      step_ = step;
      return false;
    }
    move = step.move;
    if (!move.machine_coordinates)
    {
      return true;
    }
    if (g53_.moves == G53Moves::kRefuse)
    {
      throw ConfigError("G-code line " + std::to_string(move.line) +
                        ": G53 move to machine coordinates, which the board does not have (it knows one "
                        "coordinate system, the program's); set " +
                        g53_.setting + " to skip to leave G53 moves out");
    }
    if (skipped_lines_.size() < kSkippedLinesNamed)
    {
      skipped_lines_.push_back(move.line);
    }
    ++skipped_;
  }
  return false;
}

std::string GcodeJob::skippedSummary() const
{
  if (skipped_ == 0)
  {
    return "";
  }
  std::string text = std::to_string(skipped_) + " G53 move" + (skipped_ == 1 ? "" : "s") + " left out (line";
  text += skipped_lines_.size() == 1 ? " " : "s ";
  for (size_t i = 0; i < skipped_lines_.size(); ++i)
  {
    text += (i ? ", " : "") + std::to_string(skipped_lines_[i]);
  }
  return text + (skipped_ > skipped_lines_.size() ? ", ...)" : ")");
}

std::unique_ptr<std::istream> openProgram(const std::string& path)
{
  auto in = std::make_unique<std::ifstream>(path, std::ios::binary);
  if (!*in)
  {
    throw ConfigError("cannot open " + path);
  }
  return in;
}

// ------------------------------------------------------------------------- Preview
Preview::Preview(size_t max_points) : max_points_(std::max<size_t>(max_points, 2)) {}

void Preview::add(double x_mm, double y_mm, double z_mm, bool rapid)
{
  if (added_++ % stride_ != 0)
  {
    return;
  }
  points_.push_back(PreviewPoint{x_mm, y_mm, z_mm, rapid});
  if (points_.size() >= max_points_)
  {
    // Thin to every other point and keep one in 2*stride from now on: memory stays bounded.
    size_t kept = 0;
    for (size_t i = 0; i < points_.size(); i += 2)
    {
      points_[kept++] = points_[i];
    }
    points_.resize(kept);
    stride_ *= 2;
  }
}

// ------------------------------------------------------------------------- coordinates
namespace
{
// Rounding to float may move a coordinate this far, mm (float carries 1 um up to about 16 m).
constexpr double kFloatSlackMm = 0.001;

float boardFloat(double mm, char axis, const std::string& where)
{
  const auto as_float = static_cast<float>(mm);
  if (!std::isfinite(mm) || !std::isfinite(as_float) || std::fabs(static_cast<double>(as_float) - mm) > kFloatSlackMm)
  {
    char text[160];
    std::snprintf(text, sizeof text,
                  ": %c %.17g mm cannot be sent: the board takes float coordinates (finite, to 0.001 mm)", axis, mm);
    throw ConfigError(where + text);
  }
  return as_float;
}
}  // namespace

Coordinate boardCoordinate(double x_mm, double y_mm, double z_mm, const SoftLimits& limits, const std::string& where)
{
  Coordinate c;
  c.x = boardFloat(x_mm, 'X', where);
  c.y = boardFloat(y_mm, 'Y', where);
  c.z = boardFloat(z_mm, 'Z', where);
  const std::string outside = limits.violation({x_mm / 1000.0, y_mm / 1000.0, z_mm / 1000.0});
  if (!outside.empty())
  {
    throw ConfigError(where + ": " + outside);
  }
  return c;
}

// ------------------------------------------------------------------------- Job
std::unique_ptr<Job> Job::fromProgram(const std::string& path, const gcode::ParserOptions& options,
                                      const G53Policy& g53, size_t max_preview_points, const SoftLimits& limits)
{
  std::unique_ptr<Job> job(new Job(max_preview_points));
  // The first pass: every move up to the program's end (M02/M30), what comes after it is never sent.
  GcodeJob scan(openProgram(path), options, g53);
  gcode::Move move;
  bool first_move = true;
  for (;;)
  {
    if (!scan.next(move))
    {
      if (scan.step())
      {
        continue;
      }
      break;
    }
    if (first_move)
    {
      job->preview_.add(move.start.x, move.start.y, move.start.z, true);
      first_move = false;
    }
    // The whole program is checked here, before its first set is sent.
    boardCoordinate(move.end.x, move.end.y, move.end.z, limits, "G-code line " + std::to_string(move.line));
    job->preview_.add(move.end.x, move.end.y, move.end.z, move.motion == gcode::Motion::kRapid);
    ++job->count_;
  }
  job->skipped_ = scan.skippedSummary();
  job->program_ = std::make_unique<GcodeJob>(openProgram(path), options, g53);
  return job;
}

std::unique_ptr<Job> Job::fromPoints(std::vector<Coordinate> points, size_t max_preview_points)
{
  std::unique_ptr<Job> job(new Job(max_preview_points));
  for (const Coordinate& c : points)
  {
    job->preview_.add(c.x, c.y, c.z, false);
  }
  job->count_ = points.size();
  job->points_ = std::move(points);
  return job;
}

bool Job::next(Coordinate& out)
{
  if (!program_)
  {
    if (next_point_ >= points_.size())
    {
      return false;
    }
    out = points_[next_point_++];
    return true;
  }
  gcode::Move move;
  if (!program_->next(move))
  {
    // The stream pauses at a program step (not the end): the segment's end is not the job's.
    segment_continues_ = program_->step() && program_->step()->kind != gcode::ProgramStep::Kind::kEnd;
    return false;
  }
  out.x = static_cast<float>(move.end.x);
  out.y = static_cast<float>(move.end.y);
  out.z = static_cast<float>(move.end.z);
  out.tag = move.line;
  return true;
}

std::optional<gcode::ProgramStep> Job::stepAtEnd() const
{
  if (!program_)
  {
    return std::nullopt;
  }
  return program_->step();
}
}  // namespace ethernut
}  // namespace cnc_bridge
