// at_controller_node on sim_at_controller with motion enabled: a G-code program is followed to
// its end point, a second goal is rejected while one runs, jog is refused while machining, cancel decelerates to a
// stop, disabling motion mid-path pauses the goal until enabled and resumed, a jog stops by itself when its client
// goes silent, an emergency stop mid-path aborts the goal with the reason, and home returns to the home position.
#include <signal.h>

#include <unistd.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <cctype>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <sstream>

#include "at_test_support.h"
#include "process_kill.h"

using namespace at_test;

namespace
{
std::string node, ns, prefix, pid_file, command_log, profile = "trapezoid";
double jog_timeout = 0.5;  // the node's ~jog_timeout

/// The node's ~end_tolerance (5 um, whole pulses, inclusive): a report 5 pulses off ends a goal, and
/// its position in metres is 5e-6 give or take the last bit of a double.
constexpr double kEndTolerance = 5e-6 + 1e-12;

bool near(const geometry_msgs::Point& p, double x, double y, double z, double tolerance)
{
  return std::fabs(p.x - x) <= tolerance && std::fabs(p.y - y) <= tolerance && std::fabs(p.z - z) <= tolerance;
}

std_srvs::SetBool::Response switchMotion(bool enabled)
{
  std_srvs::SetBool::Request request;
  request.data = enabled;
  return call<std_srvs::SetBool>(node + "/set_motion_enabled", request);
}

struct AtController : ::testing::Test
{
  StateWatch state{ns + "/state"};
  FollowPathClient client{node + "/follow_path", false};
  void SetUp() override { waitUntilReady(client, state); }
};
}  // namespace

// Closes a window in which the controller must receive nothing from line \p from of its log on:
// an A@ (auto mode; harmless, the controller is in auto) sent now must be the first line that
// arrives. The node writes every command in order on one link, so anything it had sent before
// arrives first; the A@ arriving proves the node and the link were running through the window
// (a slow machine cannot make the window pass by sending nothing yet).
void expectNothingReceivedBeforeAMarker(const CommandLog& received, size_t from)
{
  const auto marker = call<std_srvs::Trigger>(node + "/set_auto");
  ASSERT_TRUE(marker.success) << marker.message;
  EXPECT_EQ(received.linesUntil(from, "A"), std::vector<std::string>{"A"});
}

// The setpoints of one operation in the simulator's command log: "feed pos feed pos feed pos".
std::vector<std::array<long, 6>> setpointLines(const std::vector<std::string>& lines)
{
  std::vector<std::array<long, 6>> out;
  for (const std::string& line : lines)
  {
    std::istringstream in(line);
    std::array<long, 6> v{};
    if (std::isdigit(static_cast<unsigned char>(line[0])) || line[0] == '-')
    {
      if (in >> v[0] >> v[1] >> v[2] >> v[3] >> v[4] >> v[5])
      {
        out.push_back(v);
      }
    }
  }
  return out;
}

// cnc_plan's CSV rows as the same six numbers (feed and position per axis).
/// Distance (um) of the point \p x, \p y, \p z (um) from test/data/at_controller/square.nc's path,
/// starting at \p start (m): the rapid to X5 Y5 Z2, the plunge to Z-1, X25, Y25, the half circle
/// about X15 Y25 through Y15, and back down to Y5 (mm).
double distanceFromSquare(const geometry_msgs::Point& start, double x, double y, double z)
{
  using P = std::array<double, 3>;
  auto to_segment = [&](const P& a, const P& b)
  {
    const P ab{b[0] - a[0], b[1] - a[1], b[2] - a[2]};
    const double len2 = ab[0] * ab[0] + ab[1] * ab[1] + ab[2] * ab[2];
    double t = len2 > 0 ? ((x - a[0]) * ab[0] + (y - a[1]) * ab[1] + (z - a[2]) * ab[2]) / len2 : 0.0;
    t = std::clamp(t, 0.0, 1.0);
    return std::hypot(x - (a[0] + t * ab[0]), y - (a[1] + t * ab[1]), z - (a[2] + t * ab[2]));
  };
  const P from{start.x * 1e6, start.y * 1e6, start.z * 1e6};
  const std::vector<P> lines = {
      from, {5000, 5000, 2000}, {5000, 5000, -1000}, {25000, 5000, -1000}, {25000, 25000, -1000}};
  double best = 1e300;
  for (size_t k = 1; k < lines.size(); ++k)
  {
    best = std::min(best, to_segment(lines[k - 1], lines[k]));
  }
  best = std::min(best, to_segment({5000, 25000, -1000}, {5000, 5000, -1000}));
  if (y <= 25000)  // the half circle below Y25
  {
    best = std::min(best, std::hypot(std::hypot(x - 15000, y - 25000) - 10000, z + 1000));
  }
  return best;
}

std::vector<std::array<long, 6>> cncPlanSetpoints(const std::string& program, const geometry_msgs::Point& start)
{
  const std::string csv = "/tmp/test_at_controller_" + std::to_string(::getpid()) + ".csv";
  std::ostringstream command;
  command << CNC_PLAN << " --gcode " << program << " --profile " << profile << " --csv " << csv << " --start "
          << start.x * 1000 << ',' << start.y * 1000 << ',' << start.z * 1000 << " >/dev/null";
  EXPECT_EQ(std::system(command.str().c_str()), 0) << command.str();
  std::vector<std::array<long, 6>> out;
  std::ifstream in(csv);
  std::string line;
  std::getline(in, line);
  while (std::getline(in, line))
  {
    std::vector<double> cells;
    std::istringstream row(line);
    for (std::string cell; std::getline(row, cell, ',');)
    {
      cells.push_back(std::stod(cell));
    }
    out.push_back({long(cells[4]), long(cells[1]), long(cells[5]), long(cells[2]), long(cells[6]), long(cells[3])});
  }
  std::remove(csv.c_str());
  return out;
}

TEST_F(AtController, FollowsAGcodeProgramToItsEndPoint)
{
  CommandLog received{command_log};
  const size_t mark = received.lines().size();
  const auto start_position = state.last().position;
  cnc_bridge::AtFollowPathGoal goal;
  goal.gcode_file = "square.nc";
  goal.coolant = cnc_bridge::AtFollowPathGoal::COOLANT_DEFAULT;
  goal.tool = 3;
  goal.tool_length = 0.034;
  std::atomic<int> feedback_count{0};
  std::atomic<double> worst_error{0.0};
  client.sendGoal(goal, FollowPathClient::SimpleDoneCallback(), FollowPathClient::SimpleActiveCallback(),
                  [&](const cnc_bridge::AtFollowPathFeedbackConstPtr& f)
                  {
                    ++feedback_count;
                    const double e = std::hypot(f->following_error.x, f->following_error.y, f->following_error.z);
                    worst_error = std::max(worst_error.load(), e);
                  });
  // The rapid to the start (before M08 and S12000 M03) is an operation of its own; the cut follows.
  ASSERT_TRUE(state.waitFor(
      [](const auto& s)
      {
        return s.execution == cnc_bridge::MachineState::EXECUTION_ACTIVE &&
               s.coolant == cnc_bridge::MachineState::COOLANT_ON;
      },
      20.0));
  const auto running = state.last();
  EXPECT_EQ(running.coolant, cnc_bridge::MachineState::COOLANT_ON);  // M08 in the program: P1@
  EXPECT_NEAR(running.spindle_speed, 12000, 50);                     // S12000 M03 -> S128@ of 24000 rev/min
  EXPECT_EQ(running.tool, 3);
  ASSERT_TRUE(client.waitForResult(ros::Duration(40.0)));
  EXPECT_EQ(client.getState(), actionlib::SimpleClientGoalState::SUCCEEDED) << client.getState().getText();
  const auto result = client.getResult();
  EXPECT_TRUE(result->success);
  // The goal ended on the controller's report of the program's end point X5 Y5 Z-1 (mm), within
  // ~end_tolerance (5 um), not when the last setpoint left: final_position is that report.
  EXPECT_TRUE(near(result->final_position, 0.005, 0.005, -0.001, kEndTolerance)) << result->final_position;
  EXPECT_NE(result->message.find("the controller reported the end point X5 Y5 Z-1 mm ("), std::string::npos)
      << result->message;
  EXPECT_GT(result->setpoints, 3000u);  // some 110 mm at 20 mm/s: several seconds of 1 ms steps
  EXPECT_GT(feedback_count.load(), 10);
  // Feedback carries a real following error (the simulated axes lag behind the setpoints), in
  // metres: far below the 0.02 m side of the square (pulses or mm would be orders larger).
  EXPECT_GT(worst_error.load(), 0.0);
  EXPECT_LT(worst_error.load(), 0.02);
  // Reported position converges to the program's end point X5 Y5 Z-1 (mm), to the pulse.
  EXPECT_TRUE(state.waitFor([](const auto& s) { return near(s.position, 0.005, 0.005, -0.001, 1.5e-6); }))
      << state.last().position;
  EXPECT_EQ(state.last().coolant, cnc_bridge::MachineState::COOLANT_OFF);  // #@
  EXPECT_EQ(state.last().spindle_speed, 0.0);                              // M0@ stops the spindle
  // Every setpoint the controller received is the one cnc_plan's dry run of the same program from
  // the same start gives (same feed values, same pulses, same count).
  const auto sent = setpointLines(received.linesUntil(mark, "#"));
  const auto planned = cncPlanSetpoints(CNC_BRIDGE_AT_PROGRAMS "/square.nc", start_position);
  ASSERT_EQ(sent.size(), result->setpoints);
  ASSERT_EQ(sent.size(), planned.size());
  for (size_t k = 0; k < sent.size(); ++k)
  {
    ASSERT_EQ(sent[k], planned[k]) << "setpoint " << k;
  }
  // The jerk-limited profile passes the square's corners (90 degrees, and the turns back where the
  // half circle begins and ends) within the node's ~path_tolerance, 10 um, of the program's path
  // as the controller receives it; the half circle is cut in chords of 10 um sagitta, so 20 um
  // from the true circle there, plus the rounding to whole pulses.
  if (profile == "scurve")
  {
    double worst = 0.0;
    size_t worst_at = 0;
    for (size_t k = 0; k < sent.size(); ++k)
    {
      const double d = distanceFromSquare(start_position, sent[k][1], sent[k][3], sent[k][5]);  // fx px fy py fz pz
      if (d > worst)
      {
        worst = d;
        worst_at = k;
      }
    }
    EXPECT_LE(worst, 21.0) << "um from the program's path, at setpoint " << worst_at << " of " << sent.size() << ": "
                           << sent[worst_at][1] << " " << sent[worst_at][3] << " " << sent[worst_at][5] << "; start "
                           << start_position;
  }
}

TEST_F(AtController, JogIsRefusedWhileMachiningAndCancelDecelerates)
{
  const auto start = state.last().position;
  client.sendGoal(lineGoal(start.x + 0.1, start.y, start.z, 0.02, prefix + "machine"));
  ASSERT_TRUE(state.waitFor([](const auto& s) { return s.execution == cnc_bridge::MachineState::EXECUTION_ACTIVE; }));
  const auto jog = call<cnc_bridge::AtJog>(node + "/jog", jogRequest("x", 0.01));
  EXPECT_FALSE(jog.success);
  EXPECT_NE(jog.message.find("refused while machining"), std::string::npos) << jog.message;
  // Moving: at 20 mm/s, past 10 mm.
  ASSERT_TRUE(state.waitFor([&](const auto& s) { return s.position.x > start.x + 0.01; }));
  client.cancelGoal();
  ASSERT_TRUE(client.waitForResult(ros::Duration(10.0)));
  EXPECT_EQ(client.getState(), actionlib::SimpleClientGoalState::PREEMPTED) << client.getState().getText();
  const auto result = client.getResult();
  // Stopped short of the end, after a ramp: v^2 / 2a = 0.02^2 / (2 * 0.4) = 0.5 mm beyond the cancel.
  EXPECT_LT(result->setpoints, 5000u);
  ASSERT_TRUE(state.waitFor([](const auto& s) { return s.execution == cnc_bridge::MachineState::EXECUTION_STOPPED; }));
  const double stopped_at = state.last().position.x;
  EXPECT_LT(stopped_at, start.x + 0.09);
  // Jog is allowed again now that machining has ended.
  EXPECT_TRUE(call<cnc_bridge::AtJog>(node + "/jog", jogRequest("y", 0.01)).success);
  EXPECT_TRUE(state.waitFor([](const auto& s) { return s.mode == cnc_bridge::MachineState::MODE_MANUAL; }));
  EXPECT_TRUE(call<std_srvs::Trigger>(node + "/set_auto").success);
  EXPECT_TRUE(state.waitFor([](const auto& s) { return s.mode == cnc_bridge::MachineState::MODE_AUTO; }));
}

// A goal while another runs is rejected, naming the running goal and how to stop it; the running
// path is not touched: the machine (as the simulator reports it) ends at its end point.
TEST_F(AtController, ASecondGoalIsRejectedAndTheFirstRunsToItsEnd)
{
  const auto start = state.last().position;
  client.sendGoal(lineGoal(start.x + 0.02, start.y, start.z, 0.02, prefix + "machine"));
  ASSERT_TRUE(state.waitFor([](const auto& s) { return s.execution == cnc_bridge::MachineState::EXECUTION_ACTIVE; }));
  FollowPathClient second{node + "/follow_path", false};
  ASSERT_TRUE(second.waitForServer(ros::Duration(10.0)));
  second.sendGoal(lineGoal(start.x - 0.05, start.y + 0.05, start.z, 0.02, prefix + "machine"));
  ASSERT_TRUE(second.waitForResult(ros::Duration(10.0)));
  EXPECT_EQ(second.getState(), actionlib::SimpleClientGoalState::REJECTED) << second.getState().getText();
  const std::string text = second.getResult()->message;
  EXPECT_NE(text.find(node + "/follow_path is running goal "), std::string::npos) << text;
  EXPECT_NE(text.find("(path of 1 poses)"), std::string::npos) << text;
  EXPECT_NE(text.find("cancel it first"), std::string::npos) << text;
  EXPECT_FALSE(client.getState().isDone());
  ASSERT_TRUE(client.waitForResult(ros::Duration(20.0)));
  EXPECT_EQ(client.getState(), actionlib::SimpleClientGoalState::SUCCEEDED) << client.getState().getText();
  EXPECT_TRUE(state.waitFor([&](const auto& s) { return near(s.position, start.x + 0.02, start.y, start.z, 1.5e-6); }))
      << state.last().position;
}

// ~set_motion_enabled false mid-path pauses the goal: the path decelerates to a stop and holds,
// the goal stays active (feedback and state say paused, by whom and where), the controller
// receives no setpoint after the operation's end (M0@), and ~resume is refused, naming
// ~set_motion_enabled, until motion is enabled again. Then ~resume plans the rest of the path from
// the stop point and the goal succeeds on the path's end point.
TEST_F(AtController, DisablingMotionMidPathStopsItAndTheControllerGetsNoMoreSetpoints)
{
  CommandLog received{command_log};
  const auto start = state.last().position;
  const double end_x = start.x + 0.05;
  topic_watch::Messages<cnc_bridge::AtFollowPathFeedback> feedback;
  client.sendGoal(lineGoal(end_x, start.y, start.z, 0.02, prefix + "machine"),  // 2.5 s of setpoints
                  FollowPathClient::SimpleDoneCallback(), FollowPathClient::SimpleActiveCallback(),
                  [&](const cnc_bridge::AtFollowPathFeedbackConstPtr& f) { feedback.add(*f); });
  ASSERT_TRUE(state.waitFor([&](const auto& s) { return s.position.x > start.x + 0.01; }));
  const size_t at_disable = received.lines().size();
  const auto switched = switchMotion(false);
  EXPECT_TRUE(switched.success);
  EXPECT_EQ(switched.message, "motion disabled by " + ros::this_node::getName());
  const std::string why = "motion disabled by " + ros::this_node::getName() + " (" + node +
                          "/set_motion_enabled): decelerated to a stop along the path at X";
  ASSERT_TRUE(state.waitFor([](const auto& s) { return s.execution == cnc_bridge::MachineState::EXECUTION_PAUSED; }))
      << state.last().message;
  EXPECT_EQ(state.last().message.find(why), 0u) << state.last().message;
  EXPECT_NE(state.last().message.find("waiting for " + node + "/resume"), std::string::npos) << state.last().message;
  // The controller's side: the deceleration (a ramp of some 50 ms from 20 mm/s) and the
  // operation's end, then nothing.
  const auto until_end = received.linesUntil(at_disable, "M0");
  ASSERT_FALSE(until_end.empty()) << "the operation did not end";
  EXPECT_LT(until_end.size(), 1000u);
  EXPECT_EQ(until_end[until_end.size() - 2], "#");
  const size_t after_end = at_disable + until_end.size();
  // The axes settle on the last setpoint ("feed x feed y feed z", pulses of 1 um) and hold there.
  const auto last_setpoint = setpointLines({until_end[until_end.size() - 3]});
  ASSERT_EQ(last_setpoint.size(), 1u) << until_end[until_end.size() - 3];
  const double held_x = last_setpoint[0][1] * 1e-6;
  EXPECT_EQ(last_setpoint[0][0], 0);  // at rest: feed 0
  EXPECT_TRUE(state.waitFor([&](const auto& s) { return std::fabs(s.position.x - held_x) <= 1.5e-6; }))
      << state.last().position.x << " vs " << held_x;
  EXPECT_LT(held_x, end_x - 0.01);
  // A measurement window (that nothing arrives needs a span of time), closed by a marker: no
  // setpoint, no motion.
  ros::WallDuration(0.5).sleep();  // window: a span in which nothing may arrive
  expectNothingReceivedBeforeAMarker(received, after_end);
  const size_t after_marker = after_end + 1;
  EXPECT_NEAR(state.last().position.x, held_x, 1.5e-6);
  // Paused, not ended: the goal is active, its feedback says why and where.
  EXPECT_EQ(client.getState(), actionlib::SimpleClientGoalState::ACTIVE) << client.getState().getText();
  {
    const auto so_far = feedback.all();
    ASSERT_FALSE(so_far.empty());
    EXPECT_TRUE(so_far.back().paused);
    EXPECT_EQ(so_far.back().event.find(why), 0u) << so_far.back().event;
  }
  // ~resume and motion are refused while disabled, naming the run-time switch; nothing is sent.
  const auto early = call<std_srvs::Trigger>(node + "/resume");
  EXPECT_FALSE(early.success);
  EXPECT_NE(early.message.find("resume refused: motion is disabled; enable it with " + node + "/set_motion_enabled"),
            std::string::npos)
      << early.message;
  const auto jog = call<cnc_bridge::AtJog>(node + "/jog", jogRequest("x", 0.01));
  EXPECT_FALSE(jog.success);
  EXPECT_NE(jog.message.find(node + "/set_motion_enabled"), std::string::npos) << jog.message;
  EXPECT_NE(jog.message.find(node + "/enable_motion"), std::string::npos) << jog.message;
  EXPECT_EQ(received.lines().size(), after_marker);
  EXPECT_FALSE(client.getState().isDone());

  // Enabled and resumed: the rest of the path from the stop point, to the exact end point.
  EXPECT_EQ(switchMotion(true).message, "motion enabled by " + ros::this_node::getName());
  const auto resumed = call<std_srvs::Trigger>(node + "/resume");
  EXPECT_TRUE(resumed.success) << resumed.message;
  EXPECT_EQ(resumed.message, "resumed after the stop when motion was disabled by " + ros::this_node::getName());
  ASSERT_TRUE(client.waitForResult(ros::Duration(20.0)));
  EXPECT_EQ(client.getState(), actionlib::SimpleClientGoalState::SUCCEEDED) << client.getState().getText();
  EXPECT_TRUE(state.waitFor([&](const auto& s) { return near(s.position, end_x, start.y, start.z, 1.5e-6); }))
      << state.last().position;
  // The controller's side: one more operation that starts from rest at the stop point (no jump:
  // its first step is less than a period at full speed away) and ends on the end point at rest.
  const auto rest = received.linesUntil(after_marker, "M0");
  ASSERT_GE(rest.size(), 5u);
  EXPECT_EQ(rest[0], "M1");
  const auto setpoints = setpointLines(rest);
  ASSERT_GT(setpoints.size(), 100u);
  EXPECT_LE(std::abs(setpoints.front()[1] - last_setpoint[0][1]), 50);  // 50 mm/s for 1 ms: 50 pulses
  EXPECT_EQ(setpoints.back()[1], std::lround(end_x * 1e6));
  EXPECT_EQ(setpoints.back()[0], 0);
  EXPECT_EQ(rest[rest.size() - 2], "#");
}

// A cancel while the goal is paused by a disable ends it PREEMPTED; nothing more reaches the
// controller (a later set_auto is the barrier: it is the next thing the controller receives).
TEST_F(AtController, CancelWhilePausedByDisableEndsTheGoalWithNothingMoreSent)
{
  CommandLog received{command_log};
  const auto start = state.last().position;
  client.sendGoal(lineGoal(start.x - 0.05, start.y, start.z, 0.02, prefix + "machine"));
  ASSERT_TRUE(state.waitFor([&](const auto& s) { return s.position.x < start.x - 0.005; }));
  const size_t at_disable = received.lines().size();
  EXPECT_TRUE(switchMotion(false).success);
  ASSERT_TRUE(state.waitFor([](const auto& s) { return s.execution == cnc_bridge::MachineState::EXECUTION_PAUSED; }));
  const auto until_end = received.linesUntil(at_disable, "M0");
  ASSERT_FALSE(until_end.empty()) << "the operation did not end";
  client.cancelGoal();
  ASSERT_TRUE(client.waitForResult(ros::Duration(10.0)));
  EXPECT_EQ(client.getState(), actionlib::SimpleClientGoalState::PREEMPTED) << client.getState().getText();
  EXPECT_NE(client.getResult()->message.find("cancelled while held: motion disabled by "), std::string::npos)
      << client.getResult()->message;
  EXPECT_TRUE(switchMotion(true).success);
  EXPECT_TRUE(call<std_srvs::Trigger>(node + "/set_auto").success);
  EXPECT_EQ(received.linesUntil(at_disable + until_end.size(), "A"), std::vector<std::string>{"A"});
  EXPECT_FALSE(call<std_srvs::Trigger>(node + "/resume").success);  // nothing held any more
}

// The jog deadman, as the simulator sees it: a jog whose client goes silent gets feed 0 from the
// node (F0@ after the jog's F@, nothing else) no sooner than ~jog_timeout after the call, and the
// simulated axis stops: it moved for at least the timeout and for no longer than the timeout plus
// a tolerance (its reported position).
TEST_F(AtController, AJogStopsWithinTheJogTimeoutAfterItsClientGoesSilent)
{
  CommandLog received{command_log};
  const size_t mark = received.lines().size();
  const double start_x = state.last().position.x;
  const double speed = 0.01;  // m/s: F51@ of 0.05 m/s
  const auto called = std::chrono::steady_clock::now();
  const auto jog = call<cnc_bridge::AtJog>(node + "/jog", jogRequest("x", speed));
  ASSERT_TRUE(jog.success) << jog.message;
  ASSERT_TRUE(state.waitFor([&](const auto& s) { return s.position.x > start_x + 0.001; }));  // moving
  const double tolerance = 1.5;                                                               // s, for a loaded machine
  const auto lines = received.linesUntil(mark, "F0", jog_timeout + tolerance + 1.0);
  const double stopped_after = std::chrono::duration<double>(std::chrono::steady_clock::now() - called).count();
  EXPECT_EQ(lines, (std::vector<std::string>{"JX", "F51", "F0"}));
  EXPECT_GE(stopped_after, jog_timeout);  // the deadman never fires before its time
  EXPECT_TRUE(state.waitFor([&](const auto& s) { return s.message == "jog stopped: no jog command for 0.5 s"; }))
      << state.last().message;
  // Settled, then a measurement window in which the reported position does not move and the
  // controller receives nothing after the F0@ (closed by a marker).
  ros::WallDuration(0.3).sleep();  // window: the axis settles
  const double stopped_x = state.last().position.x;
  ros::WallDuration(0.3).sleep();  // window: a span in which nothing may move
  expectNothingReceivedBeforeAMarker(received, mark + lines.size());
  EXPECT_NEAR(state.last().position.x, stopped_x, 1e-9);
  EXPECT_GE(stopped_x - start_x, speed * jog_timeout - 1e-4);
  EXPECT_LE(stopped_x - start_x, speed * (jog_timeout + tolerance));
}

// A client that keeps calling ~jog (10 Hz, as a joystick teleoperation node publishes) renews the
// deadman: the axis keeps moving for four timeouts with no F0@ in between; once it goes silent the
// jog stops.
TEST_F(AtController, ARenewedJogKeepsMovingPastOneTimeout)
{
  CommandLog received{command_log};
  const size_t mark = received.lines().size();
  const double start_x = state.last().position.x;
  const double speed = 0.01;
  const auto until = std::chrono::steady_clock::now() + std::chrono::duration<double>(4 * jog_timeout);
  int calls = 0;
  for (ros::WallRate rate(10.0); std::chrono::steady_clock::now() < until; rate.sleep())  // the client's pace
  {
    ASSERT_TRUE(call<cnc_bridge::AtJog>(node + "/jog", jogRequest("x", speed)).success);
    ++calls;
  }
  const double renewed_x = state.last().position.x;
  const auto lines = received.linesUntil(mark, "F0", jog_timeout + 2.5);
  ASSERT_FALSE(lines.empty()) << "no F0@ after the client went silent";
  // Every call's J@ F@, then a single F0@ at the end.
  EXPECT_EQ(std::count(lines.begin(), lines.end(), "F51"), calls);
  EXPECT_EQ(std::count(lines.begin(), lines.end(), "F0"), 1);
  EXPECT_EQ(lines.size(), 2u * calls + 1);
  // It moved for more than three timeouts' worth while renewed (four timeouts of calls).
  EXPECT_GT(renewed_x - start_x, speed * 3 * jog_timeout);
  EXPECT_TRUE(call<std_srvs::Trigger>(node + "/set_auto").success);
}

// The program's own steps in a G-code goal (test/data/at_controller/program_stops.nc, with
// ~program_commands): M00 and M01 hold the goal until ~resume with nothing sent meanwhile; every
// operation carries the program's coolant and spindle in the protocol's order (M1@ P1@ S@ ...
// #@ M0@); G04 waits; M30 ends the goal and the move after it is never sent.
TEST_F(AtController, ProgramStopsHoldTheGoalUntilResumeAndM30EndsIt)
{
  CommandLog received{command_log};
  const size_t mark = received.lines().size();
  const auto start_position = state.last().position;
  topic_watch::Messages<cnc_bridge::AtFollowPathFeedback> feedback;
  // Waits for a feedback whose event is \p event (feedback and state are separate topics).
  const auto event_arrived = [&](const std::string& event)
  { return feedback.waitForLatest([&](const auto& f) { return f.event == event; }, 20.0); };
  cnc_bridge::AtFollowPathGoal goal;
  goal.gcode_file = "program_stops.nc";
  goal.coolant = cnc_bridge::AtFollowPathGoal::COOLANT_DEFAULT;
  goal.tool = -1;
  client.sendGoal(goal, FollowPathClient::SimpleDoneCallback(), FollowPathClient::SimpleActiveCallback(),
                  [&](const cnc_bridge::AtFollowPathFeedbackConstPtr& f) { feedback.add(*f); });
  const std::string resume = node + "/resume";
  // M00 on line 7: the first operation ended (M0@) at X10 and nothing follows it.
  const auto first = received.linesUntil(mark, "M0", 20.0);
  ASSERT_FALSE(first.empty());
  ASSERT_TRUE(state.waitFor([](const auto& s) { return s.execution == cnc_bridge::MachineState::EXECUTION_PAUSED; }));
  ASSERT_TRUE(event_arrived("M00 program stop at line 7: waiting for " + resume));
  EXPECT_TRUE(feedback.latest().paused);
  EXPECT_EQ(state.last().block, 7u);
  // Protocol order: M1@, then P1@ (M08), then S64@ (S6000 of 24000 rev/min), then the setpoints.
  ASSERT_GE(first.size(), 5u);
  EXPECT_EQ(first[0], "M1");
  EXPECT_EQ(first[1], "P1");
  EXPECT_EQ(first[2], "S64");
  EXPECT_EQ(first[first.size() - 2], "#");
  EXPECT_TRUE(state.waitFor([](const auto& s) { return near(s.position, 0.010, 0.005, 0.002, 1.5e-6); }))
      << state.last().position;
  // Held: a measurement window in which the controller receives nothing (closed by a marker).
  ros::WallDuration(0.3).sleep();  // window: a span in which nothing may arrive
  expectNothingReceivedBeforeAMarker(received, mark + first.size());
  EXPECT_FALSE(client.getState().isDone());
  auto answer = call<std_srvs::Trigger>(resume);
  EXPECT_TRUE(answer.success);
  EXPECT_EQ(answer.message, "resumed after the M00 program stop at line 7");

  // M01 on line 9 (~optional_stop true by default): held again after X15.
  ASSERT_TRUE(state.waitFor(
      [](const auto& s) { return s.execution == cnc_bridge::MachineState::EXECUTION_PAUSED && s.block == 9; }, 20.0));
  ASSERT_TRUE(event_arrived("M01 optional stop at line 9: waiting for " + resume));
  EXPECT_TRUE(state.waitFor([](const auto& s) { return near(s.position, 0.015, 0.005, 0.002, 1.5e-6); }));
  EXPECT_TRUE(call<std_srvs::Trigger>(resume).success);

  ASSERT_TRUE(client.waitForResult(ros::Duration(30.0)));
  EXPECT_EQ(client.getState(), actionlib::SimpleClientGoalState::SUCCEEDED) << client.getState().getText();
  // The program's end, with the controller's report of the last operation's end point X25 Y5 Z2.
  EXPECT_EQ(client.getResult()->message.rfind("M30 program end at line 14: the program ends here; nothing after it "
                                              "was sent; the controller reported the end point X25 Y5 Z2 mm (",
                                              0),
            0u)
      << client.getResult()->message;
  EXPECT_TRUE(near(client.getResult()->final_position, 0.025, 0.005, 0.002, kEndTolerance))
      << client.getResult()->final_position;
  EXPECT_TRUE(state.waitFor([](const auto& s) { return near(s.position, 0.025, 0.005, 0.002, 1.5e-6); }))
      << state.last().position;
  // The controller's side: four operations (to X10, X15, X20, X25), each with its P1@ and S64@;
  // nothing for G01 X99 after M30.
  const auto all = received.lines();
  const std::vector<std::string> since(all.begin() + static_cast<long>(mark), all.end());
  EXPECT_EQ(std::count(since.begin(), since.end(), "M1"), 4);
  EXPECT_EQ(std::count(since.begin(), since.end(), "P1"), 4);
  EXPECT_EQ(std::count(since.begin(), since.end(), "S64"), 4);
  EXPECT_EQ(std::count(since.begin(), since.end(), "M0"), 4);
  EXPECT_EQ(since.back(), "M0");
  // Operation after operation, every setpoint is the one cnc_plan's dry run of the program gives.
  const auto sent = setpointLines(since);
  const auto planned = cncPlanSetpoints(CNC_BRIDGE_AT_PROGRAMS "/program_stops.nc", start_position);
  ASSERT_GT(sent.size(), 500u);  // some 25 mm of moves at up to 20 mm/s in 1 ms steps
  ASSERT_EQ(sent.size(), planned.size());
  for (size_t k = 0; k < sent.size(); ++k)
  {
    ASSERT_EQ(sent[k], planned[k]) << "setpoint " << k;
  }
  // The dwell was announced.
  const auto all_feedback = feedback.all();
  EXPECT_TRUE(std::any_of(all_feedback.begin(), all_feedback.end(),
                          [](const auto& f) { return f.event == "G04 dwell of 0.300 s at line 11"; }));
}

// Without ~program_commands a program that commands the spindle, coolant or tool is refused
// before anything is sent, naming the line and the parameter.
TEST_F(AtController, AProgramWithMachineCommandsIsRefusedWithoutProgramCommands)
{
  CommandLog received{command_log};
  ros::param::set(node + "/program_commands", false);
  const size_t mark = received.lines().size();
  cnc_bridge::AtFollowPathGoal goal;
  goal.gcode_file = "square.nc";
  goal.coolant = cnc_bridge::AtFollowPathGoal::COOLANT_DEFAULT;
  goal.tool = -1;
  client.sendGoal(goal);
  ASSERT_TRUE(client.waitForResult(ros::Duration(10.0)));
  ros::param::set(node + "/program_commands", true);
  EXPECT_EQ(client.getState(), actionlib::SimpleClientGoalState::ABORTED);
  const std::string text = client.getResult()->message;
  EXPECT_NE(text.find("program refused: line 7: coolant on (M07/M08) at line 7 commands the machine; set " + node +
                      "/program_commands true"),
            std::string::npos)
      << text;
  // A later command is the barrier: nothing of the refused program reached the controller before it.
  EXPECT_TRUE(call<std_srvs::Trigger>(node + "/set_auto").success);
  EXPECT_EQ(received.linesUntil(mark, "A"), std::vector<std::string>{"A"});
}

// Exact or refused: a tool length, spindle speed or jog feed the wire cannot carry (NaN, infinite,
// 1e300, negative, not whole millimetres) is refused with the reason, and nothing of it reaches the
// controller (not a wrapped or zeroed value); a goal whose tool length cannot be sent is refused
// before its first byte.
TEST_F(AtController, ValuesTheWireCannotCarryAreRefusedWithNothingSent)
{
  CommandLog received{command_log};
  const size_t mark = received.lines().size();
  for (const double length : {std::nan(""), HUGE_VAL, 1e300, -1.0, 0.0505})
  {
    cnc_bridge::AtToolChange::Request tool;
    tool.tool = 2;
    tool.length = length;
    const auto change = call<cnc_bridge::AtToolChange>(node + "/tool_change", tool);
    EXPECT_FALSE(change.success) << length;
    EXPECT_NE(change.message.find("tool length"), std::string::npos) << change.message;
  }
  for (const double rpm : {std::nan(""), HUGE_VAL, 1e300, -1.0})
  {
    cnc_bridge::AtSpindle::Request spin;
    spin.speed = rpm;
    const auto spindle = call<cnc_bridge::AtSpindle>(node + "/spindle", spin);
    EXPECT_FALSE(spindle.success) << rpm;
    EXPECT_NE(spindle.message.find("spindle speed"), std::string::npos) << spindle.message;
  }
  for (const double feed : {std::nan(""), HUGE_VAL, 1e300, -0.01})
  {
    const auto jog = call<cnc_bridge::AtJog>(node + "/jog", jogRequest("x", feed));
    EXPECT_FALSE(jog.success) << feed;
    EXPECT_NE(jog.message.find("jog feed_rate"), std::string::npos) << jog.message;
  }
  const auto start = state.last().position;
  auto goal = lineGoal(start.x + 0.002, start.y, start.z, 0.02, "");
  goal.tool = 3;
  goal.tool_length = std::nan("");
  client.sendGoal(goal);
  ASSERT_TRUE(client.waitForResult(ros::Duration(20.0)));
  EXPECT_EQ(client.getState(), actionlib::SimpleClientGoalState::ABORTED);
  EXPECT_NE(client.getResult()->message.find("goal refused before anything was sent: operation 1 of 1"),
            std::string::npos)
      << client.getResult()->message;
  // A later command is the barrier: nothing of the refused requests reached the controller before it.
  EXPECT_TRUE(call<std_srvs::Trigger>(node + "/set_auto").success);
  EXPECT_EQ(received.linesUntil(mark, "A"), std::vector<std::string>{"A"});
}

// A path goal in another frame (world, where the test launch places machine zero at (0.1, 0.2, 0))
// is transformed into the machine frame with tf2: the machine ends where the world point is. A
// frame with no transform is refused with tf2's reason and nothing reaches the controller.
TEST_F(AtController, APathGoalInWorldArrivesTransformed)
{
  CommandLog received{command_log};
  const auto start = state.last().position;
  const double x = start.x + 0.004, y = start.y - 0.003;  // machine frame
  client.sendGoal(lineGoal(x + 0.1, y + 0.2, start.z, 0.02, "world"));
  ASSERT_TRUE(client.waitForResult(ros::Duration(20.0)));
  EXPECT_EQ(client.getState(), actionlib::SimpleClientGoalState::SUCCEEDED) << client.getState().getText();
  EXPECT_TRUE(state.waitFor([&](const auto& s) { return near(s.position, x, y, start.z, 1.5e-6); }))
      << state.last().position;

  const size_t mark = received.lines().size();
  client.sendGoal(lineGoal(0.0, 0.0, 0.0, 0.02, "nowhere"));
  ASSERT_TRUE(client.waitForResult(ros::Duration(20.0)));
  EXPECT_EQ(client.getState(), actionlib::SimpleClientGoalState::ABORTED);
  const std::string text = client.getResult()->message;
  EXPECT_NE(text.find("path in frame \"nowhere\" refused: no transform into \"" + prefix + "machine\": "),
            std::string::npos)
      << text;
  // A later command is the barrier: nothing of the refused goal reached the controller before it.
  EXPECT_TRUE(call<std_srvs::Trigger>(node + "/set_auto").success);
  EXPECT_EQ(received.linesUntil(mark, "A"), std::vector<std::string>{"A"});
}

TEST_F(AtController, EmergencyStopMidPathStopsMotionAndAbortsWithTheReason)
{
  CommandLog received{command_log};
  const size_t before_goal = received.lines().size();
  const auto start = state.last().position;
  client.sendGoal(lineGoal(start.x - 0.1, start.y, start.z, 0.02, prefix + "machine"));
  ASSERT_TRUE(state.waitFor([&](const auto& s) { return s.position.x < start.x - 0.01; }));
  const pid_t pid = process_kill::pidFromFile(pid_file);
  ASSERT_GT(pid, 0);
  ASSERT_EQ(kill(pid, SIGUSR1), 0);  // the simulator's emergency stop button
  ASSERT_TRUE(client.waitForResult(ros::Duration(10.0)));
  EXPECT_EQ(client.getState(), actionlib::SimpleClientGoalState::ABORTED);
  EXPECT_NE(client.getResult()->message.find("emergency stop"), std::string::npos) << client.getResult()->message;
  ASSERT_TRUE(state.waitFor([](const auto& s) { return s.estop == cnc_bridge::MachineState::ESTOP_ON; }));
  EXPECT_EQ(state.last().execution, cnc_bridge::MachineState::EXECUTION_ALARM);
  // Motion stopped. The simulator reports every 10 ms while moving; these are measurement windows
  // (asserting that nothing moves needs a span of time), not waits for an event, each closed by a
  // marker the controller must receive before anything else.
  // The node ends the operation (#@ M0@); from then on the controller receives nothing.
  const auto until_end = received.linesUntil(before_goal, "M0");
  ASSERT_FALSE(until_end.empty()) << "the operation did not end";
  const size_t at_estop = before_goal + until_end.size();
  ros::WallDuration(0.5).sleep();  // window: a span in which nothing may move
  const double stopped_x = state.last().position.x;
  EXPECT_GT(stopped_x, start.x - 0.09);
  // Motion is refused during the emergency stop, and says why.
  client.sendGoal(lineGoal(start.x, start.y, start.z, 0.02, prefix + "machine"));
  ASSERT_TRUE(client.waitForResult(ros::Duration(10.0)));
  EXPECT_EQ(client.getState(), actionlib::SimpleClientGoalState::ABORTED);
  EXPECT_NE(client.getResult()->message.find("emergency stop"), std::string::npos);
  const auto home = call<std_srvs::Trigger>(node + "/home");
  EXPECT_FALSE(home.success);
  EXPECT_NE(home.message.find("emergency stop"), std::string::npos);
  ros::WallDuration(0.5).sleep();  // window: a span in which nothing may move
  expectNothingReceivedBeforeAMarker(received, at_estop);
  EXPECT_NEAR(state.last().position.x, stopped_x, 1e-9);
  ASSERT_EQ(kill(pid, SIGUSR2), 0);  // released
  ASSERT_TRUE(state.waitFor([](const auto& s) { return s.estop == cnc_bridge::MachineState::ESTOP_OFF; }));
}

TEST_F(AtController, HomeReturnsToTheHomePosition)
{
  const auto home = call<std_srvs::Trigger>(node + "/home");
  EXPECT_TRUE(home.success) << home.message;
  EXPECT_TRUE(state.waitFor([](const auto& s) { return s.message == "at home"; }, 20.0)) << state.last().message;
  EXPECT_TRUE(near(state.last().position, 0.0, 0.0, 0.0, 1e-9)) << state.last().position;
}

int main(int argc, char** argv)
{
  testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "test_at_controller");
  ros::NodeHandle pnh("~");
  pnh.getParam("node", node);
  pnh.getParam("namespace", ns);
  pnh.getParam("tf_prefix", prefix);
  pnh.getParam("pid_file", pid_file);
  pnh.getParam("command_log", command_log);
  pnh.getParam("profile", profile);  // the node's ~profile, for cnc_plan
  ros::param::get(node + "/jog_timeout", jog_timeout);
  ros::AsyncSpinner spinner(2);
  spinner.start();
  return RUN_ALL_TESTS();
}
