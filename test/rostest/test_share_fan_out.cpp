// Two share_nodes of a cell, each on a local folder standing for a machine's share, started as
// processes of their own. ~publish_to_machines: one call publishes a program to both (byte for
// byte) and to a machine that does not exist, which is reported in its own entry without stopping
// the others. ~withdraw_all (the path ~withdraw_at takes at its time of day): every program of the
// share kept in the archive, then removed, each outcome on withdrawals; a bad ~withdraw_at stops
// the node with the reason. ~withdraw_at: a node whose clock reaches the time of day a few seconds
// after its start empties its share then, not before. ~serve_dir: the second node's folder is one
// the PC serves. A ~url with a password stops the node without repeating it (stderr, /rosout, the
// parameter server).
#include <fcntl.h>
#include <gtest/gtest.h>
#include <ros/ros.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <std_srvs/Trigger.h>

#include <algorithm>
#include <cstdio>
#include <ctime>
#include <filesystem>
#include <mutex>
#include <random>

#include <rosgraph_msgs/Log.h>

#include "cnc_bridge/FanOutProgram.h"
#include "cnc_bridge/ProgramRequestEvent.h"
#include "temp_dir.h"
#include "topic_watch.h"

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
      std::filesystem::create_directories(share(machine));
    // One machine's share, and a folder the PC serves to the other.
    start("vf2", {"_url:=" + share("vf2"), "_withdraw_at:=03:00"});
    start("st10", {"_serve_dir:=" + share("st10")});
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

  /// Starts a share_node as /cell/<machine>/share_node with \p params (_name:=value); its
  /// stderr into \p errors if given, its time zone \p tz (TZ) if given.
  pid_t start(const std::string& machine, std::vector<std::string> params, const std::string& errors = "",
              const std::string& tz = "")
  {
    params.push_back("_program_dir:=" + programs_);
    params.push_back("_machine:=" + machine);
    params.push_back("__ns:=/cell/" + machine);
    params.push_back("__name:=share_node");
    const pid_t node = ::fork();
    if (node == 0)
    {
      ::prctl(PR_SET_PDEATHSIG, SIGKILL);  // a killed test leaves no node behind
      if (!errors.empty())
        ::dup2(::open(errors.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644), STDERR_FILENO);
      if (!tz.empty())
        ::setenv("TZ", tz.c_str(), 1);
      std::vector<char*> argv{const_cast<char*>(SHARE_NODE)};
      for (std::string& param : params)
        argv.push_back(param.data());
      argv.push_back(nullptr);
      ::execv(SHARE_NODE, argv.data());
      ::_exit(127);
    }
    nodes_.push_back(node);
    return node;
  }

  /// Starts a share_node with \p params that must stop at once with status 1; \returns its stderr.
  std::string refuse(const std::string& machine, const std::vector<std::string>& params)
  {
    const std::string errors = dir_.file(machine + ".stderr");
    const pid_t node = start(machine, params, errors);
    int status = 0;
    EXPECT_EQ(::waitpid(node, &status, 0), node);  // it ends by itself
    nodes_.pop_back();
    EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 1) << machine << ": status " << status;
    return readFile(errors);
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
  // The served folder holds the program and nothing else (no temporary name left behind).
  std::vector<std::string> served;
  for (const auto& entry : std::filesystem::directory_iterator(share("st10")))
    served.push_back(entry.path().filename().string());
  EXPECT_EQ(served, (std::vector<std::string>{"O01234.nc"}));

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

TEST_F(ShareFanOutTest, WithdrawAllKeepsEveryProgramInTheArchiveAndEmptiesTheShare)
{
  topic_watch::TopicWatch<ProgramRequestEvent> withdrawals("/cell/vf2/withdrawals", 10);
  const std::string first = "%\nO01000 (OP1)\nG0 X1.\nM30\n%\n";
  const std::string second = program(3000);
  writeFile(share("vf2") + "/O01000.nc", first);
  writeFile(share("vf2") + "/O01001.nc", second);
  writeFile(share("st10") + "/O01000.nc", first);  // another machine's: stays
  // The subscription must be connected before the call, or the events could go to no one.
  withdrawals.waitForPublisher(5);
  ASSERT_EQ(withdrawals.publishers(), 1u);

  std_srvs::Trigger call;
  ASSERT_TRUE(ros::service::call("/cell/vf2/share_node/withdraw_all", call));
  EXPECT_TRUE(call.response.success) << call.response.message;
  EXPECT_NE(call.response.message.find("withdrew 2 of 2 programs"), std::string::npos) << call.response.message;
  EXPECT_FALSE(test::exists(share("vf2") + "/O01000.nc"));
  EXPECT_FALSE(test::exists(share("vf2") + "/O01001.nc"));
  EXPECT_EQ(readFile(programs_ + ".archive/O01000.nc/v0001.nc"), first);
  EXPECT_EQ(readFile(programs_ + ".archive/O01001.nc/v0001.nc"), second);
  EXPECT_NE(readFile(programs_ + ".archive/O01001.nc/v0001.meta").find("withdrawn"), std::string::npos);
  EXPECT_EQ(readFile(share("st10") + "/O01000.nc"), first);
  {
    ASSERT_TRUE(withdrawals.waitFor([](const auto& events) { return events.size() >= 2; }, 10));
    const auto events = withdrawals.all();
    for (const ProgramRequestEvent& event : events)
    {
      EXPECT_TRUE(event.success) << event.outcome;
      EXPECT_EQ(event.request, "WITHDRAW");
      EXPECT_EQ(event.source, "~withdraw_all");
      EXPECT_EQ(event.machine, "vf2");
      EXPECT_NE(event.outcome.find("archive version 1"), std::string::npos) << event.outcome;
    }
    EXPECT_EQ(events[0].program, "O01000.nc");
    EXPECT_EQ(events[1].program, "O01001.nc");
  }

  // Nothing left: nothing to do, which is no failure.
  ASSERT_TRUE(ros::service::call("/cell/vf2/share_node/withdraw_all", call));
  EXPECT_TRUE(call.response.success) << call.response.message;
  EXPECT_NE(call.response.message.find("withdrew 0 of 0 programs"), std::string::npos) << call.response.message;
}

TEST_F(ShareFanOutTest, WithdrawAtItsTimeOfDayEmptiesTheShareThenNotBefore)
{
  // ~withdraw_at is a whole minute of the local clock. The node runs in a time zone whose UTC
  // offset has seconds (POSIX TZ, tzset(3): "std offset", offset hh[:mm[:ss]], positive west of
  // Greenwich), chosen so that its local clock reads a whole minute a few seconds from now.
  const std::time_t at = std::time(nullptr) + 8;
  const int offset = static_cast<int>(at % 60);
  const std::time_t local = at - offset;  // local time = UTC - offset: a whole minute at `at`
  std::tm fields{};
  ::gmtime_r(&local, &fields);
  char tz[32];
  char time_of_day[8];
  std::snprintf(tz, sizeof tz, "TST+0:00:%02d", offset);
  std::strftime(time_of_day, sizeof time_of_day, "%H:%M", &fields);

  struct Withdrawals : topic_watch::Record
  {
    std::vector<ProgramRequestEvent> events;
    std::time_t first_event = 0;
  } seen;
  ros::NodeHandle nh;
  ros::Subscriber sub = nh.subscribe<ProgramRequestEvent>("/cell/hmc/withdrawals", 10,
                                                          [&](const ProgramRequestEvent::ConstPtr& event)
                                                          {
                                                            seen.update(
                                                                [&]
                                                                {
                                                                  if (seen.events.empty())
                                                                    seen.first_event = std::time(nullptr);
                                                                  seen.events.push_back(*event);
                                                                });
                                                          });
  std::filesystem::create_directories(share("hmc"));
  const std::string first = "%\nO01000 (OP1)\nG0 X1.\nM30\n%\n";
  const std::string second = program(3000);
  writeFile(share("hmc") + "/O01000.nc", first);
  writeFile(share("hmc") + "/O01001.nc", second);
  start("hmc", {"_url:=" + share("hmc"), std::string("_withdraw_at:=") + time_of_day}, "", tz);
  {
    ASSERT_TRUE(seen.waitFor([&] { return seen.events.size() >= 2; }, 40))
        << "no withdrawal at " << time_of_day << " " << tz;
    std::lock_guard<std::mutex> lock(seen.mutex);
    EXPECT_GE(seen.first_event, at);  // at the time, not before it
    for (const ProgramRequestEvent& event : seen.events)
    {
      EXPECT_TRUE(event.success) << event.outcome;
      EXPECT_EQ(event.request, "WITHDRAW");
      EXPECT_EQ(event.source, std::string("~withdraw_at ") + time_of_day);
    }
  }
  EXPECT_FALSE(test::exists(share("hmc") + "/O01000.nc"));
  EXPECT_FALSE(test::exists(share("hmc") + "/O01001.nc"));
  EXPECT_EQ(readFile(programs_ + ".archive/O01000.nc/v0001.nc"), first);
  EXPECT_EQ(readFile(programs_ + ".archive/O01001.nc/v0001.nc"), second);
}

TEST_F(ShareFanOutTest, AWithdrawalTimeThatIsNoTimeOfDayStopsTheNode)
{
  std::filesystem::create_directories(share("hmc"));
  const std::string error = refuse("hmc", {"_url:=" + share("hmc"), "_withdraw_at:=25:00"});
  EXPECT_NE(error.find("withdraw_at \"25:00\" is not a time of day"), std::string::npos) << error;
  EXPECT_FALSE(ros::service::exists("/cell/hmc/share_node/publish_to_machines", false));
}

TEST_F(ShareFanOutTest, ExactlyOneOfUrlAndServeDir)
{
  std::filesystem::create_directories(share("hmc"));
  // A node of its own for each case: private parameters outlive their node.
  std::string error = refuse("both", {"_url:=" + share("hmc"), "_serve_dir:=" + share("hmc")});
  EXPECT_NE(error.find("give exactly one of /cell/both/share_node/url"), std::string::npos) << error;
  EXPECT_NE(error.find("not both"), std::string::npos) << error;
  error = refuse("neither", {});
  EXPECT_NE(error.find("not neither"), std::string::npos) << error;
  error = refuse("smb", {"_serve_dir:=smb://127.0.0.1/memory"});
  EXPECT_NE(error.find("is a local folder the PC's Samba serves"), std::string::npos) << error;
  error = refuse("missing", {"_serve_dir:=" + share("missing")});
  EXPECT_NE(error.find(share("missing") + " is not a folder"), std::string::npos) << error;
  EXPECT_FALSE(test::exists(share("missing")));
}

namespace
{
/// The names of the parameters under \p key whose value (a string, at any depth) holds \p text.
void paramsHolding(const XmlRpc::XmlRpcValue& value, const std::string& key, const std::string& text,
                   std::vector<std::string>& found)
{
  if (value.getType() == XmlRpc::XmlRpcValue::TypeStruct)
  {
    for (auto it = value.begin(); it != value.end(); ++it)
      paramsHolding(it->second, key + "/" + it->first, text, found);
  }
  else if (value.getType() == XmlRpc::XmlRpcValue::TypeArray)
  {
    for (int i = 0; i < value.size(); ++i)
      paramsHolding(value[i], key + "/" + std::to_string(i), text, found);
  }
  else if (value.getType() == XmlRpc::XmlRpcValue::TypeString &&
           static_cast<const std::string&>(value).find(text) != std::string::npos)
  {
    found.push_back(key);
  }
}
}  // namespace

TEST_F(ShareFanOutTest, APasswordInTheUrlIsRefusedAndRepeatedNowhere)
{
  const std::string password = "Pw-7f3e9a";
  topic_watch::TopicWatch<rosgraph_msgs::Log> rosout("/rosout_agg", 1000, ros::NodeHandle());
  const std::string error = refuse("leak", {"_url:=smb://cnc:" + password + "@127.0.0.1/memory"});
  EXPECT_NE(error.find("/cell/leak/share_node/url holds user information with a password"), std::string::npos) << error;
  EXPECT_NE(error.find("credentials file"), std::string::npos) << error;
  EXPECT_EQ(error.find(password), std::string::npos) << error;
  for (const rosgraph_msgs::Log& line : rosout.all())
    EXPECT_EQ(line.msg.find(password), std::string::npos) << line.name << ": " << line.msg;
  XmlRpc::XmlRpcValue everything;
  ASSERT_TRUE(ros::param::get("/", everything));
  std::vector<std::string> holding;
  paramsHolding(everything, "", password, holding);
  EXPECT_EQ(holding, std::vector<std::string>{"/cell/leak/share_node/url"});  // only where the user set it
}

int main(int argc, char** argv)
{
  testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "test_share_fan_out");
  ros::AsyncSpinner spinner(2);
  spinner.start();
  return RUN_ALL_TESTS();
}

// The hybrid share: a third share_node whose served folder is the NAS, with ~drop_to both machines'
// shares and ~collect_from the VF-2's. A program copied onto the NAS reaches both machines once
// complete (one event per machine on hub_events, a line each in <archive>/hub_results.log); a
// protected one reaches neither; what the VF-2 writes on its share is collected into the NAS's vf2
// folder and kept in the archive.
TEST_F(ShareFanOutTest, TheHybridShareDropsOntoEveryMachineAndCollectsWhatTheMachineWrites)
{
  const std::string nas = dir_.file("nas");
  std::filesystem::create_directories(nas);
  XmlRpc::XmlRpcValue drop_to, collect_from;
  drop_to["vf2"] = share("vf2");
  drop_to["st10"] = share("st10");
  collect_from["vf2"] = share("vf2");
  ros::param::set("/cell/nas/share_node/drop_to", drop_to);
  ros::param::set("/cell/nas/share_node/collect_from", collect_from);
  topic_watch::TopicWatch<ProgramRequestEvent> events("/cell/nas/hub_events", 20);
  start("nas", {"_serve_dir:=" + nas, "_hub_period:=0.2", "_hub_settle:=0.5"});
  events.waitForPublisher(20);
  ASSERT_EQ(events.publishers(), 1u);

  // Copied onto the NAS as a file manager would: written under another name, then renamed.
  const std::string content = program(50 * 1024);
  writeFile(nas + "/.O01234.nc.copying", content);
  std::filesystem::rename(nas + "/.O01234.nc.copying", nas + "/O01234.nc");
  writeFile(nas + "/O09001.nc", "%\nO09001 (PROBE MACRO)\nM99\n%\n");
  auto dropped = [](const std::string& program, const std::string& machine)
  {
    return [program, machine](const std::vector<ProgramRequestEvent>& all)
    {
      return std::any_of(all.begin(), all.end(),
                         [&](const ProgramRequestEvent& e)
                         { return e.request == "DROP" && e.program == program && e.machine == machine; });
    };
  };
  ASSERT_TRUE(events.waitFor(dropped("O01234.nc", "vf2"), 20));
  ASSERT_TRUE(events.waitFor(dropped("O01234.nc", "st10"), 20));
  ASSERT_TRUE(events.waitFor(dropped("O09001.nc", "(all)"), 20));
  for (const auto& event : events.all())
  {
    EXPECT_EQ(event.success, event.program == "O01234.nc")
        << event.program << " " << event.machine << ": " << event.outcome;
    if (event.program == "O09001.nc")
      EXPECT_NE(event.outcome.find("~allow_protected_programs"), std::string::npos) << event.outcome;
  }
  EXPECT_EQ(readFile(share("vf2") + "/O01234.nc"), content);
  EXPECT_EQ(readFile(share("st10") + "/O01234.nc"), content);
  EXPECT_FALSE(test::exists(share("vf2") + "/O09001.nc"));
  EXPECT_FALSE(test::exists(share("st10") + "/O09001.nc"));

  // The operator saves an edited program at the VF-2: collected into the NAS's vf2 folder.
  const std::string edited = "%\nO02000 (EDITED AT THE CONTROL)\nG0 X1.\nM30\n%\n";
  writeFile(share("vf2") + "/O02000.nc", edited);
  ASSERT_TRUE(events.waitFor(
      [](const std::vector<ProgramRequestEvent>& all)
      {
        return std::any_of(all.begin(), all.end(),
                           [](const ProgramRequestEvent& e)
                           { return e.request == "COLLECT" && e.program == "O02000.nc"; });
      },
      20));
  EXPECT_EQ(readFile(nas + "/vf2/O02000.nc"), edited);
  const std::string archive = programs_ + ".archive";
  EXPECT_EQ(readFile(archive + "/O02000.nc/v0001.nc"), edited);
  EXPECT_NE(readFile(archive + "/O02000.nc/v0001.meta").find("collected"), std::string::npos);
  const std::string log = readFile(archive + "/hub_results.log");
  EXPECT_NE(log.find("DROP\tO01234.nc\tvf2\tok"), std::string::npos) << log;
  EXPECT_NE(log.find("DROP\tO01234.nc\tst10\tok"), std::string::npos) << log;
  EXPECT_NE(log.find("COLLECT\tO02000.nc\tvf2\tok"), std::string::npos) << log;
}
