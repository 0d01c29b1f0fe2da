// share_node's ~publish_to_machines: two share_nodes, each on a local folder standing for a
// machine's share, started as processes of their own; one call publishes a program to both (byte
// for byte) and to a machine that does not exist, which is reported in its own entry without
// stopping the others.
#include <gtest/gtest.h>
#include <ros/ros.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <filesystem>
#include <random>

#include "cnc_bridge/FanOutProgram.h"
#include "temp_dir.h"

using namespace cnc_bridge;
using cnc_bridge::test::readFile;
using cnc_bridge::test::TempDir;
using cnc_bridge::test::writeFile;

namespace
{
class ShareFanOutTest : public ::testing::Test
{
 protected:
  void SetUp() override
  {
    programs_ = dir_.file("programs");
    std::filesystem::create_directories(programs_);
    for (const char* machine : {"vf2", "st10"})
    {
      std::filesystem::create_directories(share(machine));
      start(machine, {"_url:=" + share(machine)});
    }
    for (const char* machine : {"vf2", "st10"})
      ASSERT_TRUE(ros::service::waitForService(std::string("/cell/") + machine + "/share_node/publish_to_machines",
                                               ros::Duration(20)));
  }

  void TearDown() override
  {
    for (const pid_t node : nodes_)
    {
      ::kill(node, SIGINT);
      ::waitpid(node, nullptr, 0);
    }
  }

  std::string share(const std::string& machine) const { return dir_.file("share_" + machine); }

  /// Starts a share_node as /cell/<machine>/share_node with \p params (_name:=value).
  void start(const std::string& machine, std::vector<std::string> params)
  {
    params.push_back("_program_dir:=" + programs_);
    params.push_back("_machine:=" + machine);
    params.push_back("__ns:=/cell/" + machine);
    params.push_back("__name:=share_node");
    const pid_t node = ::fork();
    if (node == 0)
    {
      ::prctl(PR_SET_PDEATHSIG, SIGKILL);  // a killed test leaves no node behind
      std::vector<char*> argv{const_cast<char*>(SHARE_NODE)};
      for (std::string& param : params)
        argv.push_back(param.data());
      argv.push_back(nullptr);
      ::execv(SHARE_NODE, argv.data());
      ::_exit(127);
    }
    nodes_.push_back(node);
  }

  TempDir dir_{"cnc_share_fan_out"};
  std::string programs_;
  std::vector<pid_t> nodes_;
};

/// A program of \p size bytes of every byte value, so that a transfer that changes any is seen.
std::string program(size_t size)
{
  std::string text = "%\nO01234 (FAN OUT)\n";
  std::mt19937 random(7);
  while (text.size() < size)
    text.push_back(static_cast<char>(random() & 0xff));
  return text;
}
}  // namespace

TEST_F(ShareFanOutTest, OneCallPublishesToEachMachineAndReportsTheMissingOne)
{
  const std::string content = program(200 * 1024);
  writeFile(programs_ + "/O01234.nc", content);
  FanOutProgram call;
  call.request.file = "O01234.nc";
  // A node's name, a machine that does not exist (between the two: it must not stop the third),
  // and a namespace holding a share_node.
  call.request.machines = {"/cell/vf2/share_node", "/cell/hmc/share_node", "/cell/st10"};
  ASSERT_TRUE(ros::service::call("/cell/vf2/share_node/publish_to_machines", call));
  EXPECT_FALSE(call.response.success);
  ASSERT_EQ(call.response.machines, call.request.machines);
  ASSERT_EQ(call.response.succeeded.size(), 3u);
  ASSERT_EQ(call.response.messages.size(), 3u);
  EXPECT_TRUE(call.response.succeeded[0]) << call.response.messages[0];
  EXPECT_FALSE(call.response.succeeded[1]);
  EXPECT_NE(call.response.messages[1].find("/cell/hmc/share_node/send_program"), std::string::npos)
      << call.response.messages[1];
  EXPECT_TRUE(call.response.succeeded[2]) << call.response.messages[2];
  EXPECT_NE(call.response.messages[2].find(share("st10")), std::string::npos) << call.response.messages[2];
  EXPECT_NE(call.response.message.find("2 of 3 machines got O01234.nc"), std::string::npos) << call.response.message;
  EXPECT_NE(call.response.message.find("/cell/hmc/share_node"), std::string::npos) << call.response.message;
  EXPECT_EQ(readFile(share("vf2") + "/O01234.nc"), content);
  EXPECT_EQ(readFile(share("st10") + "/O01234.nc"), content);

  // A program neither machine has: each reports it, nothing is written anywhere.
  call.request.file = "O04444.nc";
  call.request.machines = {"/cell/vf2/share_node", "/cell/st10/share_node"};
  call.response = FanOutProgram::Response();
  ASSERT_TRUE(ros::service::call("/cell/vf2/share_node/publish_to_machines", call));
  EXPECT_FALSE(call.response.success);
  ASSERT_EQ(call.response.succeeded, (std::vector<uint8_t>{false, false}));
  EXPECT_NE(call.response.messages[1].find("O04444.nc"), std::string::npos) << call.response.messages[1];
  EXPECT_FALSE(test::exists(share("vf2") + "/O04444.nc"));
  EXPECT_FALSE(test::exists(share("st10") + "/O04444.nc"));
}

int main(int argc, char** argv)
{
  testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "test_share_fan_out");
  ros::AsyncSpinner spinner(2);
  spinner.start();
  return RUN_ALL_TESTS();
}
