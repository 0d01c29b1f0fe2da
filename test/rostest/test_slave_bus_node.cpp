// slave_bus_node against sim_slave_bus (see slave_bus_node.test): one step frame moves the three
// simulated axes and fires the laser; each slave's answer arrives on its own topic, in metres for
// the axes; state, joint_states and tf follow; per-slave commands travel in one frame; diagnostics
// count frames, and per slave payloads, replies and the master's status 3 and 4; with motion
// disabled, axis commands are refused while generic slaves still answer; the library's CRC and
// frame size on the framed link.
#include <diagnostic_msgs/DiagnosticArray.h>
#include <gtest/gtest.h>
#include <ros/ros.h>
#include <sensor_msgs/JointState.h>
#include <std_srvs/SetBool.h>
#include <tf2_ros/buffer.h>
#include <tf2_ros/transform_listener.h>

#include <algorithm>
#include <map>
#include <mutex>

#include "cnc_bridge/BusFrame.h"
#include "cnc_bridge/MachineState.h"
#include "cnc_bridge/SlaveCommand.h"
#include "cnc_bridge/SlaveResponse.h"
#include "topic_watch.h"

namespace
{
const ros::WallDuration kWait(20.0);  // generous for a loaded CI box; healthy replies take ms

/// Collects every SlaveResponse of some slaves and lets the test wait for a condition on them.
class Responses
{
 public:
  Responses(const std::string& ns, const std::vector<std::string>& names)
  {
    ros::NodeHandle nh;
    for (const auto& name : names)
    {
      subs_.push_back(nh.subscribe<cnc_bridge::SlaveResponse>(ns + "/slaves/" + name + "/response", 100,
                                                              record_.appendTo(received_[name])));
    }
    // A reply published before its subscription is connected is lost: the tests trigger replies at
    // once, so wait until the node's publishers are connected.
    const auto deadline = ros::WallTime::now() + kWait;
    while (!connected() && ros::WallTime::now() < deadline)
    {
      ros::WallDuration(0.01).sleep();  // polling the connection count: roscpp offers no wait for it
    }
    EXPECT_TRUE(connected()) << ns << ": response topics have no publisher";
  }
  bool connected() const
  {
    return std::all_of(subs_.begin(), subs_.end(), [](const ros::Subscriber& s) { return s.getNumPublishers() > 0; });
  }
  /// Waits until \p pred holds on the responses so far.
  bool waitFor(const std::function<bool(std::map<std::string, std::vector<cnc_bridge::SlaveResponse>>&)>& pred)
  {
    return record_.waitFor([&] { return pred(received_); }, kWait.toSec());
  }
  std::vector<cnc_bridge::SlaveResponse> of(const std::string& name)
  {
    std::lock_guard<std::mutex> lock(record_.mutex);
    return received_[name];
  }

 private:
  topic_watch::Record record_;
  std::map<std::string, std::vector<cnc_bridge::SlaveResponse>> received_;
  std::vector<ros::Subscriber> subs_;  // last: unsubscribed before what the callbacks fill goes
};

template <class M>
ros::Publisher advertiseAndWait(const std::string& topic)
{
  auto pub = topic_watch::advertiseAndWait<M>(topic, kWait.toSec());
  EXPECT_GT(pub.getNumSubscribers(), 0u) << topic;
  return pub;
}

cnc_bridge::BusPayload payload(uint8_t address, std::vector<uint8_t> data)
{
  cnc_bridge::BusPayload p;
  p.address = address;
  p.data = std::move(data);
  return p;
}

/// The latest value of every key of every diagnostics status, from one subscription kept for the
/// whole test (three nodes publish on /diagnostics; a fresh subscription per check could keep
/// catching the others' messages).
class DiagnosticsWatch
{
 public:
  DiagnosticsWatch()
  {
    sub_ = ros::NodeHandle().subscribe<diagnostic_msgs::DiagnosticArray>(
        "/diagnostics", 100,
        [this](const diagnostic_msgs::DiagnosticArray::ConstPtr& msg)
        {
          record_.update(
              [&]
              {
                for (const auto& status : msg->status)
                {
                  for (const auto& kv : status.values)
                  {
                    values_[status.name][kv.key] = kv.value;
                  }
                }
              });
        });
  }
  using Values = std::map<std::string, std::string>;

  /// Waits until a status whose name contains \p name has values satisfying \p pred (all values of
  /// one status come from one message, so they are consistent with each other); copies them to \p out.
  bool waitForStatus(const std::string& name, const std::function<bool(const Values&)>& pred, Values* out = nullptr)
  {
    return record_.waitFor(
        [&]
        {
          for (const auto& status : values_)
          {
            if (status.first.find(name) != std::string::npos && pred(status.second))
            {
              if (out)
              {
                *out = status.second;
              }
              return true;
            }
          }
          return false;
        },
        kWait.toSec());
  }

  /// Waits until a status whose name contains \p name has key \p key with a numeric value satisfying \p pred.
  bool waitFor(const std::string& name, const std::string& key, const std::function<bool(double)>& pred)
  {
    return record_.waitFor(
        [&]
        {
          // Status names carry the node's namespace: "cell/laser1/slave_bus_node: slave bus".
          for (const auto& status : values_)
          {
            const auto value = status.second.find(key);
            if (status.first.find(name) != std::string::npos && value != status.second.end() &&
                pred(std::stod(value->second)))
            {
              return true;
            }
          }
          return false;
        },
        kWait.toSec());
  }

 private:
  topic_watch::Record record_;
  std::map<std::string, std::map<std::string, std::string>> values_;
  ros::Subscriber sub_;  // last: unsubscribed before what the callback fills goes
};

DiagnosticsWatch* diagnostics = nullptr;

bool waitForDiagnostic(const std::string& name, const std::string& key, const std::function<bool(double)>& pred)
{
  return diagnostics->waitFor(name, key, pred);
}

/// A numeric diagnostics value, or -1 if the key is missing.
double number(const DiagnosticsWatch::Values& values, const std::string& key)
{
  const auto found = values.find(key);
  return found == values.end() ? -1.0 : std::stod(found->second);
}

const std::string kLaser1Status = "laser1/slave_bus_node: slave bus";
/// Step frames the tests have made laser1's node send so far (each waited for its answers).
int laser1_frames = 0;
}  // namespace

TEST(SlaveBusNode, OneStepFrameMovesTheAxesAndAnswersArriveOnTheRightTopics)
{
  Responses responses("/cell/laser1", {"x", "y", "z", "laser", "aux6"});
  auto pub = advertiseAndWait<cnc_bridge::BusFrame>("/cell/laser1/bus/frame");
  // be16s device units at 10000 per metre: x 1234 = 0.1234 m, y -500 = -0.05 m, z 100 = 0.01 m.
  cnc_bridge::BusFrame frame;
  frame.payloads = {payload(1, {0x04, 0xD2}), payload(2, {0xFE, 0x0C}), payload(3, {0x00, 0x64}), payload(4, {1}),
                    payload(6, {42, 43})};
  pub.publish(frame);
  ASSERT_TRUE(responses.waitFor(
      [](auto& r)
      { return !r["x"].empty() && !r["y"].empty() && !r["z"].empty() && !r["laser"].empty() && !r["aux6"].empty(); }));
  ++laser1_frames;
  const auto x = responses.of("x").back();
  EXPECT_EQ(x.address, 1);
  EXPECT_EQ(x.name, "x");
  EXPECT_EQ(x.data, (std::vector<uint8_t>{0x04, 0xD2}));  // the simulated axis reports where it went
  ASSERT_EQ(x.values.size(), 1u);
  EXPECT_NEAR(x.values[0], 0.1234, 1e-9);
  EXPECT_NEAR(responses.of("y").back().values.at(0), -0.05, 1e-9);
  EXPECT_NEAR(responses.of("z").back().values.at(0), 0.01, 1e-9);
  EXPECT_EQ(responses.of("laser").back().values, std::vector<double>{1.0});     // the tool is on
  EXPECT_EQ(responses.of("aux6").back().data, (std::vector<uint8_t>{42, 43}));  // generic slaves echo
  EXPECT_GT(x.header.stamp.toSec(), 0.0);

  // state, joint_states and tf follow the axes (metres, machine frame, with the tf prefix).
  const auto deadline = ros::WallTime::now() + kWait;
  cnc_bridge::MachineState::ConstPtr state;
  while (ros::WallTime::now() < deadline)
  {
    state = ros::topic::waitForMessage<cnc_bridge::MachineState>("/cell/laser1/state", ros::Duration(5.0));
    if (state && state->position_valid && std::fabs(state->position.x - 0.1234) < 1e-9)
    {
      break;
    }
  }
  ASSERT_TRUE(state);
  EXPECT_TRUE(state->position_valid);
  EXPECT_EQ(state->machine, "laser1");
  EXPECT_EQ(state->link, cnc_bridge::MachineState::LINK_UP);
  EXPECT_NEAR(state->position.y, -0.05, 1e-9);
  EXPECT_NEAR(state->position.z, 0.01, 1e-9);

  const auto joints =
      ros::topic::waitForMessage<sensor_msgs::JointState>("/cell/laser1/joint_states", ros::Duration(kWait.toSec()));
  ASSERT_TRUE(joints);
  ASSERT_EQ(joints->name.size(), 3u);
  EXPECT_EQ(joints->name[0], "laser1/x_axis");
  EXPECT_NEAR(joints->position[0], 0.1234, 1e-9);

  tf2_ros::Buffer buffer;
  tf2_ros::TransformListener listener(buffer);
  const auto tf = buffer.lookupTransform("laser1/machine", "laser1/tool", ros::Time(0), ros::Duration(kWait.toSec()));
  EXPECT_NEAR(tf.transform.translation.x, 0.1234, 1e-9);
  EXPECT_NEAR(tf.transform.translation.y, -0.05, 1e-9);
}

TEST(SlaveBusNode, PerSlaveCommandsAreQueuedIntoTheNextFrame)
{
  // The counters once every earlier frame to laser1 is accounted for (one diagnostics message).
  DiagnosticsWatch::Values before;
  ASSERT_TRUE(diagnostics->waitForStatus(
      kLaser1Status, [](const DiagnosticsWatch::Values& v) { return number(v, "frames sent") == laser1_frames; },
      &before));
  Responses responses("/cell/laser1", {"x", "laser", "aux7"});
  auto x = advertiseAndWait<cnc_bridge::SlaveCommand>("/cell/laser1/slaves/x/command");
  auto laser = advertiseAndWait<cnc_bridge::SlaveCommand>("/cell/laser1/slaves/laser/command");
  auto aux7 = advertiseAndWait<cnc_bridge::SlaveCommand>("/cell/laser1/slaves/aux7/command");
  cnc_bridge::SlaveCommand cmd;
  cmd.values = {-0.25};  // m
  x.publish(cmd);
  cmd.values = {0};  // laser off
  laser.publish(cmd);
  cmd.values = {1234};  // aux7 takes the universal-CNC paper's hi*100+lo form
  aux7.publish(cmd);
  ASSERT_TRUE(responses.waitFor(
      [](auto& r)
      {
        return !r["x"].empty() && std::fabs(r["x"].back().values.at(0) + 0.25) < 1e-9 && !r["laser"].empty() &&
               r["laser"].back().values == std::vector<double>{0.0} && !r["aux7"].empty();
      }));
  EXPECT_EQ(responses.of("x").back().data, (std::vector<uint8_t>{0xF6, 0x3C}));  // -2500 be16s
  EXPECT_EQ(responses.of("aux7").back().data, (std::vector<uint8_t>{12, 34}));
  EXPECT_EQ(responses.of("aux7").back().values, std::vector<double>{1234.0});

  // The three commands went out in ONE frame (laser1's ~command_delay is 0.3 s in the test launch).
  DiagnosticsWatch::Values after;
  ASSERT_TRUE(diagnostics->waitForStatus(
      kLaser1Status,
      [&](const DiagnosticsWatch::Values& v)
      {
        return number(v, "x: payloads sent") == number(before, "x: payloads sent") + 1 &&
               number(v, "laser: payloads sent") == number(before, "laser: payloads sent") + 1 &&
               number(v, "aux7: payloads sent") == number(before, "aux7: payloads sent") + 1;
      },
      &after));
  EXPECT_EQ(number(after, "frames sent") - number(before, "frames sent"), 1.0);
  ++laser1_frames;
}

TEST(SlaveBusNode, MasterStatusThreeAndFourAreCountedAgainstTheirSlave)
{
  // sim_laser1's I2C frames carry at most 8 bytes (--max-payload 8) and slave 8's answers fail the
  // master's CRC check (--noisy-slave 8): aux6's 9 bytes come back as status 4, aux8's answer as
  // status 3, each counted against that slave; aux5 answers as usual.
  Responses responses("/cell/laser1", {"aux5"});
  auto pub = advertiseAndWait<cnc_bridge::BusFrame>("/cell/laser1/bus/frame");
  cnc_bridge::BusFrame frame;
  frame.payloads = {payload(5, {5}), payload(6, std::vector<uint8_t>(9, 6)), payload(8, {8})};
  pub.publish(frame);
  ASSERT_TRUE(responses.waitFor([](auto& r) { return !r["aux5"].empty(); }));
  DiagnosticsWatch::Values v;
  ASSERT_TRUE(diagnostics->waitForStatus(
      kLaser1Status,
      [](const DiagnosticsWatch::Values& v) {
        return number(v, "aux6: payloads too long (status 4)") >= 1 && number(v, "aux8: failed reads (status 3)") >= 1;
      },
      &v));
  EXPECT_EQ(number(v, "aux6: payloads too long (status 4)"), 1.0);
  EXPECT_EQ(number(v, "aux8: failed reads (status 3)"), 1.0);
  EXPECT_EQ(number(v, "aux5: failed reads (status 3)"), 0.0);
  EXPECT_GE(number(v, "aux6: payloads sent"), 2.0);  // the first test's two bytes, and these nine
  EXPECT_EQ(number(v, "slave reads that failed (master status 3)"), 1.0);
  EXPECT_EQ(number(v, "payloads too long for the master (status 4)"), 1.0);
  ++laser1_frames;
}

TEST(SlaveBusNode, DiagnosticsCountFramesAndReplies)
{
  // The tests above sent frames; diagnostics report them (published by a timer).
  auto pub = advertiseAndWait<cnc_bridge::BusFrame>("/cell/laser1/bus/frame");
  cnc_bridge::BusFrame frame;
  frame.payloads = {payload(5, {1})};
  pub.publish(frame);
  EXPECT_TRUE(waitForDiagnostic(kLaser1Status, "frames sent", [](double v) { return v >= 1; }));
  EXPECT_TRUE(waitForDiagnostic(kLaser1Status, "replies", [](double v) { return v >= 1; }));
  // Per slave: aux5 got this payload (and it answered).
  EXPECT_TRUE(waitForDiagnostic(kLaser1Status, "aux5: payloads sent", [](double v) { return v >= 1; }));
  EXPECT_TRUE(waitForDiagnostic(kLaser1Status, "aux5: replies", [](double v) { return v >= 1; }));
}

TEST(SlaveBusNode, MotionDisabledRefusesAxesButGenericSlavesAnswerOverTheFramedLink)
{
  Responses responses("/cell/laser2", {"x", "aux5"});
  auto x = advertiseAndWait<cnc_bridge::SlaveCommand>("/cell/laser2/slaves/x/command");
  auto aux5 = advertiseAndWait<cnc_bridge::SlaveCommand>("/cell/laser2/slaves/aux5/command");
  auto frames = advertiseAndWait<cnc_bridge::BusFrame>("/cell/laser2/bus/frame");
  cnc_bridge::SlaveCommand cmd;
  cmd.values = {0.1};
  x.publish(cmd);
  cnc_bridge::BusFrame frame;
  frame.payloads = {payload(1, {0, 1})};  // a raw payload to the axis: refused too
  frames.publish(frame);
  ASSERT_TRUE(waitForDiagnostic("laser2/slave_bus_node: slave bus", "refused inputs", [](double v) { return v >= 2; }));
  cmd.values.clear();
  cmd.data = {7, 8, 9};
  aux5.publish(cmd);
  ASSERT_TRUE(responses.waitFor([](auto& r) { return !r["aux5"].empty(); }));
  EXPECT_EQ(responses.of("aux5").back().data, (std::vector<uint8_t>{7, 8, 9}));
  EXPECT_TRUE(responses.of("x").empty());  // the axis never got a payload, so it never answered
  // Per slave: the axis got nothing, aux5 one payload.
  EXPECT_TRUE(
      waitForDiagnostic("laser2/slave_bus_node: slave bus", "aux5: payloads sent", [](double v) { return v == 1; }));
  EXPECT_TRUE(
      waitForDiagnostic("laser2/slave_bus_node: slave bus", "x: payloads sent", [](double v) { return v == 0; }));
}

// Motion switched at run time (~set_motion_enabled): on, an axis command reaches the simulated
// master and its slave answers; off again, the next one is refused and the master gets nothing
// more for the axis, while a generic slave's command still goes out.
TEST(SlaveBusNode, MotionSwitchedOffAtRunTimeRefusesTheNextAxisCommand)
{
  const std::string node = "/cell/laser2/slave_bus_node";
  const std::string status = "laser2/slave_bus_node: slave bus";
  Responses responses("/cell/laser2", {"x", "aux5"});
  auto x = advertiseAndWait<cnc_bridge::SlaveCommand>("/cell/laser2/slaves/x/command");
  auto aux5 = advertiseAndWait<cnc_bridge::SlaveCommand>("/cell/laser2/slaves/aux5/command");
  std_srvs::SetBool enable;
  enable.request.data = true;
  ASSERT_TRUE(ros::service::call(node + "/set_motion_enabled", enable));
  EXPECT_TRUE(enable.response.success) << enable.response.message;
  cnc_bridge::SlaveCommand cmd;
  cmd.values = {0.02};
  x.publish(cmd);
  ASSERT_TRUE(responses.waitFor([](auto& r) { return !r["x"].empty(); }));
  ASSERT_TRUE(waitForDiagnostic(status, "x: payloads sent", [](double v) { return v == 1; }));

  enable.request.data = false;
  ASSERT_TRUE(ros::service::call(node + "/set_motion_enabled", enable));
  DiagnosticsWatch::Values before;
  ASSERT_TRUE(diagnostics->waitForStatus(
      status,
      [](const DiagnosticsWatch::Values& v)
      {
        const auto found = v.find("motion enabled");
        return found != v.end() && found->second == "False";
      },
      &before));
  cmd.values = {0.03};
  x.publish(cmd);
  cnc_bridge::SlaveCommand lamp;
  lamp.data = {1};
  aux5.publish(lamp);  // sent after the refused axis command: once it is answered, x would have been too
  ASSERT_TRUE(waitForDiagnostic(status, "aux5: payloads sent",
                                [&](double v) { return v == number(before, "aux5: payloads sent") + 1; }));
  ASSERT_TRUE(
      waitForDiagnostic(status, "refused inputs", [&](double v) { return v == number(before, "refused inputs") + 1; }));
  EXPECT_TRUE(waitForDiagnostic(status, "x: payloads sent", [](double v) { return v == 1; }));
  EXPECT_EQ(responses.of("x").size(), 1u);
}

TEST(SlaveBusNode, LibraryCrcLinkRefusesPayloadsOverTheLibrarysFrameSize)
{
  // laser2 and its simulator speak the library's CRC (data only) on the framed link; its frames
  // carry at most 124 data bytes (the library's 128-byte buffers): a 125-byte payload is refused
  // by the node, a 100-byte one (a 109-byte framed step) goes out and is echoed (first 32 bytes).
  Responses responses("/cell/laser2", {"aux6"});
  auto aux6 = advertiseAndWait<cnc_bridge::SlaveCommand>("/cell/laser2/slaves/aux6/command");
  const std::string status = "laser2/slave_bus_node: slave bus";
  DiagnosticsWatch::Values before;
  ASSERT_TRUE(diagnostics->waitForStatus(
      status, [](const DiagnosticsWatch::Values& v) { return number(v, "refused inputs") >= 0; }, &before));
  cnc_bridge::SlaveCommand cmd;
  cmd.data.assign(125, 0x11);
  aux6.publish(cmd);
  ASSERT_TRUE(
      waitForDiagnostic(status, "refused inputs", [&](double v) { return v >= number(before, "refused inputs") + 1; }));
  cmd.data.assign(100, 0x22);
  aux6.publish(cmd);
  ASSERT_TRUE(responses.waitFor([](auto& r) { return !r["aux6"].empty(); }));
  EXPECT_EQ(responses.of("aux6").size(), 1u);
  EXPECT_EQ(responses.of("aux6").back().data, std::vector<uint8_t>(32, 0x22));
  EXPECT_TRUE(waitForDiagnostic(status, "aux6: payloads sent", [](double v) { return v == 1; }));
}

TEST(SlaveBusNode, CorruptedAnswersAreCountedAsCrcErrorsAndTimeoutsPerSlave)
{
  // sim_laser3 changes one byte of every second uplink write: of four one-slave steps, two answers
  // arrive and two fail the CRC, so slave aux5 times out twice.
  Responses responses("/cell/laser3", {"aux5"});
  auto pub = advertiseAndWait<cnc_bridge::BusFrame>("/cell/laser3/bus/frame");
  cnc_bridge::BusFrame frame;
  for (uint8_t i = 0; i < 4; ++i)
  {
    frame.payloads = {payload(5, {i})};
    pub.publish(frame);
  }
  const std::string status = "laser3/slave_bus_node: slave bus";
  EXPECT_TRUE(waitForDiagnostic(status, "uplink CRC errors", [](double v) { return v >= 2; }));
  EXPECT_TRUE(waitForDiagnostic(status, "timeouts", [](double v) { return v >= 2; }));
  ASSERT_TRUE(responses.waitFor([](auto& r) { return r["aux5"].size() >= 2; }));
  const auto got = responses.of("aux5");
  EXPECT_EQ(got.size(), 2u);
  EXPECT_EQ(got[0].data, std::vector<uint8_t>{0});  // steps 0 and 2 got through; 1 and 3 were corrupted
  EXPECT_EQ(got[1].data, std::vector<uint8_t>{2});
}

int main(int argc, char** argv)
{
  testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "test_slave_bus_node");
  ros::AsyncSpinner spinner(2);
  spinner.start();
  DiagnosticsWatch watch;
  diagnostics = &watch;
  return RUN_ALL_TESTS();
}
