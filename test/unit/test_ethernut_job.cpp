// Jobs for the ethernut board (job.h): a program's coordinates, segments and steps, the G53
// policy, the count and the preview's bounded thinning, on the fixtures of test/data/gcode and on
// short programs written here; and the hold a motion disable puts on a running job (motion_hold.h).
#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <future>
#include <sstream>

#include "cancel_probe.h"
#include "cnc_bridge/common/error.h"
#include "cnc_bridge/ethernut/job.h"
#include "cnc_bridge/ethernut/motion_hold.h"
#include "temp_dir.h"

using namespace cnc_bridge;
using namespace cnc_bridge::ethernut;
using Kind = gcode::ProgramStep::Kind;
using cnc_bridge::test::TempDir;

namespace
{
const std::string kFixtures = CNC_BRIDGE_FIXTURE_DIR;

GcodeJob jobOf(const std::string& program, G53Moves moves)
{
  return GcodeJob(std::make_unique<std::istringstream>(program), gcode::ParserOptions(),
                  G53Policy{moves, "~g53_moves"});
}

// One segment as streamed: the coordinates up to its end and the step it ended at.
struct Segment
{
  std::vector<Coordinate> coordinates;
  std::optional<gcode::ProgramStep> step;
  bool continues = false;
};

std::vector<Segment> segmentsOf(Job& job)
{
  std::vector<Segment> segments;
  for (;;)
  {
    job.startSegment();
    Segment segment;
    Coordinate c;
    while (job.next(c))
    {
      segment.coordinates.push_back(c);
    }
    segment.step = job.stepAtEnd();
    segment.continues = job.segmentContinues();
    segments.push_back(segment);
    if (!segment.continues)
    {
      return segments;
    }
  }
}
}  // namespace

TEST(EthernutGcodeJob, ARefusedG53MoveNamesItsLineAndTheSetting)
{
  GcodeJob job = jobOf("G21 G90\nG00 X1 Y2 Z3\nG53 G00 Z0\nG00 X5\n", G53Moves::kRefuse);
  gcode::Move move;
  ASSERT_TRUE(job.next(move));
  try
  {
    job.next(move);
    FAIL() << "the G53 move was not refused";
  }
  catch (const ConfigError& e)
  {
    EXPECT_NE(std::string(e.what()).find("G-code line 3: G53 move"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("set ~g53_moves to skip"), std::string::npos) << e.what();
  }
}

TEST(EthernutGcodeJob, ASkippedG53MoveLeavesTheProgramPositionAlone)
{
  GcodeJob job = jobOf("G21 G90\nG00 X1 Y2 Z3\nG53 G00 Z0\nG00 X5\n", G53Moves::kSkip);
  gcode::Move move;
  ASSERT_TRUE(job.next(move));
  EXPECT_EQ(move.line, 2u);
  ASSERT_TRUE(job.next(move));
  EXPECT_EQ(move.line, 4u);
  EXPECT_DOUBLE_EQ(move.end.x, 5.0);
  EXPECT_DOUBLE_EQ(move.end.y, 2.0);
  EXPECT_DOUBLE_EQ(move.end.z, 3.0);  // Z of line 2, not the G53 Z0
  EXPECT_FALSE(job.next(move));
  EXPECT_FALSE(job.step().has_value());  // the end of the text, no M02/M30
  EXPECT_EQ(job.skippedSummary(), "1 G53 move left out (line 3)");
}

TEST(EthernutGcodeJob, TheSkippedSummaryNamesAtMostFiveLines)
{
  GcodeJob job =
      jobOf("G21 G90\nG00 X1\nG53 Z1\nG53 Z2\nG53 Z3\nG53 Z4\nG53 Z5\nG53 Z6\nG53 Z7\nG00 X2\n", G53Moves::kSkip);
  gcode::Move move;
  int moves = 0;
  while (job.next(move))
  {
    ++moves;
  }
  EXPECT_EQ(moves, 2);
  EXPECT_EQ(job.skippedSummary(), "7 G53 moves left out (lines 3, 4, 5, 6, 7, ...)");
  EXPECT_EQ(jobOf("G21\nG00 X1\n", G53Moves::kSkip).skippedSummary(), "");
}

TEST(EthernutJob, TheHaasFixtureIsRefusedAtItsFirstG53MoveUnlessSkipped)
{
  const std::string haas = kFixtures + "/haas_O05555.nc";
  try
  {
    Job::fromProgram(haas, gcode::ParserOptions(), G53Policy{G53Moves::kRefuse, "~g53_moves"}, 100);
    FAIL() << "the fixture's G53 moves were not refused";
  }
  catch (const ConfigError& e)
  {
    EXPECT_NE(std::string(e.what()).find("G-code line 9:"), std::string::npos) << e.what();
  }
  const auto job = Job::fromProgram(haas, gcode::ParserOptions(), G53Policy{G53Moves::kSkip, "~g53_moves"}, 100000);
  EXPECT_EQ(job->skippedSummary(), "4 G53 moves left out (lines 9, 53, 57, 59)");
  // The count is what is streamed, none of it from a G53 line.
  uint64_t streamed = 0;
  for (const Segment& segment : segmentsOf(*job))
  {
    for (const Coordinate& c : segment.coordinates)
    {
      EXPECT_TRUE(c.tag != 9 && c.tag != 53 && c.tag != 57 && c.tag != 59) << "line " << c.tag;
      ++streamed;
    }
  }
  EXPECT_GT(streamed, 0u);
  EXPECT_EQ(job->coordinateCount(), streamed);
  EXPECT_EQ(job->preview().added(), streamed + 1);  // the first move's start, then every end
}

TEST(EthernutJob, AProgramIsStreamedInSegmentsEndingAtItsOwnSteps)
{
  const auto job = Job::fromProgram(kFixtures + "/program_stops.nc", gcode::ParserOptions(), G53Policy(), 100);
  EXPECT_EQ(job->coordinateCount(), 5u);  // the move after M30 is not counted
  const std::vector<Segment> segments = segmentsOf(*job);
  struct Expected
  {
    std::vector<float> x;
    Kind step;
    uint32_t line;
  };
  const std::vector<Expected> expected = {{{0.0f}, Kind::kSpindle, 5}, {{}, Kind::kCoolant, 6},
                                          {{10.0f}, Kind::kStop, 8},   {{20.0f}, Kind::kOptionalStop, 10},
                                          {{30.0f}, Kind::kDwell, 12}, {{40.0f}, Kind::kSpindle, 14},
                                          {{}, Kind::kCoolant, 14},    {{}, Kind::kEnd, 15}};
  ASSERT_EQ(segments.size(), expected.size());
  for (size_t i = 0; i < segments.size(); ++i)
  {
    SCOPED_TRACE("segment " + std::to_string(i));
    ASSERT_EQ(segments[i].coordinates.size(), expected[i].x.size());
    for (size_t j = 0; j < expected[i].x.size(); ++j)
    {
      EXPECT_FLOAT_EQ(segments[i].coordinates[j].x, expected[i].x[j]);
    }
    ASSERT_TRUE(segments[i].step.has_value());
    EXPECT_EQ(segments[i].step->kind, expected[i].step);
    EXPECT_EQ(segments[i].step->line, expected[i].line);
    EXPECT_EQ(segments[i].continues, expected[i].step != Kind::kEnd);
  }
  EXPECT_EQ(segments[2].coordinates[0].tag, 7u);  // the G-code line of each coordinate
  EXPECT_EQ(segments[0].coordinates[0].z, 5.0f);
  EXPECT_DOUBLE_EQ(segments[4].step->dwell_s, 0.3);
  EXPECT_EQ(segments[7].step->m_code, 30);
}

TEST(EthernutJob, TheProgramPreviewStartsWithARapidFromTheFirstMovesStart)
{
  const auto job = Job::fromProgram(kFixtures + "/program_stops.nc", gcode::ParserOptions(), G53Policy(), 100);
  const std::vector<PreviewPoint>& points = job->preview().points();
  ASSERT_EQ(points.size(), 6u);  // the start, then the five moves' ends
  EXPECT_TRUE(points[0].rapid);
  EXPECT_TRUE(points[1].rapid);  // G00 X0 Y0 Z5
  EXPECT_DOUBLE_EQ(points[1].z, 5.0);
  for (size_t i = 2; i < points.size(); ++i)
  {
    EXPECT_FALSE(points[i].rapid);  // G01
    EXPECT_DOUBLE_EQ(points[i].x, 10.0 * static_cast<double>(i - 1));
  }
}

// The whole program is checked before the job exists (before its first set is sent): a coordinate a
// float cannot carry, or one outside the soft limits, refuses the job naming its line and the limit.
TEST(EthernutJob, AProgramWithOneCoordinateTheBoardCannotTakeIsRefusedWhole)
{
  const TempDir dir;
  const std::string huge = dir.write("huge.nc", "G21 G90\nG0 X1 Y1\nG1 X2 F100\nG1 X1E39\n");
  const std::string far =
      dir.write("far.nc", "G21 G90\nG0 X1 Y1\nG1 X2 F100\nG1 Y1000000000000000000000000000000000000000\nG1 Y600\n");
  const auto refusal = [](const std::string& path, const SoftLimits& limits)
  {
    try
    {
      Job::fromProgram(path, gcode::ParserOptions(), G53Policy(), 100, limits);
    }
    catch (const Error& e)
    {
      return std::string(e.what());
    }
    return std::string("accepted");
  };
  EXPECT_NE(refusal(huge, SoftLimits()).find("line 4"), std::string::npos);  // E: a word no code uses
  const std::string too_far = refusal(far, SoftLimits());
  EXPECT_EQ(too_far.rfind("G-code line 4: Y ", 0), 0u) << too_far;
  EXPECT_NE(too_far.find(" mm cannot be sent: the board takes float coordinates (finite, to 0.001 mm)"),
            std::string::npos)
      << too_far;
  const std::string within = dir.write("within.nc", "G21 G90\nG0 X1 Y1\nG1 X2 F100\nG1 Y600\n");
  SoftLimits limits;
  limits.setting = "/router/ethernut_node/soft_limits";
  limits.axes[1] = std::make_pair(0.0, 0.5);
  EXPECT_EQ(refusal(within, SoftLimits()), "accepted");
  EXPECT_EQ(refusal(within, limits),
            "G-code line 4: Y 0.6 m is outside the soft limits 0..0.5 m (/router/ethernut_node/soft_limits)");
}

TEST(EthernutJob, BoardCoordinatesAreExactToTheBoardsFloatOrRefused)
{
  const Coordinate c = boardCoordinate(1.5, -2.25, 100.125, SoftLimits(), "point 0");
  EXPECT_EQ(c.x, 1.5f);
  EXPECT_EQ(c.y, -2.25f);
  EXPECT_EQ(c.z, 100.125f);
  for (const double bad : {std::nan(""), HUGE_VAL, -HUGE_VAL, 1e300, 1e39, 1e12})
  {
    EXPECT_THROW(boardCoordinate(bad, 0, 0, SoftLimits(), "point 3"), ConfigError) << bad;
    EXPECT_THROW(boardCoordinate(0, 0, bad, SoftLimits(), "point 3"), ConfigError) << bad;
  }
  SoftLimits limits;
  limits.axes[0] = std::make_pair(-0.1, 0.1);
  EXPECT_NO_THROW(boardCoordinate(100.0, 5000.0, 0, limits, "point 1"));  // Y and Z: no limit
  try
  {
    boardCoordinate(100.5, 0, 0, limits, "point 7");
    FAIL() << "a point outside the soft limits was taken";
  }
  catch (const ConfigError& e)
  {
    EXPECT_EQ(std::string(e.what()), "point 7: X 0.1005 m is outside the soft limits -0.1..0.1 m (soft_limits)");
  }
}

TEST(EthernutJob, APointsJobIsOneSegmentWithoutSteps)
{
  std::vector<Coordinate> points(3);
  points[1].x = 1.5f;
  points[2].y = -2.0f;
  const auto job = Job::fromPoints(points, 100);
  EXPECT_EQ(job->coordinateCount(), 3u);
  EXPECT_EQ(job->preview().points().size(), 3u);
  EXPECT_FALSE(job->preview().points()[1].rapid);
  const std::vector<Segment> segments = segmentsOf(*job);
  ASSERT_EQ(segments.size(), 1u);
  ASSERT_EQ(segments[0].coordinates.size(), 3u);
  EXPECT_FLOAT_EQ(segments[0].coordinates[1].x, 1.5f);
  EXPECT_FLOAT_EQ(segments[0].coordinates[2].y, -2.0f);
  EXPECT_FALSE(segments[0].step.has_value());
  EXPECT_EQ(job->skippedSummary(), "");
}

TEST(EthernutPreview, ThinningKeepsEveryOtherPointAndThenOneInTwiceAsMany)
{
  Preview preview(4);
  for (int i = 0; i < 8; ++i)
  {
    preview.add(i, 0.0, 0.0, i % 2 == 0);
  }
  // 0 1 2 3 -> thinned to 0 2 (one in 2 from now on); 4 6 -> 0 2 4 6 thinned to 0 4 (one in 4).
  ASSERT_EQ(preview.points().size(), 2u);
  EXPECT_DOUBLE_EQ(preview.points()[0].x, 0.0);
  EXPECT_DOUBLE_EQ(preview.points()[1].x, 4.0);
  EXPECT_TRUE(preview.points()[1].rapid);
  EXPECT_EQ(preview.added(), 8u);
}

TEST(EthernutPreview, AManyPointJobStaysWithinTheLimitAndKeepsAtLeastHalfOfIt)
{
  for (const size_t limit : {size_t(0), size_t(2), size_t(7), size_t(1000)})
  {
    SCOPED_TRACE("limit " + std::to_string(limit));
    Preview preview(limit);
    const size_t bound = std::max<size_t>(limit, 2);
    for (int i = 0; i < 100000; ++i)
    {
      preview.add(i, i, i, false);
      ASSERT_LT(preview.points().size(), bound);
    }
    EXPECT_GE(preview.points().size(), bound / 2);
    EXPECT_DOUBLE_EQ(preview.points().front().x, 0.0);  // the start is kept
    for (size_t i = 1; i < preview.points().size(); ++i)
    {
      EXPECT_LT(preview.points()[i - 1].x, preview.points()[i].x);  // in order
    }
  }
}

// ------------------------------------------------------------------------- MotionHold
using cnc_bridge::test::CancelProbe;
using cnc_bridge::test::kPatience;

TEST(EthernutMotionHold, ADisableHoldsOnlyARunningGoalAndTheFirstDisableNamesIt)
{
  MotionHold hold;
  EXPECT_FALSE(hold.disable("motion disabled by /cell"));  // no goal runs
  EXPECT_EQ(hold.hold(), "");
  hold.setGoalRunning(true);
  EXPECT_TRUE(hold.disable("motion disabled by /operator"));
  EXPECT_TRUE(hold.disable("motion disabled by /cell"));
  EXPECT_EQ(hold.hold(), "motion disabled by /operator");
  EXPECT_EQ(hold.resume(), "motion disabled by /operator");
  EXPECT_EQ(hold.hold(), "");
  EXPECT_EQ(hold.resume(), "");  // nothing left, the resume counted all the same
  EXPECT_EQ(hold.snapshot().resumes, 2u);
  EXPECT_TRUE(hold.disable("motion disabled by /cell"));
  hold.setGoalRunning(false);
  EXPECT_EQ(hold.hold(), "");  // the goal ended: no hold outlives it
}

TEST(EthernutMotionHold, OnlyAResumeAfterTheSnapshotEndsTheWait)
{
  MotionHold hold(std::chrono::hours(1));
  const MotionHold::Snapshot before = hold.snapshot();
  hold.resume();
  EXPECT_TRUE(hold.waitForResume(before.resumes, [] { return false; }));
  const MotionHold::Snapshot after = hold.snapshot();
  EXPECT_FALSE(hold.waitForResume(after.resumes, [] { return true; }));  // the earlier resume does not count
}

TEST(EthernutMotionHold, AResumeWakesAWaitingJobAndACancelEndsTheWait)
{
  MotionHold hold(std::chrono::hours(1));  // only the resume's notification can end this wait
  hold.setGoalRunning(true);
  hold.disable("motion disabled by /operator");
  CancelProbe probe;
  const uint64_t resumes = hold.snapshot().resumes;
  auto waiting = std::async(std::launch::async, [&] { return hold.waitForResume(resumes, probe.predicate()); });
  ASSERT_EQ(probe.asked.get_future().wait_for(kPatience), std::future_status::ready);
  EXPECT_EQ(hold.resume(), "motion disabled by /operator");
  ASSERT_EQ(waiting.wait_for(kPatience), std::future_status::ready);
  EXPECT_TRUE(waiting.get());

  MotionHold polled(std::chrono::milliseconds(5));
  CancelProbe cancel;
  auto cancelled = std::async(std::launch::async, [&] { return polled.waitForResume(0, cancel.predicate()); });
  ASSERT_EQ(cancel.asked.get_future().wait_for(kPatience), std::future_status::ready);
  cancel.cancel = true;  // no notification: the wait finds it by polling
  ASSERT_EQ(cancelled.wait_for(kPatience), std::future_status::ready);
  EXPECT_FALSE(cancelled.get());
}
