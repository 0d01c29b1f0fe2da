// dnc_node drip-feed through the ~transfer action against sim_haas_serial drip: feedback (line,
// N number, bytes, percent, held), dnc/current_line, state.block, the commanded position
// (dnc/commanded_position and tf, none during a backup), the control receiving every byte
// in order without overrun, a restart from an N number, ~plan_drip, a second goal rejected while
// a feed runs, ~pause/~resume, cancel, refusals; and a backup through the action of a second node
// against sim_haas_serial punch. The simulated control's buffer (256 characters, DC3 at 192, DC1
// at 64) is this project's choice, not a manual's: test/data/dnc_drip/README.md lists which
// control behaviour comes from which manual.
#include <actionlib/client/simple_action_client.h>
#include <gtest/gtest.h>
#include <ros/ros.h>
#include <sys/stat.h>

#include <cmath>
#include <fstream>
#include <functional>
#include <iostream>
#include <mutex>
#include <optional>
#include <sstream>

#include <diagnostic_msgs/DiagnosticArray.h>
#include <geometry_msgs/PointStamped.h>
#include <std_srvs/Trigger.h>
#include <tf2_msgs/TFMessage.h>

#include "cnc_bridge/DncLine.h"
#include "cnc_bridge/MachineState.h"
#include "cnc_bridge/PlanDrip.h"
#include "cnc_bridge/TransferAction.h"
#include "line_log.h"
#include "topic_watch.h"

namespace
{
std::string ns, pty, received_path, stats_path, program_path, backup_ns, backup_dir, punch_pty;
using Client = actionlib::SimpleActionClient<cnc_bridge::TransferAction>;

using line_log::readFile;
using line_log::waitUntil;

// The simulator renames its stats file into place when a program is complete.
bool waitForContent(const std::string& path, const std::function<bool(const std::string&)>& ready, double seconds)
{
  return line_log::waitForFile(
      path, [&] { return ready(readFile(path)); }, seconds);
}

struct Watch : topic_watch::Record
{
  std::vector<cnc_bridge::TransferFeedback> feedback;
  std::vector<cnc_bridge::DncLine> lines;
  uint32_t max_state_block = 0;
  bool state_paused = false;
};
}  // namespace

TEST(DncDrip, FeedThroughTheActionWithFeedbackLinesAndState)
{
  ros::NodeHandle nh;
  Watch watch;
  auto line_sub = nh.subscribe<cnc_bridge::DncLine>(ns + "/dnc/current_line", 1000, watch.appendTo(watch.lines));
  auto state_sub = nh.subscribe<cnc_bridge::MachineState>(
      ns + "/state", 100,
      [&](const cnc_bridge::MachineState::ConstPtr& msg)
      {
        watch.update(
            [&]
            {
              watch.max_state_block = std::max(watch.max_state_block, msg->block);
              watch.state_paused |= msg->execution == msg->EXECUTION_PAUSED;
            });
      });
  Client client(ns + "/dnc_node/transfer", true);
  ASSERT_TRUE(client.waitForServer(ros::Duration(20)));
  // The simulator makes its pty link when it starts; the node opens it per transfer.
  ASSERT_TRUE(line_log::waitUntilExists(pty, 20));  // never read it: a pty
  ASSERT_TRUE(waitUntil([&] { return line_sub.getNumPublishers() > 0; }, 20));

  cnc_bridge::TransferGoal goal;
  goal.direction = goal.DIRECTION_SEND;
  goal.protocol = "drip";
  goal.file = "drip_rostest.nc";
  client.sendGoal(goal, Client::SimpleDoneCallback(), Client::SimpleActiveCallback(), watch.appendTo(watch.feedback));
  ASSERT_TRUE(client.waitForResult(ros::Duration(60)));
  ASSERT_EQ(actionlib::SimpleClientGoalState::SUCCEEDED, client.getState().state_) << client.getResult()->message;
  const auto result = client.getResult();
  const std::string program = readFile(program_path);
  EXPECT_EQ(program.size(), result->bytes);  // the file is '%'-framed with LF: sent as it is
  EXPECT_EQ(103u, result->stopped_at_line);  // the closing '%'
  EXPECT_EQ("N100", result->stopped_at_block);

  // The control received the program whole and in order. Its counts of characters after each
  // XOFF and of overflow are printed, not asserted: on a pty they include the kernel's and the
  // simulator's own scheduling delays (a reader thread that runs late finds a backlog it then
  // counts as arriving after its XOFF, even on an idle machine). The allowance of 10 and an
  // overflow of 0 are asserted on the simulated wire in test_drip_feed and measured in bench/dnc.
  ASSERT_TRUE(waitForContent(
      stats_path, [](const std::string& s) { return !s.empty(); }, 20));
  const std::string stats = readFile(stats_path);
  std::cout << "sim_haas_serial drip: " << stats;
  EXPECT_NE(stats.find("program complete"), std::string::npos) << stats;
  EXPECT_EQ(program, readFile(received_path));

  std::lock_guard<std::mutex> lock(watch.mutex);
  ASSERT_FALSE(watch.feedback.empty());
  bool held = false;
  uint32_t last_line = 0;
  for (const auto& f : watch.feedback)
  {
    EXPECT_GE(f.line, last_line);
    last_line = f.line;
    EXPECT_EQ(program.size(), f.total);
    held |= f.held;
  }
  // The simulated control executes 1000 characters/s from a 256-character buffer: it holds us.
  EXPECT_TRUE(held);
  EXPECT_TRUE(watch.state_paused);
  EXPECT_GE(watch.max_state_block, 90u);
  // dnc/current_line: every line, in order, with its N number.
  ASSERT_EQ(103u, watch.lines.size());
  for (size_t i = 0; i < watch.lines.size(); ++i)
  {
    EXPECT_EQ(i + 1, watch.lines[i].line);
  }
  EXPECT_EQ("N50", watch.lines[51].block_number);
  EXPECT_EQ("N50 G1 X10.0 Y0.5 F200.", watch.lines[51].text);
  EXPECT_EQ("drip_rostest.nc", watch.lines[0].program);
}

TEST(DncDrip, RestartFromABlockNumberSendsTheModalBlocksThenTheRest)
{
  Client client(ns + "/dnc_node/transfer", true);
  ASSERT_TRUE(client.waitForServer(ros::Duration(20)));
  const std::string before = readFile(received_path);
  cnc_bridge::TransferGoal goal;
  goal.direction = goal.DIRECTION_SEND;
  goal.protocol = "drip";
  goal.file = "drip_rostest.nc";
  goal.start_block = "N95";
  ASSERT_TRUE(client.sendGoalAndWait(goal, ros::Duration(60)) == actionlib::SimpleClientGoalState::SUCCEEDED)
      << client.getResult()->message;
  const std::string expected_tail =
      "%\n(RESTART AT LINE 97)\nG21 G17 G90 G54\nT4 M6\nS4000 M3\nM8\nG1 F240.\n"
      "N95 G1 X15.5 Y20.5 F200.\nN96 G1 X16.6 Y21.5 F210.\nN97 G1 X17.7 Y22.5 F220.\nN98 G1 X18.8 Y23.5 F230.\n"
      "N99 G1 X19.9 Y24.5 F240.\nN100 M30\n%\n";
  ASSERT_TRUE(waitForContent(
      received_path, [&](const std::string& s) { return s.size() >= before.size() + expected_tail.size(); }, 20));
  EXPECT_EQ(before + expected_tail, readFile(received_path));
}

TEST(DncDrip, WrongDirectionIsRefusedWithAReason)
{
  Client client(ns + "/dnc_node/transfer", true);
  ASSERT_TRUE(client.waitForServer(ros::Duration(20)));
  cnc_bridge::TransferGoal goal;
  goal.direction = goal.DIRECTION_RECEIVE;
  goal.protocol = "drip";
  goal.file = "never.nc";
  client.sendGoalAndWait(goal, ros::Duration(20));
  EXPECT_EQ(actionlib::SimpleClientGoalState::ABORTED, client.getState().state_);
  EXPECT_NE(client.getResult()->message.find("backup"), std::string::npos) << client.getResult()->message;
}

// Feeds drip_rostest.nc with \p client and records feedback and dnc/current_line, for the tests
// below that act on a running feed.
class RunningFeed
{
 public:
  explicit RunningFeed(Client& client) : client_(client)
  {
    ros::NodeHandle nh;
    line_sub_ = nh.subscribe<cnc_bridge::DncLine>(ns + "/dnc/current_line", 1000, record_.appendTo(lines_));
  }
  bool connected()
  {
    return waitUntil([&] { return line_sub_.getNumPublishers() > 0; }, 20);
  }
  void start(const std::string& start_block = "")
  {
    cnc_bridge::TransferGoal goal;
    goal.direction = goal.DIRECTION_SEND;
    goal.protocol = "drip";
    goal.file = "drip_rostest.nc";
    goal.start_block = start_block;
    client_.sendGoal(goal, Client::SimpleDoneCallback(), Client::SimpleActiveCallback(), record_.appendTo(feedback_));
  }
  /// Waits (on messages, not time) until \p ready holds for what has arrived.
  bool waitFor(const std::function<bool(const std::vector<cnc_bridge::DncLine>&,
                                        const std::vector<cnc_bridge::TransferFeedback>&)>& ready,
               double seconds = 30)
  {
    return record_.waitFor([&] { return ready(lines_, feedback_); }, seconds);
  }
  size_t lineCount()
  {
    std::lock_guard<std::mutex> lock(record_.mutex);
    return lines_.size();
  }

 private:
  Client& client_;
  topic_watch::Record record_;
  std::vector<cnc_bridge::DncLine> lines_;
  std::vector<cnc_bridge::TransferFeedback> feedback_;
  ros::Subscriber line_sub_;  // last: unsubscribed before what the callback fills goes
};

bool lineAtLeast(const std::vector<cnc_bridge::DncLine>& lines, uint32_t n)
{
  return !lines.empty() && lines.back().line >= n;
}

TEST(DncDrip, PlanDripShowsThePreambleAndResumeLineBeforeAnythingIsSent)
{
  ros::NodeHandle nh;
  auto plan = nh.serviceClient<cnc_bridge::PlanDrip>(ns + "/dnc_node/plan_drip");
  ASSERT_TRUE(plan.waitForExistence(ros::Duration(20)));
  cnc_bridge::PlanDrip srv;
  srv.request.file = "drip_rostest.nc";
  srv.request.start_block = "N95";
  ASSERT_TRUE(plan.call(srv));
  ASSERT_TRUE(srv.response.success) << srv.response.message;
  EXPECT_EQ("(RESTART AT LINE 97)\nG21 G17 G90 G54\nT4 M6\nS4000 M3\nM8\nG1 F240.\n", srv.response.preamble);
  EXPECT_EQ(97u, srv.response.resume_line);
  EXPECT_EQ("N95", srv.response.resume_block);
  EXPECT_EQ(0u, srv.response.character_issue_count);
  EXPECT_GT(srv.response.total_bytes, 0u);

  // An operator's edit is checked too, before it can go.
  srv.request.restart_preamble = "G21 G90 G54\nt4 M6\n";
  ASSERT_TRUE(plan.call(srv));
  EXPECT_EQ(srv.request.restart_preamble, srv.response.preamble);
  ASSERT_EQ(1u, srv.response.character_issue_count);
  EXPECT_NE(srv.response.character_issues.at(0).find("restart preamble line 2"), std::string::npos)
      << srv.response.character_issues.at(0);
  // Checked as a feed sends it: an edit with CR LF line ends and a blank line would go (the feed
  // sends its own end of block), so the plan does not call it refused.
  srv.request.restart_preamble = "G21 G90 G54\r\n\r\nT4 M6\r\n";
  ASSERT_TRUE(plan.call(srv));
  EXPECT_EQ(0u, srv.response.character_issue_count) << srv.response.message;
  EXPECT_GT(srv.response.total_bytes, 0u) << srv.response.message;

  // A file with a character an ISO control cannot take: reported with its line; a feed is refused.
  cnc_bridge::PlanDrip bad;
  bad.request.file = "drip_lowercase.nc";
  ASSERT_TRUE(plan.call(bad));
  EXPECT_TRUE(bad.response.success) << bad.response.message;
  ASSERT_EQ(1u, bad.response.character_issue_count);
  EXPECT_NE(bad.response.character_issues.at(0).find("line 4"), std::string::npos)
      << bad.response.character_issues.at(0);
  Client client(ns + "/dnc_node/transfer", true);
  ASSERT_TRUE(client.waitForServer(ros::Duration(20)));
  cnc_bridge::TransferGoal goal;
  goal.direction = goal.DIRECTION_SEND;
  goal.protocol = "drip";
  goal.file = "drip_lowercase.nc";
  client.sendGoalAndWait(goal, ros::Duration(20));
  EXPECT_EQ(actionlib::SimpleClientGoalState::ABORTED, client.getState().state_);
  EXPECT_NE(client.getResult()->message.find("line 4"), std::string::npos) << client.getResult()->message;

  // A file outside program_dir is refused.
  cnc_bridge::PlanDrip outside;
  outside.request.file = "../../../package.xml";
  ASSERT_TRUE(plan.call(outside));
  EXPECT_FALSE(outside.response.success);
}

TEST(DncDrip, PauseAndResumeRefuseWhenNoFeedRuns)
{
  ros::NodeHandle nh;
  auto pause = nh.serviceClient<std_srvs::Trigger>(ns + "/dnc_node/pause");
  auto resume = nh.serviceClient<std_srvs::Trigger>(ns + "/dnc_node/resume");
  ASSERT_TRUE(pause.waitForExistence(ros::Duration(20)));
  std_srvs::Trigger srv;
  ASSERT_TRUE(pause.call(srv));
  EXPECT_FALSE(srv.response.success);
  EXPECT_NE(srv.response.message.find("no drip-feed is running"), std::string::npos) << srv.response.message;
  ASSERT_TRUE(resume.call(srv));
  EXPECT_FALSE(srv.response.success);
}

TEST(DncDrip, ASecondGoalWhileAFeedRunsIsRejectedAndTheFeedCompletes)
{
  Client first(ns + "/dnc_node/transfer", true);
  Client second(ns + "/dnc_node/transfer", true);
  ASSERT_TRUE(first.waitForServer(ros::Duration(20)));
  ASSERT_TRUE(second.waitForServer(ros::Duration(20)));
  RunningFeed feed(first);
  ASSERT_TRUE(feed.connected());
  const std::string before = readFile(received_path);
  feed.start();
  ASSERT_TRUE(feed.waitFor([](const auto& lines, const auto&) { return lineAtLeast(lines, 5); }));

  cnc_bridge::TransferGoal goal;
  goal.direction = goal.DIRECTION_SEND;
  goal.protocol = "drip";
  goal.file = "drip_rostest.nc";
  second.sendGoal(goal);
  ASSERT_TRUE(second.waitForResult(ros::Duration(20)));
  EXPECT_EQ(actionlib::SimpleClientGoalState::REJECTED, second.getState().state_);
  const std::string text = second.getState().getText();
  EXPECT_NE(text.find("refused: another transfer is running"), std::string::npos) << text;
  // It names the running goal and how to replace it (docs/ROS_INTERFACE.md, one new-goal policy).
  EXPECT_NE(text.find("(send drip_rostest.nc by drip)"), std::string::npos) << text;
  EXPECT_NE(text.find("cancel it first (" + ns + "/dnc_node/transfer/cancel"), std::string::npos) << text;

  // The running feed was not preempted: it completes, and the control has the program whole.
  ASSERT_TRUE(first.waitForResult(ros::Duration(60)));
  ASSERT_EQ(actionlib::SimpleClientGoalState::SUCCEEDED, first.getState().state_) << first.getResult()->message;
  const std::string program = readFile(program_path);
  ASSERT_TRUE(waitForContent(
      received_path, [&](const std::string& s) { return s.size() >= before.size() + program.size(); }, 20));
  EXPECT_EQ(before + program, readFile(received_path));
}

TEST(DncDrip, PauseStopsTheFeedAndResumeFinishesIt)
{
  ros::NodeHandle nh;
  auto pause = nh.serviceClient<std_srvs::Trigger>(ns + "/dnc_node/pause");
  auto resume = nh.serviceClient<std_srvs::Trigger>(ns + "/dnc_node/resume");
  ASSERT_TRUE(pause.waitForExistence(ros::Duration(20)));
  topic_watch::TopicWatch<cnc_bridge::MachineState> states(ns + "/state", 100);
  Client client(ns + "/dnc_node/transfer", true);
  ASSERT_TRUE(client.waitForServer(ros::Duration(20)));
  RunningFeed feed(client);
  ASSERT_TRUE(feed.connected());
  const std::string before = readFile(received_path);
  feed.start();
  ASSERT_TRUE(feed.waitFor([](const auto& lines, const auto&) { return lineAtLeast(lines, 10); }));

  std_srvs::Trigger srv;
  ASSERT_TRUE(pause.call(srv));
  ASSERT_TRUE(srv.response.success) << srv.response.message;
  states.clear();
  // The sender confirms in its feedback once it stands still; from then on, over the next five
  // feedback messages (one per feedback period while paused), nothing more goes out.
  size_t paused_at = 0;
  ASSERT_TRUE(feed.waitFor(
      [&](const auto&, const auto& feedback)
      {
        for (size_t i = 0; i < feedback.size(); ++i)
        {
          if (feedback[i].paused)
          {
            paused_at = i;
            return true;
          }
        }
        return false;
      }));
  const size_t lines_when_paused = feed.lineCount();
  uint64_t bytes_when_paused = 0;
  bool all_paused = true;
  uint64_t last_bytes = 0;
  ASSERT_TRUE(feed.waitFor(
      [&](const auto&, const auto& feedback)
      {
        bytes_when_paused = feedback[paused_at].bytes;
        if (feedback.size() < paused_at + 6)
          return false;
        for (size_t i = paused_at; i < feedback.size(); ++i)
        {
          all_paused = all_paused && feedback[i].paused;
          last_bytes = feedback[i].bytes;
        }
        return true;
      }));
  EXPECT_TRUE(all_paused);
  EXPECT_EQ(bytes_when_paused, last_bytes);
  EXPECT_EQ(lines_when_paused, feed.lineCount());
  ASSERT_TRUE(states.waitForLatest(
      [](const auto& s) { return s.execution == cnc_bridge::MachineState::EXECUTION_PAUSED; }, 10));
  EXPECT_FALSE(client.getState().isDone());

  ASSERT_TRUE(pause.call(srv));  // pausing twice is harmless
  EXPECT_TRUE(srv.response.success);
  ASSERT_TRUE(resume.call(srv));
  ASSERT_TRUE(srv.response.success) << srv.response.message;
  ASSERT_TRUE(client.waitForResult(ros::Duration(60)));
  ASSERT_EQ(actionlib::SimpleClientGoalState::SUCCEEDED, client.getState().state_) << client.getResult()->message;
  EXPECT_GT(feed.lineCount(), lines_when_paused);
  const std::string program = readFile(program_path);
  ASSERT_TRUE(waitForContent(
      received_path, [&](const std::string& s) { return s.size() >= before.size() + program.size(); }, 20));
  EXPECT_EQ(before + program, readFile(received_path));
  ASSERT_TRUE(resume.call(srv));  // nothing runs any more
  EXPECT_FALSE(srv.response.success);
}

// Last of the feeds: the simulated control is left mid-program by the cancel.
TEST(DncDrip, CancelReportsWhereItStoppedAndTheLinkCarriesTheNextFeed)
{
  Client client(ns + "/dnc_node/transfer", true);
  ASSERT_TRUE(client.waitForServer(ros::Duration(20)));
  RunningFeed feed(client);
  ASSERT_TRUE(feed.connected());
  feed.start();
  ASSERT_TRUE(feed.waitFor([](const auto& lines, const auto&) { return lineAtLeast(lines, 20); }));
  client.cancelGoal();
  ASSERT_TRUE(client.waitForResult(ros::Duration(20)));
  EXPECT_EQ(actionlib::SimpleClientGoalState::PREEMPTED, client.getState().state_);
  const auto result = client.getResult();
  EXPECT_FALSE(result->success);
  EXPECT_GE(result->stopped_at_line, 20u);
  EXPECT_LT(result->stopped_at_line, 103u);
  EXPECT_NE(result->message.find("cancelled"), std::string::npos) << result->message;
  EXPECT_NE(result->message.find("last complete line " + std::to_string(result->stopped_at_line)), std::string::npos)
      << result->message;
  ASSERT_FALSE(result->stopped_at_block.empty());

  // Diagnostics count it as a cancel, not as a failure.
  struct Diagnostics : topic_watch::Record
  {
    std::string cancelled_count;
  } diagnostics;
  auto diag_sub = ros::NodeHandle().subscribe<diagnostic_msgs::DiagnosticArray>(
      "/diagnostics", 100,
      [&](const diagnostic_msgs::DiagnosticArray::ConstPtr& msg)
      {
        for (const auto& status : msg->status)
        {
          bool this_node = false;
          std::string cancelled;
          for (const auto& kv : status.values)
          {
            this_node |= kv.key == "program_dir" && kv.value.find("dnc_drip") != std::string::npos;
            if (kv.key == "cancelled")
              cancelled = kv.value;
          }
          if (this_node && !cancelled.empty())
          {
            diagnostics.update([&] { diagnostics.cancelled_count = cancelled; });
          }
        }
      });
  EXPECT_TRUE(diagnostics.waitFor([&] { return diagnostics.cancelled_count == "1"; }, 10))
      << "cancelled in diagnostics: '" << diagnostics.cancelled_count << "'";

  // The same link takes the restart after the block it stopped at.
  const int stopped = std::stoi(result->stopped_at_block.substr(1));
  cnc_bridge::TransferGoal goal;
  goal.direction = goal.DIRECTION_SEND;
  goal.protocol = "drip";
  goal.file = "drip_rostest.nc";
  goal.start_block = "N" + std::to_string(stopped + 1);
  ASSERT_EQ(actionlib::SimpleClientGoalState::SUCCEEDED, client.sendGoalAndWait(goal, ros::Duration(60)).state_)
      << client.getResult()->message;
  EXPECT_EQ(103u, client.getResult()->stopped_at_line);
}

// The block ends of drip_rostest.nc worked out from its text (not with the parser the node uses):
// metres, program coordinates, from the first block that names X, Y and Z on.
std::vector<geometry_msgs::Point> blockEnds(const std::string& program)
{
  std::vector<geometry_msgs::Point> ends;
  std::istringstream lines(program);
  std::optional<double> axis[3];
  for (std::string line; std::getline(lines, line);)
  {
    bool moved = false;
    for (int a = 0; a < 3; ++a)
    {
      const size_t at = line.find(static_cast<char>('X' + a));
      if (at != std::string::npos)
      {
        axis[a] = std::stod(line.substr(at + 1)) / 1000.0;
        moved = true;
      }
    }
    if (moved && axis[0] && axis[1] && axis[2])
    {
      geometry_msgs::Point p;
      p.x = *axis[0];
      p.y = *axis[1];
      p.z = *axis[2];
      ends.push_back(p);
    }
  }
  return ends;
}

// The first of \p ends at or after \p from that is \p p, or ends.size().
size_t findEnd(const std::vector<geometry_msgs::Point>& ends, size_t from, double x, double y, double z)
{
  for (size_t k = from; k < ends.size(); ++k)
  {
    if (std::fabs(ends[k].x - x) < 1e-9 && std::fabs(ends[k].y - y) < 1e-9 && std::fabs(ends[k].z - z) < 1e-9)
      return k;
  }
  return ends.size();
}

// During a feed the node publishes the end of the last motion block it fed (ahead of the tool:
// the control buffers), in the program's frame, on dnc/commanded_position and as tf
// fanuc/program -> fanuc/commanded_tool: block ends of the program in the order they were fed (at
// most ~state_rate a second, so not every one), none before the first motion block (N5, line 6).
TEST(DncDrip, CommandedPositionIsTheLastBlockEndFedInTheProgramFrame)
{
  ros::NodeHandle nh;
  struct Seen : topic_watch::Record
  {
    std::vector<geometry_msgs::PointStamped> points;
    std::vector<geometry_msgs::TransformStamped> frames;
    std::vector<cnc_bridge::DncLine> lines;
  } seen;
  auto point_sub =
      nh.subscribe<geometry_msgs::PointStamped>(ns + "/dnc/commanded_position", 1000, seen.appendTo(seen.points));
  auto line_sub = nh.subscribe<cnc_bridge::DncLine>(ns + "/dnc/current_line", 1000, seen.appendTo(seen.lines));
  auto tf_sub = nh.subscribe<tf2_msgs::TFMessage>("/tf", 1000,
                                                  [&](const tf2_msgs::TFMessage::ConstPtr& msg)
                                                  {
                                                    seen.update(
                                                        [&]
                                                        {
                                                          for (const auto& t : msg->transforms)
                                                          {
                                                            if (t.child_frame_id == "fanuc/commanded_tool")
                                                              seen.frames.push_back(t);
                                                          }
                                                        });
                                                  });
  Client client(ns + "/dnc_node/transfer", true);
  ASSERT_TRUE(client.waitForServer(ros::Duration(20)));
  ASSERT_TRUE(line_log::waitUntilExists(pty, 20));  // never read it: a pty
  ASSERT_TRUE(waitUntil(
      [&]
      { return line_sub.getNumPublishers() > 0 && point_sub.getNumPublishers() > 0 && tf_sub.getNumPublishers() > 0; },
      20));
  {
    std::lock_guard<std::mutex> lock(seen.mutex);
    EXPECT_TRUE(seen.points.empty());  // nothing before a feed (nor after the tests before this one)
  }

  cnc_bridge::TransferGoal goal;
  goal.direction = goal.DIRECTION_SEND;
  goal.protocol = "drip";
  goal.file = "drip_rostest.nc";
  ASSERT_EQ(actionlib::SimpleClientGoalState::SUCCEEDED, client.sendGoalAndWait(goal, ros::Duration(60)).state_)
      << client.getResult()->message;
  const ros::Time done = ros::Time::now();
  // Every line published reaches us; a point published with a line comes before it.
  ASSERT_TRUE(seen.waitFor([&] { return seen.lines.size() >= 103; }, 20));

  const std::vector<geometry_msgs::Point> ends = blockEnds(readFile(program_path));
  ASSERT_EQ(95u, ends.size());  // N5 .. N99
  std::lock_guard<std::mutex> lock(seen.mutex);
  // The simulated control takes ~3 s for the program (1000 characters/s): ~30 at 10 Hz.
  ASSERT_GE(seen.points.size(), 5u);
  ros::Time line5_sent;
  for (const auto& line : seen.lines)
  {
    if (line.line == 5)
      line5_sent = line.header.stamp;
  }
  ASSERT_FALSE(line5_sent.isZero());
  size_t next = 0;
  for (const auto& p : seen.points)
  {
    EXPECT_EQ("fanuc/program", p.header.frame_id);
    EXPECT_GE(p.header.stamp, line5_sent);  // none before the first motion block
    EXPECT_LE(p.header.stamp, done);        // none after the feed
    const size_t k = findEnd(ends, next, p.point.x, p.point.y, p.point.z);
    ASSERT_LT(k, ends.size()) << "(" << p.point.x << ", " << p.point.y << ", " << p.point.z
                              << ") is no block end of the program after block end " << next;
    next = k + 1;  // consecutive block ends differ: each point is a later block than the one before
  }
  // tf: the same positions, in order (an unchanged one is sent again while the control holds us).
  ASSERT_FALSE(seen.frames.empty());
  next = 0;
  for (const auto& t : seen.frames)
  {
    EXPECT_EQ("fanuc/program", t.header.frame_id);
    EXPECT_LE(t.header.stamp, done);
    const auto& v = t.transform.translation;
    const size_t k = findEnd(ends, next, v.x, v.y, v.z);
    ASSERT_LT(k, ends.size()) << "(" << v.x << ", " << v.y << ", " << v.z << ") is no block end";
    next = k;
  }
}

TEST(DncBackup, TheActionStoresWhatTheControlPunches)
{
  Client client(backup_ns + "/dnc_node/transfer", true);
  ASSERT_TRUE(client.waitForServer(ros::Duration(20)));
  ASSERT_TRUE(line_log::waitUntilExists(punch_pty, 20));
  topic_watch::Messages<cnc_bridge::TransferFeedback> received;
  cnc_bridge::TransferGoal goal;
  goal.direction = goal.DIRECTION_RECEIVE;
  goal.protocol = "backup";
  goal.file = "backup.nc";
  // A backup stores a program: it commands no position (published only during a drip-feed).
  topic_watch::TopicWatch<geometry_msgs::PointStamped> commanded(backup_ns + "/dnc/commanded_position");
  ASSERT_TRUE(waitUntil([&] { return commanded.publishers() > 0; }, 20));
  client.sendGoal(goal, Client::SimpleDoneCallback(), Client::SimpleActiveCallback(),
                  [&](const cnc_bridge::TransferFeedbackConstPtr& f) { received.add(*f); });
  ASSERT_TRUE(client.waitForResult(ros::Duration(60)));
  EXPECT_EQ(0u, commanded.size());
  ASSERT_EQ(actionlib::SimpleClientGoalState::SUCCEEDED, client.getState().state_) << client.getResult()->message;
  const std::string program = readFile(program_path);
  EXPECT_EQ(program, readFile(backup_dir + "/backup.nc"));
  EXPECT_EQ(103u, client.getResult()->stopped_at_line);
  const auto feedback = received.all();
  ASSERT_FALSE(feedback.empty());
  EXPECT_GT(feedback.back().line, 0u);
}

int main(int argc, char** argv)
{
  testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "test_dnc_drip");
  ros::NodeHandle pnh("~");
  pnh.getParam("namespace", ns);
  pnh.getParam("pty", pty);
  pnh.getParam("received", received_path);
  pnh.getParam("stats", stats_path);
  pnh.getParam("program", program_path);
  pnh.getParam("backup_namespace", backup_ns);
  pnh.getParam("backup_dir", backup_dir);
  pnh.getParam("punch_pty", punch_pty);
  ros::AsyncSpinner spinner(2);
  spinner.start();
  return RUN_ALL_TESTS();
}
