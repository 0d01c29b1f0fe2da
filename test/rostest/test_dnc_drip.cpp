// dnc_node drip-feed through the ~transfer action against sim_haas_serial drip: feedback (line,
// N number, bytes, percent, held), dnc/current_line, state.block, the control receiving every byte
// in order without overrun, a restart from an N number, and refusals (wrong direction, a character
// the control cannot take is not the case here: see the unit tests).
#include <actionlib/client/simple_action_client.h>
#include <gtest/gtest.h>
#include <ros/ros.h>
#include <sys/stat.h>

#include <condition_variable>
#include <fstream>
#include <functional>
#include <mutex>
#include <sstream>

#include "cnc_bridge/DncLine.h"
#include "cnc_bridge/MachineState.h"
#include "cnc_bridge/TransferAction.h"

namespace
{
std::string ns, pty, received_path, stats_path, program_path;
using Client = actionlib::SimpleActionClient<cnc_bridge::TransferAction>;

std::string readFile(const std::string& path)
{
  std::ifstream in(path, std::ios::binary);
  std::ostringstream out;
  out << in.rdbuf();
  return out.str();
}

// Waits until \p ready holds, checked every 20 ms up to the limit (files the simulator writes, a
// link it makes: there is nothing to subscribe to).
bool waitUntil(const std::function<bool()>& ready, double seconds)
{
  const ros::WallTime deadline = ros::WallTime::now() + ros::WallDuration(seconds);
  while (ros::WallTime::now() < deadline)
  {
    if (ready())
      return true;
    ros::WallDuration(0.02).sleep();
  }
  return ready();
}

// The simulator renames its stats file into place when a program is complete.
bool waitForContent(const std::string& path, const std::function<bool(const std::string&)>& ready, double seconds)
{
  return waitUntil([&] { return ready(readFile(path)); }, seconds);
}

struct Watch
{
  std::mutex mutex;
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
  auto line_sub = nh.subscribe<cnc_bridge::DncLine>(ns + "/dnc/current_line", 1000,
                                                    [&](const cnc_bridge::DncLine::ConstPtr& msg)
                                                    {
                                                      std::lock_guard<std::mutex> lock(watch.mutex);
                                                      watch.lines.push_back(*msg);
                                                    });
  auto state_sub =
      nh.subscribe<cnc_bridge::MachineState>(ns + "/state", 100,
                                             [&](const cnc_bridge::MachineState::ConstPtr& msg)
                                             {
                                               std::lock_guard<std::mutex> lock(watch.mutex);
                                               watch.max_state_block = std::max(watch.max_state_block, msg->block);
                                               watch.state_paused |= msg->execution == msg->EXECUTION_PAUSED;
                                             });
  Client client(ns + "/dnc_node/transfer", true);
  ASSERT_TRUE(client.waitForServer(ros::Duration(20)));
  // The simulator makes its pty link when it starts; the node opens it per transfer.
  struct stat info;
  ASSERT_TRUE(waitUntil([&] { return ::stat(pty.c_str(), &info) == 0; }, 20));  // never read it: a pty
  ASSERT_TRUE(waitUntil([&] { return line_sub.getNumPublishers() > 0; }, 20));

  cnc_bridge::TransferGoal goal;
  goal.direction = goal.DIRECTION_SEND;
  goal.protocol = "drip";
  goal.file = "drip_rostest.nc";
  client.sendGoal(goal, Client::SimpleDoneCallback(), Client::SimpleActiveCallback(),
                  [&](const cnc_bridge::TransferFeedbackConstPtr& f)
                  {
                    std::lock_guard<std::mutex> lock(watch.mutex);
                    watch.feedback.push_back(*f);
                  });
  ASSERT_TRUE(client.waitForResult(ros::Duration(60)));
  ASSERT_EQ(actionlib::SimpleClientGoalState::SUCCEEDED, client.getState().state_) << client.getResult()->message;
  const auto result = client.getResult();
  const std::string program = readFile(program_path);
  EXPECT_EQ(program.size(), result->bytes);  // the file is '%'-framed with LF: sent as it is
  EXPECT_EQ(103u, result->stopped_at_line);  // the closing '%'
  EXPECT_EQ("N100", result->stopped_at_block);

  // The control received the program whole, in order, with no overrun.
  ASSERT_TRUE(waitForContent(
      stats_path, [](const std::string& s) { return !s.empty(); }, 20));
  const std::string stats = readFile(stats_path);
  EXPECT_NE(stats.find("overruns 0,"), std::string::npos) << stats;
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
  ros::AsyncSpinner spinner(2);
  spinner.start();
  return RUN_ALL_TESTS();
}
