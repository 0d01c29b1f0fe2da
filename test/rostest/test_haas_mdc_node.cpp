// haas_mdc_node against sim_haas_mdc (see haas_mdc_node.test): the state follows the scripted
// machine through idle, busy, feed hold and alarm; a cycle-end event carries the new part count;
// writes outside the allow-list are refused; raw queries are read-only; the link drops and comes
// back; all while a second MDC client on the same control receives (and causes) broadcast replies.
// The Classic (serial, STX/ETB framed) instance is checked for the same essentials.
#include <gtest/gtest.h>
#include <ros/ros.h>
#include <sensor_msgs/JointState.h>

#include <atomic>
#include <condition_variable>
#include <mutex>
#include <thread>

#include "cnc_bridge/CycleEvent.h"
#include "cnc_bridge/MachineState.h"
#include "cnc_bridge/MdcQuery.h"
#include "cnc_bridge/MdcReadVariable.h"
#include "cnc_bridge/MdcWriteVariable.h"
#include "cnc_bridge/common/error.h"
#include "cnc_bridge/transport/backoff.h"
#include "cnc_bridge/transport/tcp.h"

using cnc_bridge::CycleEvent;
using cnc_bridge::MachineState;

namespace
{
const std::string kNgc = "/cell/haas_ngc";
const std::string kClassic = "/cell/haas_classic";
constexpr double kInch = 0.0254;

// Everything the nodes publish, recorded from the start so no test misses a transition.
struct Recorder
{
  std::mutex mutex;
  std::condition_variable changed;
  std::vector<MachineState> ngc_states, classic_states;
  std::vector<CycleEvent> events;

  template <class Predicate>
  bool waitFor(Predicate predicate, double seconds)
  {
    std::unique_lock<std::mutex> lock(mutex);
    return changed.wait_for(lock, std::chrono::duration<double>(seconds), [&] { return predicate(); });
  }

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
  for (int attempt = 0; attempt < 5; ++attempt)
  {
    recorder->waitFor(
        [&]
        {
          const auto& states = classic ? recorder->classic_states : recorder->ngc_states;
          return !states.empty() && states.back().link == MachineState::LINK_UP;
        },
        15.0);
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
  EXPECT_TRUE(
      recorder->sawState([](const MachineState& s)
                         { return s.execution == MachineState::EXECUTION_ALARM && s.message == "Haas status ALARM"; },
                         20.0));
  // Tool 3 during the cycle, spindle at 8000 rpm.
  EXPECT_TRUE(recorder->sawState([](const MachineState& s) { return s.tool == 3 && s.spindle_speed == 8000.0; }, 20.0));
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
  // Busy 2 s + feed hold 0.5 s + busy 1 s in the script, seen through 0.25 s polls.
  EXPECT_NEAR(end.cycle_time, 3.5, 0.6);
  EXPECT_GE(end.header.stamp.toSec(), start.header.stamp.toSec() + 2.9);
}

TEST(HaasMdcNode, WritesOutsideTheAllowListAreRefused)
{
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

  // An allowed one goes through and reads back.
  write.request.variable = 100;
  write.request.value = 42.5;
  EXPECT_TRUE(callWhenUp(kNgc + "/haas_mdc_node/write_variable", write)) << write.response.message;
  cnc_bridge::MdcReadVariable read;
  read.request.variable = 100;
  ASSERT_TRUE(callWhenUp(kNgc + "/haas_mdc_node/read_variable", read)) << read.response.message;
  EXPECT_DOUBLE_EQ(read.response.value, 42.5);
}

TEST(HaasMdcNode, RawQueriesAreReadOnly)
{
  cnc_bridge::MdcQuery query;
  query.request.query = "?E100 1";
  ASSERT_TRUE(call(kNgc + "/haas_mdc_node/query", query));
  EXPECT_FALSE(query.response.success);
  EXPECT_NE(query.response.message.find("read-only"), std::string::npos);

  query.request.query = "?Q100";
  ASSERT_TRUE(callWhenUp(kNgc + "/haas_mdc_node/query", query)) << query.response.message;
  EXPECT_EQ(query.response.reply, "SERIAL NUMBER, 1234567");
}

TEST(HaasMdcNode, LinkLossAndReturn)
{
  // The script drops every connection once per loop: the link goes down, then up again.
  size_t down_at = 0;
  ASSERT_TRUE(recorder->waitFor(
      [&]
      {
        for (size_t i = 0; i < recorder->ngc_states.size(); ++i)
        {
          if (i > 0 && recorder->ngc_states[i - 1].link == MachineState::LINK_UP &&
              recorder->ngc_states[i].link != MachineState::LINK_UP)
          {
            down_at = i;
            return true;
          }
        }
        return false;
      },
      25.0));
  ASSERT_TRUE(recorder->waitFor(
      [&]
      {
        for (size_t i = down_at; i < recorder->ngc_states.size(); ++i)
        {
          const auto& s = recorder->ngc_states[i];
          if (s.link == MachineState::LINK_UP && s.execution != MachineState::EXECUTION_UNKNOWN)
            return true;
        }
        return false;
      },
      15.0));
  std::lock_guard<std::mutex> lock(recorder->mutex);
  EXPECT_EQ(recorder->ngc_states[down_at].execution, MachineState::EXECUTION_UNKNOWN);
  EXPECT_FALSE(recorder->ngc_states[down_at].position_valid);
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

int main(int argc, char** argv)
{
  testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "test_haas_mdc_node");
  ros::NodeHandle nh, pnh("~");
  pnh.param("tcp_port", sim_port, 15143);
  Recorder rec;
  recorder = &rec;
  auto record = [&](std::vector<MachineState>& into)
  {
    return [&](const MachineState::ConstPtr& s)
    {
      std::lock_guard<std::mutex> lock(rec.mutex);
      into.push_back(*s);
      rec.changed.notify_all();
    };
  };
  auto ngc = nh.subscribe<MachineState>(kNgc + "/state", 1000, record(rec.ngc_states));
  auto classic = nh.subscribe<MachineState>(kClassic + "/state", 1000, record(rec.classic_states));
  auto events = nh.subscribe<CycleEvent>(kNgc + "/events", 100,
                                         [&](const CycleEvent::ConstPtr& e)
                                         {
                                           std::lock_guard<std::mutex> lock(rec.mutex);
                                           rec.events.push_back(*e);
                                           rec.changed.notify_all();
                                         });
  ros::AsyncSpinner spinner(2);
  spinner.start();

  // The second MDC client of the control: polls on its own, so every reply it causes also reaches
  // the node, interleaved with the node's own replies. It reconnects after the script's drops.
  std::atomic<bool> done{false};
  std::thread other_client(
      [&]
      {
        const char* queries[] = {"?Q500\r\n", "?Q104\r\n", "?Q600 5022\r\n", "?Q201\r\n", "?Q999\r\n"};
        size_t n = 0;
        cnc_bridge::StopSignal pause;
        while (!done)
        {
          try
          {
            auto link = cnc_bridge::TcpConnection::connect("127.0.0.1", static_cast<uint16_t>(sim_port),
                                                           cnc_bridge::Milliseconds(1000));
            while (!done)
            {
              link->write(std::string(queries[n++ % 5]));
              uint8_t buffer[512];
              link->read(buffer, sizeof buffer, cnc_bridge::Milliseconds(50));
            }
          }
          catch (const cnc_bridge::Error&)
          {
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
