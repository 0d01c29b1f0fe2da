// haas_mdc_node against sim_haas_mdc (see haas_mdc_node.test): the state follows the scripted
// machine through idle, busy, feed hold and alarm; a cycle-end event carries the new part count;
// writes outside the allow-list are refused; raw queries are read-only; the link drops and comes
// back; all while a second MDC client on the same control receives (and causes) broadcast replies.
// The Classic (serial, STX/ETB framed) instance is checked for the same essentials.
#include <gtest/gtest.h>
#include <ros/ros.h>
#include <sensor_msgs/JointState.h>
#include <std_srvs/SetBool.h>

#include <diagnostic_msgs/DiagnosticArray.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <fstream>
#include <functional>
#include <map>
#include <mutex>
#include <optional>
#include <thread>

#include "cnc_bridge/CycleEvent.h"
#include "cnc_bridge/MachineState.h"
#include "cnc_bridge/MacroVariables.h"
#include "cnc_bridge/MdcQuery.h"
#include "cnc_bridge/MdcReadVariable.h"
#include "cnc_bridge/MdcWriteVariable.h"
#include "cnc_bridge/SendProgram.h"
#include "cnc_bridge/common/error.h"
#include "cnc_bridge/transport/backoff.h"
#include "cnc_bridge/transport/tcp.h"
#include "line_log.h"
#include "topic_watch.h"

using cnc_bridge::CycleEvent;
using cnc_bridge::MachineState;
using cnc_bridge::MacroVariables;

namespace
{
const std::string kNgc = "/cell/haas_ngc";
const std::string kClassic = "/cell/haas_classic";
constexpr double kInch = 0.0254;
std::string ngc_queries, classic_queries;  // what each simulated control received (--query-log)

std::vector<std::string> queriesReceived(const std::string& log)
{
  std::vector<std::string> lines;
  std::ifstream in(log);
  for (std::string line; std::getline(in, line);)
    lines.push_back(line);
  return lines;
}

// Waits until the control has received \p query after its first \p from queries.
bool waitForQuery(const std::string& log, const std::string& query, size_t from, double seconds = 10.0)
{
  // The simulator writes the log from another process: the file is all there is to wait on.
  return line_log::waitForFile(
      log,
      [&]
      {
        const auto lines = queriesReceived(log);
        return std::find(lines.begin() + static_cast<long>(std::min(from, lines.size())), lines.end(), query) !=
               lines.end();
      },
      seconds);
}

// The writes (?E...) a control received after its first \p from queries, once a status poll
// sent after this call has arrived: the node polls one query at a time over one connection, so
// a write it sent before that poll was received before it.
std::vector<std::string> writesReceivedSince(const std::string& log, size_t from)
{
  EXPECT_TRUE(waitForQuery(log, "?Q500", queriesReceived(log).size())) << "no status poll reached the control";
  std::vector<std::string> writes;
  const auto lines = queriesReceived(log);
  for (size_t i = from; i < lines.size(); ++i)
    if (lines[i].rfind("?E", 0) == 0)
      writes.push_back(lines[i]);
  return writes;
}

// One report of a node's `mdc` diagnostics task.
struct MdcDiagnostics
{
  ros::Time stamp;
  std::map<std::string, std::string> values;

  double number(const std::string& key) const
  {
    const auto it = values.find(key);
    return it == values.end() ? -1.0 : std::stod(it->second);
  }
};

// Everything the nodes publish, recorded from the start so no test misses a transition.
struct Recorder : topic_watch::Record
{
  std::vector<MachineState> ngc_states, classic_states;
  std::vector<CycleEvent> events;
  std::vector<MacroVariables> variables;  // the NGC node's `variables` topic
  std::vector<MdcDiagnostics> ngc_diagnostics, classic_diagnostics;

  bool sawState(const std::function<bool(const MachineState&)>& match, double seconds, bool classic = false)
  {
    return waitFor(
        [&]
        {
          const auto& states = classic ? classic_states : ngc_states;
          return std::any_of(states.begin(), states.end(), match);
        },
        seconds);
  }
};
Recorder* recorder = nullptr;
int sim_port = 0;
std::string program_dir;
std::atomic<bool> other_client_connected{false};

template <class Srv>
bool call(const std::string& name, Srv& srv)
{
  if (!ros::service::waitForService(name, ros::Duration(20.0)))
    return false;
  return ros::service::call(name, srv);
}

// Calls a service that needs the link; the script drops the link once per loop, so a call that
// fails for want of a link is repeated once the node reports the link up again.
template <class Srv>
bool callWhenUp(const std::string& name, Srv& srv, bool classic = false)
{
  auto& states = classic ? recorder->classic_states : recorder->ngc_states;
  size_t seen = 0;  // a retry waits for a state published after the failed call
  for (int attempt = 0; attempt < 5; ++attempt)
  {
    recorder->waitFor([&] { return states.size() > seen && states.back().link == MachineState::LINK_UP; }, 15.0);
    {
      std::lock_guard<std::mutex> lock(recorder->mutex);
      seen = states.size();
    }
    if (!call(name, srv))
      return false;
    if (srv.response.success)
      return true;
  }
  return false;
}
}  // namespace

TEST(HaasMdcNode, StateFollowsTheScriptedMachineThroughIdleBusyHoldAndAlarm)
{
  auto execution = [](uint8_t e) { return [e](const MachineState& s) { return s.execution == e; }; };
  // One 9 s loop of the script shows every state; allow two loops.
  EXPECT_TRUE(recorder->sawState(execution(MachineState::EXECUTION_READY), 20.0));
  EXPECT_TRUE(recorder->sawState(execution(MachineState::EXECUTION_ACTIVE), 20.0));
  EXPECT_TRUE(recorder->sawState(execution(MachineState::EXECUTION_PAUSED), 20.0));
  EXPECT_TRUE(recorder->sawState(execution(MachineState::EXECUTION_ALARM), 20.0));
  EXPECT_TRUE(recorder->sawState([](const MachineState& s) { return s.mode == MachineState::MODE_MDI; }, 20.0));
  EXPECT_TRUE(recorder->sawState(
      [](const MachineState& s)
      {
        return s.mode == MachineState::MODE_AUTO && s.program == "O00110" && s.part_count >= 4523 &&
               s.link == MachineState::LINK_UP && s.machine == "haas_ngc" && s.header.frame_id == "haas_ngc/machine";
      },
      20.0));
  // The alarm carries its Haas status in plain words.
  EXPECT_TRUE(recorder->sawState(
      [](const MachineState& s)
      { return s.execution == MachineState::EXECUTION_ALARM && s.message == "Haas status ALARM ON"; },
      20.0));
  // E-stop from the status: a status that is no alarm says it is released; an alarm that does not
  // name the e-stop leaves it unknown (a Haas in e-stop reports ALARM too).
  EXPECT_TRUE(
      recorder->sawState([](const MachineState& s)
                         { return s.execution == MachineState::EXECUTION_READY && s.estop == MachineState::ESTOP_OFF; },
                         20.0));
  EXPECT_TRUE(recorder->sawState(
      [](const MachineState& s)
      { return s.execution == MachineState::EXECUTION_ALARM && s.estop == MachineState::ESTOP_UNKNOWN; },
      20.0));
  EXPECT_FALSE(recorder->sawState(
      [](const MachineState& s)
      {
        return s.execution != MachineState::EXECUTION_ALARM && s.estop != MachineState::ESTOP_OFF &&
               s.link == MachineState::LINK_UP && s.execution != MachineState::EXECUTION_UNKNOWN;
      },
      0.0));
  // Tool 3 during the cycle, spindle at 8000 rpm.
  EXPECT_TRUE(recorder->sawState([](const MachineState& s) { return s.tool == 3 && s.spindle_speed == 8000.0; }, 20.0));
}

// ~watch_variables [500] on the `variables` topic: the script's program sets #500 to 1 when the
// part is done and back to 0 at the next loop. The topic follows it, publishes nothing while the
// value stays (three more polls of #500 reach the control and nothing new arrives), says NaN
// (not known) while the link is down, and never repeats the values it published last.
TEST(HaasMdcNode, VariablesTopicFollowsAVariableTheProgramSets)
{
  auto value_is = [](double v)
  {
    return [v](const MacroVariables& m)
    { return m.numbers == std::vector<uint32_t>{500} && m.values.size() == 1 && m.values[0] == v; };
  };
  auto unknown = [](const MacroVariables& m) { return m.values.size() == 1 && std::isnan(m.values[0]); };
  // Index of the first recorded message from \p from on that matches, once it arrived.
  auto await = [&](const std::function<bool(const MacroVariables&)>& match, size_t from) -> std::optional<size_t>
  {
    std::optional<size_t> found;
    recorder->waitFor(
        [&]
        {
          for (size_t i = from; i < recorder->variables.size(); ++i)
            if (match(recorder->variables[i]))
              return (found = i).has_value();
          return false;
        },
        25.0);
    return found;
  };
  // 0 (the part being cut), then 1 (done): one 9 s loop of the script, allow two.
  const auto zero = await(value_is(0.0), 0);
  ASSERT_TRUE(zero);
  const auto one = await(value_is(1.0), *zero + 1);
  ASSERT_TRUE(one);
  size_t polls = 0;
  {
    std::lock_guard<std::mutex> lock(recorder->mutex);
    const auto& m = recorder->variables[*one];
    EXPECT_EQ(m.machine, "haas_ngc");
    EXPECT_FALSE(m.header.stamp.isZero());
    for (size_t i = *zero + 1; i < *one; ++i)
      EXPECT_TRUE(unknown(recorder->variables[i]) || value_is(0.0)(recorder->variables[i]));
    polls = recorder->variables.size();
  }
  // Unchanged polls publish nothing: three more ?Q600 500 reach the control (one query at a time,
  // so the replies to the first two were handled), then two state messages as a barrier for
  // anything the node published before them; #500 stays 1 for 3 s, until the script's drop.
  const auto q600 = [] { return queriesReceived(ngc_queries); };
  size_t seen = 0;
  for (int more = 0; more < 3; ++more)
  {
    ASSERT_TRUE(waitForQuery(ngc_queries, "?Q600 500", q600().size()));
    ++seen;
  }
  size_t states = 0;
  {
    std::lock_guard<std::mutex> lock(recorder->mutex);
    states = recorder->ngc_states.size();
  }
  ASSERT_TRUE(recorder->waitFor([&] { return recorder->ngc_states.size() >= states + 2; }, 5.0));
  {
    std::lock_guard<std::mutex> lock(recorder->mutex);
    EXPECT_EQ(recorder->variables.size(), polls) << "published again without a change after " << seen << " polls";
  }
  // The script's drop: not known while the link is down; then 0 again on the next loop.
  const auto lost = await(unknown, *one + 1);
  ASSERT_TRUE(lost);
  ASSERT_TRUE(await(value_is(0.0), *lost + 1));
  std::lock_guard<std::mutex> lock(recorder->mutex);
  for (size_t i = 1; i < recorder->variables.size(); ++i)
  {
    const auto& a = recorder->variables[i - 1].values;
    const auto& b = recorder->variables[i].values;
    EXPECT_FALSE(a.size() == b.size() &&
                 (a == b || (unknown(recorder->variables[i - 1]) && unknown(recorder->variables[i]))))
        << "message " << i << " repeats the one before";
  }
}

TEST(HaasMdcNode, PositionsAreConvertedFromInchesToMetres)
{
  // The script moves X from 0 to 8 in (0.2032 m) and back; work zero is at X 5 in (0.127 m).
  EXPECT_TRUE(recorder->sawState([](const MachineState& s) { return s.position_valid && s.position.x > 0.15; }, 20.0));
  EXPECT_TRUE(recorder->sawState([](const MachineState& s) { return s.work_offset_valid; }, 20.0));
  std::lock_guard<std::mutex> lock(recorder->mutex);
  for (const auto& s : recorder->ngc_states)
  {
    if (!s.position_valid)
      continue;
    EXPECT_GE(s.position.x, -1e-9);
    EXPECT_LE(s.position.x, 8 * kInch + 1e-9);
    EXPECT_LE(s.position.z, 1e-9);
    EXPECT_GE(s.position.z, -3 * kInch - 1e-9);
    if (s.work_offset_valid)
    {
      EXPECT_NEAR(s.work_offset.x, 5 * kInch, 1e-6);
      EXPECT_NEAR(s.work_offset.y, 4 * kInch, 1e-6);
      EXPECT_NEAR(s.work_offset.z, -2 * kInch, 1e-6);
    }
  }
}

TEST(HaasMdcNode, JointStatesCarryTheAxesInMetres)
{
  const auto joints = ros::topic::waitForMessage<sensor_msgs::JointState>(kNgc + "/joint_states", ros::Duration(20.0));
  ASSERT_TRUE(joints);
  ASSERT_EQ(joints->name.size(), 3u);
  EXPECT_EQ(joints->name[0], "haas_ngc/x_axis");
  EXPECT_LE(joints->position[0], 8 * kInch + 1e-9);
}

TEST(HaasMdcNode, CycleEndEventArrivesWhenPartsIncrease)
{
  // A cycle seen from start to end (the node may have joined mid-cycle: that end has no start).
  CycleEvent start, end;
  ASSERT_TRUE(recorder->waitFor(
      [&]
      {
        bool started = false;
        for (const auto& e : recorder->events)
        {
          if (e.event == CycleEvent::CYCLE_START)
          {
            start = e;
            started = true;
          }
          else if (e.event == CycleEvent::CYCLE_END && started)
          {
            end = e;
            return true;
          }
        }
        return false;
      },
      25.0));
  EXPECT_EQ(end.machine, "haas_ngc");
  EXPECT_EQ(end.program, "O00110");
  EXPECT_GE(start.part_count, 4523);
  EXPECT_EQ(end.part_count, start.part_count + 1);
  // Busy 2 s + feed hold 0.5 s + busy 1 s in the script: the control (Q303) says 3 s, in whole seconds.
  EXPECT_DOUBLE_EQ(end.cycle_time, 3.0);
  EXPECT_NE(end.text.find("cycle time from the control"), std::string::npos) << end.text;
  EXPECT_GE(end.header.stamp.toSec(), start.header.stamp.toSec() + 2.9);
}

TEST(HaasMdcNode, WritesOutsideTheAllowListAreRefused)
{
  const size_t ngc_mark = queriesReceived(ngc_queries).size();
  const size_t classic_mark = queriesReceived(classic_queries).size();
  cnc_bridge::MdcWriteVariable write;
  write.request.variable = 5021;
  write.request.value = 1.0;
  ASSERT_TRUE(call(kNgc + "/haas_mdc_node/write_variable", write));
  EXPECT_FALSE(write.response.success);
  EXPECT_NE(write.response.message.find("writable_variables"), std::string::npos) << write.response.message;

  // The Classic instance has no allow-list: every write is refused.
  cnc_bridge::MdcWriteVariable classic;
  classic.request.variable = 100;
  classic.request.value = 1.0;
  ASSERT_TRUE(call(kClassic + "/haas_mdc_node/write_variable", classic));
  EXPECT_FALSE(classic.response.success);
  EXPECT_NE(classic.response.message.find("disabled"), std::string::npos) << classic.response.message;
  EXPECT_EQ(writesReceivedSince(ngc_queries, ngc_mark), std::vector<std::string>{})
      << "a refused write reached the NGC";
  EXPECT_EQ(writesReceivedSince(classic_queries, classic_mark), std::vector<std::string>{})
      << "a refused write reached the Classic control";

  // An allow-listed variable, but motion (which gates writes) is off by default: refused naming the
  // switch, and nothing reaches the control.
  const size_t disabled_mark = queriesReceived(ngc_queries).size();
  write.request.variable = 100;
  write.request.value = 42.5;
  ASSERT_TRUE(call(kNgc + "/haas_mdc_node/write_variable", write));
  EXPECT_FALSE(write.response.success);
  EXPECT_EQ(write.response.message, "write_variable refused: motion is disabled; enable it with " + kNgc +
                                        "/haas_mdc_node/set_motion_enabled (std_srvs/SetBool, data: true), or start "
                                        "the node with the parameter " +
                                        kNgc + "/haas_mdc_node/enable_motion true");
  EXPECT_EQ(writesReceivedSince(ngc_queries, disabled_mark), std::vector<std::string>{})
      << "a write reached the NGC while motion was disabled";
  std_srvs::SetBool enable;
  enable.request.data = true;
  ASSERT_TRUE(call(kNgc + "/haas_mdc_node/set_motion_enabled", enable));
  EXPECT_TRUE(enable.response.success);

  // Values the write cannot carry exactly are refused with the reason, not cut, rounded or zeroed.
  const size_t exact_mark = queriesReceived(ngc_queries).size();
  for (const double value : {1e300, 1e-7, 1.23456789, std::nan(""), HUGE_VAL, -HUGE_VAL})
  {
    write.request.value = value;
    ASSERT_TRUE(call(kNgc + "/haas_mdc_node/write_variable", write));
    EXPECT_FALSE(write.response.success) << value;
    EXPECT_NE(write.response.message.find("cannot be written exactly"), std::string::npos) << write.response.message;
  }
  EXPECT_EQ(writesReceivedSince(ngc_queries, exact_mark), std::vector<std::string>{})
      << "a value the write cannot carry reached the NGC";

  // An allowed one goes through and reads back.
  write.request.value = 42.5;
  EXPECT_TRUE(callWhenUp(kNgc + "/haas_mdc_node/write_variable", write)) << write.response.message;
  cnc_bridge::MdcReadVariable read;
  read.request.variable = 100;
  ASSERT_TRUE(callWhenUp(kNgc + "/haas_mdc_node/read_variable", read)) << read.response.message;
  EXPECT_DOUBLE_EQ(read.response.value, 42.5);
  // The answer says what unit the value is in (a length: the control's G20/G21, as polled).
  EXPECT_EQ(read.response.message.find("#100 = 42.5, as the control reports it: a length"), 0u)
      << read.response.message;
  EXPECT_TRUE(read.response.message.find("in inch (G20") != std::string::npos ||
              read.response.message.find("in mm (G21") != std::string::npos)
      << "the control's unit is polled (#4006): " << read.response.message;
  EXPECT_EQ(writesReceivedSince(ngc_queries, ngc_mark), std::vector<std::string>{"?E100 42.5"});
}

TEST(HaasMdcNode, RawQueriesAreReadOnly)
{
  const size_t mark = queriesReceived(ngc_queries).size();
  cnc_bridge::MdcQuery query;
  query.request.query = "?E100 1";
  ASSERT_TRUE(call(kNgc + "/haas_mdc_node/query", query));
  EXPECT_FALSE(query.response.success);
  EXPECT_NE(query.response.message.find("read-only"), std::string::npos);
  EXPECT_EQ(writesReceivedSince(ngc_queries, mark), std::vector<std::string>{})
      << "a refused raw write reached the NGC";

  query.request.query = "?Q100";
  ASSERT_TRUE(callWhenUp(kNgc + "/haas_mdc_node/query", query)) << query.response.message;
  EXPECT_EQ(query.response.reply, "SERIAL NUMBER, 1234567");
}

// Waits in \p states (one instance's recorded state) for the link to go from UP to not UP, then
// for it to be UP again with the machine followed; returns the state of the loss, or nothing.
std::optional<MachineState> waitForLinkLossAndReturn(const std::vector<MachineState>& states)
{
  size_t down_at = 0;
  const bool lost = recorder->waitFor(
      [&]
      {
        for (size_t i = 1; i < states.size(); ++i)
          if (states[i - 1].link == MachineState::LINK_UP && states[i].link != MachineState::LINK_UP)
          {
            down_at = i;
            return true;
          }
        return false;
      },
      25.0);
  EXPECT_TRUE(lost) << "the link never went down";
  const bool back = lost && recorder->waitFor(
                                [&]
                                {
                                  for (size_t i = down_at; i < states.size(); ++i)
                                    if (states[i].link == MachineState::LINK_UP &&
                                        states[i].execution != MachineState::EXECUTION_UNKNOWN)
                                      return true;
                                  return false;
                                },
                                15.0);
  EXPECT_TRUE(!lost || back) << "the link did not come back";
  if (!back)
    return std::nullopt;
  std::lock_guard<std::mutex> lock(recorder->mutex);
  return states[down_at];
}

TEST(HaasMdcNode, LinkLossAndReturn)
{
  // The script drops every connection once per loop: the link goes down, then up again.
  const auto lost = waitForLinkLossAndReturn(recorder->ngc_states);
  ASSERT_TRUE(lost);
  EXPECT_EQ(lost->execution, MachineState::EXECUTION_UNKNOWN);
  EXPECT_FALSE(lost->position_valid);
}

TEST(HaasMdcNode, ClassicSerialControlWithFramedRepliesIsFollowedToo)
{
  EXPECT_TRUE(recorder->sawState(
      [](const MachineState& s)
      {
        return s.link == MachineState::LINK_UP && s.execution == MachineState::EXECUTION_ACTIVE && s.position_valid &&
               s.program == "O00110";
      },
      25.0, true));
  cnc_bridge::MdcQuery query;
  query.request.query = "?Q102";
  ASSERT_TRUE(callWhenUp(kClassic + "/haas_mdc_node/query", query, true)) << query.response.message;
  EXPECT_EQ(query.response.reply, "MODEL, VF2D");
}

TEST(HaasMdcNode, DiagnosticsCountOtherClientsRepliesLatencyAndUnansweredQueries)
{
  // The test's second MDC client polls all the while: its replies reach the node too.
  MdcDiagnostics d;
  ASSERT_TRUE(recorder->waitFor(
      [&]
      {
        for (const auto& each : recorder->ngc_diagnostics)
          if (each.number("other clients' replies") > 0 && each.number("answered") > 0)
          {
            d = each;
            return true;
          }
        return false;
      },
      20.0));
  for (const char* key : {"latency last (ms)", "latency mean (ms)", "latency max (ms)", "unanswered", "queries sent"})
    ASSERT_TRUE(d.values.count(key)) << key;
  // Against a local simulator a reply takes well under the 1 s reply timeout.
  EXPECT_GT(d.number("latency mean (ms)"), 0.0);
  EXPECT_LT(d.number("latency mean (ms)"), 1000.0);
  EXPECT_GE(d.number("latency max (ms)"), d.number("latency mean (ms)"));
  EXPECT_LE(d.number("latency max (ms)"), 1000.0 + 100.0);
  // One query at a time: every query sent is answered, unanswered, or the one still waiting.
  EXPECT_LE(d.number("unanswered") + d.number("answered"), d.number("queries sent"));
  EXPECT_GE(d.number("unanswered") + d.number("answered") + 1, d.number("queries sent"));
}

TEST(HaasMdcNode, TheSimulatedControlRefusesAThirdConnection)
{
  // The node and the test's second client hold the control's two MDC connections; a third is
  // closed at once. A try counts only if both stayed connected throughout (the script drops every
  // connection once per loop, which also closes ours); otherwise it is repeated.
  bool refused = false;
  for (int attempt = 0; attempt < 10 && !refused; ++attempt)
  {
    recorder->waitFor(
        [&] { return !recorder->ngc_states.empty() && recorder->ngc_states.back().link == MachineState::LINK_UP; },
        15.0);
    size_t states_before;
    {
      std::lock_guard<std::mutex> lock(recorder->mutex);
      states_before = recorder->ngc_states.size();
    }
    if (!other_client_connected)
    {
      ros::Duration(0.2).sleep();  // poll: the other client's reconnect sets a flag, nothing to wait on
      continue;
    }
    bool closed = false;
    try
    {
      auto third = cnc_bridge::TcpConnection::connect("127.0.0.1", static_cast<uint16_t>(sim_port),
                                                      cnc_bridge::Milliseconds(1000));
      third->write(std::string("?Q100\r\n"));
      uint8_t buffer[256];
      // A reply would mean we were let in; a refused connection reads end-of-stream at once.
      for (int i = 0; i < 10; ++i)
        third->read(buffer, sizeof buffer, cnc_bridge::Milliseconds(100));
    }
    catch (const cnc_bridge::LinkError&)
    {
      closed = true;
    }
    // The window is closed by the node's own traffic, not by a pause: two status polls of the node
    // reach the control after the attempt, then a state published after them reaches the test. A
    // drop the node noticed meanwhile was published before that state (one publisher, in order).
    const size_t queries_after_attempt = queriesReceived(ngc_queries).size();
    ASSERT_TRUE(waitForQuery(ngc_queries, "?Q500", queries_after_attempt)) << "the node stopped polling";
    ASSERT_TRUE(waitForQuery(ngc_queries, "?Q500", queriesReceived(ngc_queries).size())) << "the node stopped polling";
    size_t states_after_polls;
    {
      std::lock_guard<std::mutex> lock(recorder->mutex);
      states_after_polls = recorder->ngc_states.size();
    }
    ASSERT_TRUE(recorder->waitFor([&] { return recorder->ngc_states.size() > states_after_polls; }, 10.0));
    bool node_kept_its_link = true;
    {
      std::lock_guard<std::mutex> lock(recorder->mutex);
      for (size_t i = states_before; i < recorder->ngc_states.size(); ++i)
        if (recorder->ngc_states[i].link != MachineState::LINK_UP)
          node_kept_its_link = false;
    }
    refused = closed && node_kept_its_link && other_client_connected;
  }
  EXPECT_TRUE(refused);
}

TEST(HaasMdcNode, SerialLinkLossAndReturn)
{
  // The script's 1 s line outage: no replies, so the Classic instance (0.2 s reply timeout, 2
  // unanswered in a row) declares the link down, reopens the port and follows the machine again.
  const auto lost = waitForLinkLossAndReturn(recorder->classic_states);
  ASSERT_TRUE(lost);
  EXPECT_EQ(lost->execution, MachineState::EXECUTION_UNKNOWN);
}

TEST(HaasMdcNode, ADncTransferOnTheSharedSerialLineSilencesThePoller)
{
  // dnc_node sends a program on the Classic instance's line; the simulator never asks for it, so
  // the send holds the port lock for its 4 s start wait and then fails. Meanwhile haas_mdc_node
  // must not send one query; afterwards it polls again, its settings reapplied.
  {
    std::ofstream program(program_dir + "/O01000.nc");
    program << "%\nO01000\nG00 X0\nM30\n%\n";
  }
  cnc_bridge::SendProgram send;
  send.request.file = "O01000.nc";
  const std::string service = kClassic + "/dnc/dnc_node/send_program";
  ASSERT_TRUE(ros::service::waitForService(service, ros::Duration(20.0)));
  // Not during the script's line outage (the poller is then reopening the port): wait for polls.
  ASSERT_TRUE(
      recorder->sawState([](const MachineState& s)
                         { return s.link == MachineState::LINK_UP && s.execution != MachineState::EXECUTION_UNKNOWN; },
                         20.0, true));
  const ros::Time started = ros::Time::now();
  ASSERT_TRUE(ros::service::call(service, send));
  const ros::Time ended = ros::Time::now();
  EXPECT_FALSE(send.response.success);  // no receiver
  // It got the port: the poller let go of it between two queries.
  EXPECT_EQ(send.response.message.find("in use by another process"), std::string::npos) << send.response.message;
  EXPECT_GE((ended - started).toSec(), 3.5);

  // The diagnostics reported while the transfer held the line (after at most one query in flight
  // and the 20 ms retry of the lock) show no query sent.
  MdcDiagnostics after;
  ASSERT_TRUE(recorder->waitFor(
      [&]
      {
        for (const auto& d : recorder->classic_diagnostics)
          if (d.stamp > ended && d.number("port regained after a DNC transfer") >= 1)
          {
            after = d;
            return true;
          }
        return false;
      },
      20.0));
  EXPECT_GT(after.number("polls skipped for a DNC transfer"), 0.0);
  std::lock_guard<std::mutex> lock(recorder->mutex);
  std::vector<double> sent_during;
  for (const auto& d : recorder->classic_diagnostics)
    if (d.stamp > started + ros::Duration(0.5) && d.stamp < ended - ros::Duration(0.1))
      sent_during.push_back(d.number("queries sent"));
  ASSERT_GE(sent_during.size(), 2u);
  EXPECT_EQ(sent_during.front(), sent_during.back());
  EXPECT_GT(after.number("queries sent"), sent_during.back());  // polling again
}

int main(int argc, char** argv)
{
  testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "test_haas_mdc_node");
  ros::NodeHandle nh, pnh("~");
  pnh.param("tcp_port", sim_port, 15143);
  pnh.param<std::string>("program_dir", program_dir, "/tmp");
  pnh.param<std::string>("ngc_queries", ngc_queries, "");
  pnh.param<std::string>("classic_queries", classic_queries, "");
  Recorder rec;
  recorder = &rec;
  auto ngc = nh.subscribe<MachineState>(kNgc + "/state", 1000, rec.appendTo(rec.ngc_states));
  auto classic = nh.subscribe<MachineState>(kClassic + "/state", 1000, rec.appendTo(rec.classic_states));
  auto events = nh.subscribe<CycleEvent>(kNgc + "/events", 100, rec.appendTo(rec.events));
  auto variables = nh.subscribe<MacroVariables>(kNgc + "/variables", 100, rec.appendTo(rec.variables));
  auto diagnostics = nh.subscribe<diagnostic_msgs::DiagnosticArray>(
      "/diagnostics", 100,
      [&](const diagnostic_msgs::DiagnosticArray::ConstPtr& array)
      {
        for (const auto& status : array->status)
        {
          const bool ngc = status.name.find("haas_ngc/haas_mdc_node") != std::string::npos;
          const bool classic = status.name.find("haas_classic/haas_mdc_node") != std::string::npos;
          if ((!ngc && !classic) || status.name.find(": mdc") == std::string::npos)
            continue;
          MdcDiagnostics d;
          d.stamp = array->header.stamp;
          for (const auto& kv : status.values)
            d.values[kv.key] = kv.value;
          rec.update([&] { (ngc ? rec.ngc_diagnostics : rec.classic_diagnostics).push_back(d); });
        }
      });
  ros::AsyncSpinner spinner(2);
  spinner.start();

  // The second MDC client of the control: polls on its own, so every reply it causes also reaches
  // the node, interleaved with the node's own replies. It reconnects after the script's drops.
  std::atomic<bool> done{false};
  std::thread other_client(
      [&]
      {
        // No Q600: an NGC control's macro reply names no variable, so a second client reading
        // variables makes every client's readings ambiguous (docs/haas_mdc_node.md).
        const char* queries[] = {"?Q500\r\n", "?Q104\r\n", "?Q303\r\n", "?Q201\r\n", "?Q999\r\n"};
        size_t n = 0;
        cnc_bridge::StopSignal pause;
        while (!done)
        {
          try
          {
            auto link = cnc_bridge::TcpConnection::connect("127.0.0.1", static_cast<uint16_t>(sim_port),
                                                           cnc_bridge::Milliseconds(1000));
            // Connected means answered: a third connection is accepted and then closed at once.
            link->write(std::string("?Q100\r\n"));
            uint8_t first[512];
            link->read(first, sizeof first, cnc_bridge::Milliseconds(1000));
            other_client_connected = true;
            while (!done)
            {
              link->write(std::string(queries[n++ % 5]));
              uint8_t buffer[512];
              link->read(buffer, sizeof buffer, cnc_bridge::Milliseconds(50));
            }
          }
          catch (const cnc_bridge::Error&)
          {
            other_client_connected = false;
            pause.waitFor(cnc_bridge::Milliseconds(100));  // connection refused or dropped: retry
          }
        }
      });
  const int result = RUN_ALL_TESTS();
  done = true;
  other_client.join();
  spinner.stop();
  return result;
}
