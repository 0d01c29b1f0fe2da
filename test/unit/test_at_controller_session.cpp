// The controller session (controller_session.h) against fake links: reports folded into the
// snapshot, link loss reported (and the e-stop then unknown), the motion gate refusing with
// nothing sent, a disable during an operation, and a goal's plan; the goal runner
// (goal_runner.h): program stops held until resume, cancel while held, M01 and M30, a pause by a
// disable resumed to the path's end; the jog deadman's stop and the session monitor's diagnostics.
// The tests wait on the events of the listeners or on the bytes the fake controller receives, never
// on sleeps.
#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <future>
#include <mutex>
#include <thread>

#include "cnc_bridge/at_protocol/controller_session.h"
#include "cnc_bridge/at_protocol/goal_runner.h"
#include "cnc_bridge/at_protocol/session_monitor.h"
#include "cnc_bridge/common/error.h"
#include "cnc_bridge/transport/forwarding_transport.h"
#include "testing/fake_transport.h"

using namespace cnc_bridge;
using namespace cnc_bridge::at_protocol;

namespace
{
const Milliseconds kWait(10000);

/// A link the session owns that forwards to a FakeTransport the test keeps.
class SharedFake : public ForwardingTransport
{
 public:
  explicit SharedFake(const std::shared_ptr<FakeTransport>& fake) : ForwardingTransport(*fake), fake_(fake) {}

 private:
  std::shared_ptr<FakeTransport> fake_;
};

/// Everything the session told its listener, and the links it opened, to wait on.
struct Recorder : ControllerListener
{
  struct LinkEvent
  {
    LinkState combined;
    std::string why;
    bool reports_lost;
  };

  std::mutex mutex;
  std::condition_variable changed;
  std::vector<LinkEvent> links;
  std::vector<std::string> reports;  // the events' messages, position reports as "position"
  std::vector<std::string> errors;
  std::vector<JogStop> jog_stops;
  std::vector<std::shared_ptr<FakeTransport>> command_links, report_links;

  void onLink(LinkState combined, const std::string& why, bool reports_lost) override
  {
    record([&] { links.push_back({combined, why, reports_lost}); });
  }
  void onReport(const ReportEvent& event, const ControllerSnapshot&) override
  {
    record([&] { reports.push_back(event.kind == ReportEvent::Kind::kPosition ? "position" : event.message); });
  }
  void onReportError(const std::string& what) override
  {
    record([&] { errors.push_back(what); });
  }
  void onJogStopped(const JogStop& stop) override
  {
    record([&] { jog_stops.push_back(stop); });
  }

  std::unique_ptr<Transport> open(std::vector<std::shared_ptr<FakeTransport>>& opened, const std::string& name)
  {
    auto fake = std::make_shared<FakeTransport>(name);
    record([&] { opened.push_back(fake); });
    return std::make_unique<SharedFake>(fake);
  }

  void record(const std::function<void()>& change)
  {
    {
      std::lock_guard<std::mutex> lock(mutex);
      change();
    }
    changed.notify_all();
  }

  bool waitFor(const std::function<bool()>& condition)
  {
    std::unique_lock<std::mutex> lock(mutex);
    return changed.wait_for(lock, kWait, condition);
  }

  bool linkIs(LinkState state) { return !links.empty() && links.back().combined == state; }

  /// Whether a link event was \p combined with a failure of the link \p which names.
  bool told(LinkState combined, const std::string& which)
  {
    for (const auto& event : links)
    {
      if (event.combined == combined && event.why.rfind(which, 0) == 0 && event.why.size() > which.size())
      {
        return true;
      }
    }
    return false;
  }

  std::shared_ptr<FakeTransport> lastReportLink()
  {
    std::lock_guard<std::mutex> lock(mutex);
    return report_links.back();
  }
  std::shared_ptr<FakeTransport> lastCommandLink()
  {
    std::lock_guard<std::mutex> lock(mutex);
    return command_links.back();
  }
};

/// The value of \p key in a monitor report's \p values ("(none)" if it has none).
std::string valueOf(const SessionMonitor::Values& values, const std::string& key)
{
  const auto found = std::find_if(values.begin(), values.end(), [&](const auto& value) { return value.first == key; });
  return found == values.end() ? "(none)" : found->second;
}

/// The fake controller's axes: at each operation's end (#@) they report the last setpoint received
/// plus \p offset, as a controller whose axes arrived there (or stopped short by the offset).
struct FakeAxes
{
  std::atomic<bool> arrive{true};  ///< false: no report at all after an operation
  std::array<int32_t, 3> offset{0, 0, 0};
  std::mutex mutex;
  CommandReassembler commands;  // guarded by mutex
  Setpoint last{};              // guarded by mutex

  /// \returns the report line after \p bytes written to the controller, "" if none.
  std::string after(const std::vector<uint8_t>& bytes)
  {
    std::lock_guard<std::mutex> lock(mutex);
    std::string report;
    for (const std::string& message : commands.feed(bytes.data(), bytes.size()).messages)
    {
      const Command command = decodeCommand(message);
      if (const auto* setpoint = std::get_if<Setpoint>(&command))
      {
        last = *setpoint;
      }
      else if (std::holds_alternative<EndOperation>(command) && arrive)
      {
        report = std::to_string(last.position[0] + offset[0]) + " " + std::to_string(last.position[1] + offset[1]) +
                 " " + std::to_string(last.position[2] + offset[2]) + "\n";
      }
    }
    return report;
  }
};

struct AtControllerSession : ::testing::Test
{
  Recorder recorder;
  FakeAxes axes;
  std::unique_ptr<ControllerSession> session;

  ControllerSession::Options options(bool motion_enabled)
  {
    ControllerSession::Options options;
    options.motion_enabled = motion_enabled;
    options.disabled_refusal = [](const std::string& what) { return what + " refused: motion is disabled (test)"; };
    return options;
  }

  void start(const ControllerSession::Options& options)
  {
    ControllerLinks links;
    links.command_name = "command";
    links.open_command = [this]
    {
      std::unique_ptr<Transport> link = recorder.open(recorder.command_links, "controller:5000");
      recorder.lastCommandLink()->onWrite(
          [this](FakeTransport&, const std::vector<uint8_t>& bytes)
          {
            const std::string report = axes.after(bytes);
            if (!report.empty())
            {
              recorder.lastReportLink()->feed(report);
            }
          });
      return link;
    };
    links.report_name = "report";
    links.open_report = [this] { return recorder.open(recorder.report_links, "controller:5001"); };
    session = std::make_unique<ControllerSession>(links, options, &recorder);
    session->start();
    ASSERT_TRUE(recorder.waitFor([&] { return recorder.linkIs(LinkState::kUp); }));
  }

  /// The controller reports \p lines; returns once the listener heard \p reports more reports.
  void report(const std::string& lines, size_t reports)
  {
    size_t before;
    {
      std::lock_guard<std::mutex> lock(recorder.mutex);
      before = recorder.reports.size();
    }
    recorder.lastReportLink()->feed(lines);
    ASSERT_TRUE(recorder.waitFor([&] { return recorder.reports.size() >= before + reports; }));
  }

  std::string received()
  {
    const auto bytes = recorder.lastCommandLink()->written();
    return std::string(bytes.begin(), bytes.end());
  }

  void TearDown() override
  {
    if (session)
    {
      session->stop();
    }
  }
};
}  // namespace

TEST_F(AtControllerSession, ReportsUpdateTheSnapshotAndAreTold)
{
  start(options(true));
  EXPECT_EQ(session->snapshot().estop, EStop::kUnknown);  // nothing reported yet
  EXPECT_FALSE(session->snapshot().position_valid);
  report("E0\n1000 -2000 3\r\nJY\nH\n", 4);
  ControllerSnapshot now = session->snapshot();
  EXPECT_EQ(now.estop, EStop::kOff);
  EXPECT_TRUE(now.position_valid);
  EXPECT_EQ(now.position, (std::array<int32_t, 3>{1000, -2000, 3}));
  EXPECT_EQ(now.jog_axis, 1);
  EXPECT_TRUE(now.at_home);
  {
    std::lock_guard<std::mutex> lock(recorder.mutex);
    EXPECT_EQ(recorder.reports,
              (std::vector<std::string>{"emergency stop released (E0)", "position", "jog mode, axis Y", "at home"}));
  }
  // A move leaves home; A leaves jog mode; E1 is an emergency stop.
  report("1001 -2000 3\nA\nE1\n", 3);
  now = session->snapshot();
  EXPECT_FALSE(now.at_home);
  EXPECT_EQ(now.jog_axis, -1);
  EXPECT_EQ(now.estop, EStop::kOn);
  // A line that is no report is counted and told, and the stream goes on.
  recorder.lastReportLink()->feed("hello\nE0\n");
  ASSERT_TRUE(recorder.waitFor([&] { return recorder.reports.size() >= 8; }));
  EXPECT_EQ(session->reportErrors(), 1u);
  EXPECT_EQ(session->snapshot().estop, EStop::kOff);
}

TEST_F(AtControllerSession, ALostReportLinkIsToldAndMakesTheEStopUnknownUntilTheNextE0)
{
  start(options(true));
  report("E0\n", 1);
  EXPECT_EQ(session->motionRefusal("jog"), "");
  recorder.lastReportLink()->disconnect();  // the controller closed its report socket
  ASSERT_TRUE(recorder.waitFor([&] { return recorder.told(LinkState::kDown, "report link: "); }));
  {
    std::lock_guard<std::mutex> lock(recorder.mutex);
    for (const auto& event : recorder.links)
    {
      if (event.why.rfind("report link: ", 0) == 0)
      {
        EXPECT_TRUE(event.reports_lost) << event.why;
      }
    }
  }
  EXPECT_EQ(session->snapshot().estop, EStop::kUnknown);
  EXPECT_NE(session->motionRefusal("jog").find("emergency stop state is unknown"), std::string::npos);
  // The link is opened again (after the backoff): up, but motion waits for E0 on it.
  ASSERT_TRUE(recorder.waitFor([&] { return recorder.report_links.size() == 2 && recorder.linkIs(LinkState::kUp); }));
  EXPECT_EQ(session->snapshot().estop, EStop::kUnknown);
  EXPECT_EQ(session->reportReconnects(), 1u);
  report("E0\n", 1);
  EXPECT_EQ(session->motionRefusal("jog"), "");
}

TEST_F(AtControllerSession, MotionIsRefusedWhileDisabledAndTheControllerReceivesNothing)
{
  start(options(false));
  report("E0\n", 1);
  const std::string refusal = "jog refused: motion is disabled (test)";
  Answer answer = session->jog("x", 0.01);
  EXPECT_FALSE(answer.success);
  EXPECT_EQ(answer.message, refusal);
  EXPECT_EQ(session->home().message, "go home refused: motion is disabled (test)");
  EXPECT_EQ(session->toolChange(3, 0.05).message, "tool change refused: motion is disabled (test)");
  EXPECT_EQ(session->spindle(12000).message, "spindle start refused: motion is disabled (test)");
  EXPECT_FALSE(session->jogDeadman().armed());
  EXPECT_EQ(received(), "");
  // Stopping the spindle is always allowed; enabled, the jog goes out: 10 mm/s of 50 is F51.
  EXPECT_TRUE(session->spindle(0).success);
  session->setMotionEnabled(true, "/operator");
  answer = session->jog("x", 0.01);
  EXPECT_TRUE(answer.success) << answer.message;
  EXPECT_EQ(answer.message, "sent JX@F51@");
  EXPECT_TRUE(session->jogDeadman().armed());
  EXPECT_EQ(received(), "S0@JX@F51@");
}

TEST_F(AtControllerSession, AJogWithNoNewJogCommandWithinTheDeadmanTimeGetsFeedZeroAndIsTold)
{
  ControllerSession::Options deadman = options(true);
  deadman.jog_timeout = 0.05;
  start(deadman);
  SessionMonitor monitor(*session);
  report("E0\n", 1);
  const auto jogged = Deadman::Clock::now();
  const Answer answer = session->jog("x", 0.01);
  ASSERT_TRUE(answer.success) << answer.message;
  // Nothing renews the jog: the session's deadman thread sends F0@ and tells the listener.
  ASSERT_TRUE(recorder.waitFor([&] { return !recorder.jog_stops.empty(); }));
  EXPECT_GE(Deadman::Clock::now() - jogged, std::chrono::milliseconds(50));  // not before its time
  EXPECT_EQ(received(), "JX@F51@F0@");
  {
    std::lock_guard<std::mutex> lock(recorder.mutex);
    ASSERT_EQ(recorder.jog_stops.size(), 1u);
    EXPECT_TRUE(recorder.jog_stops[0].sent) << recorder.jog_stops[0].failure;
    EXPECT_EQ(recorder.jog_stops[0].why, "jog stopped: no jog command for 0.05 s");
  }
  EXPECT_FALSE(session->jogDeadman().armed());
  EXPECT_EQ(session->lastJogStop(), "jog stopped: no jog command for 0.05 s");
  EXPECT_EQ(valueOf(monitor.report().controller, "last jog stop"), "jog stopped: no jog command for 0.05 s");
}

TEST_F(AtControllerSession, TheMonitorShowsTheEStopAsItsLevelAndTheCountersAsDiagnosticsWriteThem)
{
  start(options(true));
  SessionMonitor monitor(*session);
  SessionMonitor::Report now = monitor.report();
  EXPECT_EQ(now.level, SessionMonitor::Level::kWarn);
  EXPECT_EQ(now.summary, "emergency stop state unknown (no E0/E1 report yet)");
  EXPECT_EQ(valueOf(now.controller, "last jog stop"), "none");
  EXPECT_EQ(valueOf(now.controller, "jog deadman (s, 0: off)"), "0.5");
  report("E1\n", 1);
  now = monitor.report();
  EXPECT_EQ(now.level, SessionMonitor::Level::kError);
  EXPECT_EQ(now.summary, "emergency stop (E1)");
  recorder.lastReportLink()->feed("hello\nE0\nJY\n");
  ASSERT_TRUE(recorder.waitFor([&] { return recorder.reports.size() >= 3; }));
  now = monitor.report();
  EXPECT_EQ(now.level, SessionMonitor::Level::kOk);
  EXPECT_EQ(now.summary.rfind("phase: ", 0), 0u) << now.summary;
  EXPECT_EQ(valueOf(now.streaming, "report errors"), "1");
  EXPECT_EQ(valueOf(now.streaming, "underruns (setpoint later than one period)"), "0");
  EXPECT_EQ(valueOf(now.controller, "mode"), "jog Y");
  EXPECT_EQ(valueOf(now.controller, "at home"), "False");
  EXPECT_EQ(valueOf(now.controller, "spindle value (0..255)"), "0");
}

TEST_F(AtControllerSession, AnEStopRefusesMotionAndAFailedWriteDropsTheCommandLink)
{
  start(options(true));
  report("E1\n", 1);
  EXPECT_EQ(session->home().message, "go home refused: the controller reports an emergency stop (E1)");
  EXPECT_EQ(received(), "");
  // A@ is not motion; the controller has gone, so it fails and the link goes down and comes back.
  recorder.lastCommandLink()->disconnect();
  const Answer answer = session->setAuto();
  EXPECT_FALSE(answer.success);
  ASSERT_TRUE(recorder.waitFor([&] { return recorder.told(LinkState::kDown, "command link: "); }));
  ASSERT_TRUE(recorder.waitFor([&] { return recorder.command_links.size() == 2 && recorder.linkIs(LinkState::kUp); }));
  EXPECT_TRUE(session->setAuto().success);
  EXPECT_EQ(received(), "A@");
}

TEST_F(AtControllerSession, ADisableDuringAnOperationStopsItAlongThePathAndSaysWhoAndWhere)
{
  start(options(true));
  report("E0\n0 0 0\n", 2);
  GoalRequest goal;
  goal.has_path = true;
  goal.path_m = {{0.2, 0.0, 0.0}};
  goal.feed_rate = 0.04;
  const auto plans = session->planGoal(goal, session->snapshot().position, false, "program_commands");
  ASSERT_EQ(plans.size(), 1u);
  const Operation operation = session->operationFor(plans[0], -1, 0.0);
  std::promise<void> started;
  ControllerSession::OperationWatch watch;
  watch.started = [&](const Job&) { started.set_value(); };
  auto run = std::async(std::launch::async, [&] { return session->runOperation(plans[0], operation, watch); });
  ASSERT_EQ(started.get_future().wait_for(kWait), std::future_status::ready);
  ASSERT_TRUE(recorder.lastCommandLink()->waitForWritten(2000, kWait));  // streaming
  session->setMotionEnabled(false, "/cell_manager");
  ASSERT_EQ(run.wait_for(kWait), std::future_status::ready);
  const OperationResult result = run.get();
  EXPECT_EQ(result.job->state(), Job::State::kCancelled);
  EXPECT_FALSE(result.cancelled);
  ASSERT_TRUE(result.disabled.has_value());
  EXPECT_EQ(result.disabled->by, "/cell_manager");
  EXPECT_GT(result.disabled->sent, 0u);
  EXPECT_LT(result.disabled->sent, result.disabled->planned);
  EXPECT_GT(result.disabled->position[0], 0.0);
  EXPECT_LT(result.disabled->position[0], 200000.0);
  EXPECT_EQ(session->motionDisabledBy(), "/cell_manager");
  EXPECT_EQ(session->motionRefusal("follow_path"), "follow_path refused: motion is disabled (test)");
  const std::string sent = received();
  EXPECT_EQ(sent.compare(sent.size() - 5, 5, "#@M0@"), 0) << sent.substr(sent.size() - 40);
}

TEST_F(AtControllerSession, AGoalIsPlannedFromTheReportedPositionInWholePulses)
{
  ControllerSession::Options settings = options(true);
  settings.default_feed = 0.02;
  start(settings);
  GoalRequest goal;
  goal.has_path = true;
  goal.path_m = {{0.0010004, 0.0, 0.0}, {0.001, 0.002, -0.0005}};
  goal.tool = 4;
  session->setCoolant(true);
  const auto plans = session->planGoal(goal, {100, 0, 0}, false, "program_commands");
  ASSERT_EQ(plans.size(), 1u);
  EXPECT_EQ(plans[0].points, (std::vector<Vec3>{{100, 0, 0}, {1000, 0, 0}, {1000, 2000, -500}}));
  EXPECT_EQ(plans[0].feeds, (std::vector<double>{20.0, 20.0}));  // ~default_feed_rate, mm/s
  EXPECT_TRUE(plans[0].coolant);
  EXPECT_EQ(plans[0].tool, 4);
  // Both or neither source is refused; a program needs the program directory.
  goal.gcode_file = "part.nc";
  EXPECT_THROW(session->planGoal(goal, {0, 0, 0}, false, "program_commands"), ConfigError);
  goal.has_path = false;
  try
  {
    session->planGoal(goal, {0, 0, 0}, false, "program_commands");
    FAIL() << "a G-code goal without a program directory was planned";
  }
  catch (const ConfigError& e)
  {
    EXPECT_EQ(std::string(e.what()), "G-code goals need the parameter program_dir");
  }
}

namespace
{
/// A goal's listener that records the holds and can cancel.
struct GoalRecorder : GoalListener
{
  std::atomic<bool> cancel{false};
  bool optional_stop = true;
  std::mutex mutex;
  std::condition_variable changed;
  std::vector<std::pair<std::string, uint32_t>> holds;  // feedback event, program line
  std::vector<std::string> passed;
  int operations = 0;

  bool cancelRequested() override { return cancel; }
  bool optionalStop() override { return optional_stop; }
  void operationEnded(const OperationResult&) override
  {
    std::lock_guard<std::mutex> lock(mutex);
    ++operations;
  }
  void optionalStopPassed(const GoalFeedback& feedback) override { passed.push_back(feedback.event); }
  void holding(const GoalFeedback& feedback, uint32_t line) override
  {
    EXPECT_TRUE(feedback.paused);
    {
      std::lock_guard<std::mutex> lock(mutex);
      holds.emplace_back(feedback.event, line);
    }
    changed.notify_all();
  }
  bool waitForHolds(size_t count)
  {
    std::unique_lock<std::mutex> lock(mutex);
    return changed.wait_for(lock, kWait, [&] { return holds.size() >= count; });
  }

  std::vector<std::string> awaiting;  // feedback events while waiting for the end point
  void awaitingEnd(const GoalFeedback& feedback) override
  {
    {
      std::lock_guard<std::mutex> lock(mutex);
      awaiting.push_back(feedback.event);
    }
    changed.notify_all();
  }
  /// Waits until an awaitingEnd event contains \p text.
  bool waitForAwaiting(const std::string& text)
  {
    std::unique_lock<std::mutex> lock(mutex);
    return changed.wait_for(lock, kWait,
                            [&]
                            {
                              return std::any_of(awaiting.begin(), awaiting.end(),
                                                 [&](const std::string& event)
                                                 { return event.find(text) != std::string::npos; });
                            });
  }
};

gcode::ProgramStep programStep(gcode::ProgramStep::Kind kind, uint32_t line, uint16_t m_code)
{
  gcode::ProgramStep step;
  step.kind = kind;
  step.line = line;
  step.m_code = m_code;
  return step;
}

/// Two short operations along X (1 mm each, from 0), the first followed by \p after.
std::vector<OperationPlan> twoOperations(const gcode::ProgramStep& after)
{
  std::vector<OperationPlan> plans(2);
  plans[0].points = {{0, 0, 0}, {1000, 0, 0}};
  plans[0].feeds = {20.0};
  plans[0].after = after;
  plans[1].points = {{1000, 0, 0}, {2000, 0, 0}};
  plans[1].feeds = {20.0};
  return plans;
}
}  // namespace

// The whole goal is checked before its first byte: a second operation whose spindle speed is
// above ~spindle_max_rpm, or a tool length the wire cannot carry, fails the goal with nothing sent
// (not after the first operation moved the machine).
TEST_F(AtControllerSession, AGoalWhoseLaterOperationCannotBeSentIsRefusedBeforeAnythingIsSent)
{
  start(options(true));
  report("E0\n0 0 0\n", 2);
  GoalRunner runner(*session, GoalRunner::Names{"/m/resume", "/m/set_motion_enabled", "/m/optional_stop"});
  GoalRecorder goal;
  auto plans = twoOperations(programStep(gcode::ProgramStep::Kind::kDwell, 7, 0));
  plans[1].spindle_rpm = 30000;  // ~spindle_max_rpm is 24000
  GoalOutcome outcome = runner.run(plans, -1, 0.0, goal);
  EXPECT_EQ(outcome.end, GoalOutcome::End::kAborted);
  EXPECT_EQ(outcome.message,
            "goal refused before anything was sent: operation 2 of 2: spindle speed (rev/min, ~spindle_max_rpm) 30000 "
            "is outside 0..24000");
  plans[1].spindle_rpm = 0;
  plans[1].tool = 3;
  for (const double length : {std::nan(""), 1e300, -0.001, 0.0505})
  {
    outcome = runner.run(plans, 3, length, goal);
    EXPECT_EQ(outcome.end, GoalOutcome::End::kAborted) << length;
    EXPECT_NE(outcome.message.find("operation 2 of 2: '@'-protocol: tool length"), std::string::npos)
        << outcome.message;
  }
  EXPECT_EQ(received(), "");
}

// Exact or refused: a tool length that is not a whole millimetre, NaN or huge, a spindle speed or
// jog feed that is NaN, infinite or out of range is refused with the reason; nothing is sent (not
// wrapped to an integer, clamped or zeroed).
TEST_F(AtControllerSession, ValuesTheWireCannotCarryAreRefusedNotWrappedOrZeroed)
{
  start(options(true));
  report("E0\n", 1);
  for (const double length : {std::nan(""), HUGE_VAL, 1e300, -1.0, 2147483.648, 0.0505})
  {
    const Answer answer = session->toolChange(2, length);
    EXPECT_FALSE(answer.success) << length;
    EXPECT_NE(answer.message.find("tool length"), std::string::npos) << answer.message;
  }
  EXPECT_FALSE(session->toolChange(2147483647, 0.05).success);
  for (const double rpm : {std::nan(""), HUGE_VAL, -HUGE_VAL, 1e300, -1.0, 24000.5})
  {
    const Answer answer = session->spindle(rpm);
    EXPECT_FALSE(answer.success) << rpm;
    EXPECT_NE(answer.message.find("spindle speed"), std::string::npos) << answer.message;
  }
  for (const double feed : {std::nan(""), HUGE_VAL, 1e300, -0.001, 1.0})
  {
    const Answer answer = session->jog("x", feed);
    EXPECT_FALSE(answer.success) << feed;
    EXPECT_NE(answer.message.find("jog feed_rate"), std::string::npos) << answer.message;
  }
  EXPECT_EQ(received(), "");
  EXPECT_EQ(session->toolChange(2, 0.05).message, "sent T2 50@");  // 0.05 m: whole millimetres
  EXPECT_EQ(session->spindle(24000).message, "sent S255@");
}

TEST_F(AtControllerSession, AProgramStopHoldsTheGoalUntilResumeWhichIsRefusedWhileMotionIsDisabled)
{
  start(options(true));
  report("E0\n0 0 0\n", 2);
  GoalRunner runner(*session, GoalRunner::Names{"/m/resume", "/m/set_motion_enabled", "/m/optional_stop"});
  EXPECT_EQ(runner.resume().message,
            "nothing to resume: no follow_path goal is held (at a program stop M00/M01, or paused by motion "
            "disabled)");
  GoalRecorder goal;
  const auto plans = twoOperations(programStep(gcode::ProgramStep::Kind::kStop, 7, 0));
  auto run = std::async(std::launch::async, [&] { return runner.run(plans, -1, 0.0, goal); });
  ASSERT_TRUE(goal.waitForHolds(1));
  const std::string stop = plans[0].after->describe();
  EXPECT_EQ(goal.holds[0], std::make_pair(stop + ": waiting for /m/resume", 7u));
  const size_t sent_at_stop = received().size();
  EXPECT_EQ(received().compare(sent_at_stop - 5, 5, "#@M0@"), 0);
  // Disabled, resume is refused and the goal stays held; enabled, it goes on.
  session->setMotionEnabled(false, "/cell_manager");
  EXPECT_EQ(runner.resume().message, "resume refused: motion is disabled (test)");
  EXPECT_EQ(run.wait_for(Milliseconds(50)), std::future_status::timeout);
  session->setMotionEnabled(true, "/cell_manager");
  const Answer resumed = runner.resume();
  EXPECT_TRUE(resumed.success);
  EXPECT_EQ(resumed.message, "resumed after the " + stop);
  ASSERT_EQ(run.wait_for(kWait), std::future_status::ready);
  const GoalOutcome outcome = run.get();
  EXPECT_EQ(outcome.end, GoalOutcome::End::kSucceeded) << outcome.message;
  EXPECT_EQ(goal.operations, 2);
  EXPECT_GT(received().size(), sent_at_stop);
  ASSERT_TRUE(outcome.final_position.has_value());
}

TEST_F(AtControllerSession, ACancelWhileHeldEndsTheGoalWithNothingMoreSent)
{
  start(options(true));
  report("E0\n0 0 0\n", 2);
  GoalRunner runner(*session, GoalRunner::Names{});
  GoalRecorder goal;
  const auto plans = twoOperations(programStep(gcode::ProgramStep::Kind::kOptionalStop, 3, 1));
  auto run = std::async(std::launch::async, [&] { return runner.run(plans, -1, 0.0, goal); });
  ASSERT_TRUE(goal.waitForHolds(1));
  const std::string sent_at_stop = received();
  goal.cancel = true;
  ASSERT_EQ(run.wait_for(kWait), std::future_status::ready);
  const GoalOutcome outcome = run.get();
  EXPECT_EQ(outcome.end, GoalOutcome::End::kCancelled);
  EXPECT_TRUE(outcome.held_when_cancelled);
  EXPECT_EQ(outcome.message, "cancelled at the " + plans[0].after->describe());
  EXPECT_EQ(goal.operations, 1);
  EXPECT_EQ(received(), sent_at_stop);
}

TEST_F(AtControllerSession, AnOptionalStopPassesWhenTheSwitchIsOffAndTheProgramEndEndsTheGoal)
{
  start(options(true));
  report("E0\n0 0 0\n", 2);
  GoalRunner runner(*session, GoalRunner::Names{"resume", "set_motion_enabled", "/m/optional_stop"});
  GoalRecorder goal;
  goal.optional_stop = false;
  auto plans = twoOperations(programStep(gcode::ProgramStep::Kind::kOptionalStop, 3, 1));
  plans[1].after = programStep(gcode::ProgramStep::Kind::kEnd, 9, 30);
  const GoalOutcome outcome = runner.run(plans, -1, 0.0, goal);
  EXPECT_EQ(outcome.end, GoalOutcome::End::kSucceeded) << outcome.message;
  EXPECT_TRUE(outcome.program_end);
  // The program's end, and where the controller said its last operation ended.
  EXPECT_EQ(outcome.message.rfind(plans[1].after->describe() +
                                      ": the program ends here; nothing after it was sent; the controller reported "
                                      "the end point X2 Y0 Z0 mm (0 um from it) ",
                                  0),
            0u)
      << outcome.message;
  EXPECT_TRUE(goal.holds.empty());
  ASSERT_EQ(goal.passed.size(), 1u);
  EXPECT_EQ(goal.passed[0], plans[0].after->describe() + " passed (/m/optional_stop false)");
  EXPECT_EQ(goal.operations, 2);
}

TEST_F(AtControllerSession, ADisableMidOperationPausesTheGoalAndResumeFinishesThePathToItsEnd)
{
  start(options(true));
  report("E0\n0 0 0\n", 2);
  GoalRunner runner(*session, GoalRunner::Names{"resume", "/m/set_motion_enabled", "optional_stop"});
  GoalRecorder goal;
  std::vector<OperationPlan> plans(1);
  plans[0].points = {{0, 0, 0}, {200000, 0, 0}};
  plans[0].feeds = {40.0};
  auto run = std::async(std::launch::async, [&] { return runner.run(plans, -1, 0.0, goal); });
  ASSERT_TRUE(recorder.lastCommandLink()->waitForWritten(2000, kWait));  // streaming
  session->setMotionEnabled(false, "/cell_manager");
  ASSERT_TRUE(goal.waitForHolds(1));
  EXPECT_EQ(goal.holds[0].first.rfind("motion disabled by /cell_manager (/m/set_motion_enabled): decelerated to a "
                                      "stop along the path at X",
                                      0),
            0u)
      << goal.holds[0].first;
  EXPECT_EQ(goal.holds[0].second, 0u);
  session->setMotionEnabled(true, "/cell_manager");
  EXPECT_EQ(runner.resume().message, "resumed after the stop when motion was disabled by /cell_manager");
  ASSERT_EQ(run.wait_for(kWait), std::future_status::ready);
  const GoalOutcome outcome = run.get();
  EXPECT_EQ(outcome.end, GoalOutcome::End::kSucceeded) << outcome.message;
  EXPECT_EQ(goal.operations, 2);
  // The last setpoint of the rest is the path's end point exactly.
  CommandReassembler commands;
  const auto sent = recorder.lastCommandLink()->written();
  const auto messages = commands.feed(sent.data(), sent.size()).messages;
  Setpoint last{};
  for (const auto& message : messages)
  {
    const Command command = decodeCommand(message);
    if (const auto* setpoint = std::get_if<Setpoint>(&command))
    {
      last = *setpoint;
    }
  }
  EXPECT_EQ(last.position, (std::array<int32_t, 3>{200000, 0, 0}));
}

// ---- the end of a path: confirmed by the controller's report, not by the last setpoint leaving ------

namespace
{
/// One operation from X0 to X1 mm.
std::vector<OperationPlan> oneMillimetre()
{
  std::vector<OperationPlan> plans(1);
  plans[0].points = {{0, 0, 0}, {1000, 0, 0}};
  plans[0].feeds = {20.0};
  return plans;
}
}  // namespace

TEST_F(AtControllerSession, AGoalSucceedsWhenTheControllerReportsTheEndPointWithinTheTolerance)
{
  start(options(true));
  report("E0\n0 0 0\n", 2);
  axes.offset = {3, 0, -2};  // 3.6 um from the end point: within the default 5 um
  GoalRunner runner(*session, GoalRunner::Names{});
  GoalRecorder goal;
  const GoalOutcome outcome = runner.run(oneMillimetre(), -1, 0.0, goal);
  EXPECT_EQ(outcome.end, GoalOutcome::End::kSucceeded) << outcome.message;
  ASSERT_TRUE(outcome.final_position.has_value());
  EXPECT_EQ(*outcome.final_position, (std::array<int32_t, 3>{1003, 0, -2}));  // the report that confirmed it
  EXPECT_EQ(
      outcome.message.rfind("path complete: the controller reported the end point X1 Y0 Z0 mm (3.6 um from it) ", 0),
      0u)
      << outcome.message;
}

// The old rule (success as the last setpoint leaves, with whatever position was reported last)
// ended this goal at once; now it waits while the reports are outside the tolerance.
TEST_F(AtControllerSession, AGoalWaitsWhileTheReportedPositionIsOutsideTheToleranceAndSucceedsOnceItArrives)
{
  start(options(true));
  report("E0\n0 0 0\n", 2);
  axes.offset = {0, 49, 0};  // lagging 49 um behind, as the demo's path once "ended"
  GoalRunner runner(*session, GoalRunner::Names{});
  GoalRecorder goal;
  auto run = std::async(std::launch::async, [&] { return runner.run(oneMillimetre(), -1, 0.0, goal); });
  // The report after the last setpoint was judged: 49 um away, the goal waits.
  ASSERT_TRUE(goal.waitForAwaiting("its last report is 49 um from it"));
  {
    std::lock_guard<std::mutex> lock(goal.mutex);
    EXPECT_EQ(goal.awaiting.back(),
              "waiting for the controller to report the end point X1 Y0 Z0 mm (within 5 um): its last report is 49 "
              "um from it");
  }
  EXPECT_EQ(run.wait_for(std::chrono::seconds(0)), std::future_status::timeout);
  recorder.lastReportLink()->feed("1000 6 0\n");  // still 6 um away: waits on
  ASSERT_TRUE(goal.waitForAwaiting("its last report is 6 um from it"));
  EXPECT_EQ(run.wait_for(std::chrono::seconds(0)), std::future_status::timeout);
  recorder.lastReportLink()->feed("1000 0 0\n");  // arrived
  ASSERT_EQ(run.wait_for(kWait), std::future_status::ready);
  const GoalOutcome outcome = run.get();
  EXPECT_EQ(outcome.end, GoalOutcome::End::kSucceeded) << outcome.message;
  ASSERT_TRUE(outcome.final_position.has_value());
  EXPECT_EQ(*outcome.final_position, (std::array<int32_t, 3>{1000, 0, 0}));
  EXPECT_NE(outcome.message.find("the end point X1 Y0 Z0 mm (0 um from it)"), std::string::npos) << outcome.message;
}

TEST_F(AtControllerSession, AGoalFailsWhenTheEndPointIsNotReportedWithinTheTimeoutSayingHowFarAndForHowLong)
{
  start(options(true));
  report("E0\n0 0 0\n", 2);
  axes.offset = {-49, 0, 0};  // the axes stop 49 um short and stay there
  GoalRunner runner(
      *session,
      GoalRunner::Names{"resume", "set_motion_enabled", "optional_stop", "/m/end_tolerance", "/m/end_timeout"},
      EndCheck{5.0, 0.3});
  GoalRecorder goal;
  const auto started = std::chrono::steady_clock::now();
  const GoalOutcome outcome = runner.run(oneMillimetre(), -1, 0.0, goal);
  EXPECT_GE(std::chrono::steady_clock::now() - started, std::chrono::milliseconds(300));
  EXPECT_EQ(outcome.end, GoalOutcome::End::kAborted);
  EXPECT_EQ(outcome.message,
            "every setpoint was sent, but the controller did not report the end point X1 Y0 Z0 mm within 5 um "
            "(/m/end_tolerance) in the 0.3 s (/m/end_timeout) after the last setpoint: its last report, X0.951 Y0 Z0 "
            "mm, is 49 um from it (the axes stopped short, or lag)");
  ASSERT_TRUE(outcome.final_position.has_value());
  EXPECT_EQ(*outcome.final_position, (std::array<int32_t, 3>{951, 0, 0}));
}

// A report of the end point from before the last setpoint is no confirmation (a path that comes
// back to where it started would otherwise "end" on its start report): no report after it fails.
TEST_F(AtControllerSession, AReportFromBeforeTheLastSetpointDoesNotConfirmTheEnd)
{
  start(options(true));
  report("E0\n1000 0 0\n", 2);  // the end point, reported before the goal
  axes.arrive = false;
  GoalRunner runner(*session, GoalRunner::Names{}, EndCheck{5.0, 0.2});
  GoalRecorder goal;
  const GoalOutcome outcome = runner.run(oneMillimetre(), -1, 0.0, goal);
  EXPECT_EQ(outcome.end, GoalOutcome::End::kAborted);
  EXPECT_NE(outcome.message.find("no position report came after the last setpoint (is the report link up?); the one "
                                 "before, X1 Y0 Z0 mm, is 0 um from it"),
            std::string::npos)
      << outcome.message;
}

TEST_F(AtControllerSession, AnEStopWhileWaitingForTheEndPointAbortsTheGoal)
{
  start(options(true));
  report("E0\n0 0 0\n", 2);
  axes.offset = {0, 0, 200};
  GoalRunner runner(*session, GoalRunner::Names{});
  GoalRecorder goal;
  auto run = std::async(std::launch::async, [&] { return runner.run(oneMillimetre(), -1, 0.0, goal); });
  ASSERT_TRUE(goal.waitForAwaiting("its last report is 200 um from it"));
  recorder.lastReportLink()->feed("E1\n");
  ASSERT_EQ(run.wait_for(kWait), std::future_status::ready);
  const GoalOutcome outcome = run.get();
  EXPECT_EQ(outcome.end, GoalOutcome::End::kAborted);
  EXPECT_EQ(outcome.message.rfind("emergency stop reported by the controller (E1) before it reported the end point", 0),
            0u)
      << outcome.message;
}
