// JobRunner: the one job runner of the nodes that execute programs (ethernut_node, the '@'
// controller): the program's own steps between two segments (M00, M01 and the optional stop
// switch, G04, tool/spindle/coolant), the holds of a disabled motion switch, resume and cancel;
// without ROS, against a recording listener.
#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <future>
#include <mutex>
#include <string>
#include <vector>

#include "cnc_bridge/common/job_runner.h"

using namespace cnc_bridge;

namespace
{
constexpr auto kPatience = std::chrono::seconds(10);  // a wait that must end ends long before this

gcode::ProgramStep step(gcode::ProgramStep::Kind kind, uint32_t line, uint16_t m_code = 0)
{
  gcode::ProgramStep s;
  s.kind = kind;
  s.line = line;
  s.m_code = m_code;
  return s;
}

/// Every call of the runner as a line of text, in order; a test waits for one to come.
class Recorder : public JobListener
{
 public:
  std::atomic<bool> cancel{false};
  std::atomic<bool> optional_stop{true};

  bool cancelRequested() override
  {
    add("asked");
    return cancel.load();
  }
  bool optionalStop() override { return optional_stop.load(); }
  void stepReached(const gcode::ProgramStep& s) override { add("reached " + s.describe()); }
  void stepDone(const gcode::ProgramStep&, const JobFeedback& f) override { add("done " + f.event); }
  void dwelling(const JobFeedback& f) override { add("dwelling " + f.event); }
  void optionalStopPassed(const JobFeedback& f) override { add("passed " + f.event); }
  void holding(const JobFeedback& f, uint32_t line) override
  {
    add("holding " + f.event + " @" + std::to_string(line) + (f.paused ? " paused" : ""));
  }
  void resumed(const std::string& what) override { add("resumed " + what); }
  void motionHeld(const std::string& hold) override { add("motion held " + hold); }
  void motionResumed(const std::string& hold) override { add("motion resumed " + hold); }

  /// Waits until a call starting with \p prefix came.
  bool waitFor(const std::string& prefix)
  {
    std::unique_lock<std::mutex> lock(mutex_);
    return changed_.wait_for(lock, kPatience,
                             [&] {
                               return std::any_of(calls_.begin(), calls_.end(),
                                                  [&](const std::string& c) { return c.rfind(prefix, 0) == 0; });
                             });
  }
  /// The calls but the cancel questions.
  std::vector<std::string> calls()
  {
    std::lock_guard<std::mutex> lock(mutex_);
    std::vector<std::string> out;
    std::copy_if(calls_.begin(), calls_.end(), std::back_inserter(out),
                 [](const std::string& c) { return c != "asked"; });
    return out;
  }

 private:
  void add(const std::string& call)
  {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      if (call == "asked" && !calls_.empty() && calls_.back() == "asked")
      {
        return;  // the polls of one wait, once
      }
      calls_.push_back(call);
    }
    changed_.notify_all();
  }

  std::mutex mutex_;
  std::condition_variable changed_;
  std::vector<std::string> calls_;
};

class JobRunnerTest : public ::testing::Test
{
 protected:
  SafetySwitch motion{SafetySwitch::Names{"motion", "/mill/set_motion_enabled", "/mill/enable_motion"}, true};
  JobRunner runner{motion, JobRunner::Names{"/mill/resume", "/mill/set_motion_enabled", "/mill/optional_stop"}};
  Recorder listener;
  JobFeedback feedback;
};
}  // namespace

TEST_F(JobRunnerTest, AProgramStopHoldsUntilResumeWhichIsRefusedWhileMotionIsDisabled)
{
  const std::string nothing = "nothing to resume";
  EXPECT_EQ(runner.resume(nothing).message, nothing);
  const gcode::ProgramStep m00 = step(gcode::ProgramStep::Kind::kStop, 7);
  auto run = std::async(std::launch::async, [&] { return runner.carryOut(m00, feedback, listener); });
  ASSERT_TRUE(listener.waitFor("holding"));
  EXPECT_EQ(runner.held(), m00.describe());
  motion.set(false, "/cell_manager");
  const ResumeAnswer refused = runner.resume(nothing);
  EXPECT_FALSE(refused.success);
  EXPECT_EQ(refused.message, motion.refusal("resume"));
  EXPECT_EQ(runner.held(), m00.describe());  // still held
  motion.set(true, "/cell_manager");
  const ResumeAnswer resumed = runner.resume(nothing);
  EXPECT_TRUE(resumed.success);
  EXPECT_EQ(resumed.message, "resumed after the " + m00.describe());
  ASSERT_EQ(run.wait_for(kPatience), std::future_status::ready);
  EXPECT_TRUE(run.get());
  EXPECT_FALSE(feedback.paused);
  EXPECT_EQ(listener.calls(),
            (std::vector<std::string>{"reached " + m00.describe(),
                                      "holding " + m00.describe() + ": waiting for /mill/resume @7 paused",
                                      "resumed " + m00.describe()}));
}

TEST_F(JobRunnerTest, AnOptionalStopPassesWhenTheSwitchIsOffAndHoldsWhenItIsOn)
{
  const gcode::ProgramStep m01 = step(gcode::ProgramStep::Kind::kOptionalStop, 3, 1);
  listener.optional_stop = false;
  EXPECT_TRUE(runner.carryOut(m01, feedback, listener));
  EXPECT_EQ(feedback.event, m01.describe() + " passed (/mill/optional_stop false)");
  EXPECT_EQ(runner.held(), "");
  listener.optional_stop = true;
  auto run = std::async(std::launch::async, [&] { return runner.carryOut(m01, feedback, listener); });
  ASSERT_TRUE(listener.waitFor("holding " + m01.describe()));
  EXPECT_TRUE(runner.resume("").success);
  ASSERT_EQ(run.wait_for(kPatience), std::future_status::ready);
  EXPECT_TRUE(run.get());
}

TEST_F(JobRunnerTest, ACancelWhileHeldEndsTheHoldWithNothingLeftToResume)
{
  const gcode::ProgramStep m00 = step(gcode::ProgramStep::Kind::kStop, 12);
  auto run = std::async(std::launch::async, [&] { return runner.carryOut(m00, feedback, listener); });
  ASSERT_TRUE(listener.waitFor("holding"));
  listener.cancel = true;  // no notification: the wait finds it by polling
  ASSERT_EQ(run.wait_for(kPatience), std::future_status::ready);
  EXPECT_FALSE(run.get());
  EXPECT_EQ(runner.held(), "");
  EXPECT_FALSE(runner.resume("nothing").success);
  const std::vector<std::string> calls = listener.calls();
  EXPECT_EQ(std::count_if(calls.begin(), calls.end(), [](const std::string& c) { return c.rfind("resumed", 0) == 0; }),
            0);
}

TEST_F(JobRunnerTest, ADwellWaitsItsTimeAndACancelEndsItEarly)
{
  gcode::ProgramStep dwell = step(gcode::ProgramStep::Kind::kDwell, 5);
  dwell.dwell_s = 0.05;
  const auto start = std::chrono::steady_clock::now();
  EXPECT_TRUE(runner.carryOut(dwell, feedback, listener));
  EXPECT_GE(std::chrono::steady_clock::now() - start, std::chrono::milliseconds(50));
  EXPECT_EQ(listener.calls().back(), "dwelling " + dwell.describe());
  dwell.dwell_s = 3600.0;
  listener.cancel = true;
  auto run = std::async(std::launch::async, [&] { return runner.carryOut(dwell, feedback, listener); });
  ASSERT_EQ(run.wait_for(kPatience), std::future_status::ready);
  EXPECT_FALSE(run.get());
}

TEST_F(JobRunnerTest, ToolSpindleAndCoolantStepsAreReportedWithoutAHold)
{
  gcode::ProgramStep tool = step(gcode::ProgramStep::Kind::kToolChange, 2, 6);
  tool.tool = 4;
  gcode::ProgramStep coolant = step(gcode::ProgramStep::Kind::kCoolant, 3, 8);
  coolant.coolant = true;
  EXPECT_TRUE(runner.carryOut(tool, feedback, listener));
  EXPECT_TRUE(runner.carryOut(coolant, feedback, listener));
  EXPECT_EQ(listener.calls(),
            (std::vector<std::string>{"reached " + tool.describe(), "done " + tool.describe(),
                                      "reached " + coolant.describe(), "done " + coolant.describe()}));
  EXPECT_EQ(runner.held(), "");
}

// The ethernut board keeps its move when motion is disabled: the job is held from the disable
// until motion is enabled AND resume is called; enabling alone starts nothing.
TEST_F(JobRunnerTest, ADisableDuringAJobHoldsItsNextSegmentUntilEnabledAndResumed)
{
  const JobRunner::Scope job(runner);
  motion.set(false, "/cell_manager");
  EXPECT_TRUE(runner.holdOnDisable("motion disabled by /cell_manager"));
  EXPECT_TRUE(runner.holdOnDisable("motion disabled by /later"));  // the first disable is named
  EXPECT_EQ(runner.motionHold(), "motion disabled by /cell_manager");
  std::atomic<int> started{0};
  auto run = std::async(std::launch::async, [&] { return runner.startSegment([&] { ++started; }, listener); });
  ASSERT_TRUE(listener.waitFor("motion held motion disabled by /cell_manager"));
  motion.set(true, "/cell_manager");
  EXPECT_EQ(run.wait_for(std::chrono::milliseconds(100)), std::future_status::timeout);  // enabled alone: held
  EXPECT_EQ(started.load(), 0);
  const ResumeAnswer resumed = runner.resume("nothing");
  EXPECT_TRUE(resumed.success);
  EXPECT_EQ(resumed.message, "resumed after the hold (motion disabled by /cell_manager)");
  ASSERT_EQ(run.wait_for(kPatience), std::future_status::ready);
  EXPECT_TRUE(run.get());
  EXPECT_EQ(started.load(), 1);
  EXPECT_EQ(runner.motionHold(), "");
  EXPECT_EQ(listener.calls().back(), "motion resumed motion disabled by /cell_manager");
}

TEST_F(JobRunnerTest, WithoutARunningJobADisableHoldsNothingAndASegmentStartsAtOnce)
{
  EXPECT_FALSE(runner.holdOnDisable("motion disabled by /cell_manager"));
  EXPECT_EQ(runner.motionHold(), "");
  bool started = false;
  EXPECT_TRUE(runner.startSegment([&] { started = true; }, listener));
  EXPECT_TRUE(started);
  EXPECT_TRUE(listener.calls().empty());
}

TEST_F(JobRunnerTest, ACancelWhileASegmentIsHeldStartsNothing)
{
  const JobRunner::Scope job(runner);
  motion.set(false, "/cell_manager");  // the listener has not named the hold: "motion disabled"
  listener.cancel = true;
  bool started = false;
  EXPECT_FALSE(runner.startSegment([&] { started = true; }, listener));
  EXPECT_FALSE(started);
  EXPECT_EQ(listener.calls(), std::vector<std::string>{"motion held motion disabled"});
}

// The '@' controller decelerates to a stop when disabled: between two operations the goal holds
// only while motion is disabled, and goes on once enabled and resumed.
TEST_F(JobRunnerTest, AwaitMotionHoldsWhileMotionIsDisabledUntilEnabledAndResumed)
{
  std::string held_at;
  EXPECT_TRUE(runner.awaitMotion(feedback, listener, held_at));  // enabled: no hold
  EXPECT_TRUE(listener.calls().empty());
  motion.set(false, "/cell_manager");
  auto run = std::async(std::launch::async, [&] { return runner.awaitMotion(feedback, listener, held_at); });
  ASSERT_TRUE(listener.waitFor("holding"));
  EXPECT_EQ(
      listener.calls().back(),
      "holding motion disabled by /cell_manager (/mill/set_motion_enabled) before the next operation: waiting for "
      "/mill/resume @0 paused");
  EXPECT_FALSE(runner.resume("").success);  // still disabled
  motion.set(true, "/operator");
  EXPECT_EQ(runner.resume("").message, "resumed after the stop when motion was disabled by /cell_manager");
  ASSERT_EQ(run.wait_for(kPatience), std::future_status::ready);
  EXPECT_TRUE(run.get());
}

TEST_F(JobRunnerTest, WakeMakesAHeldJobAskForItsCancelAtOnce)
{
  JobRunner slow(motion, JobRunner::Names{}, nullptr, std::chrono::hours(1));  // no poll ends a wait in the test
  auto run = std::async(std::launch::async,
                        [&] { return slow.carryOut(step(gcode::ProgramStep::Kind::kStop, 1), feedback, listener); });
  ASSERT_TRUE(listener.waitFor("holding"));
  ASSERT_TRUE(listener.waitFor("asked"));
  listener.cancel = true;
  slow.wake();
  ASSERT_EQ(run.wait_for(kPatience), std::future_status::ready);
  EXPECT_FALSE(run.get());
}
