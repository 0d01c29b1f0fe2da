// dnc_node's drip-feed breaking off, seen from the simulated control (sim_haas_serial drip, see
// dnc_drip_link.test): the serial link dropped mid-feed, and the node killed mid-feed. Either way
// the control received a prefix of the program, executed the whole blocks of it and nothing else,
// and waits for data (a DNC control starves, it does not run on). After the operator's RESET, a
// restart from the block after the last one the control executed runs to the program's end.
#include <actionlib/client/simple_action_client.h>
#include <gtest/gtest.h>
#include <ros/ros.h>
#include <signal.h>
#include <sys/stat.h>

#include <algorithm>
#include <fstream>
#include <functional>
#include <memory>
#include <regex>
#include <sstream>

#include "cnc_bridge/DncLine.h"
#include "cnc_bridge/PlanDrip.h"
#include "cnc_bridge/TransferAction.h"
#include "line_log.h"
#include "process_kill.h"
#include "topic_watch.h"

namespace
{
using Client = actionlib::SimpleActionClient<cnc_bridge::TransferAction>;
using Lines = std::vector<std::string>;

const char* const kWaiting = "waiting for data";
std::string program_path;

using line_log::readFile;
using line_log::waitUntil;

/// The lines of \p text that end with a line feed (a partial last line left out).
Lines wholeLines(const std::string& text)
{
  Lines lines;
  std::istringstream in(text.substr(0, text.rfind('\n') + 1));
  for (std::string line; std::getline(in, line);)
  {
    lines.push_back(line);
  }
  return lines;
}

/// The blocks among the entries of an execution log ("block <text>").
Lines blocksOf(const Lines& log)
{
  Lines blocks;
  for (const auto& entry : log)
  {
    if (entry.rfind("block ", 0) == 0)
    {
      blocks.push_back(entry.substr(6));
    }
  }
  return blocks;
}

/// The simulated control and the files it writes (dnc_drip_link.test).
struct Control
{
  std::string pty, received_path, log_path, pid_file;

  Control()
  {
    ros::NodeHandle pnh("~");
    pnh.getParam("pty", pty);
    pnh.getParam("received", received_path);
    pnh.getParam("execution_log", log_path);
    pnh.getParam("pid_file", pid_file);
  }
  std::string received() const { return readFile(received_path); }
  Lines log() const { return line_log::LineLog(log_path).lines(); }
  /// Waits until \p ready holds, looking again at each change of the execution log.
  bool waitForLog(const std::function<bool()>& ready, double seconds) const
  {
    return line_log::waitForFile(log_path, ready, seconds);
  }
  bool logEndsWith(const std::string& entry) const
  {
    const Lines entries = log();
    return !entries.empty() && entries.back() == entry;
  }
  /// The operator's RESET (SIGHUP): the control drops the program it was starved in.
  bool reset() const
  {
    const pid_t pid = process_kill::pidFromFile(pid_file);
    return pid > 0 && ::kill(pid, SIGHUP) == 0 && waitForLog([&] { return logEndsWith("reset"); }, 10);
  }
};

/// What a control received and executed from a mark on (its files grow through the test).
struct Since
{
  size_t received_at = 0;
  size_t log_at = 0;

  explicit Since(const Control& control) : received_at(control.received().size()), log_at(control.log().size()) {}
  std::string received(const Control& control) const { return control.received().substr(received_at); }
  Lines log(const Control& control) const
  {
    const Lines all = control.log();
    return Lines(all.begin() + static_cast<long>(std::min(log_at, all.size())), all.end());
  }
};

/// The machine's dnc_node: its ~transfer action and the lines it reports sent (dnc/current_line).
class Machine
{
 public:
  Machine()
  {
    ros::NodeHandle("~").getParam("namespace", ns_);
    lines_sub_ =
        ros::NodeHandle().subscribe<cnc_bridge::DncLine>(ns_ + "/dnc/current_line", 1000, record_.appendTo(lines_));
  }
  std::string node() const { return ns_ + "/dnc_node"; }

  /// The action server is up, the control's pty exists and dnc/current_line is connected.
  bool ready(Client& client, const Control& control)
  {
    return client.waitForServer(ros::Duration(20)) &&
           line_log::waitUntilExists(control.pty, 20) &&  // never read it: a pty
           waitUntil([&] { return lines_sub_.getNumPublishers() > 0; }, 20);
  }
  /// The line the node reported sent last, once it is at least \p line; 0 if it did not get there.
  uint32_t waitForLine(uint32_t line)
  {
    uint32_t last = 0;
    record_.waitFor(
        [&]
        {
          last = lines_.empty() ? 0 : lines_.back().line;
          return last >= line;
        },
        30);
    return last;
  }
  static cnc_bridge::TransferGoal feed(const std::string& start_block = "")
  {
    cnc_bridge::TransferGoal goal;
    goal.direction = goal.DIRECTION_SEND;
    goal.protocol = "drip";
    goal.file = "drip_rostest.nc";
    goal.start_block = start_block;
    return goal;
  }
  /// The program as a restart from \p start_block sends it: '%', the preamble ~plan_drip shows,
  /// the program's lines from the resume line on.
  std::string restartText(const std::string& start_block) const
  {
    auto plan = ros::NodeHandle().serviceClient<cnc_bridge::PlanDrip>(node() + "/plan_drip");
    cnc_bridge::PlanDrip srv;
    srv.request.file = "drip_rostest.nc";
    srv.request.start_block = start_block;
    if (!plan.waitForExistence(ros::Duration(20)) || !plan.call(srv) || !srv.response.success)
    {
      return "";
    }
    std::string text = "%\n" + srv.response.preamble;
    const Lines program = wholeLines(readFile(program_path));
    for (size_t i = srv.response.resume_line - 1; i < program.size(); ++i)
    {
      text += program[i] + "\n";
    }
    return text;
  }

 private:
  std::string ns_;
  topic_watch::Record record_;
  std::vector<cnc_bridge::DncLine> lines_;
  ros::Subscriber lines_sub_;  // last: unsubscribed before what the callback fills goes
};

/// The control received a prefix of the program that breaks off before its end (\p received),
/// executed its whole blocks, no other, and then waited for data (\p log).
void expectAPrefixRunToItsLastWholeBlockThenWaiting(const std::string& received, const Lines& log)
{
  const std::string program = readFile(program_path);
  ASSERT_FALSE(received.empty());
  EXPECT_LT(received.size(), program.size());
  EXPECT_EQ(0, program.compare(0, received.size(), received)) << "not a prefix of the program:\n" << received;
  EXPECT_EQ(wholeLines(received), blocksOf(log));
  ASSERT_FALSE(log.empty());
  EXPECT_EQ(kWaiting, log.back());
}

/// "N<k+1>" for the last block executed in \p log, "N<k> ..."; empty if it has no N number.
std::string blockAfterTheLastExecuted(const Lines& log)
{
  const Lines blocks = blocksOf(log);
  std::smatch number;
  if (blocks.empty() || !std::regex_search(blocks.back(), number, std::regex("^N([0-9]+)")))
  {
    return "";
  }
  return "N" + std::to_string(std::stoi(number[1]) + 1);
}

/// After the operator's RESET, \p machine restarts the program from the block after the last one
/// \p control executed; the control receives that restart whole and executes every block of it.
// With \p feed and \p before: the control received exactly \p before from the mark \p feed up to the
// restart, which closes a window in which nothing may arrive by a later message on the same line.
void expectARestartAfterTheLastExecutedBlockRunsToTheEnd(Machine& machine, const Control& control,
                                                         const Since* feed = nullptr, const std::string& before = "")
{
  const std::string start_block = blockAfterTheLastExecuted(control.log());
  ASSERT_FALSE(start_block.empty()) << "no N number executed";
  ASSERT_TRUE(control.reset());
  const std::string expected = machine.restartText(start_block);
  ASSERT_FALSE(expected.empty()) << "~plan_drip from " << start_block;
  const Since mark(control);
  Client client(machine.node() + "/transfer", true);
  ASSERT_TRUE(client.waitForServer(ros::Duration(20)));
  ASSERT_EQ(actionlib::SimpleClientGoalState::SUCCEEDED,
            client.sendGoalAndWait(Machine::feed(start_block), ros::Duration(60)).state_)
      << client.getResult()->message;
  const std::string sent = client.getResult()->message;
  const size_t blocks = wholeLines(expected).size();
  EXPECT_TRUE(control.waitForLog([&] { return blocksOf(mark.log(control)).size() >= blocks; }, 20)) << sent;
  EXPECT_EQ(expected, mark.received(control));
  EXPECT_EQ(wholeLines(expected), blocksOf(mark.log(control))) << sent;
  if (feed)
  {
    EXPECT_EQ(before + expected, feed->received(control)) << "something arrived between the feed and its restart";
  }
}
}  // namespace

/// Each test: the control and the node ready, the control's record so far marked, a feed sent.
class DncDripLink : public ::testing::Test
{
 protected:
  void startFeed()
  {
    ASSERT_TRUE(machine.ready(client, control));
    mark = std::make_unique<const Since>(control);
    client.sendGoal(Machine::feed());
  }

  Control control;
  Machine machine;
  Client client{machine.node() + "/transfer", true};
  std::unique_ptr<const Since> mark;  ///< what the control had before the feed
};

// First of the feeds: the simulator closes its pty after the 1200th character it received (the
// cable pulled; what the node had queued beyond it is lost) and makes a new one at the same link
// (plugged back in). The goal fails naming the port; the control executes the whole blocks it got
// and waits. The node opens the port for each transfer, so the restart goes over the new link.
TEST_F(DncDripLink, LinkLossFailsTheGoalNamingThePortLeavesTheControlWaitingAndTheRestartRunsOnTheNewLink)
{
  ASSERT_NO_FATAL_FAILURE(startFeed());
  ASSERT_TRUE(client.waitForResult(ros::Duration(60)));
  EXPECT_EQ(actionlib::SimpleClientGoalState::ABORTED, client.getState().state_);
  const auto result = client.getResult();
  EXPECT_NE(result->message.find(control.pty), std::string::npos) << result->message;

  // The link is gone: nothing more can arrive; the control executes its buffer and starves.
  ASSERT_TRUE(control.waitForLog([&] { return control.logEndsWith(kWaiting); }, 10));
  const std::string received = mark->received(control);
  EXPECT_EQ(1200u, received.size());
  expectAPrefixRunToItsLastWholeBlockThenWaiting(received, mark->log(control));
  // The node reports what it wrote, which is more than arrived: a restart goes by the control.
  EXPECT_GE(result->stopped_at_line, wholeLines(received).size());

  expectARestartAfterTheLastExecutedBlockRunsToTheEnd(machine, control);
}

// The node killed (SIGKILL: no shutdown, nothing more written) in the middle of a feed. What it
// had written reaches the control, nothing after; the control executes the whole blocks it got
// and waits. roslaunch starts the node again (respawn); it runs the restart.
TEST_F(DncDripLink, NodeDeathLeavesTheControlWaitingAfterTheBlocksItReceivedAndTheRespawnedNodeRunsTheRestart)
{
  ASSERT_NO_FATAL_FAILURE(startFeed());
  // By line 40 (some 900 characters) the control holds the feed: its DC3 goes at 512 buffered.
  const uint32_t sent = machine.waitForLine(40);
  ASSERT_GE(sent, 40u);
  const pid_t pid = process_kill::nodePid(machine.node());
  ASSERT_GT(pid, 0);
  ASSERT_EQ(0, ::kill(pid, SIGKILL));

  // A measurement window (that nothing more arrives needs a span of time): within it, what was on
  // its way arrives (the pty holds at most a few characters: the node paces its writes to the
  // line, and the control takes them at the line's rate). Then the control executes its buffer
  // and reports that it waits. That nothing more arrives after it is checked when the restart's
  // characters arrive on the same line: they follow what is received now, with nothing between.
  ros::WallDuration(0.5).sleep();  // window: what was on its way arrives
  ASSERT_TRUE(control.waitForLog([&] { return control.logEndsWith(kWaiting); }, 10));
  const std::string received = mark->received(control);
  const Lines log = mark->log(control);

  expectAPrefixRunToItsLastWholeBlockThenWaiting(received, log);
  // Every line the node reported sent before it died was on its way: it arrived whole.
  EXPECT_GE(wholeLines(received).size(), sent);

  ASSERT_TRUE(waitUntil(
      [&]
      {
        const pid_t now = process_kill::nodePid(machine.node());
        return now > 0 && now != pid;
      },
      30))
      << "no respawned node";
  expectARestartAfterTheLastExecutedBlockRunsToTheEnd(machine, control, mark.get(), received);
}

int main(int argc, char** argv)
{
  testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "test_dnc_drip_link");
  ros::NodeHandle("~").getParam("program", program_path);
  ros::AsyncSpinner spinner(2);
  spinner.start();
  return RUN_ALL_TESTS();
}
