// ethernut_node against sim_ethernut: jobs streamed in order despite RESENDs (checked against the
// simulator's log of accepted coordinates and against our own parse of the program), G53 moves
// skipped or refused, the preview published before the job runs, pause/resume, cancel, a second goal
// rejected while a job runs, the kill gate, diagnostics, link loss (silence and a dropped
// connection), the board's debug lines, and the node's death in the middle of a job.
#include <actionlib/client/simple_action_client.h>
#include <diagnostic_msgs/DiagnosticArray.h>
#include <gtest/gtest.h>
#include <nav_msgs/Path.h>
#include <ros/ros.h>
#include <signal.h>
#include <std_msgs/String.h>
#include <std_srvs/SetBool.h>
#include <std_srvs/Trigger.h>
#include <visualization_msgs/MarkerArray.h>

#include "line_log.h"

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <fstream>
#include <map>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "cnc_bridge/EthernutCoordinates.h"
#include "cnc_bridge/EthernutSetMode.h"
#include "cnc_bridge/MachineState.h"
#include "cnc_bridge/RunJobAction.h"
#include "cnc_bridge/gcode/gcode.h"
#include "process_kill.h"
#include "topic_watch.h"

using cnc_bridge::MachineState;
using cnc_bridge::RunJobAction;
using cnc_bridge::RunJobFeedbackConstPtr;
using cnc_bridge::RunJobGoal;
using Client = actionlib::SimpleActionClient<RunJobAction>;

namespace
{
std::string ns, prefix, sim_log, sim_messages, program_dir;

// Everything the node publishes that the tests look at, in arrival order.
struct Watch : topic_watch::Record
{
  MachineState state;
  bool have_state = false;
  std::vector<std::pair<ros::WallTime, uint8_t>> links;  // every link value, with arrival time
  std::vector<std::string> messages;                     // every state message, in arrival order
  nav_msgs::Path path;
  uint64_t path_seq = 0;  // event counter value when the path arrived
  visualization_msgs::MarkerArray markers;
  uint64_t events = 0;
  std::vector<cnc_bridge::RunJobFeedback> feedback;
  std::vector<ros::WallTime> feedback_times;  // arrival of each feedback
  uint64_t first_feedback_seq = 0;
  ros::WallTime last_feedback_time;
  std::map<std::string, std::string> protocol;  // the last "ethernut protocol" diagnostics, key -> value
  std::vector<std::string> debug_lines;         // every line on debug, in arrival order
  std::map<std::string, std::string> debug;     // the last "ethernut debug channel" diagnostics

  template <typename F>
  bool waitFor(F condition, double seconds = 20.0)
  {
    return Record::waitFor(condition, seconds);
  }
};
Watch* watch = nullptr;

void onState(const MachineState::ConstPtr& m)
{
  watch->update(
      [&]
      {
        if (!watch->have_state || watch->state.link != m->link)
        {
          watch->links.push_back({ros::WallTime::now(), m->link});
        }
        if (watch->messages.empty() || watch->messages.back() != m->message)
        {
          watch->messages.push_back(m->message);
        }
        watch->state = *m;
        watch->have_state = true;
        ++watch->events;
      });
}

void onPath(const nav_msgs::Path::ConstPtr& m)
{
  watch->update(
      [&]
      {
        watch->path = *m;
        watch->path_seq = ++watch->events;
      });
}

void onMarkers(const visualization_msgs::MarkerArray::ConstPtr& m)
{
  watch->update([&] { watch->markers = *m; });
}

void onFeedback(const RunJobFeedbackConstPtr& f)
{
  watch->update(
      [&]
      {
        if (watch->feedback.empty())
        {
          watch->first_feedback_seq = ++watch->events;
        }
        watch->feedback.push_back(*f);
        watch->feedback_times.push_back(ros::WallTime::now());
        watch->last_feedback_time = ros::WallTime::now();
      });
}

void onDiagnostics(const diagnostic_msgs::DiagnosticArray::ConstPtr& m)
{
  for (const auto& status : m->status)
  {
    const bool protocol = status.name.find("ethernut protocol") != std::string::npos;
    const bool debug = status.name.find("ethernut debug channel") != std::string::npos;
    if ((!protocol && !debug) || status.values.empty())
    {
      continue;
    }
    watch->update(
        [&]
        {
          auto& values = protocol ? watch->protocol : watch->debug;
          values.clear();
          for (const auto& kv : status.values)
          {
            values[kv.key] = kv.value;
          }
        });
  }
}

void onDebug(const std_msgs::String::ConstPtr& m)
{
  watch->update([&] { watch->debug_lines.push_back(m->data); });
}

// A number from the last protocol diagnostics (caller holds watch->mutex); NaN if absent.
double diag(const std::string& key)
{
  const auto it = watch->protocol.find(key);
  return it == watch->protocol.end() ? std::nan("") : std::stod(it->second);
}

void clearJob()
{
  std::lock_guard<std::mutex> lock(watch->mutex);
  watch->feedback.clear();
  watch->feedback_times.clear();
  watch->first_feedback_seq = 0;
  watch->path_seq = 0;
}

std::vector<std::array<float, 3>> simLog()
{
  std::vector<std::array<float, 3>> lines;
  std::ifstream in(sim_log);
  float x, y, z;
  while (in >> x >> y >> z)
  {
    lines.push_back({x, y, z});
  }
  return lines;
}

// The names of the messages the simulated board received so far (its --message-log).
std::vector<std::string> simMessages()
{
  std::vector<std::string> names;
  std::ifstream in(sim_messages);
  for (std::string name; std::getline(in, name);)
  {
    names.push_back(name);
  }
  return names;
}

// Waits until the board has received a message named \p name after its first \p from messages.
bool waitForSimMessage(const std::string& name, size_t from, double seconds = 10.0)
{
  // The board writes the log from another process: woken by each change of the file.
  return line_log::waitForFile(
      sim_messages,
      [&]
      {
        const auto names = simMessages();
        return std::find(names.begin() + static_cast<long>(std::min(from, names.size())), names.end(), name) !=
               names.end();
      },
      seconds);
}

// The coordinates the node must send for a program: the end of every move, mm, as float; G53
// moves left out (~g53_moves: skip), the program position kept across them.
std::vector<std::array<float, 3>> expectedFor(const std::string& file)
{
  std::ifstream in(program_dir + "/" + file);
  std::vector<std::array<float, 3>> out;
  cnc_bridge::gcode::ParserOptions options;
  options.separate_machine_moves = true;
  cnc_bridge::gcode::forEachMove(
      in,
      [&](const cnc_bridge::gcode::Move& m)
      {
        if (!m.machine_coordinates)
        {
          out.push_back({static_cast<float>(m.end.x), static_cast<float>(m.end.y), static_cast<float>(m.end.z)});
        }
      },
      options);
  return out;
}

void expectSameCoordinates(const std::vector<std::array<float, 3>>& got, size_t from,
                           const std::vector<std::array<float, 3>>& expected)
{
  ASSERT_EQ(got.size() - from, expected.size());
  for (size_t i = 0; i < expected.size(); ++i)
  {
    for (int a = 0; a < 3; ++a)
    {
      // The simulator logs 4 decimals of the float it received.
      ASSERT_NEAR(got[from + i][a], expected[i][a], 1e-3) << "coordinate " << i << " axis " << a;
    }
  }
}

bool call(const std::string& service, std_srvs::Trigger::Response& res)
{
  std_srvs::Trigger srv;
  const bool ok = ros::service::call(ns + "/ethernut_node/" + service, srv);
  res = srv.response;
  return ok;
}

// Board ready: link up and the session through its handshake (execution READY).
bool boardReady(double seconds = 20.0)
{
  return watch->waitFor(
      []
      {
        return watch->have_state && watch->state.link == MachineState::LINK_UP &&
               watch->state.execution == MachineState::EXECUTION_READY;
      },
      seconds);
}

std::unique_ptr<Client> actionClient()
{
  auto client = std::make_unique<Client>(ns + "/ethernut_node/run_job", false);
  EXPECT_TRUE(client->waitForServer(ros::Duration(20.0)));
  return client;
}

bool setMotion(bool enabled, std_srvs::SetBool::Response& res)
{
  std_srvs::SetBool set;
  set.request.data = enabled;
  const bool ok = ros::service::call(ns + "/ethernut_node/set_motion_enabled", set);
  res = set.response;
  return ok;
}

// How many of the board's received messages since its first \p from are named \p name.
long simMessagesNamed(const std::string& name, size_t from)
{
  const auto names = simMessages();
  return std::count(names.begin() + static_cast<long>(std::min(from, names.size())), names.end(), name);
}

RunJobGoal pointsGoal(const std::vector<std::array<double, 3>>& points_m)
{
  RunJobGoal goal;
  for (const auto& p : points_m)
  {
    geometry_msgs::Point g;
    g.x = p[0];
    g.y = p[1];
    g.z = p[2];
    goal.points.push_back(g);
  }
  return goal;
}
}  // namespace

TEST(EthernutJob, KillIsRefusedByDefault)
{
  ASSERT_TRUE(boardReady());
  const size_t before = simMessages().size();
  std_srvs::Trigger::Response res;
  ASSERT_TRUE(call("kill", res));
  EXPECT_FALSE(res.success);
  EXPECT_NE(res.message.find(ns + "/ethernut_node/enable_kill"), std::string::npos) << res.message;
  EXPECT_TRUE(boardReady(5.0));  // a kill would have made the board drop the link
  // An idle link carries the node's alive requests (one per keepalive period of silence); one
  // that arrives after the refusal was sent after it, so a kill sent by the refusal is in the log
  // before it.
  ASSERT_TRUE(waitForSimMessage("alive-request", simMessages().size()));
  const auto received = simMessages();
  EXPECT_EQ(std::count(received.begin() + static_cast<long>(before), received.end(), "kill"), 0)
      << "the board received a kill the node refused";
  EXPECT_NE(res.message.find(ns + "/ethernut_node/set_kill_enabled"), std::string::npos) << res.message;

  // The run-time switch answers with its caller and shows in diagnostics; switched off again,
  // kill stays refused and the board receives none.
  std_srvs::SetBool set;
  set.request.data = true;
  ASSERT_TRUE(ros::service::call(ns + "/ethernut_node/set_kill_enabled", set));
  EXPECT_EQ(set.response.message, "kill enabled by " + ros::this_node::getName());
  set.request.data = false;
  ASSERT_TRUE(ros::service::call(ns + "/ethernut_node/set_kill_enabled", set));
  EXPECT_EQ(set.response.message, "kill disabled by " + ros::this_node::getName());
  const size_t again = simMessages().size();
  ASSERT_TRUE(call("kill", res));
  EXPECT_FALSE(res.success) << res.message;
  ASSERT_TRUE(watch->waitFor(
      []
      {
        const auto it = watch->protocol.find("kill last change");
        return it != watch->protocol.end() && it->second.rfind("disabled by " + ros::this_node::getName(), 0) == 0;
      },
      10.0));
  ASSERT_TRUE(waitForSimMessage("alive-request", simMessages().size()));
  const auto later = simMessages();
  EXPECT_EQ(std::count(later.begin() + static_cast<long>(again), later.end(), "kill"), 0)
      << "the board received a kill the node refused";
}

// The whole job is checked before its first set: a points goal whose third point a float cannot
// carry is refused naming the point, and the board receives none of its sets (not the first two).
TEST(EthernutJob, AJobWithOnePointTheBoardCannotTakeIsRefusedWithNothingSent)
{
  ASSERT_TRUE(boardReady());
  auto client = actionClient();
  const size_t messages_before = simMessages().size();
  const size_t before = simLog().size();
  client->sendGoal(pointsGoal({{0.001, 0.002, 0.003}, {0.002, 0.002, 0.003}, {1e39, 0.0, 0.0}}));
  ASSERT_TRUE(client->waitForResult(ros::Duration(20.0)));
  EXPECT_EQ(client->getState(), actionlib::SimpleClientGoalState::ABORTED);
  const std::string text = client->getResult()->message;
  EXPECT_EQ(text.rfind("job refused: point 2: X ", 0), 0u) << text;
  EXPECT_NE(text.find("cannot be sent: the board takes float coordinates"), std::string::npos) << text;
  // An alive request that arrives after the refusal was sent after it.
  ASSERT_TRUE(waitForSimMessage("alive-request", simMessages().size()));
  EXPECT_EQ(simMessagesNamed("coordinates", messages_before), 0);
  EXPECT_EQ(simMessagesNamed("READYTOSEND", messages_before), 0);
  EXPECT_EQ(simLog().size(), before);
}

TEST(EthernutJob, QcncStyleProgramStreamsEveryCoordinateInOrderDespiteResends)
{
  ASSERT_TRUE(boardReady());
  auto client = actionClient();
  clearJob();
  const size_t before = simLog().size();
  RunJobGoal goal;
  goal.file = "seed_hello.nc";
  client->sendGoal(goal, Client::SimpleDoneCallback(), Client::SimpleActiveCallback(), &onFeedback);
  ASSERT_TRUE(client->waitForResult(ros::Duration(30.0)));
  ASSERT_EQ(client->getState(), actionlib::SimpleClientGoalState::SUCCEEDED) << client->getState().getText();
  const auto result = client->getResult();
  const auto expected = expectedFor("seed_hello.nc");
  EXPECT_EQ(result->coordinate_count, expected.size());
  EXPECT_EQ(result->coordinates_done, expected.size());
  EXPECT_GE(result->resends, 1u);  // the simulator asks again for every 4th set
  expectSameCoordinates(simLog(), before, expected);

  // The preview came out before the job ran (before the first feedback) and matches the program.
  ASSERT_TRUE(watch->waitFor(
      [] { return watch->path_seq > 0 && !watch->feedback.empty() && watch->feedback.back().percent > 99.999f; }, 5.0));
  std::lock_guard<std::mutex> lock(watch->mutex);
  EXPECT_LT(watch->path_seq, watch->first_feedback_seq);
  EXPECT_EQ(watch->path.header.frame_id, prefix + "machine");
  ASSERT_EQ(watch->path.poses.size(), expected.size() + 1);            // the start point plus every move
  EXPECT_NEAR(watch->path.poses.back().pose.position.z, 0.005, 1e-9);  // Z5 mm in metres
  EXPECT_EQ(watch->feedback.back().line, 9u);                          // N70 Z5 is line 9 of the file
}

TEST(EthernutJob, HaasProgramPreviewStaysInsideThePartAndStreamsInOrder)
{
  ASSERT_TRUE(boardReady());
  auto client = actionClient();
  clearJob();
  const size_t before = simLog().size();
  RunJobGoal goal;
  goal.file = "haas_O05555.nc";
  client->sendGoal(goal, Client::SimpleDoneCallback(), Client::SimpleActiveCallback(), &onFeedback);
  ASSERT_TRUE(client->waitForResult(ros::Duration(60.0)));
  ASSERT_EQ(client->getState(), actionlib::SimpleClientGoalState::SUCCEEDED) << client->getState().getText();
  const auto expected = expectedFor("haas_O05555.nc");
  EXPECT_GT(expected.size(), 100u);  // the arcs are cut into chords
  const auto streamed = simLog();
  expectSameCoordinates(streamed, before, expected);
  // The four G53 moves (machine coordinates, lines 9, 53, 57, 59) are left out (~g53_moves: skip)
  // and the program's Z is kept across them: the last set is N66455 X2.1875 at the Z1. clearance
  // of N235, not G53 Y0 (in work coordinates: a plunge to Y0 Z0 on the part).
  EXPECT_NE(client->getResult()->message.find("4 G53 moves left out (lines 9, 53, 57, 59)"), std::string::npos)
      << client->getResult()->message;
  ASSERT_FALSE(streamed.empty());
  EXPECT_NEAR(streamed.back()[0], 2.1875 * 25.4, 1e-3);
  EXPECT_NEAR(streamed.back()[1], 2.906 * 25.4, 1e-3);
  EXPECT_NEAR(streamed.back()[2], 1.0 * 25.4, 1e-3);

  std::lock_guard<std::mutex> lock(watch->mutex);
  const double inch = 0.0254;
  ASSERT_EQ(watch->path.poses.size(), expected.size() + 1);  // the start point plus every streamed move
  EXPECT_NEAR(watch->path.poses.back().pose.position.z, 1.0 * inch, 1e-9);
  for (const auto& pose : watch->path.poses)
  {
    const auto& p = pose.pose.position;
    // Part extent (the G53 retracts are not in the preview).
    EXPECT_GE(p.x, -1.3 * inch - 1e-6);
    EXPECT_LE(p.x, 5.675 * inch + 1e-6);
    EXPECT_GE(p.y, -1e-6);
    EXPECT_LE(p.y, 2.906 * inch + 1e-6);
    EXPECT_GE(p.z, -0.125 * inch - 1e-6);
    EXPECT_LE(p.z, 1.0 * inch + 1e-6);
  }
  size_t rapid_points = 0, feed_points = 0;
  for (const auto& m : watch->markers.markers)
  {
    if (m.ns == "rapid")
    {
      rapid_points = m.points.size();
    }
    if (m.ns == "feed")
    {
      feed_points = m.points.size();
      EXPECT_EQ(m.header.frame_id, prefix + "machine");
    }
  }
  EXPECT_GT(rapid_points, 0u);
  EXPECT_GT(feed_points, rapid_points);
}

TEST(EthernutJob, ReportedPositionEndsAtTheLastCoordinate)
{
  ASSERT_TRUE(boardReady());
  auto client = actionClient();
  RunJobGoal goal = pointsGoal({{0.01, 0.02, 0.003}, {0.012, -0.004, 0.001}});
  client->sendGoal(goal);
  ASSERT_TRUE(client->waitForResult(ros::Duration(30.0)));
  ASSERT_EQ(client->getState(), actionlib::SimpleClientGoalState::SUCCEEDED);
  // Status-4 reports are the machine position in mm; the state carries metres.
  EXPECT_TRUE(watch->waitFor(
      []
      {
        const auto& p = watch->state.position;
        return watch->state.position_valid && std::fabs(p.x - 0.012) < 1e-6 && std::fabs(p.y + 0.004) < 1e-6 &&
               std::fabs(p.z - 0.001) < 1e-6;
      },
      10.0));
  // The commanded position (the last set the board acknowledged) rides in the same message.
  std::lock_guard<std::mutex> lock(watch->mutex);
  const auto& c = watch->state.commanded_position;
  EXPECT_TRUE(watch->state.commanded_valid);
  EXPECT_NEAR(c.x, 0.012, 1e-6);
  EXPECT_NEAR(c.y, -0.004, 1e-6);
  EXPECT_NEAR(c.z, 0.001, 1e-6);
  // A list of points is all feed moves: the preview has no rapid line list (rviz refuses an empty
  // one and shows the display in error), and every line list it has holds lines.
  for (const auto& m : watch->markers.markers)
  {
    EXPECT_NE(m.ns, "rapid");
    if (m.type == visualization_msgs::Marker::LINE_LIST)
    {
      EXPECT_FALSE(m.points.empty()) << m.ns;
    }
  }
}

TEST(EthernutJob, PauseHoldsTheJobAndResumeFinishesIt)
{
  ASSERT_TRUE(boardReady());
  auto client = actionClient();
  clearJob();
  const size_t before = simLog().size();
  // 0.2 m apart at 2000 mm/s: 100 ms per move.
  std::vector<std::array<double, 3>> points;
  for (int i = 0; i < 8; ++i)
  {
    points.push_back({(i % 2) * 0.2, 0.0, 0.0});
  }
  client->sendGoal(pointsGoal(points), Client::SimpleDoneCallback(), Client::SimpleActiveCallback(), &onFeedback);
  ASSERT_TRUE(watch->waitFor([] { return !watch->feedback.empty() && watch->feedback.back().coordinate_index >= 1; }));
  std_srvs::Trigger::Response res;
  ASSERT_TRUE(call("pause", res));
  ASSERT_TRUE(res.success) << res.message;
  ASSERT_TRUE(watch->waitFor([] { return watch->state.execution == MachineState::EXECUTION_PAUSED; }, 5.0));
  const size_t held = simLog().size();
  // While paused nothing completes: wait longer than three moves would take.
  EXPECT_FALSE(watch->waitFor([&] { return simLog().size() > held; }, 0.4));
  EXPECT_FALSE(client->getState().isDone());
  ASSERT_TRUE(call("resume", res));
  ASSERT_TRUE(res.success) << res.message;
  ASSERT_TRUE(client->waitForResult(ros::Duration(30.0)));
  ASSERT_EQ(client->getState(), actionlib::SimpleClientGoalState::SUCCEEDED) << client->getState().getText();
  std::vector<std::array<float, 3>> expected;
  for (const auto& p : points)
  {
    expected.push_back({static_cast<float>(p[0] * 1000), 0.0f, 0.0f});
  }
  expectSameCoordinates(simLog(), before, expected);
}

// ~set_motion_enabled false while a job streams: the board is paused (it holds the move in
// progress) and receives no more sets, the goal stays active with feedback paused and why;
// ~resume is refused while motion is disabled; enabled again, ~resume lets every set reach the
// board. A job sent while motion is disabled is refused naming the service and the parameter,
// and the board receives nothing of it.
TEST(EthernutJob, DisablingMotionMidJobPausesTheBoardUntilEnabledAndResumed)
{
  ASSERT_TRUE(boardReady());
  auto client = actionClient();
  clearJob();
  const size_t before = simLog().size();
  const size_t messages_before = simMessages().size();
  std::vector<std::array<double, 3>> points;  // 0.2 m apart at 2000 mm/s: 100 ms per move
  for (int i = 0; i < 8; ++i)
  {
    points.push_back({(i % 2) * 0.2, 0.0, 0.0});
  }
  client->sendGoal(pointsGoal(points), Client::SimpleDoneCallback(), Client::SimpleActiveCallback(), &onFeedback);
  ASSERT_TRUE(watch->waitFor([] { return !watch->feedback.empty() && watch->feedback.back().coordinate_index >= 1; }));
  const std::string me = ros::this_node::getName();
  const std::string set_motion = ns + "/ethernut_node/set_motion_enabled";
  std_srvs::SetBool::Response set;
  ASSERT_TRUE(setMotion(false, set));
  EXPECT_EQ(set.message, "motion disabled by " + me);

  // Held: the board got a pause request, the goal is active and its feedback says why.
  ASSERT_TRUE(watch->waitFor([] { return !watch->feedback.empty() && watch->feedback.back().paused; }, 10.0));
  {
    std::lock_guard<std::mutex> lock(watch->mutex);
    const std::string event = watch->feedback.back().event;
    EXPECT_EQ(event.rfind("motion disabled by " + me + ": the board holds the move in progress", 0), 0u) << event;
    EXPECT_NE(event.find(set_motion), std::string::npos) << event;
    EXPECT_NE(event.find(ns + "/ethernut_node/resume"), std::string::npos) << event;
  }
  ASSERT_TRUE(waitForSimMessage("pause-request", messages_before));
  ASSERT_TRUE(watch->waitFor([] { return watch->state.execution == MachineState::EXECUTION_PAUSED; }, 5.0));
  const size_t held = simLog().size();
  const size_t held_messages = simMessages().size();
  EXPECT_LT(held - before, points.size());
  // Nothing more reaches the board meanwhile: wait longer than three moves would take.
  EXPECT_FALSE(watch->waitFor([&] { return simLog().size() > held; }, 0.4));
  EXPECT_FALSE(client->getState().isDone());

  // ~resume is refused while motion is disabled and names the switch; the board stays paused.
  std_srvs::Trigger::Response res;
  ASSERT_TRUE(call("resume", res));
  EXPECT_FALSE(res.success);
  EXPECT_NE(res.message.find("resume refused: motion is disabled"), std::string::npos) << res.message;
  EXPECT_NE(res.message.find(set_motion), std::string::npos) << res.message;
  EXPECT_NE(res.message.find(ns + "/ethernut_node/enable_motion"), std::string::npos) << res.message;

  // A second client's job meanwhile is turned away and sends nothing (one goal at a time).
  auto other = actionClient();
  other->sendGoal(pointsGoal({{0.01, 0.02, 0.003}}));
  ASSERT_TRUE(other->waitForResult(ros::Duration(20.0)));
  EXPECT_NE(other->getState(), actionlib::SimpleClientGoalState::SUCCEEDED);
  // Diagnostics show the switch and who moved it.
  ASSERT_TRUE(watch->waitFor(
      [&]
      {
        const auto it = watch->protocol.find("motion last change");
        return it != watch->protocol.end() && it->second.rfind("disabled by " + me, 0) == 0 &&
               watch->protocol["motion enabled"] == "False";
      },
      10.0));
  EXPECT_EQ(simMessagesNamed("coordinates", held_messages), 0);
  EXPECT_EQ(simMessagesNamed("READYTOSEND", held_messages), 0);
  EXPECT_EQ(simLog().size(), held);

  // Enabled again: ~resume goes on and every set of the job reaches the board, in order.
  ASSERT_TRUE(setMotion(true, set));
  EXPECT_EQ(set.message, "motion enabled by " + me);
  // Enabling alone moves nothing: state says the job waits for ~resume.
  const std::string held_message =
      "motion enabled by " + me + "; the job stays held until " + ns + "/ethernut_node/resume";
  EXPECT_TRUE(watch->waitFor([&] { return watch->state.message == held_message; }, 5.0)) << watch->state.message;
  EXPECT_EQ(simMessagesNamed("READYTOSEND", held_messages), 0);
  ASSERT_TRUE(call("resume", res));
  EXPECT_TRUE(res.success) << res.message;
  EXPECT_EQ(res.message, "resumed after the hold (motion disabled by " + me + ")");
  ASSERT_TRUE(client->waitForResult(ros::Duration(30.0)));
  ASSERT_EQ(client->getState(), actionlib::SimpleClientGoalState::SUCCEEDED) << client->getState().getText();
  EXPECT_EQ(client->getResult()->coordinates_done, points.size());
  std::vector<std::array<float, 3>> expected;
  for (const auto& p : points)
  {
    expected.push_back({static_cast<float>(p[0] * 1000), 0.0f, 0.0f});
  }
  expectSameCoordinates(simLog(), before, expected);
  {
    std::lock_guard<std::mutex> lock(watch->mutex);
    EXPECT_FALSE(watch->feedback.back().paused);
  }
  EXPECT_TRUE(boardReady(10.0));

  // A job while motion is disabled is refused naming the service and the parameter; the board
  // receives nothing of it.
  ASSERT_TRUE(setMotion(false, set));
  const size_t refused_from = simMessages().size();
  const size_t refused_log = simLog().size();
  client->sendGoal(pointsGoal({{0.01, 0.02, 0.003}}));
  ASSERT_TRUE(client->waitForResult(ros::Duration(20.0)));
  EXPECT_EQ(client->getState(), actionlib::SimpleClientGoalState::ABORTED);
  const std::string text = client->getResult()->message;
  EXPECT_NE(text.find("job refused: motion is disabled"), std::string::npos) << text;
  EXPECT_NE(text.find(set_motion), std::string::npos) << text;
  EXPECT_NE(text.find(ns + "/ethernut_node/enable_motion"), std::string::npos) << text;
  ASSERT_TRUE(setMotion(true, set));
  // An alive request that arrives after the refusal was sent after it: whatever the refused job
  // sent would be in the log before it.
  ASSERT_TRUE(waitForSimMessage("alive-request", simMessages().size()));
  EXPECT_EQ(simMessagesNamed("READYTOSEND", refused_from), 0);
  EXPECT_EQ(simMessagesNamed("coordinates", refused_from), 0);
  EXPECT_EQ(simLog().size(), refused_log);
}

// A points goal in world (ethernut_node.test places router/machine at (0.1, 0.2, 0.05) m, turned 90
// degrees about Z) arrives at the board in machine coordinates; the preview is in the machine
// frame. A goal in a frame with no transform is refused with tf2's reason, and a file job with a
// frame too; the board receives nothing of either.
TEST(EthernutJob, APointsGoalInWorldArrivesTransformed)
{
  ASSERT_TRUE(boardReady());
  auto client = actionClient();
  clearJob();
  const size_t before = simLog().size();
  // world (0.1, 0.21, 0.052) is 0.01 m along world Y from the machine zero: machine X 10 mm, Z 2 mm;
  // world (0.08, 0.2, 0.05) is 0.02 m along world -X: machine Y 20 mm.
  RunJobGoal goal = pointsGoal({{0.1, 0.21, 0.052}, {0.08, 0.2, 0.05}});
  goal.header.frame_id = "world";
  client->sendGoal(goal, Client::SimpleDoneCallback(), Client::SimpleActiveCallback(), &onFeedback);
  ASSERT_TRUE(client->waitForResult(ros::Duration(30.0)));
  ASSERT_EQ(client->getState(), actionlib::SimpleClientGoalState::SUCCEEDED) << client->getState().getText();
  expectSameCoordinates(simLog(), before, {{10, 0, 2}, {0, 20, 0}});
  {
    std::lock_guard<std::mutex> lock(watch->mutex);
    EXPECT_EQ(watch->path.header.frame_id, prefix + "machine");
    ASSERT_EQ(watch->path.poses.size(), 2u);
    EXPECT_NEAR(watch->path.poses[0].pose.position.x, 0.01, 1e-9);
    EXPECT_NEAR(watch->path.poses[1].pose.position.y, 0.02, 1e-9);
  }

  const size_t refused_from = simMessages().size();
  goal.header.frame_id = "nowhere";
  client->sendGoal(goal);
  ASSERT_TRUE(client->waitForResult(ros::Duration(20.0)));
  EXPECT_EQ(client->getState(), actionlib::SimpleClientGoalState::ABORTED);
  std::string text = client->getResult()->message;
  EXPECT_EQ(
      text.rfind("job refused: points in frame \"nowhere\" refused: no transform into \"" + prefix + "machine\": ", 0),
      0u)
      << text;
  EXPECT_GT(text.size(), 80u) << "tf2's reason is missing: " << text;
  RunJobGoal file_goal;
  file_goal.file = "seed_hello.nc";
  file_goal.header.frame_id = "world";
  client->sendGoal(file_goal);
  ASSERT_TRUE(client->waitForResult(ros::Duration(20.0)));
  EXPECT_EQ(client->getState(), actionlib::SimpleClientGoalState::ABORTED);
  text = client->getResult()->message;
  EXPECT_NE(text.find("applies to points only"), std::string::npos) << text;
  // An alive request that arrives after the refusals was sent after them.
  ASSERT_TRUE(waitForSimMessage("alive-request", simMessages().size()));
  EXPECT_EQ(simMessagesNamed("READYTOSEND", refused_from), 0);
  EXPECT_EQ(simMessagesNamed("coordinates", refused_from), 0);
  EXPECT_EQ(simLog().size(), before + 2);
}

TEST(EthernutJob, CancelStopsStreamingAndPausesTheBoard)
{
  ASSERT_TRUE(boardReady());
  auto client = actionClient();
  clearJob();
  const size_t before = simLog().size();
  std::vector<std::array<double, 3>> points;
  for (int i = 0; i < 20; ++i)
  {
    points.push_back({(i % 2) * 0.2, 0.0, 0.0});
  }
  client->sendGoal(pointsGoal(points), Client::SimpleDoneCallback(), Client::SimpleActiveCallback(), &onFeedback);
  ASSERT_TRUE(watch->waitFor([] { return !watch->feedback.empty(); }));
  client->cancelGoal();
  ASSERT_TRUE(client->waitForResult(ros::Duration(20.0)));
  EXPECT_EQ(client->getState(), actionlib::SimpleClientGoalState::PREEMPTED);
  ASSERT_TRUE(watch->waitFor([] { return watch->state.execution == MachineState::EXECUTION_PAUSED; }, 5.0));
  EXPECT_LT(simLog().size() - before, points.size());
  std_srvs::Trigger::Response res;
  ASSERT_TRUE(call("resume", res));  // the held move completes; nothing more is sent
  EXPECT_TRUE(res.success) << res.message;
  EXPECT_TRUE(boardReady(10.0));
}

// A new goal while a job streams is rejected with a result that names the running goal and how to
// stop it (docs/ROS_INTERFACE.md, one new-goal policy); the running job is not touched: every one
// of its sets reaches the simulator, and none of the rejected goal's.
TEST(EthernutJob, SecondGoalIsRejectedAndTheRunningJobCompletes)
{
  ASSERT_TRUE(boardReady());
  auto first = actionClient();
  auto second = actionClient();
  clearJob();
  const size_t before = simLog().size();
  std::vector<std::array<double, 3>> points;  // 100 ms per move at 2000 mm/s
  for (int i = 0; i < 8; ++i)
  {
    points.push_back({(i % 2) * 0.2, 0.0, 0.0});
  }
  first->sendGoal(pointsGoal(points), Client::SimpleDoneCallback(), Client::SimpleActiveCallback(), &onFeedback);
  ASSERT_TRUE(watch->waitFor([] { return !watch->feedback.empty(); }));
  second->sendGoal(pointsGoal({{0.01, 0.02, 0.003}, {0.02, 0.01, 0.002}}));
  ASSERT_TRUE(second->waitForResult(ros::Duration(20.0)));
  EXPECT_EQ(second->getState(), actionlib::SimpleClientGoalState::REJECTED) << second->getState().getText();
  const std::string text = second->getResult()->message;
  EXPECT_FALSE(second->getResult()->success);
  EXPECT_NE(text.find(ns + "/ethernut_node/run_job is running goal "), std::string::npos) << text;
  EXPECT_NE(text.find("(8 points)"), std::string::npos) << text;
  EXPECT_NE(text.find("cancel it first"), std::string::npos) << text;
  EXPECT_FALSE(first->getState().isDone());
  ASSERT_TRUE(first->waitForResult(ros::Duration(30.0)));
  ASSERT_EQ(first->getState(), actionlib::SimpleClientGoalState::SUCCEEDED) << first->getState().getText();
  EXPECT_EQ(first->getResult()->coordinates_done, points.size());
  std::vector<std::array<float, 3>> expected;
  for (const auto& p : points)
  {
    expected.push_back({static_cast<float>(p[0] * 1000), 0.0f, 0.0f});
  }
  expectSameCoordinates(simLog(), before, expected);  // exactly the first job's sets
  EXPECT_TRUE(boardReady(10.0));
}

// True once the last feedback says the job is held at a program stop.
bool heldAtProgramStop(double seconds = 20.0)
{
  return watch->waitFor([] { return !watch->feedback.empty() && watch->feedback.back().paused; }, seconds);
}

// The program's own stops (test/data/gcode/program_stops.nc): M00 and M01 hold the stream at the
// end of their block until ~resume and nothing more reaches the board meanwhile; the spindle and
// coolant words show in state; G04 holds the stream for its time; M30 ends the job and the move
// after it never reaches the board.
TEST(EthernutJob, ProgramStopsHoldTheStreamUntilResumeAndM30EndsTheJob)
{
  ASSERT_TRUE(boardReady());
  auto client = actionClient();
  clearJob();
  const size_t before = simLog().size();
  RunJobGoal goal;
  goal.file = "program_stops.nc";
  client->sendGoal(goal, Client::SimpleDoneCallback(), Client::SimpleActiveCallback(), &onFeedback);
  const std::string resume = ns + "/ethernut_node/resume";

  // M00 on line 8, after G01 X10.
  ASSERT_TRUE(heldAtProgramStop());
  {
    std::lock_guard<std::mutex> lock(watch->mutex);
    EXPECT_EQ(watch->feedback.back().event, "M00 program stop at line 8: waiting for " + resume);
    EXPECT_EQ(watch->feedback.back().line, 8u);
  }
  ASSERT_TRUE(watch->waitFor([] { return watch->state.execution == MachineState::EXECUTION_PAUSED; }, 5.0));
  {
    std::lock_guard<std::mutex> lock(watch->mutex);
    EXPECT_EQ(watch->state.spindle_speed, 8000.0);              // S8000 M03
    EXPECT_EQ(watch->state.coolant, MachineState::COOLANT_ON);  // M08
    EXPECT_EQ(watch->state.block, 8u);
    EXPECT_NE(watch->state.message.find("M00 program stop at line 8"), std::string::npos) << watch->state.message;
  }
  expectSameCoordinates(simLog(), before, {{0, 0, 5}, {10, 0, 5}});
  // Held: nothing more reaches the board (a measurement window of several moves' time).
  EXPECT_FALSE(watch->waitFor([&] { return simLog().size() > before + 2; }, 0.4));
  EXPECT_FALSE(client->getState().isDone());
  std_srvs::Trigger::Response res;
  clearJob();
  ASSERT_TRUE(call("resume", res));
  EXPECT_TRUE(res.success) << res.message;
  EXPECT_EQ(res.message, "resumed after the M00 program stop at line 8");

  // M01 on line 10 (~optional_stop defaults to true), after G01 X20.
  ASSERT_TRUE(heldAtProgramStop());
  {
    std::lock_guard<std::mutex> lock(watch->mutex);
    EXPECT_EQ(watch->feedback.back().event, "M01 optional stop at line 10: waiting for " + resume);
  }
  expectSameCoordinates(simLog(), before, {{0, 0, 5}, {10, 0, 5}, {20, 0, 5}});
  clearJob();
  ASSERT_TRUE(call("resume", res));
  EXPECT_TRUE(res.success) << res.message;

  ASSERT_TRUE(client->waitForResult(ros::Duration(30.0)));
  ASSERT_EQ(client->getState(), actionlib::SimpleClientGoalState::SUCCEEDED) << client->getState().getText();
  const auto result = client->getResult();
  EXPECT_NE(result->message.find("M30 program end at line 15: the job ends here; nothing after it was sent"),
            std::string::npos)
      << result->message;
  EXPECT_EQ(result->coordinate_count, 5u);
  EXPECT_EQ(result->coordinates_done, 5u);
  // The board's side: every move up to M30, and not G01 X99 after it.
  expectSameCoordinates(simLog(), before, {{0, 0, 5}, {10, 0, 5}, {20, 0, 5}, {30, 0, 5}, {40, 0, 5}});

  // G04 P0.3 on line 12 was announced and held the stream: X40 was acknowledged no sooner.
  {
    std::lock_guard<std::mutex> lock(watch->mutex);
    size_t dwell = watch->feedback.size();
    for (size_t i = 0; i < watch->feedback.size(); ++i)
    {
      if (watch->feedback[i].event == "G04 dwell of 0.300 s at line 12")
      {
        dwell = i;
        break;
      }
    }
    ASSERT_LT(dwell, watch->feedback.size()) << "no dwell feedback";
    size_t x40 = watch->feedback.size();
    for (size_t i = dwell; i < watch->feedback.size(); ++i)
    {
      if (watch->feedback[i].coordinate_index == 4)
      {
        x40 = i;
        break;
      }
    }
    ASSERT_LT(x40, watch->feedback.size());
    EXPECT_GE((watch->feedback_times[x40] - watch->feedback_times[dwell]).toSec(), 0.25);
  }
  // M05 M09 before M30: spindle and coolant off in state.
  EXPECT_TRUE(watch->waitFor(
      [] { return watch->state.spindle_speed == 0.0 && watch->state.coolant == MachineState::COOLANT_OFF; }, 5.0));
  EXPECT_TRUE(boardReady(10.0));
}

// With ~optional_stop false (the OPT STOP switch off), M01 is passed and said so; M00 still holds.
TEST(EthernutJob, OptionalStopIsPassedWhenTheSwitchIsOff)
{
  ASSERT_TRUE(boardReady());
  ros::param::set(ns + "/ethernut_node/optional_stop", false);
  auto client = actionClient();
  clearJob();
  const size_t before = simLog().size();
  RunJobGoal goal;
  goal.file = "program_stops.nc";
  client->sendGoal(goal, Client::SimpleDoneCallback(), Client::SimpleActiveCallback(), &onFeedback);
  ASSERT_TRUE(heldAtProgramStop());
  std_srvs::Trigger::Response res;
  ASSERT_TRUE(call("resume", res));
  EXPECT_TRUE(res.success) << res.message;
  ASSERT_TRUE(client->waitForResult(ros::Duration(30.0)));
  ros::param::del(ns + "/ethernut_node/optional_stop");
  ASSERT_EQ(client->getState(), actionlib::SimpleClientGoalState::SUCCEEDED) << client->getState().getText();
  std::lock_guard<std::mutex> lock(watch->mutex);
  bool passed = false;
  for (const auto& f : watch->feedback)
  {
    passed = passed || f.event == "M01 optional stop at line 10 passed (" + ns + "/ethernut_node/optional_stop false)";
  }
  EXPECT_TRUE(passed);
  size_t pauses = 0;
  for (size_t i = 0; i < watch->feedback.size(); ++i)
  {
    if (watch->feedback[i].paused && (i == 0 || !watch->feedback[i - 1].paused))
    {
      ++pauses;
    }
  }
  EXPECT_EQ(pauses, 1u);  // M00 only
  EXPECT_EQ(simLog().size() - before, 5u);
}

// The protocol diagnostics after the jobs above: RESENDs counted (the simulator asks again for
// every 4th set), no keepalive missed, both round trips measured and plausible on loopback.
TEST(EthernutJob, DiagnosticsReportRoundTripsResendsAndKeepalives)
{
  ASSERT_TRUE(boardReady());
  // Link round trips are sampled by alive requests, which go out while the idle board is silent.
  ASSERT_TRUE(watch->waitFor([] { return diag("link round trip samples") >= 1; }, 20.0));
  std::lock_guard<std::mutex> lock(watch->mutex);
  EXPECT_GE(diag("resends"), 3);  // at least one in each of the qCNC-style, Haas and second-goal jobs
  EXPECT_EQ(diag("keepalive misses"), 0);
  EXPECT_GE(diag("keepalive requests"), 1);
  EXPECT_GT(diag("coordinates acknowledged"), 100);
  EXPECT_EQ(diag("reconnects"), 0);
  const double link = diag("link round trip mean (ms)");
  EXPECT_GT(link, 0.0);
  EXPECT_LT(link, 500.0);  // loopback; generous for a loaded machine
  EXPECT_LE(diag("link round trip last (ms)"), diag("link round trip max (ms)"));
  // Coordinate -> NEXT includes the move (0.2 m at 2 m/s in the jobs above): longer than the link's.
  EXPECT_GT(diag("coordinate round trip max (ms)"), 50.0);
  EXPECT_GT(diag("coordinate round trip max (ms)"), diag("link round trip max (ms)"));
}

// While motion is off (the launch file's default), ~reset (its opcode drives the axes to 0/0/0)
// and ~set_mode (standalone: the board runs on its own) are refused naming the switch, and the
// board receives neither: no reset and no mode message arrives before an alive request the node
// sent after the refusals.
TEST(EthernutLink, ResetAndSetModeAreRefusedWhileMotionIsDisabled)
{
  ASSERT_TRUE(boardReady());
  const size_t before = simMessages().size();
  std_srvs::Trigger::Response reset;
  ASSERT_TRUE(call("reset", reset));
  EXPECT_FALSE(reset.success);
  EXPECT_EQ(reset.message, "reset refused: motion is disabled; enable it with " + ns +
                               "/ethernut_node/set_motion_enabled (std_srvs/SetBool, data: true), or start the node "
                               "with the parameter " +
                               ns + "/ethernut_node/enable_motion true");
  std_srvs::Trigger::Response clear;
  ASSERT_TRUE(call("clear", clear));
  EXPECT_FALSE(clear.success);
  EXPECT_EQ(clear.message.rfind("clear refused: motion is disabled", 0), 0u) << clear.message;
  for (const std::string mode : {"standalone", "gui-control", "file"})
  {
    cnc_bridge::EthernutSetMode set;
    set.request.mode = mode;
    ASSERT_TRUE(ros::service::call(ns + "/ethernut_node/set_mode", set));
    EXPECT_FALSE(set.response.success) << mode;
    EXPECT_EQ(
        set.response.message.rfind(
            "set_mode refused: motion is disabled; enable it with " + ns + "/ethernut_node/set_motion_enabled", 0),
        0u)
        << set.response.message;
  }
  ASSERT_TRUE(waitForSimMessage("alive-request", simMessages().size()));
  for (const char* name : {"reset", "standalone-mode", "gui-control-mode", "file-mode"})
  {
    EXPECT_EQ(simMessagesNamed(name, before), 0) << "the board received " << name << " while motion was disabled";
  }
  EXPECT_TRUE(boardReady(5.0));  // standalone would have dropped the link
}

// Motion is off unless configured on (the launch file's default): a job is refused naming
// ~set_motion_enabled and ~enable_motion, and the board receives nothing of it; switched on at run
// time, jobs run (the tests below).
TEST(EthernutLink, JobsAreRefusedUntilMotionIsEnabled)
{
  ASSERT_TRUE(boardReady());
  auto client = actionClient();
  const size_t before = simLog().size();
  const size_t messages_before = simMessages().size();
  client->sendGoal(pointsGoal({{0.001, 0.002, 0.003}}));
  ASSERT_TRUE(client->waitForResult(ros::Duration(20.0)));
  EXPECT_EQ(client->getState(), actionlib::SimpleClientGoalState::ABORTED);
  const std::string text = client->getResult()->message;
  EXPECT_EQ(text, "job refused: motion is disabled; enable it with " + ns +
                      "/ethernut_node/set_motion_enabled (std_srvs/SetBool, data: true), or start the node with the "
                      "parameter " +
                      ns + "/ethernut_node/enable_motion true");
  // An alive request that arrives after the refusal was sent after it.
  ASSERT_TRUE(waitForSimMessage("alive-request", simMessages().size()));
  EXPECT_EQ(simMessagesNamed("READYTOSEND", messages_before), 0);
  EXPECT_EQ(simMessagesNamed("coordinates", messages_before), 0);
  EXPECT_EQ(simLog().size(), before);
  std_srvs::SetBool::Response set;
  ASSERT_TRUE(setMotion(true, set));
  EXPECT_TRUE(set.success);
}

// Default ~g53_moves (refuse): a program with G53 moves is refused before anything is sent, with
// the line and the parameter named.
TEST(EthernutLink, G53MovesAreRefusedByDefault)
{
  ASSERT_TRUE(boardReady());
  auto client = actionClient();
  const size_t before = simLog().size();
  RunJobGoal goal;
  goal.file = "haas_O05555.nc";
  client->sendGoal(goal);
  ASSERT_TRUE(client->waitForResult(ros::Duration(20.0)));
  EXPECT_EQ(client->getState(), actionlib::SimpleClientGoalState::ABORTED);
  const std::string text = client->getState().getText();
  EXPECT_NE(text.find("G-code line 9: G53"), std::string::npos) << text;
  EXPECT_NE(text.find(ns + "/ethernut_node/g53_moves"), std::string::npos) << text;
  EXPECT_EQ(simLog().size(), before);
  EXPECT_TRUE(boardReady(5.0));
}

TEST(EthernutLink, DeadLinkIsDetectedWithinTheTimeoutAndTheNodeReconnects)
{
  ASSERT_TRUE(boardReady());
  auto client = actionClient();
  clearJob();
  // The simulator goes silent when the 5th set arrives (INET_DEL 600 ms in the settings file).
  std::vector<std::array<double, 3>> points;
  for (int i = 0; i < 20; ++i)
  {
    points.push_back({0.001 * i, 0.0, 0.0});
  }
  size_t links_before;
  {
    std::lock_guard<std::mutex> lock(watch->mutex);
    links_before = watch->links.size();
  }
  client->sendGoal(pointsGoal(points), Client::SimpleDoneCallback(), Client::SimpleActiveCallback(), &onFeedback);
  ASSERT_TRUE(client->waitForResult(ros::Duration(20.0)));
  EXPECT_EQ(client->getState(), actionlib::SimpleClientGoalState::ABORTED);
  EXPECT_NE(client->getState().getText().find("silent"), std::string::npos) << client->getState().getText();
  EXPECT_EQ(client->getResult()->coordinates_done, 4u);
  ASSERT_TRUE(watch->waitFor(
      [&]
      {
        for (size_t i = links_before; i < watch->links.size(); ++i)
        {
          if (watch->links[i].second == MachineState::LINK_DOWN)
          {
            return true;
          }
        }
        return false;
      }));
  {
    std::lock_guard<std::mutex> lock(watch->mutex);
    ros::WallTime down;
    for (size_t i = links_before; i < watch->links.size(); ++i)
    {
      if (watch->links[i].second != MachineState::LINK_UP)
      {
        down = watch->links[i].first;
        break;
      }
    }
    // Silence began when the 5th set went out, just after the 4th NEXT (last feedback, sent at
    // most 50 ms later). Detection: the 600 ms timeout plus one poll, and slack for message
    // delivery on a loaded machine.
    const double detect = (down - watch->last_feedback_time).toSec();
    EXPECT_GT(detect, 0.3);
    EXPECT_LT(detect, 2.0);
  }
  // The node reconnects (the simulator answers the new connection) and runs the next job.
  ASSERT_TRUE(boardReady(20.0));
  const size_t before = simLog().size();
  client->sendGoal(pointsGoal({{0.001, 0.002, 0.003}, {0.004, 0.005, 0.006}}));
  ASSERT_TRUE(client->waitForResult(ros::Duration(20.0)));
  ASSERT_EQ(client->getState(), actionlib::SimpleClientGoalState::SUCCEEDED) << client->getState().getText();
  expectSameCoordinates(simLog(), before, {{1, 2, 3}, {4, 5, 6}});
}

// The simulator drops the connection (--drop-after) in the middle of a job: the job is aborted as
// a lost link at once (no waiting for a timeout), the node reconnects and runs the next job.
TEST(EthernutLink, DroppedConnectionAbortsTheJobAndTheNodeReconnects)
{
  ASSERT_TRUE(boardReady());
  auto client = actionClient();
  clearJob();
  std::vector<std::array<double, 3>> points;
  for (int i = 0; i < 20; ++i)
  {
    points.push_back({0.001 * i, 0.001, 0.0});
  }
  size_t links_before;
  {
    std::lock_guard<std::mutex> lock(watch->mutex);
    links_before = watch->links.size();
  }
  client->sendGoal(pointsGoal(points));
  ASSERT_TRUE(client->waitForResult(ros::Duration(20.0)));
  EXPECT_EQ(client->getState(), actionlib::SimpleClientGoalState::ABORTED);
  EXPECT_NE(client->getState().getText().find("link lost"), std::string::npos) << client->getState().getText();
  EXPECT_LT(client->getResult()->coordinates_done, points.size());
  ASSERT_TRUE(watch->waitFor(
      [&]
      {
        for (size_t i = links_before; i < watch->links.size(); ++i)
        {
          if (watch->links[i].second != MachineState::LINK_UP)
          {
            return true;
          }
        }
        return false;
      }));
  ASSERT_TRUE(boardReady(20.0));
  const size_t before = simLog().size();
  client->sendGoal(pointsGoal({{0.007, 0.008, 0.009}}));
  ASSERT_TRUE(client->waitForResult(ros::Duration(20.0)));
  ASSERT_EQ(client->getState(), actionlib::SimpleClientGoalState::SUCCEEDED) << client->getState().getText();
  expectSameCoordinates(simLog(), before, {{7, 8, 9}});

  // Diagnostics count across connections: the silence of the test above (unanswered alive
  // requests) and both reconnections.
  ASSERT_TRUE(watch->waitFor([] { return diag("reconnects") >= 2; }, 10.0));
  std::lock_guard<std::mutex> lock(watch->mutex);
  EXPECT_GE(diag("keepalive misses"), 1);
}

bool callCoordinates(const std::string& service, double x, double y, double z,
                     cnc_bridge::EthernutCoordinates::Response& res)
{
  cnc_bridge::EthernutCoordinates srv;
  srv.request.x = x;
  srv.request.y = y;
  srv.request.z = z;
  const bool ok = ros::service::call(ns + "/ethernut_node/" + service, srv);
  res = srv.response;
  return ok;
}

// Reset and clear share one opcode (row 8); "Reset also terminates all active connections"
// (qCNC): ~clear keeps the connection (no new handshake), ~reset closes it, the link says why and
// comes back with a new handshake.
TEST(EthernutLink, ClearKeepsTheConnectionAndResetClosesItAndReconnects)
{
  ASSERT_TRUE(boardReady());
  std_srvs::SetBool::Response motion;
  ASSERT_TRUE(setMotion(true, motion));
  ASSERT_TRUE(motion.success) << motion.message;
  const size_t before_clear = simMessages().size();
  std_srvs::Trigger::Response clear;
  ASSERT_TRUE(call("clear", clear));
  EXPECT_TRUE(clear.success) << clear.message;
  ASSERT_TRUE(waitForSimMessage("reset", before_clear));
  const size_t after_clear = simMessages().size();
  ASSERT_TRUE(waitForSimMessage("alive-request", after_clear));  // the same connection goes on
  EXPECT_EQ(simMessagesNamed("init-request", before_clear), 0) << "clear reconnected";

  size_t messages_before;
  {
    std::lock_guard<std::mutex> lock(watch->mutex);
    messages_before = watch->messages.size();
  }
  const size_t before_reset = simMessages().size();
  std_srvs::Trigger::Response reset;
  ASSERT_TRUE(call("reset", reset));
  EXPECT_TRUE(reset.success) << reset.message;
  ASSERT_TRUE(waitForSimMessage("reset", before_reset));
  ASSERT_TRUE(waitForSimMessage("init-request", before_reset));  // a new connection's handshake
  ASSERT_TRUE(watch->waitFor(
      [&]
      {
        for (size_t i = messages_before; i < watch->messages.size(); ++i)
        {
          if (watch->messages[i].find("reset: the connection was closed as ~reset does") != std::string::npos)
            return true;
        }
        return false;
      }));
  EXPECT_TRUE(boardReady(20.0));
  ASSERT_TRUE(setMotion(false, motion));
}

// Rows 2 and 3: ~sync_oled reaches the board (a display: nothing moves); ~board_command, whose
// effect the node cannot know, is behind the motion switch, and neither takes a value the board's
// float32 cannot carry.
TEST(EthernutLink, SyncOledReachesTheBoardAndBoardCommandWaitsForTheMotionSwitch)
{
  ASSERT_TRUE(boardReady());
  std_srvs::SetBool::Response motion;
  ASSERT_TRUE(setMotion(false, motion));
  const size_t before = simMessages().size();
  cnc_bridge::EthernutCoordinates::Response res;
  ASSERT_TRUE(callCoordinates("board_command", 1, 2, 3, res));
  EXPECT_FALSE(res.success);
  EXPECT_EQ(res.message.rfind("board_command refused: motion is disabled", 0), 0u) << res.message;
  for (const double bad : {std::nan(""), 1e300, -std::numeric_limits<double>::infinity()})
  {
    ASSERT_TRUE(callCoordinates("sync_oled", 1, bad, 3, res));
    EXPECT_FALSE(res.success);
    EXPECT_NE(res.message.find("sync_oled refused: y = "), std::string::npos) << res.message;
  }
  ASSERT_TRUE(callCoordinates("sync_oled", 12.5, -3.25, 0.5, res));
  EXPECT_TRUE(res.success) << res.message;
  ASSERT_TRUE(waitForSimMessage("sync-oled", before));
  ASSERT_TRUE(waitForSimMessage("alive-request", simMessages().size()));
  EXPECT_EQ(simMessagesNamed("command", before), 0) << "the board received a command while motion was disabled";
  EXPECT_EQ(simMessagesNamed("sync-oled", before), 1) << "a refused value reached the board";

  ASSERT_TRUE(setMotion(true, motion));
  const size_t enabled = simMessages().size();
  ASSERT_TRUE(callCoordinates("board_command", 1, 2, 3, res));
  EXPECT_TRUE(res.success) << res.message;
  EXPECT_TRUE(waitForSimMessage("command", enabled));
  ASSERT_TRUE(setMotion(false, motion));
}

// The number at the end of a debug line ("1 TCP GUI close 7" -> 7) if it starts with \p start; -1 if not.
long debugValue(const std::string& line, const std::string& start)
{
  if (line.rfind(start, 0) != 0 || line.size() == start.size())
  {
    return -1;
  }
  const std::string digits = line.substr(start.size());
  return digits.find_first_not_of("0123456789") == std::string::npos ? std::stol(digits) : -1;
}

// The board prints on its debug port (the simulator's pty, read as ~debug_port): what it says for
// a clear, a reset (the node closes the connection, which the board sees closed and accepted again,
// then the handshake) and a two-set job arrives on `debug` in order, each line whole (no cut, no
// escape); diagnostics show the channel up, the lines counted and the last one.
TEST(EthernutLink, TheBoardsDebugLinesArePublishedInOrderAndWhole)
{
  ASSERT_TRUE(boardReady());
  ASSERT_TRUE(watch->waitFor([] { return watch->debug["link"] == "up"; }, 20.0)) << "the debug channel is not up";
  size_t from;
  {
    std::lock_guard<std::mutex> lock(watch->mutex);
    from = watch->debug_lines.size();
  }
  std_srvs::SetBool::Response motion;
  ASSERT_TRUE(setMotion(true, motion));
  std_srvs::Trigger::Response clear, reset;
  ASSERT_TRUE(call("clear", clear));
  ASSERT_TRUE(clear.success) << clear.message;
  const size_t before_reset = simMessages().size();
  ASSERT_TRUE(call("reset", reset));
  ASSERT_TRUE(reset.success) << reset.message;
  ASSERT_TRUE(waitForSimMessage("init-request", before_reset));
  ASSERT_TRUE(boardReady(20.0));
  auto client = actionClient();
  client->sendGoal(pointsGoal({{0.001, 0.002, 0.003}, {0.004, 0.005, 0.006}}));
  ASSERT_TRUE(client->waitForResult(ros::Duration(20.0)));
  ASSERT_EQ(client->getState(), actionlib::SimpleClientGoalState::SUCCEEDED) << client->getState().getText();
  ASSERT_TRUE(setMotion(false, motion));

  // Lines of the tests before may still be on their way: ours start at the clear's reset.
  const std::vector<std::string> fixed = {"2 GUI TCP reset 0",     "2 GUI TCP reset 0",  "", "", "2 GUI TCP init 78",
                                          "2 GUI TCP filemode 15", "2 GUI TCP ready 50", "", ""};
  std::vector<std::string> ours;
  ASSERT_TRUE(watch->waitFor(
      [&]
      {
        const auto first =
            std::find(watch->debug_lines.begin() + static_cast<long>(from), watch->debug_lines.end(), fixed[0]);
        ours.assign(first, watch->debug_lines.end());
        return ours.size() >= fixed.size();
      },
      10.0))
      << "debug lines received: " << ours.size();
  ASSERT_EQ(ours.size(), fixed.size()) << "more debug lines than the board printed";
  for (size_t i = 0; i < fixed.size(); ++i)
  {
    if (!fixed[i].empty())
    {
      EXPECT_EQ(ours[i], fixed[i]) << "line " << i;
    }
  }
  // The connection the reset closed, the next one accepted; the job's two sets, one after the other.
  const long closed = debugValue(ours[2], "1 TCP GUI close ");
  EXPECT_GT(closed, 0) << ours[2];
  EXPECT_EQ(debugValue(ours[3], "1 TCP GUI accept "), closed + 1) << ours[3];
  const long first_set = debugValue(ours[7], "3 GUI MCP coord ");
  EXPECT_GT(first_set, 0) << ours[7];
  EXPECT_EQ(debugValue(ours[8], "3 GUI MCP coord "), first_set + 1) << ours[8];

  ASSERT_TRUE(watch->waitFor([&] { return watch->debug["last line"] == ours.back(); }, 10.0));
  std::lock_guard<std::mutex> lock(watch->mutex);
  EXPECT_EQ(watch->debug["link"], "up");
  EXPECT_GE(std::stol(watch->debug["lines received"]), static_cast<long>(from + fixed.size()));
  EXPECT_EQ(watch->debug["cut lines"], "0");
  EXPECT_EQ(watch->debug["escaped bytes"], "0");
}

// The state the test last received (a copy, taken under the lock).
MachineState lastState()
{
  std::lock_guard<std::mutex> lock(watch->mutex);
  return watch->state;
}

// Node death: the node killed (SIGKILL: no pause, no goodbye) while the board moves the second set
// of a job. Nothing reaches the board after the death, the third set least of all; the board holds
// the set in flight where it was when the connection ended (the simulated board stops the move and
// answers no NEXT) and keeps that position across connections. The launch respawns the node, which
// reads the held position from the board's report and runs the next job.
TEST(EthernutNodeDeath,
     NothingReachesTheBoardAfterTheNodeDiesTheBoardHoldsTheSetInFlightAndARespawnedNodeRunsTheNextJob)
{
  ASSERT_TRUE(boardReady());
  const pid_t pid = process_kill::nodePid(ns + "/ethernut_node");
  ASSERT_GT(pid, 0);
  auto client = actionClient();
  const size_t done_before = simLog().size();
  const size_t messages_before = simMessages().size();
  // 10 mm apart at the simulator's 20 mm/s: every set moves for half a second.
  client->sendGoal(pointsGoal({{0.010, 0, 0}, {0.020, 0, 0}, {0.030, 0, 0}, {0.040, 0, 0}}));
  // The board reports its position every 20 ms: the kill lands well inside the second move.
  ASSERT_TRUE(watch->waitFor([] { return watch->state.position.x > 0.012; }));
  const double x_at_kill = lastState().position.x;
  ASSERT_EQ(kill(pid, SIGKILL), 0);
  const auto windows = process_kill::countOverWindows([] { return simMessages().size(); });
  EXPECT_EQ(windows.after_second, windows.after_first) << "the board received messages after the node died";
  EXPECT_EQ(simMessagesNamed("coordinates", messages_before), 2) << "only the first two sets reached the board";
  expectSameCoordinates(simLog(), done_before, {{10, 0, 0}});  // the set in flight was not finished
  const ros::Time dead_by = ros::Time::now();                  // a state stamped later comes from the respawned node

  // Respawned: its state (from the board's first report on the new connection) is the held
  // position, part-way to the set in flight.
  ASSERT_TRUE(watch->waitFor(
      [&]
      {
        return watch->state.header.stamp > dead_by && watch->state.link == MachineState::LINK_UP &&
               watch->state.position_valid && watch->state.execution == MachineState::EXECUTION_READY;
      },
      30.0))
      << "no state from a respawned node";
  EXPECT_NE(process_kill::nodePid(ns + "/ethernut_node"), pid);
  const double held_x = lastState().position.x;
  EXPECT_GE(held_x, x_at_kill);
  EXPECT_LT(held_x, 0.0195);
  auto next = actionClient();
  next->sendGoal(pointsGoal({{0.005, 0.001, 0}}));
  ASSERT_TRUE(next->waitForResult(ros::Duration(20.0)));
  ASSERT_EQ(next->getState(), actionlib::SimpleClientGoalState::SUCCEEDED) << next->getState().getText();
  expectSameCoordinates(simLog(), done_before, {{10, 0, 0}, {5, 1, 0}});
}

int main(int argc, char** argv)
{
  testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "test_ethernut_node");
  ros::NodeHandle pnh("~");
  pnh.param<std::string>("namespace", ns, "");
  pnh.param<std::string>("tf_prefix", prefix, "");
  pnh.param<std::string>("sim_log", sim_log, "");
  pnh.param<std::string>("sim_messages", sim_messages, "");
  pnh.param<std::string>("program_dir", program_dir, "");
  Watch w;
  watch = &w;
  ros::NodeHandle nh;
  auto state_sub = nh.subscribe(ns + "/state", 100, &onState);
  auto path_sub = nh.subscribe(ns + "/job/path", 10, &onPath);
  auto markers_sub = nh.subscribe(ns + "/job/markers", 10, &onMarkers);
  auto diagnostics_sub = nh.subscribe("/diagnostics", 10, &onDiagnostics);
  auto debug_sub = nh.subscribe(ns + "/debug", 100, &onDebug);
  ros::AsyncSpinner spinner(2);
  spinner.start();
  const int result = RUN_ALL_TESTS();
  spinner.stop();
  return result;
}
