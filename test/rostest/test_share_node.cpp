// share_node (launch/share_node.launch) against a real smbd (test/unit/samba_server.h): send and receive by service and
// by the ~transfer action (feedback, exact bytes on the server's disk), ~list_programs with O numbers and comments, a
// protected program refused with nothing on the share, ~remove_program off unless enabled, and the link state: UP while
// the share answers, DOWN with the reason when smbd stops, UP again when it returns.
#include <actionlib/client/simple_action_client.h>
#include <gtest/gtest.h>
#include <ros/ros.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <filesystem>
#include <memory>
#include <optional>

#include "cnc_bridge/ComparePrograms.h"
#include "cnc_bridge/DprntLine.h"
#include "cnc_bridge/ListPrograms.h"
#include "cnc_bridge/MachineState.h"
#include "cnc_bridge/ProgramHistory.h"
#include "cnc_bridge/ProgramRequestEvent.h"
#include "cnc_bridge/ReceiveProgram.h"
#include "cnc_bridge/RemoveProgram.h"
#include "cnc_bridge/SendProgram.h"
#include "cnc_bridge/TransferAction.h"
#include "cnc_bridge/WithdrawProgram.h"
#include "samba_server.h"
#include "temp_dir.h"
#include "topic_watch.h"

using namespace cnc_bridge;
using cnc_bridge::test::readFile;
using cnc_bridge::test::TempDir;
using cnc_bridge::test::writeFile;

namespace
{
const std::string kNs = "/cell/lathe/share_node/";

class ShareNodeTest : public ::testing::Test
{
 protected:
  void SetUp() override
  {
    server_ = std::make_unique<test::SambaServer>(dir_.path);
    server_->start();
    programs_ = dir_.path + "/programs";
    states_ = std::make_unique<topic_watch::TopicWatch<MachineState>>("/cell/lathe/state", 100, nh_);
    requests_ =
        std::make_unique<topic_watch::TopicWatch<ProgramRequestEvent>>("/cell/lathe/program_requests", 100, nh_);
    node_ = ::fork();
    if (node_ == 0)
    {
      ::prctl(PR_SET_PDEATHSIG, SIGKILL);  // a killed test leaves no node behind
      ::setenv("ROS_NAMESPACE", "/cell/lathe", 1);
      // The production launch file, as a cell includes it, with only the share's address changed.
      const std::string url = "url:=" + server_->url("secure");
      const std::string credentials = "credentials_file:=" + server_->credentials("node.auth");
      const std::string dir = "program_dir:=" + programs_;
      ::execlp("roslaunch", "roslaunch", "cnc_bridge", "share_node.launch", url.c_str(), credentials.c_str(),
               dir.c_str(), "check_period:=0.3", "timeout:=3", "machine:=lathe", nullptr);
      ::_exit(127);
    }
    ASSERT_TRUE(ros::service::waitForService(kNs + "send_program", ros::Duration(30)));
  }

  void TearDown() override
  {
    ::kill(node_, SIGINT);
    ::waitpid(node_, nullptr, 0);
  }

  /// Waits for a state whose link is \p link; \returns its message ("<none>" if none came in time).
  std::string waitForLink(uint8_t link, double seconds)
  {
    std::string message;
    const bool seen = states_->waitForLatest(
        [&](const MachineState& state)
        {
          message = state.message;
          return state.link == link;
        },
        seconds);
    return seen ? message : "<none>";
  }

  /// The next program request event (after the \p seen first ones); nothing if none came in time.
  std::optional<ProgramRequestEvent> waitForRequest(size_t seen, double seconds)
  {
    std::optional<ProgramRequestEvent> request;
    requests_->waitFor(
        [&](const std::vector<ProgramRequestEvent>& requests)
        {
          if (requests.size() > seen)
            request = requests[seen];
          return request.has_value();
        },
        seconds);
    return request;
  }

  TempDir dir_{"cnc_share_node"};
  std::unique_ptr<topic_watch::TopicWatch<ProgramRequestEvent>> requests_;
  std::unique_ptr<test::SambaServer> server_;
  std::string programs_;
  pid_t node_ = -1;
  ros::NodeHandle nh_;
  std::unique_ptr<topic_watch::TopicWatch<MachineState>> states_;
};
}  // namespace

TEST_F(ShareNodeTest, ServicesActionListingAndRefusals)
{
  EXPECT_NE(waitForLink(MachineState::LINK_UP, 10), "<none>");
  const std::string program = "%\nO01234 (SHAFT OP1)\nG0 X1.\nM30\n%\n";
  writeFile(programs_ + "/O01234.nc", program);
  SendProgram send;
  send.request.file = "O01234.nc";
  ASSERT_TRUE(ros::service::call(kNs + "send_program", send));
  EXPECT_TRUE(send.response.success) << send.response.message;
  EXPECT_EQ(send.response.bytes, program.size());
  EXPECT_EQ(readFile(server_->folder("secure") + "/O01234.nc"), program);

  const std::string from_control = "%\nO05000 (FROM THE CONTROL)\nM30\n%\n";
  writeFile(server_->folder("secure") + "/O05000.nc", from_control);
  ReceiveProgram receive;
  receive.request.file = "O05000.nc";
  ASSERT_TRUE(ros::service::call(kNs + "receive_program", receive));
  EXPECT_TRUE(receive.response.success) << receive.response.message;
  EXPECT_EQ(readFile(programs_ + "/O05000.nc"), from_control);

  // The action: 5 MB with feedback up to 100 %.
  std::string big = "%\nO02000 (BIG)\n";
  while (big.size() < 5 * 1024 * 1024)
    big += "G01 X" + std::to_string(big.size() % 997) + ". Y1. F200.\n";
  writeFile(programs_ + "/O02000.nc", big);
  actionlib::SimpleActionClient<TransferAction> client(kNs + "transfer", true);
  ASSERT_TRUE(client.waitForServer(ros::Duration(10)));
  TransferGoal goal;
  goal.direction = TransferGoal::DIRECTION_SEND;
  goal.file = "O02000.nc";
  float last_percent = -1;
  client.sendGoal(goal, {}, {}, [&](const TransferFeedbackConstPtr& f) { last_percent = f->percent; });
  ASSERT_TRUE(client.waitForResult(ros::Duration(30)));
  EXPECT_EQ(client.getState(), actionlib::SimpleClientGoalState::SUCCEEDED) << client.getResult()->message;
  EXPECT_EQ(client.getResult()->bytes, big.size());
  EXPECT_FLOAT_EQ(last_percent, 100.0f);
  EXPECT_EQ(readFile(server_->folder("secure") + "/O02000.nc"), big);

  ListPrograms list;
  ASSERT_TRUE(ros::service::call(kNs + "list_programs", list));
  ASSERT_TRUE(list.response.success) << list.response.message;
  ASSERT_EQ(list.response.programs.size(), 3u);
  EXPECT_EQ(list.response.programs[0].name, "O01234.nc");
  EXPECT_EQ(list.response.programs[0].number, 1234);
  EXPECT_EQ(list.response.programs[0].comment, "SHAFT OP1");
  EXPECT_EQ(list.response.programs[0].size, program.size());
  EXPECT_GT(list.response.programs[0].mtime.sec, 0u);
  EXPECT_EQ(list.response.programs[2].comment, "FROM THE CONTROL");

  // Protected: refused by its O number, nothing new on the share.
  writeFile(programs_ + "/probe.nc", "%\nO09010 (WIPS)\nM99\n%\n");
  send.request.file = "probe.nc";
  ASSERT_TRUE(ros::service::call(kNs + "send_program", send));
  EXPECT_FALSE(send.response.success);
  EXPECT_NE(send.response.message.find("O08000-O09999"), std::string::npos) << send.response.message;
  EXPECT_NE(send.response.message.find("~allow_protected_programs"), std::string::npos) << send.response.message;
  EXPECT_FALSE(test::exists(server_->folder("secure") + "/probe.nc"));

  RemoveProgram remove;
  remove.request.file = "O01234.nc";
  ASSERT_TRUE(ros::service::call(kNs + "remove_program", remove));
  EXPECT_FALSE(remove.response.success);
  EXPECT_NE(remove.response.message.find("~enable_remove"), std::string::npos) << remove.response.message;
  EXPECT_TRUE(test::exists(server_->folder("secure") + "/O01234.nc"));
}

// Every program sent or received is kept in the archive beside ~program_dir: two different sends
// make two versions, an identical third none; history and diff through the services.
TEST_F(ShareNodeTest, ArchiveKeepsEachDistinctVersionOnce)
{
  SendProgram send;
  send.request.file = "O03000.nc";
  for (const std::string feed : {"F100.", "F250.", "F250."})
  {
    writeFile(programs_ + "/O03000.nc", "%\nO03000 (FACE)\nG01 X10. " + feed + "\nM30\n%\n");
    ASSERT_TRUE(ros::service::call(kNs + "send_program", send));
    ASSERT_TRUE(send.response.success) << send.response.message;
  }
  ProgramHistory history;
  history.request.file = "O03000.nc";
  ASSERT_TRUE(ros::service::call(kNs + "program_history", history));
  ASSERT_TRUE(history.response.success) << history.response.message;
  ASSERT_EQ(history.response.versions.size(), 2u);
  EXPECT_EQ(history.response.versions[0].number, 1u);
  EXPECT_EQ(history.response.versions[1].number, 2u);
  EXPECT_EQ(history.response.versions[1].node, "share_node");
  EXPECT_EQ(history.response.versions[1].machine, "lathe");
  EXPECT_EQ(history.response.versions[1].direction, "sent");
  EXPECT_EQ(history.response.versions[1].crc32.size(), 8u);

  ComparePrograms compare;
  compare.request.file = "O03000.nc";
  compare.request.from = 1;
  compare.request.to = 2;
  ASSERT_TRUE(ros::service::call(kNs + "compare_programs", compare));
  ASSERT_TRUE(compare.response.success) << compare.response.message;
  EXPECT_NE(compare.response.diff.find("\n-G01 X10. F100.\n+G01 X10. F250.\n"), std::string::npos)
      << compare.response.diff;
  // The newest version against the current file: identical.
  compare.request.from = 0;
  compare.request.to = 0;
  ASSERT_TRUE(ros::service::call(kNs + "compare_programs", compare));
  EXPECT_TRUE(compare.response.success) << compare.response.message;
  EXPECT_EQ(compare.response.diff, "");
  compare.request.from = 7;
  ASSERT_TRUE(ros::service::call(kNs + "compare_programs", compare));
  EXPECT_FALSE(compare.response.success);
  EXPECT_NE(compare.response.message.find("kept: 1, 2"), std::string::npos) << compare.response.message;

  // Withdrawn: kept in the archive (here the content of version 2), then gone from the share.
  WithdrawProgram withdraw;
  withdraw.request.file = "O03000.nc";
  ASSERT_TRUE(ros::service::call(kNs + "withdraw_program", withdraw));
  EXPECT_TRUE(withdraw.response.success) << withdraw.response.message;
  EXPECT_EQ(withdraw.response.version, 2u);
  EXPECT_FALSE(test::exists(server_->folder("secure") + "/O03000.nc"));
  ASSERT_TRUE(ros::service::call(kNs + "withdraw_program", withdraw));
  EXPECT_FALSE(withdraw.response.success);  // nothing left to withdraw
  EXPECT_NE(withdraw.response.message.find("no program 'O03000.nc'"), std::string::npos) << withdraw.response.message;

  // A program received from the control is kept too.
  writeFile(server_->folder("secure") + "/O03001.nc", "%\nO03001 (EDITED AT THE CONTROL)\n%\n");
  ReceiveProgram receive;
  receive.request.file = "O03001.nc";
  ASSERT_TRUE(ros::service::call(kNs + "receive_program", receive));
  ASSERT_TRUE(receive.response.success) << receive.response.message;
  history.request.file = "O03001.nc";
  ASSERT_TRUE(ros::service::call(kNs + "program_history", history));
  ASSERT_EQ(history.response.versions.size(), 1u);
  EXPECT_EQ(history.response.versions[0].direction, "received");
}

// The operator asks at the control: a request file dropped in the share's requests/ folder, or a
// DPRNT line LOAD O1234, makes share_node publish the program into the share; an unknown number is
// answered with the reason; every request is published on program_requests.
TEST_F(ShareNodeTest, RequestsFromTheControlArePublishedIntoTheShare)
{
  const std::string program = "%\nO01234 (REQUESTED)\nM30\n%\n";
  writeFile(programs_ + "/O01234.nc", program);
  writeFile(programs_ + "/O01235.nc", "%\nO01235 (BY DPRNT)\nM30\n%\n");
  // Events are not queued for a subscriber that is not connected yet: wait for the connection.
  requests_->waitForPublisher(10);
  ASSERT_GT(requests_->publishers(), 0u);
  const std::string requests = server_->folder("secure") + "/requests";
  std::filesystem::create_directories(requests);
  writeFile(requests + "/from_operator.nc", "%\nO00001 (LOAD O1234)\nM30\n%\n");
  auto event = waitForRequest(0, 15);
  ASSERT_TRUE(event);
  EXPECT_TRUE(event->success) << event->outcome;
  EXPECT_EQ(event->request, "LOAD");
  EXPECT_EQ(event->number, 1234u);
  EXPECT_EQ(event->program, "O01234.nc");
  EXPECT_EQ(event->source, "share requests/from_operator.nc");
  EXPECT_EQ(readFile(server_->folder("secure") + "/O01234.nc"), program);
  EXPECT_FALSE(test::exists(requests + "/from_operator.nc"));  // served once

  writeFile(requests + "/unknown.nc", "%\nO00001 (SEND O4444)\n%\n");
  event = waitForRequest(1, 15);
  ASSERT_TRUE(event);
  EXPECT_FALSE(event->success);
  EXPECT_NE(event->outcome.find("no O04444.nc"), std::string::npos) << event->outcome;
  EXPECT_FALSE(test::exists(server_->folder("secure") + "/O04444.nc"));

  ros::Publisher dprnt = nh_.advertise<DprntLine>("/cell/lathe/dprnt/raw", 10);
  DprntLine line;
  line.text = "LOAD O1235";
  // Published until the node has subscribed (a latched topic would replay old lines).
  std::optional<ProgramRequestEvent> by_dprnt;
  for (int i = 0; i < 50 && !by_dprnt; ++i)
  {
    dprnt.publish(line);
    by_dprnt = waitForRequest(2, 0.2);
  }
  ASSERT_TRUE(by_dprnt);
  EXPECT_TRUE(by_dprnt->success) << by_dprnt->outcome;
  EXPECT_EQ(by_dprnt->source, "dprnt");
  EXPECT_TRUE(test::exists(server_->folder("secure") + "/O01235.nc"));
}

TEST_F(ShareNodeTest, LinkDownWhenTheServerStopsAndUpWhenItReturns)
{
  EXPECT_NE(waitForLink(MachineState::LINK_UP, 10), "<none>");
  server_->stop();
  const std::string reason = waitForLink(MachineState::LINK_DOWN, 15);
  EXPECT_NE(reason.find("127.0.0.1:" + std::to_string(server_->port)), std::string::npos) << reason;
  SendProgram send;
  writeFile(programs_ + "/O00001.nc", "%\nO1\n%\n");
  send.request.file = "O00001.nc";
  ASSERT_TRUE(ros::service::call(kNs + "send_program", send));
  EXPECT_FALSE(send.response.success);
  server_->start();
  EXPECT_NE(waitForLink(MachineState::LINK_UP, 15), "<none>");
  ASSERT_TRUE(ros::service::call(kNs + "send_program", send));
  EXPECT_TRUE(send.response.success) << send.response.message;
}

int main(int argc, char** argv)
{
  testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "test_share_node");
  ros::AsyncSpinner spinner(2);
  spinner.start();
  return RUN_ALL_TESTS();
}
