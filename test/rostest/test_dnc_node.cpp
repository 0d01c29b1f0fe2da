// dnc_node against sim_haas_serial xmodem (test/rostest/dnc_node.test): programs sent and received
// by service and by the ~transfer action, feedback, cancel, the one-transfer-at-a-time refusal,
// path escapes refused, and the state topic. Every wait is on a message, a service reply or an
// inotify event with a deadline (line_log.h); nothing sleeps.
#include <actionlib/client/simple_action_client.h>
#include <dirent.h>
#include <gtest/gtest.h>

#include <ros/ros.h>
#include <sys/stat.h>
#include <unistd.h>
#include <filesystem>

#include <algorithm>
#include <fstream>
#include <memory>

#include "cnc_bridge/MachineState.h"
#include "cnc_bridge/ReceiveProgram.h"
#include "cnc_bridge/SendProgram.h"
#include "cnc_bridge/TransferAction.h"
#include "line_log.h"
#include "topic_watch.h"

using cnc_bridge::MachineState;

namespace
{
std::string param(const std::string& name)
{
  std::string value;
  ros::NodeHandle("~").getParam(name, value);
  return value;
}

using line_log::readFile;
using line_log::waitUntilExists;

bool exists(const std::string& path)
{
  struct stat st;
  return ::stat(path.c_str(), &st) == 0;
}

/// A text program of about \p size bytes with LF line ends.
std::string program(size_t size)
{
  std::string out = "%\nO01234 (DNC TEST)\n";
  for (unsigned n = 10; out.size() < size; n += 5)
    out += "N" + std::to_string(n) + "G01X" + std::to_string(n % 977) + ".25Y-" + std::to_string(n % 311) + "F50.\n";
  return out + "M30\n%\n";
}

class DncNodeTest : public ::testing::Test
{
 protected:
  void SetUp() override
  {
    ns_ = param("namespace");
    program_dir_ = param("program_dir");
    control_dir_ = param("control_dir");
    nh_ = ros::NodeHandle(ns_);
    send_ = nh_.serviceClient<cnc_bridge::SendProgram>("dnc_node/send_program");
    receive_ = nh_.serviceClient<cnc_bridge::ReceiveProgram>("dnc_node/receive_program");
    ASSERT_TRUE(send_.waitForExistence(ros::Duration(30)));
    ASSERT_TRUE(receive_.waitForExistence(ros::Duration(30)));
    ASSERT_TRUE(waitUntilExists(param("link"), 30)) << "the simulator's pty link never appeared";
    states_ = std::make_unique<topic_watch::TopicWatch<MachineState>>("state", 50, nh_);
  }

  void writeProgram(const std::string& name, const std::string& contents)
  {
    std::ofstream(program_dir_ + "/" + name, std::ios::binary) << contents;
  }

  std::vector<MachineState> states() { return states_->all(); }

  std::string ns_, program_dir_, control_dir_;
  ros::NodeHandle nh_;
  ros::ServiceClient send_, receive_;
  std::unique_ptr<topic_watch::TopicWatch<MachineState>> states_;
};
}  // namespace

TEST_F(DncNodeTest, SendsAProgramByServiceAndTheControlStoresIt)
{
  const std::string contents = readFile(param("program"));
  writeProgram("O05555.nc", contents);
  cnc_bridge::SendProgram srv;
  srv.request.file = "O05555.nc";
  ASSERT_TRUE(send_.call(srv));
  EXPECT_TRUE(srv.response.success) << srv.response.message;
  EXPECT_EQ(srv.response.bytes, contents.size());
  EXPECT_EQ(srv.response.blocks, 8u);
  // The simulated Haas answers EOT with CAN CAN CAN, which the result reports as complete.
  EXPECT_NE(srv.response.message.find("CAN"), std::string::npos) << srv.response.message;
  ASSERT_TRUE(waitUntilExists(control_dir_ + "/O05555.nc", 10));
  EXPECT_EQ(readFile(control_dir_ + "/O05555.nc"), contents);
  // Kept in the archive beside ~program_dir, with where it went.
  EXPECT_EQ(readFile(program_dir_ + ".archive/O05555.nc/v0001.nc"), contents);
  EXPECT_NE(readFile(program_dir_ + ".archive/O05555.nc/v0001.meta").find("direction = sent"), std::string::npos);
}

TEST_F(DncNodeTest, ReceivesAProgramByServiceInChecksumAndCrcFallbackModes)
{
  for (const std::string protocol : {"", "xmodem-crc"})
  {
    cnc_bridge::ReceiveProgram srv;
    srv.request.file = "from_haas" + protocol + ".nc";
    srv.request.protocol = protocol;
    ASSERT_TRUE(receive_.call(srv));
    EXPECT_TRUE(srv.response.success) << srv.response.message;
    EXPECT_EQ(readFile(program_dir_ + "/" + srv.request.file), readFile(param("program")));
    EXPECT_EQ(srv.response.blocks, 8u);
  }
}

TEST_F(DncNodeTest, TransferActionGivesFeedbackAndAResult)
{
  const std::string contents = program(20000);
  writeProgram("O01234.nc", contents);
  actionlib::SimpleActionClient<cnc_bridge::TransferAction> client(nh_, "dnc_node/transfer", true);
  ASSERT_TRUE(client.waitForServer(ros::Duration(30)));
  cnc_bridge::TransferGoal goal;
  goal.direction = cnc_bridge::TransferGoal::DIRECTION_SEND;
  goal.file = "O01234.nc";
  topic_watch::Messages<cnc_bridge::TransferFeedback> received;
  client.sendGoal(goal, {}, {}, [&](const cnc_bridge::TransferFeedbackConstPtr& f) { received.add(*f); });
  ASSERT_TRUE(client.waitForResult(ros::Duration(60)));
  EXPECT_EQ(client.getState(), actionlib::SimpleClientGoalState::SUCCEEDED) << client.getState().getText();
  const auto result = client.getResult();
  EXPECT_TRUE(result->success);
  EXPECT_EQ(result->bytes, contents.size());
  const auto feedback = received.all();
  ASSERT_FALSE(feedback.empty());
  EXPECT_EQ(feedback.back().bytes, feedback.back().total);
  EXPECT_FLOAT_EQ(feedback.back().percent, 100.0f);
  EXPECT_GT(feedback.back().block, 100u);
  ASSERT_TRUE(waitUntilExists(control_dir_ + "/O01234.nc", 10));
  EXPECT_EQ(readFile(control_dir_ + "/O01234.nc"), contents);
}

TEST_F(DncNodeTest, CancelStopsATransferAndASecondRequestMeanwhileIsRefused)
{
  writeProgram("O04321.nc", program(200000));  // ~18 s at 115200 baud: plenty of time to cancel
  writeProgram("small.nc", "%\nO1\nM30\n%\n");
  actionlib::SimpleActionClient<cnc_bridge::TransferAction> client(nh_, "dnc_node/transfer", true);
  ASSERT_TRUE(client.waitForServer(ros::Duration(30)));
  cnc_bridge::TransferGoal goal;
  goal.direction = cnc_bridge::TransferGoal::DIRECTION_SEND;
  goal.file = "O04321.nc";
  topic_watch::Messages<cnc_bridge::TransferFeedback> feedback;
  client.sendGoal(goal, {}, {}, [&](const cnc_bridge::TransferFeedbackConstPtr& f) { feedback.add(*f); });
  ASSERT_TRUE(feedback.waitFor([](const auto& all) { return !all.empty(); }, 30));
  cnc_bridge::SendProgram busy;
  busy.request.file = "small.nc";
  ASSERT_TRUE(send_.call(busy));
  EXPECT_FALSE(busy.response.success);
  EXPECT_NE(busy.response.message.find("another transfer"), std::string::npos) << busy.response.message;

  client.cancelGoal();
  ASSERT_TRUE(client.waitForResult(ros::Duration(20)));
  EXPECT_EQ(client.getState(), actionlib::SimpleClientGoalState::PREEMPTED) << client.getState().getText();
  EXPECT_NE(client.getResult()->message.find("cancelled"), std::string::npos) << client.getResult()->message;
  EXPECT_FALSE(exists(control_dir_ + "/O04321.nc"));  // the control got CANs and stored nothing

  // The state showed the transfer as active with the program's name while it ran.
  bool saw_active = false;
  for (const auto& s : states())
    saw_active = saw_active || (s.execution == MachineState::EXECUTION_ACTIVE && s.program == "O04321.nc" &&
                                s.mode == MachineState::MODE_DNC);
  EXPECT_TRUE(saw_active);
  // Once the port is open, state no longer says it is being opened, and says what runs on it.
  bool saw_sending = false;
  for (const auto& s : states())
  {
    if (s.link != MachineState::LINK_UP)
      continue;
    EXPECT_NE(s.message.rfind("opening ", 0), 0u) << "link UP but state says: " << s.message;
    saw_sending = saw_sending || s.message.rfind("sending O04321.nc", 0) == 0;
  }
  EXPECT_TRUE(saw_sending);

  // The link is usable again at once.
  cnc_bridge::SendProgram again;
  again.request.file = "small.nc";
  ASSERT_TRUE(send_.call(again));
  EXPECT_TRUE(again.response.success) << again.response.message;
}

TEST_F(DncNodeTest, ReceivesAProgramThroughTheTransferAction)
{
  actionlib::SimpleActionClient<cnc_bridge::TransferAction> client(nh_, "dnc_node/transfer", true);
  ASSERT_TRUE(client.waitForServer(ros::Duration(30)));
  cnc_bridge::TransferGoal goal;
  goal.direction = cnc_bridge::TransferGoal::DIRECTION_RECEIVE;
  goal.file = "received_by_action.nc";
  topic_watch::Messages<cnc_bridge::TransferFeedback> received;
  client.sendGoal(goal, {}, {}, [&](const cnc_bridge::TransferFeedbackConstPtr& f) { received.add(*f); });
  ASSERT_TRUE(client.waitForResult(ros::Duration(60)));
  EXPECT_EQ(client.getState(), actionlib::SimpleClientGoalState::SUCCEEDED) << client.getState().getText();
  const auto result = client.getResult();
  EXPECT_TRUE(result->success) << result->message;
  const std::string expected = readFile(param("program"));
  EXPECT_EQ(readFile(program_dir_ + "/received_by_action.nc"), expected);
  EXPECT_EQ(result->bytes, expected.size());
  EXPECT_EQ(result->blocks, 8u);
  // Feedback and result travel on different topics: the feedback may arrive after the result.
  ASSERT_TRUE(received.waitFor([](const auto& all) { return !all.empty(); }, 10));
  const auto feedback = received.all();
  EXPECT_GE(feedback.front().block, 1u);
  EXPECT_GT(feedback.front().bytes, 0u);
  EXPECT_EQ(feedback.front().total, 0u);  // a receiver does not know the size
}

// Cancelling a RECEIVE through the action while blocks arrive (the slow control: ~1 s per block):
// PREEMPTED, CANs to the control, and the destination as it was: the previous file, or none.
TEST_F(DncNodeTest, CancellingAReceiveKeepsThePreviousFileOrNone)
{
  const std::string dir = param("slow_program_dir");
  ros::NodeHandle slow(param("slow_namespace"));
  actionlib::SimpleActionClient<cnc_bridge::TransferAction> client(slow, "dnc_node/transfer", true);
  ASSERT_TRUE(client.waitForServer(ros::Duration(30)));
  std::ofstream(dir + "/kept.nc", std::ios::binary) << "previous version\n";
  for (const std::string file : {"kept.nc", "fresh.nc"})
  {
    cnc_bridge::TransferGoal goal;
    goal.direction = cnc_bridge::TransferGoal::DIRECTION_RECEIVE;
    goal.file = file;
    topic_watch::Messages<cnc_bridge::TransferFeedback> feedback;
    client.sendGoal(goal, {}, {}, [&](const cnc_bridge::TransferFeedbackConstPtr& f) { feedback.add(*f); });
    const auto got_block = [](const auto& all)
    { return std::any_of(all.begin(), all.end(), [](const auto& f) { return f.block >= 1; }); };
    ASSERT_TRUE(feedback.waitFor(got_block, 30)) << file;
    client.cancelGoal();
    ASSERT_TRUE(client.waitForResult(ros::Duration(20))) << file;
    EXPECT_EQ(client.getState(), actionlib::SimpleClientGoalState::PREEMPTED)
        << file << ": " << client.getState().getText();
    EXPECT_FALSE(client.getResult()->success);
  }
  EXPECT_EQ(readFile(dir + "/kept.nc"), "previous version\n");
  EXPECT_FALSE(exists(dir + "/fresh.nc"));
  // Nothing else in the directory: no temporary file of either cancelled receive.
  std::vector<std::string> names;
  if (DIR* d = ::opendir(dir.c_str()))
  {
    while (dirent* e = ::readdir(d))
      if (std::string(e->d_name) != "." && std::string(e->d_name) != "..")
        names.push_back(e->d_name);  // a temporary file is ".<name>.XXXXXX"
    ::closedir(d);
  }
  EXPECT_EQ(names, std::vector<std::string>{"kept.nc"});
}

TEST_F(DncNodeTest, FilesOutsideTheProgramDirectoryAreRefused)
{
  ASSERT_EQ(::symlink("/etc/hostname", (program_dir_ + "/escape.nc").c_str()), 0);
  for (const std::string name : {"../../etc/passwd", "/etc/hostname", "escape.nc", "missing.nc"})
  {
    cnc_bridge::SendProgram srv;
    srv.request.file = name;
    ASSERT_TRUE(send_.call(srv));
    EXPECT_FALSE(srv.response.success) << name;
    EXPECT_EQ(srv.response.message.rfind("refused", 0), 0u) << srv.response.message;
  }
  for (const std::string name : {"../outside.nc", "/tmp/outside.nc", "escape.nc"})
  {
    cnc_bridge::ReceiveProgram srv;
    srv.request.file = name;
    ASSERT_TRUE(receive_.call(srv));
    EXPECT_FALSE(srv.response.success) << name;
    EXPECT_EQ(srv.response.message.rfind("refused", 0), 0u) << srv.response.message;
  }
  cnc_bridge::SendProgram bad_protocol;
  bad_protocol.request.file = "small.nc";
  bad_protocol.request.protocol = "zmodem";
  ASSERT_TRUE(send_.call(bad_protocol));
  EXPECT_FALSE(bad_protocol.response.success);
  EXPECT_NE(bad_protocol.response.message.find("unknown protocol"), std::string::npos);
}

// O08000-O09999 (Haas probing/WIPS and OEM macros) is refused by every protocol, by the file's
// name or by the program's own O number, and the control (ready and NAKing) stores nothing.
TEST_F(DncNodeTest, ProtectedProgramsAreRefusedAndTheControlReceivesNothing)
{
  std::string contents = readFile(param("program"));
  contents.replace(contents.find("O05555"), 6, "O09002");
  writeProgram("O09002.nc", contents);
  writeProgram("wips.nc", contents);
  for (const std::string protocol : {"", "drip"})
  {
    for (const std::string name : {"O09002.nc", "wips.nc"})
    {
      cnc_bridge::SendProgram srv;
      srv.request.file = name;
      srv.request.protocol = protocol;
      ASSERT_TRUE(send_.call(srv));
      EXPECT_FALSE(srv.response.success) << name;
      EXPECT_EQ(srv.response.message.rfind("refused", 0), 0u) << srv.response.message;
      EXPECT_NE(srv.response.message.find("O08000-O09999"), std::string::npos) << srv.response.message;
      EXPECT_NE(srv.response.message.find("~allow_protected_programs"), std::string::npos) << srv.response.message;
      EXPECT_EQ(srv.response.bytes, 0u);
    }
  }
  EXPECT_FALSE(exists(control_dir_ + "/O09002.nc"));  // the service returns after the transfer would have ended
}

// The number is read where the control takes it: a comment block and blank lines before O09010
// used to hide it (only the first block was looked at) and the program was sent. Refused now, by
// the service and the action, and the simulated Haas stores nothing.
TEST_F(DncNodeTest, AProtectedNumberAfterACommentBlockIsRefusedAndTheControlReceivesNothing)
{
  std::string contents = readFile(param("program"));
  contents.replace(contents.find("O05555"), 6, "O09010");
  contents.replace(contents.find('%'), 1, "%\n(SETUP SHEET)\n\n   \n");
  writeProgram("setup.nc", contents);
  auto stored = [this]
  {
    std::vector<std::string> names;
    std::error_code error;
    for (const auto& entry : std::filesystem::directory_iterator(control_dir_, error))
      names.push_back(entry.path().filename().string());
    std::sort(names.begin(), names.end());
    return names;
  };
  const std::vector<std::string> before = stored();
  cnc_bridge::SendProgram srv;
  srv.request.file = "setup.nc";
  ASSERT_TRUE(send_.call(srv));
  EXPECT_FALSE(srv.response.success);
  EXPECT_EQ(srv.response.message.rfind("refused", 0), 0u) << srv.response.message;
  EXPECT_NE(srv.response.message.find("O09010"), std::string::npos) << srv.response.message;
  EXPECT_NE(srv.response.message.find("~allow_protected_programs"), std::string::npos) << srv.response.message;
  EXPECT_EQ(srv.response.bytes, 0u);
  EXPECT_FALSE(exists(control_dir_ + "/O09010.nc"));
  EXPECT_EQ(stored(), before);  // the control stored nothing
}

// A drip-feed runs the program on the control as it arrives: with ~enable_motion at its default
// (false) it is refused, naming the switch and the parameter, before the port is opened, and the
// control stores nothing; an XModem send (no motion) goes through at once afterwards.
TEST_F(DncNodeTest, ADripFeedIsRefusedWhileMotionIsDisabledAndTheControlReceivesNothing)
{
  std::string contents = readFile(param("program"));
  contents.replace(contents.find("O05555"), 6, "O05556");
  writeProgram("O05556.nc", contents);
  cnc_bridge::SendProgram drip;
  drip.request.file = "O05556.nc";
  drip.request.protocol = "drip";
  ASSERT_TRUE(send_.call(drip));
  EXPECT_FALSE(drip.response.success);
  EXPECT_EQ(drip.response.message.rfind("refused: a drip-feed", 0), 0u) << drip.response.message;
  EXPECT_NE(drip.response.message.find("dnc_node/set_motion_enabled"), std::string::npos) << drip.response.message;
  EXPECT_NE(drip.response.message.find("dnc_node/enable_motion"), std::string::npos) << drip.response.message;
  EXPECT_EQ(drip.response.bytes, 0u);
  EXPECT_FALSE(exists(control_dir_ + "/O05556.nc"));
  // The port is free and the control in step: an XModem send (no motion) stores the program whole,
  // with nothing of the refused feed before it.
  cnc_bridge::SendProgram xmodem;
  xmodem.request.file = "O05556.nc";
  ASSERT_TRUE(send_.call(xmodem));
  EXPECT_TRUE(xmodem.response.success) << xmodem.response.message;
  ASSERT_TRUE(waitUntilExists(control_dir_ + "/O05556.nc", 10));
  EXPECT_EQ(readFile(control_dir_ + "/O05556.nc"), contents);
}

int main(int argc, char** argv)
{
  ::testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "test_dnc_node");
  ros::AsyncSpinner spinner(2);
  spinner.start();
  return RUN_ALL_TESTS();
}
