// The controller session (controller_session.h) against fake links: reports folded into the
// snapshot, link loss reported (and the e-stop then unknown), the motion gate refusing with
// nothing sent, a disable during an operation, and a goal's plan. The tests wait on the events
// of the listener or on the bytes the fake controller receives, never on sleeps.
#include <gtest/gtest.h>

#include <condition_variable>
#include <future>
#include <mutex>
#include <thread>

#include "cnc_bridge/at_protocol/controller_session.h"
#include "cnc_bridge/common/error.h"
#include "cnc_bridge/transport/fake_transport.h"
#include "cnc_bridge/transport/forwarding_transport.h"

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

struct AtControllerSession : ::testing::Test
{
  Recorder recorder;
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
    links.open_command = [this] { return recorder.open(recorder.command_links, "controller:5000"); };
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
