// Time to cycle end (cnc_bridge/cell/cycle_time.h): the planned time of small programs against the
// closed forms of a trapezoid from rest to rest (t = L/v + v/a when the move reaches its speed,
// 2 sqrt(L/a) when it does not), dwells, tool changes, rapids at the axes' rapid rate, the feed
// capped by the profile; then the countdown on a clock, its feed holds and its refinement from
// reported blocks.
#include <gtest/gtest.h>

#include <stdlib.h>

#include <cmath>
#include <cstdlib>
#include <fstream>
#include <memory>
#include <sstream>
#include <string>

#include "cnc_bridge/cell/cycle_time.h"
#include "cnc_bridge/common/error.h"

using namespace cnc_bridge;
using namespace cnc_bridge::cell;

namespace
{
// Every axis: rapids at 100 mm/s, 1000 mm/s^2 of which the planner keeps 20 % for corners, so a
// straight move accelerates at 800 mm/s^2; cutting at most 50 mm/s; a tool change takes 7 s.
CycleProfile profile()
{
  CycleProfile p;
  p.max_feed = 50.0;
  p.rapid_rate = 100.0;
  p.acceleration = 1000.0;
  p.tool_change_time = 7.0;
  p.corner_share = 0.2;
  return p;
}
constexpr double kAccel = 800.0;  // mm/s^2 along a straight move of one axis

// Rest to rest over L at speed v with acceleration a.
double trapezoid(double length, double v, double a)
{
  return length >= v * v / a ? length / v + v / a : 2.0 * std::sqrt(length / a);
}

CyclePlan plan(const std::string& program, const CycleProfile& p = profile())
{
  std::istringstream in(program);
  return CyclePlan::plan(in, p, "test program");
}
}  // namespace

TEST(CycleTime, FeedMoveOfKnownLengthAtKnownFeed)
{
  // 100 mm at F1200 (20 mm/s): 100/20 + 20/800 s.
  const CyclePlan p = plan("G21 G90\nG01 X100. F1200.\nM30\n");
  EXPECT_NEAR(p.total(), trapezoid(100.0, 20.0, kAccel), 1e-9);
  EXPECT_NEAR(p.total(), 5.025, 1e-9);
}

TEST(CycleTime, ShortMoveNeverReachesItsFeed)
{
  // 2 mm at 40 mm/s would need 2 mm to reach and leave its speed: 2 sqrt(L/a).
  const CyclePlan p = plan("G21 G90\nG01 X2. F2400.\nM30\n");
  EXPECT_NEAR(p.total(), 2.0 * std::sqrt(2.0 / kAccel), 1e-9);
}

TEST(CycleTime, FeedAboveTheProfilesMaxFeedRunsAtIt)
{
  const CyclePlan p = plan("G21 G90\nG01 X100. F6000.\nM30\n");  // 100 mm/s asked, 50 allowed
  EXPECT_NEAR(p.total(), trapezoid(100.0, 50.0, kAccel), 1e-9);
}

TEST(CycleTime, InchFeedsAndLengths)
{
  // 2 in = 50.8 mm at 30 in/min = 12.7 mm/s.
  const CyclePlan p = plan("G20 G90\nG01 X2. F30.\nM30\n");
  EXPECT_NEAR(p.total(), trapezoid(50.8, 12.7, kAccel), 1e-9);
}

TEST(CycleTime, RapidAtTheAxesRapidRate)
{
  // X30 Y40: direction (0.6, 0.8); Y at its 100 mm/s limit gives 125 mm/s along the path, and its
  // 1000 mm/s^2 gives 1250 (0.8 of it: 1000) along the path.
  const CyclePlan p = plan("G21 G90\nG00 X30. Y40.\nM30\n");
  EXPECT_NEAR(p.total(), 50.0 / 125.0 + 125.0 / 1000.0, 1e-9);
}

TEST(CycleTime, DwellInSecondsOrMillisecondsPerDialect)
{
  EXPECT_NEAR(plan("G04 P2.5\nM30\n").total(), 2.5, 1e-12);  // Haas: a decimal point, seconds
  EXPECT_NEAR(plan("G04 P500\nM30\n").total(), 0.5, 1e-12);  // Haas: without, milliseconds
  CycleProfile linuxcnc = profile();
  linuxcnc.dialect = gcode::Dialect::kLinuxCnc;
  EXPECT_NEAR(plan("G04 P3\nM2\n", linuxcnc).total(), 3.0, 1e-12);  // LinuxCNC: seconds
}

TEST(CycleTime, ToolChangeTakesTheProfilesTime)
{
  EXPECT_NEAR(plan("T2 M06\nT5 M06\nM30\n").total(), 14.0, 1e-12);
  CycleProfile quick = profile();
  quick.tool_change_time = 1.5;
  EXPECT_NEAR(plan("T2 M06\nM30\n", quick).total(), 1.5, 1e-12);
}

TEST(CycleTime, BlocksOnTheTimeLine)
{
  // line 1: comment (no block), 2: tool change 7 s, 3: rapid 10 mm on X, 4: dwell 1 s, 5: feed
  // 20 mm at 10 mm/s, 6: M30.
  const CyclePlan p = plan("(part)\nT1 M06\nG00 X10.\nG04 P1.\nG01 X30. F600.\nM30\n");
  const double rapid = trapezoid(10.0, 100.0, kAccel);
  const double feed = trapezoid(20.0, 10.0, kAccel);
  ASSERT_EQ(p.blocks().size(), 5u);
  const uint32_t lines[] = {2, 3, 4, 5, 6};
  const double durations[] = {7.0, rapid, 1.0, feed, 0.0};
  double start = 0.0;
  for (size_t i = 0; i < 5; ++i)
  {
    EXPECT_EQ(p.blocks()[i].line, lines[i]);
    EXPECT_NEAR(p.blocks()[i].start, start, 1e-9);
    EXPECT_NEAR(p.blocks()[i].duration, durations[i], 1e-9);
    start += durations[i];
  }
  EXPECT_NEAR(p.total(), 7.0 + rapid + 1.0 + feed, 1e-9);
  EXPECT_NEAR(p.remainingFrom(3), feed, 1e-9);
  EXPECT_EQ(p.find(1), 0u);  // a line without a block: the next block
  EXPECT_EQ(p.find(5), 3u);
  EXPECT_FALSE(p.find(7));
}

TEST(CycleTime, CornersAreBlendedNotStoppedOn)
{
  // Two collinear 50 mm feed moves at 20 mm/s take as long as one 100 mm move: the planner's
  // look-ahead passes the junction at speed (an exact stop would add 20/800 s).
  const CyclePlan p = plan("G21 G90\nG01 X50. F1200.\nX100.\nM30\n");
  EXPECT_NEAR(p.total(), trapezoid(100.0, 20.0, kAccel), 1e-9);
  ASSERT_EQ(p.blocks().size(), 3u);
  EXPECT_NEAR(p.blocks()[0].duration, 50.0 / 20.0 + 20.0 / (2 * kAccel), 1e-9);
}

TEST(CycleTime, ArcChordsMakeOneBlock)
{
  const CyclePlan p = plan("G21 G90 G17\nG01 X10. F600.\nG02 X-10. I-10. J0.\nM30\n");
  ASSERT_EQ(p.blocks().size(), 3u);
  EXPECT_EQ(p.blocks()[1].line, 3u);
  // Half a circle of radius 10 at 10 mm/s: pi s, and a little more where the planner slows for
  // the chords' corners.
  EXPECT_GT(p.blocks()[1].duration, M_PI - 1e-3);
  EXPECT_LT(p.blocks()[1].duration, 1.25 * M_PI);
}

TEST(CycleTime, NothingAfterTheProgramEnd)
{
  EXPECT_NEAR(plan("G04 P1.\nM30\nG04 P5.\n").total(), 1.0, 1e-12);
}

TEST(CycleTime, WhatCannotBePlannedIsAnErrorNotANumber)
{
  try
  {
    plan("G21 G90\nG01 X10.\nM30\n");
    FAIL() << "a feed move without F planned";
  }
  catch (const ConfigError& e)
  {
    EXPECT_NE(std::string(e.what()).find("line 2"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("no feed"), std::string::npos) << e.what();
  }
  EXPECT_THROW(plan("#100 = 1\nM30\n"), gcode::ParseError);  // macros: the parser refuses them
  CycleProfile bad = profile();
  bad.rapid_rate = 0.0;
  try
  {
    plan("M30\n", bad);
    FAIL() << "a zero rapid rate accepted";
  }
  catch (const ConfigError& e)
  {
    EXPECT_NE(std::string(e.what()).find("rapid_rate"), std::string::npos) << e.what();
  }
  bad = profile();
  bad.tool_change_time = std::nan("");
  EXPECT_THROW(plan("M30\n", bad), ConfigError);
}

namespace
{
// T1 M06 (7 s), G04 P2. (2 s), G04 P3. (3 s), M30: 12 s.
std::shared_ptr<const CyclePlan> twelveSeconds()
{
  return std::make_shared<CyclePlan>(plan("T1 M06\nG04 P2.\nG04 P3.\nM30\n"));
}
}  // namespace

TEST(CycleCountdown, RunsOnTheClock)
{
  CycleCountdown countdown(twelveSeconds(), 100.0);
  EXPECT_DOUBLE_EQ(countdown.remaining(100.0), 12.0);
  EXPECT_DOUBLE_EQ(countdown.remaining(104.5), 7.5);
  EXPECT_DOUBLE_EQ(countdown.remaining(112.0), 0.0);
  EXPECT_DOUBLE_EQ(countdown.remaining(130.0), 0.0);  // slower than planned: due now, never negative
}

TEST(CycleCountdown, StandsStillInAFeedHold)
{
  CycleCountdown countdown(twelveSeconds(), 0.0);
  countdown.setRunning(false, 3.0);
  EXPECT_DOUBLE_EQ(countdown.remaining(10.0), 9.0);
  countdown.setRunning(false, 10.0);  // held again: no change
  countdown.setRunning(true, 10.0);
  EXPECT_DOUBLE_EQ(countdown.remaining(11.0), 8.0);
  CycleCountdown held_from_start(twelveSeconds(), 0.0, false);
  EXPECT_DOUBLE_EQ(held_from_start.remaining(50.0), 12.0);
}

TEST(CycleCountdown, RefinedFromAReportedBlock)
{
  CycleCountdown countdown(twelveSeconds(), 0.0);
  // At 1 s the machine reports line 3 (the 3 s dwell, planned from 9 s): 3 s left, not 11.
  EXPECT_TRUE(countdown.reportBlock(3, 1.0));
  EXPECT_DOUBLE_EQ(countdown.remaining(1.0), 3.0);
  EXPECT_DOUBLE_EQ(countdown.remaining(2.0), 2.0);
  // The same block reported again changes nothing.
  EXPECT_TRUE(countdown.reportBlock(3, 2.5));
  EXPECT_DOUBLE_EQ(countdown.remaining(2.5), 1.5);
  // The clock never runs past the reported block's end: still in line 3 at 10 s, M30 next.
  EXPECT_DOUBLE_EQ(countdown.remaining(10.0), 0.0);
  EXPECT_EQ(countdown.reportedBlock(), 2u);
}

TEST(CycleCountdown, ABlockCapsTheClockAndALaterBlockMovesOn)
{
  CycleCountdown countdown(twelveSeconds(), 0.0);
  EXPECT_TRUE(countdown.reportBlock(1, 0.0));        // the tool change, 0..7 s
  EXPECT_DOUBLE_EQ(countdown.remaining(20.0), 5.0);  // a slow tool change: held at its end
  EXPECT_TRUE(countdown.reportBlock(2, 20.0));       // the 2 s dwell starts
  EXPECT_DOUBLE_EQ(countdown.remaining(21.0), 4.0);
  // The clock ahead of a report keeps its estimate inside the reported block.
  CycleCountdown ahead(twelveSeconds(), 0.0);
  EXPECT_TRUE(ahead.reportBlock(2, 8.0));  // 8 s run: 1 s into the dwell of 7..9 s
  EXPECT_DOUBLE_EQ(ahead.remaining(8.0), 4.0);
}

TEST(CycleCountdown, AnUnknownLineLeavesTheClock)
{
  CycleCountdown countdown(twelveSeconds(), 0.0);
  EXPECT_FALSE(countdown.reportBlock(99, 1.0));
  EXPECT_DOUBLE_EQ(countdown.remaining(1.0), 11.0);
  EXPECT_FALSE(countdown.reportedBlock());
  // A line before the block reported last is looked for from that block on (a loop runs it
  // again), never before it: the estimate does not go back.
  EXPECT_TRUE(countdown.reportBlock(3, 2.0));
  countdown.reportBlock(1, 2.0);
  EXPECT_DOUBLE_EQ(countdown.remaining(2.0), 3.0);
  EXPECT_EQ(countdown.reportedBlock(), 2u);
}

namespace
{
// A program folder in /tmp with the files given, removed at the end.
class Folder
{
 public:
  Folder()
  {
    char pattern[] = "/tmp/cycle_time_XXXXXX";
    path_ = ::mkdtemp(pattern);
  }
  ~Folder() { std::system(("rm -rf '" + path_ + "'").c_str()); }
  void write(const std::string& name, const std::string& text) const { std::ofstream(path_ + "/" + name) << text; }
  const std::string& path() const { return path_; }

 private:
  std::string path_;
};

CycleObservation seen(Execution execution, const std::string& program = "O00110", uint32_t block = 0,
                      Link link = Link::Up)
{
  CycleObservation observation;
  observation.link = link;
  observation.execution = execution;
  observation.program = program;
  observation.block = block;
  return observation;
}

const char* const kTwelveSeconds = "%\nO00110\nT1 M06\nG04 P2.\nG04 P3.\nM30\n%\n";
}  // namespace

TEST(CycleWatch, FromCycleStartToCycleEnd)
{
  Folder folder;
  folder.write("O00110.nc", kTwelveSeconds);
  CycleWatch watch(profile(), folder.path());
  watch.observe(seen(Execution::Ready), 0.0);
  EXPECT_TRUE(std::isnan(watch.predict(0.0).remaining));
  EXPECT_EQ(watch.predict(0.0).reason, "no cycle running");
  watch.observe(seen(Execution::Active), 10.0);
  CyclePrediction p = watch.predict(10.0);
  EXPECT_EQ(p.program, "O00110");
  EXPECT_DOUBLE_EQ(p.planned, 12.0);
  EXPECT_DOUBLE_EQ(p.remaining, 12.0);
  EXPECT_TRUE(p.reason.empty());
  EXPECT_DOUBLE_EQ(watch.predict(13.0).remaining, 9.0);
  watch.observe(seen(Execution::Paused), 13.0);  // a feed hold: the countdown stands
  EXPECT_DOUBLE_EQ(watch.predict(20.0).remaining, 9.0);
  watch.observe(seen(Execution::Active), 20.0);
  watch.observe(seen(Execution::Active, "O00110", 5), 21.0);  // line 5: the 3 s dwell from 9 s
  p = watch.predict(21.0);
  EXPECT_DOUBLE_EQ(p.remaining, 3.0);
  EXPECT_EQ(p.block, 5u);
  watch.observe(seen(Execution::Ready), 24.0);  // the cycle's end
  EXPECT_TRUE(std::isnan(watch.predict(24.0).remaining));
  EXPECT_TRUE(std::isnan(watch.predict(24.0).planned));
}

TEST(CycleWatch, ACycleUnderWayAtTheStartIsUnknownUntilABlockIsReported)
{
  Folder folder;
  folder.write("O00110", kTwelveSeconds);  // found without .nc too
  CycleWatch watch(profile(), folder.path());
  watch.observe(seen(Execution::Active), 5.0);
  CyclePrediction p = watch.predict(5.0);
  EXPECT_TRUE(std::isnan(p.remaining));
  EXPECT_DOUBLE_EQ(p.planned, 12.0);
  EXPECT_NE(p.reason.find("before its start was seen"), std::string::npos) << p.reason;
  watch.observe(seen(Execution::Active, "O00110", 4), 6.0);  // line 4: the 2 s dwell from 7 s
  EXPECT_DOUBLE_EQ(watch.predict(6.0).remaining, 5.0);
}

TEST(CycleWatch, ALostLinkEndsThePrediction)
{
  Folder folder;
  folder.write("O00110.nc", kTwelveSeconds);
  CycleWatch watch(profile(), folder.path());
  watch.observe(seen(Execution::Ready), 0.0);
  watch.observe(seen(Execution::Active), 1.0);
  EXPECT_FALSE(std::isnan(watch.predict(2.0).remaining));
  watch.observe(seen(Execution::Active, "O00110", 0, Link::Down), 2.0);
  EXPECT_TRUE(std::isnan(watch.predict(2.0).remaining));
  // Back up in the middle of the cycle: its start was not seen.
  watch.observe(seen(Execution::Active), 3.0);
  EXPECT_TRUE(std::isnan(watch.predict(3.0).remaining));
}

TEST(CycleWatch, AProgramNotFoundOrNotPlannableGivesItsReasonNotANumber)
{
  Folder folder;
  folder.write("O01000.nc", "%\nO01000\n#100 = 0\nM30\n%\n");  // a macro program
  folder.write("O02000.nc", "%\nO02000\nG01 X10.\nM30\n%\n");  // no feed
  CycleWatch watch(profile(), folder.path());
  const struct
  {
    const char* program;
    const char* reason;
  } cases[] = {{"O09999", "is not in"},
               {"O01000", "line 3"},
               {"O02000", "no feed"},
               {"../etc/passwd", "not in"},
               {"", "no program"}};
  for (const auto& c : cases)
  {
    watch.observe(seen(Execution::Ready, c.program), 0.0);
    watch.observe(seen(Execution::Active, c.program), 1.0);
    const CyclePrediction p = watch.predict(1.0);
    EXPECT_TRUE(std::isnan(p.remaining)) << c.program;
    EXPECT_NE(p.reason.find(c.reason), std::string::npos) << c.program << ": " << p.reason;
  }
  EXPECT_THROW(CycleWatch(profile(), ""), ConfigError);
}

TEST(CycleWatch, AProgramChangedBetweenCyclesIsPlannedAgain)
{
  Folder folder;
  folder.write("O00110.nc", kTwelveSeconds);
  CycleWatch watch(profile(), folder.path());
  watch.observe(seen(Execution::Ready), 0.0);
  watch.observe(seen(Execution::Active), 1.0);
  EXPECT_DOUBLE_EQ(watch.predict(1.0).planned, 12.0);
  watch.observe(seen(Execution::Ready), 2.0);
  folder.write("O00110.nc", "%\nO00110\nG04 P4.5\nM30\n%\n");  // another size: another version
  watch.observe(seen(Execution::Active), 3.0);
  EXPECT_DOUBLE_EQ(watch.predict(3.0).planned, 4.5);
}
