// BusRunner without ROS: the runner opens a pty through the link factory, a SimMaster serves the
// other side in its own thread, and a recording listener stands in for the node. Every wait is a
// condition variable with a deadline; nothing sleeps.
#include <gtest/gtest.h>

#include <condition_variable>
#include <mutex>
#include <thread>

#include "cnc_bridge/common/error.h"
#include "cnc_bridge/common/safety_switch.h"
#include "cnc_bridge/slave_bus/bus_runner.h"
#include "sim/slave_bus/sim_master.h"
#include "testing/pty.h"

using namespace cnc_bridge;
using namespace cnc_bridge::slave_bus;
using namespace std::chrono_literals;

namespace
{
/// x axis at 1 (1 unit = 1 mm), a tool at 2, a generic slave at 3.
SlaveTable threeSlaves()
{
  std::vector<SlaveConfig> slaves = {{1, "x", Role::kAxisX, Encoding::kBigEndian16s, 1000.0},
                                     {2, "spindle", Role::kTool, Encoding::kBytes, 1.0},
                                     {3, "gripper", Role::kGeneric, Encoding::kBytes, 1.0}};
  return SlaveTable(std::move(slaves), 0, WireFormat(), "~slaves", "~bus_size");
}

/// The master and its slaves on the far side of a pty, in their own thread; every payload a slave
/// got is recorded.
class SimulatedBus
{
 public:
  SimulatedBus()
  {
    std::vector<SimSlave> slaves;
    slaves.emplace_back(1, SimRole::kAxis, Encoding::kBigEndian16s);
    slaves.emplace_back(2, SimRole::kTool, Encoding::kBytes);
    slaves.emplace_back(3, SimRole::kGeneric, Encoding::kBytes);
    SimMaster::Options options;
    options.on_delivery = [this](uint8_t address, const std::vector<uint8_t>& payload)
    {
      std::lock_guard<std::mutex> lock(mutex_);
      delivered_.emplace_back(address, payload);
    };
    master_ = std::make_unique<SimMaster>(pty_, std::move(slaves), options);
    thread_ = std::thread([this] { master_->run(stop_); });
  }
  ~SimulatedBus()
  {
    stop_.stop();
    pty_.interrupt();
    thread_.join();
  }
  const std::string& device() const { return pty_.slavePath(); }
  std::vector<std::pair<uint8_t, std::vector<uint8_t>>> delivered()
  {
    std::lock_guard<std::mutex> lock(mutex_);
    return delivered_;
  }

 private:
  PtyMaster pty_;
  StopSignal stop_;
  std::unique_ptr<SimMaster> master_;
  std::thread thread_;
  std::mutex mutex_;
  std::vector<std::pair<uint8_t, std::vector<uint8_t>>> delivered_;
};

/// What the node would be told.
class Recorder : public BusListener
{
 public:
  void onLink(LinkState state, const std::string&) override
  {
    record([&] { link_ = state; });
  }
  void onExecution(bool active) override
  {
    record([&] { executions_.push_back(active); });
  }
  void onReply(const SlaveReply& reply) override
  {
    record([&] { replies_.push_back(reply); });
  }
  void onRefused(const std::string& why) override
  {
    record([&] { refusals_.push_back(why); });
  }

  bool waitForLink(LinkState state)
  {
    std::unique_lock<std::mutex> lock(mutex_);
    return changed_.wait_for(lock, 5s, [&] { return link_ == state; });
  }
  /// Waits for \p count replies; \returns them.
  std::vector<SlaveReply> waitForReplies(size_t count)
  {
    std::unique_lock<std::mutex> lock(mutex_);
    changed_.wait_for(lock, 5s, [&] { return replies_.size() >= count; });
    return replies_;
  }
  std::vector<std::string> refusals()
  {
    std::lock_guard<std::mutex> lock(mutex_);
    return refusals_;
  }
  std::vector<bool> executions()
  {
    std::lock_guard<std::mutex> lock(mutex_);
    return executions_;
  }

 private:
  template <class Change>
  void record(Change change)
  {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      change();
    }
    changed_.notify_all();
  }

  std::mutex mutex_;
  std::condition_variable changed_;
  LinkState link_ = LinkState::kDown;
  std::vector<bool> executions_;
  std::vector<SlaveReply> replies_;
  std::vector<std::string> refusals_;
};

BusSettings settingsFor(const std::string& device)
{
  BusSettings settings(threeSlaves());
  SerialSettings serial;
  serial.device = device;
  serial.baud = 115200;
  settings.link = LinkSettings::serialLine(serial);
  return settings;
}

SafetySwitch::Names motionNames()
{
  return {"motion", "/bus/set_motion_enabled", "/bus/enable_motion"};
}
}  // namespace

TEST(BusRunner, ACommandTravelsToItsSlaveAndTheAxisPositionComesBack)
{
  SimulatedBus bus;
  SafetySwitch motion(motionNames(), true);
  Recorder events;
  BusRunner runner(settingsFor(bus.device()), motion, events);
  runner.start();
  ASSERT_TRUE(events.waitForLink(LinkState::kUp));

  ASSERT_TRUE(runner.submitCommand(0, {0.012}, {}));
  const std::vector<SlaveReply> replies = events.waitForReplies(1);
  ASSERT_EQ(replies.size(), 1u);
  EXPECT_EQ(replies[0].index, 0u);
  ASSERT_TRUE(replies[0].decoded);
  ASSERT_EQ(replies[0].values.size(), 1u);
  EXPECT_NEAR(replies[0].values[0], 0.012, 1e-9);
  EXPECT_TRUE(replies[0].axis_update);
  EXPECT_TRUE(replies[0].all_axes_known) << "x is the only axis";
  ASSERT_EQ(bus.delivered().size(), 1u);
  EXPECT_EQ(bus.delivered()[0].first, 1);
  EXPECT_EQ(bus.delivered()[0].second, (std::vector<uint8_t>{0, 12}));  // 12 mm, big-endian
  runner.stop();
  const std::vector<bool> executions = events.executions();
  ASSERT_FALSE(executions.empty());
  EXPECT_TRUE(executions.front()) << "the step went out";
  EXPECT_FALSE(executions.back()) << "and nothing was left queued";
  EXPECT_TRUE(events.refusals().empty());
}

TEST(BusRunner, WithMotionDisabledNothingThatMovesReachesTheBus)
{
  SimulatedBus bus;
  SafetySwitch motion(motionNames(), false);
  Recorder events;
  BusRunner runner(settingsFor(bus.device()), motion, events);
  runner.start();
  ASSERT_TRUE(events.waitForLink(LinkState::kUp));

  EXPECT_FALSE(runner.submitCommand(0, {0.01}, {}));       // the axis
  EXPECT_FALSE(runner.submitFrame({{2, {1}}}));            // the tool, in an explicit frame
  EXPECT_FALSE(runner.submitFrame({{3, {7}}, {5, {1}}}));  // an address nobody configured
  const std::vector<std::string> refusals = events.refusals();
  ASSERT_EQ(refusals.size(), 3u);
  EXPECT_NE(refusals[0].find("slaves/x/command refused: slave x (it moves or cuts) refused: motion is disabled; "
                             "enable it with /bus/set_motion_enabled"),
            std::string::npos)
      << refusals[0];
  EXPECT_NE(refusals[1].find("bus/frame refused: address 2"), std::string::npos) << refusals[1];
  EXPECT_NE(refusals[2].find("address 5"), std::string::npos) << refusals[2];

  // A generic slave is not motion: its command goes out, and it is the only thing the master got.
  ASSERT_TRUE(runner.submitCommand(2, {}, {42}));
  ASSERT_EQ(events.waitForReplies(1).size(), 1u);
  runner.stop();
  const auto delivered = bus.delivered();
  ASSERT_EQ(delivered.size(), 1u);
  EXPECT_EQ(delivered[0].first, 3);
}

TEST(BusRunner, InputsAreRefusedWhileTheLinkIsNotUp)
{
  SimulatedBus bus;
  SafetySwitch motion(motionNames(), true);
  Recorder events;
  BusRunner runner(settingsFor(bus.device()), motion, events);  // not started: no link

  EXPECT_FALSE(runner.submitCommand(2, {}, {1}));
  ASSERT_EQ(events.refusals().size(), 1u);
  EXPECT_NE(events.refusals()[0].find("the slave bus link is not up (" + bus.device() + "@115200 8N1)"),
            std::string::npos)
      << events.refusals()[0];
  runner.stop();
  EXPECT_TRUE(bus.delivered().empty());
}

TEST(BusRunner, AWrongFrameOrAFullQueueIsRefusedAndNothingIsSent)
{
  SimulatedBus bus;
  SafetySwitch motion(motionNames(), true);
  Recorder events;
  BusSettings settings = settingsFor(bus.device());
  settings.max_queued_steps = 1;
  settings.command_delay = 3600s;  // the step of commands waits for more: it never leaves in this test
  BusRunner runner(std::move(settings), motion, events);
  runner.start();
  ASSERT_TRUE(events.waitForLink(LinkState::kUp));

  EXPECT_FALSE(runner.submitFrame({{9, {1}}}));  // outside the bus of 3
  EXPECT_TRUE(runner.submitCommand(2, {}, {1}));
  EXPECT_FALSE(runner.submitCommand(2, {}, {2}));  // the same slot again needs a second step: full
  const std::vector<std::string> refusals = events.refusals();
  ASSERT_EQ(refusals.size(), 2u);
  EXPECT_NE(refusals[0].find("bus/frame refused"), std::string::npos) << refusals[0];
  EXPECT_NE(refusals[1].find("1 steps already queued"), std::string::npos) << refusals[1];
  runner.stop();
  EXPECT_TRUE(bus.delivered().empty());
}

TEST(BusRunner, AWrongLinkIsRefusedWhenTheRunnerIsMade)
{
  SafetySwitch motion(motionNames(), true);
  Recorder events;
  EXPECT_THROW(BusRunner(settingsFor("telnet2://host:23"), motion, events), ConfigError);
}
