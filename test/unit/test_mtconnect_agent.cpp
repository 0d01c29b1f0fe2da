// The round trip through the reference agent (mtconnect/cppagent v1.8.0.3, mtconnect_agent.h):
// the cell's machines published by the SHDR adapter, the agent configured with the adapter's own
// Devices.xml and agent.cfg, each device followed by the client (Follower + MachineModel) over
// the agent's HTTP stream. What the client reads must agree with what the adapter was given,
// field for field, for two devices on one adapter; an alarm arrives as a FAULT condition with its
// words; a machine the node lost is UNAVAILABLE; a restarted adapter is sent the whole state again.
#include <gtest/gtest.h>

#include <condition_variable>
#include <functional>
#include <mutex>
#include <thread>

#include "cnc_bridge/common/error.h"
#include "cnc_bridge/mtconnect/follower.h"
#include "cnc_bridge/mtconnect/machine_model.h"
#include "cnc_bridge/mtconnect/shdr.h"
#include "cnc_bridge/mtconnect/shdr_adapter.h"
#include "cnc_bridge/transport/tcp.h"
#include "mtconnect_agent.h"
#include "temp_dir.h"

using namespace cnc_bridge;
using namespace cnc_bridge::mtconnect;

namespace
{
/// One device followed through the agent, as mtconnect_node follows it, on a thread of its own.
class Client : public FollowerListener
{
 public:
  Client(unsigned port, const std::string& device)
      : http_("127.0.0.1:" + std::to_string(port),
              [port] { return TcpConnection::connect("127.0.0.1", static_cast<uint16_t>(port), Milliseconds(2000)); })
  {
    FollowerSettings settings;
    settings.device = device;
    settings.interval = Milliseconds(20);
    settings.heartbeat = Milliseconds(500);
    follower_ = std::make_unique<Follower>(settings, http_, *this);
    thread_ = std::thread(
        [this]
        {
          while (!stop_.stopped())
          {
            try
            {
              follower_->probe();
              follower_->follow(stop_);
            }
            catch (const std::exception& e)
            {
              std::lock_guard<std::mutex> lock(mutex_);
              errors_ += std::string(e.what()) + "\n";
            }
            stop_.waitFor(Milliseconds(200));  // the node's backoff before it reconnects
          }
        });
  }
  ~Client() override
  {
    stop_.stop();
    http_.interrupt();
    thread_.join();
  }

  void onProbe(const Document&, const Device& device) override
  {
    std::lock_guard<std::mutex> lock(mutex_);
    model_.setDevice(device);
  }
  void onObservations(const std::vector<Observation>& observations, bool snapshot) override
  {
    std::lock_guard<std::mutex> lock(mutex_);
    const auto changes = model_.apply(observations, snapshot);
    events_.insert(events_.end(), changes.events.begin(), changes.events.end());
    changed_.notify_all();
  }

  /// Waits (for what the agent sends, at most 20 s) until \p holds is true of the model.
  bool waitFor(const std::function<bool(const MachineModel&)>& holds)
  {
    std::unique_lock<std::mutex> lock(mutex_);
    return changed_.wait_for(lock, std::chrono::seconds(20), [&] { return holds(model_); });
  }
  template <class F>
  auto with(F f)
  {
    std::lock_guard<std::mutex> lock(mutex_);
    return f(model_, events_);
  }
  std::string errors()
  {
    std::lock_guard<std::mutex> lock(mutex_);
    return errors_;
  }

 private:
  HttpClient http_;
  std::unique_ptr<Follower> follower_;
  StopSignal stop_;
  std::mutex mutex_;
  std::condition_variable changed_;
  MachineModel model_;
  std::vector<CycleEvent> events_;
  std::string errors_;
  std::thread thread_;
};

MachineReport vf2Running()
{
  MachineReport r;
  r.link_up = true;
  r.view.estop = Tristate::kOff;
  r.view.mode = Mode::kAuto;
  r.view.execution = Execution::kActive;
  r.view.program = "O1234";
  r.view.line = 30;
  r.view.part_count = 41;
  r.view.position = {0.1234567, -0.2, 0.0305};
  r.view.commanded = {0.1234, -0.2, 0.03};
  r.view.spindle_rpm = 1200;
  r.view.feed_rate = 0.0125;
  r.view.tool = 3;
  r.view.door = "CLOSED";
  return r;
}

MachineReport laserReady()
{
  MachineReport r;
  r.link_up = true;
  r.view.estop = Tristate::kOff;
  r.view.mode = Mode::kManual;
  r.view.execution = Execution::kReady;
  r.view.position = {0.5, 0.25, 0.0};
  r.view.part_count = 7;
  return r;  // no program, spindle, feed, tool, door: the laser does not report them
}

bool near(const std::optional<double>& a, const std::optional<double>& b)
{
  return a.has_value() == b.has_value() && (!a || std::abs(*a - *b) < 1e-9);
}

/// The client's execution for the adapter's: an alarm is STOPPED with a FAULT condition.
Execution asRead(Execution e)
{
  return e == Execution::kAlarm ? Execution::kStopped : e;
}

/// Field for field: what the client reads is what the adapter was given. Empty when they agree.
std::string differences(const MachineReport& sent, const MachineView& got)
{
  std::string out;
  auto check = [&](bool same, const char* field)
  {
    if (!same)
      out += std::string(field) + " ";
  };
  const MachineView& v = sent.view;
  check(got.available == std::optional<bool>(sent.link_up ? std::optional<bool>(true) : std::nullopt), "available");
  check(got.estop == (sent.link_up ? v.estop : Tristate::kUnknown), "estop");
  check(got.mode == (sent.link_up ? v.mode : Mode::kUnknown), "mode");
  check(got.execution == (sent.link_up ? asRead(v.execution) : Execution::kUnknown), "execution");
  check(got.program == (sent.link_up ? v.program : ""), "program");
  check(got.line == (sent.link_up ? v.line : 0), "line");
  check(got.part_count == (sent.link_up ? v.part_count : -1), "part_count");
  check(got.tool == (sent.link_up ? v.tool : -1), "tool");
  check(got.door == (sent.link_up ? v.door : ""), "door");
  for (size_t axis = 0; axis < 3; ++axis)
  {
    check(near(got.position[axis], sent.link_up ? v.position[axis] : std::nullopt), "position");
    check(near(got.commanded[axis], sent.link_up ? v.commanded[axis] : std::nullopt), "commanded");
  }
  check(near(got.spindle_rpm, sent.link_up ? v.spindle_rpm : std::nullopt), "spindle_rpm");
  check(near(got.feed_rate, sent.link_up ? v.feed_rate : std::nullopt), "feed_rate");
  return out;
}

class MtconnectAgentRoundTrip : public ::testing::Test
{
 protected:
  void SetUp() override
  {
    settings_.address = "127.0.0.1";
    settings_.port = 0;
    settings_.heartbeat = Milliseconds(1000);
    adapter_ = std::make_unique<ShdrAdapter>(settings_, std::vector<std::string>{"vf2", "laser"});
    const std::vector<DeviceSpec> devices{{"vf2", "cell-vf2"}, {"laser", "cell-laser"}};
    const uint16_t adapter_port = adapter_->port();
    agent_ = std::make_unique<test::ReferenceAgent>(
        dir_.path, devicesXml(devices),
        [&](unsigned http_port)
        { return agentConfig(devices, "Devices.xml", "127.0.0.1", adapter_port, static_cast<uint16_t>(http_port)); });
  }

  /// Waits until \p client reads \p sent; fails naming the fields that differ.
  void expectRead(Client& client, const MachineReport& sent, const char* what)
  {
    const bool agreed = client.waitFor([&](const MachineModel& m) { return differences(sent, m.view()).empty(); });
    const std::string diff = client.with([&](const MachineModel& m, auto&) { return differences(sent, m.view()); });
    EXPECT_TRUE(agreed) << what << ": the client reads differently: " << diff << "\nclient errors: " << client.errors()
                        << "\n"
                        << agent_->log();
  }

  void publish(const std::string& device, const MachineReport& report)
  {
    adapter_->publish(device, report, std::chrono::system_clock::now());
  }

  test::TempDir dir_{"cnc_mtconnect_agent"};
  AdapterSettings settings_;
  std::unique_ptr<ShdrAdapter> adapter_;
  std::unique_ptr<test::ReferenceAgent> agent_;
};
}  // namespace

TEST_F(MtconnectAgentRoundTrip, TwoMachinesAgreeFieldForFieldThroughTheAgent)
{
  Client vf2(agent_->http_port, "vf2");
  Client laser(agent_->http_port, "laser");
  MachineReport vf2_state = vf2Running();
  publish("vf2", vf2_state);
  expectRead(vf2, vf2_state, "vf2 running");
  // The laser's node has not reached it yet: the agent says it knows nothing.
  expectRead(laser, MachineReport{}, "laser not reached");

  const MachineReport laser_state = laserReady();
  publish("laser", laser_state);
  expectRead(laser, laser_state, "laser ready");

  // The cycle ends: part count up, spindle stopped, door opened; the client sees the cycle end.
  vf2_state.view.execution = Execution::kReady;
  vf2_state.view.part_count = 42;
  vf2_state.view.spindle_rpm = 0;
  vf2_state.view.feed_rate = 0;
  vf2_state.view.door = "OPEN";
  vf2_state.view.line = 0;
  publish("vf2", vf2_state);
  expectRead(vf2, vf2_state, "vf2 cycle end");
  const bool cycle_end = vf2.with(
      [](const MachineModel&, const std::vector<CycleEvent>& events)
      {
        for (const auto& e : events)
        {
          if (e.type == CycleEvent::kCycleEnd)
            return true;
        }
        return false;
      });
  EXPECT_TRUE(cycle_end);
  // The laser did not change with the vf2.
  expectRead(laser, laser_state, "laser unchanged");
  EXPECT_GE(adapter_->stats().pings, 1u) << "the agent's heartbeat was not answered";
}

TEST_F(MtconnectAgentRoundTrip, AlarmArrivesAsAFaultWithItsWordsAndClears)
{
  Client laser(agent_->http_port, "laser");
  MachineReport state = laserReady();
  state.view.execution = Execution::kActive;
  publish("laser", state);
  expectRead(laser, state, "laser active");

  state.view.execution = Execution::kAlarm;
  state.message = "slave 2 (X axis) does not answer";
  publish("laser", state);
  expectRead(laser, state, "laser alarm");
  const bool fault = laser.waitFor(
      [](const MachineModel& m)
      {
        for (const auto& c : m.activeConditions())
        {
          if (c.level == ConditionLevel::kFault && c.text == "slave 2 (X axis) does not answer" &&
              c.condition_type == "SYSTEM")
            return true;
        }
        return false;
      });
  EXPECT_TRUE(fault) << agent_->log();

  state.view.execution = Execution::kReady;
  state.message.clear();
  publish("laser", state);
  EXPECT_TRUE(laser.waitFor([](const MachineModel& m) { return m.activeConditions().empty(); }));
}

TEST_F(MtconnectAgentRoundTrip, LostMachineIsUnavailableAndARestartedAdapterResendsAll)
{
  Client vf2(agent_->http_port, "vf2");
  const MachineReport state = vf2Running();
  publish("vf2", state);
  expectRead(vf2, state, "vf2 running");

  publish("vf2", MachineReport{});  // the node lost the machine
  expectRead(vf2, MachineReport{}, "vf2 lost");
  publish("vf2", state);
  expectRead(vf2, state, "vf2 back");

  // The adapter (its node) restarts on the same port with the machine's state: the agent
  // reconnects and is sent everything again, not only what changes after.
  const uint16_t port = adapter_->port();
  adapter_.reset();
  expectRead(vf2, MachineReport{}, "adapter gone: the agent marks the device unavailable");
  settings_.port = port;
  adapter_ = std::make_unique<ShdrAdapter>(settings_, std::vector<std::string>{"vf2", "laser"});
  publish("vf2", state);
  expectRead(vf2, state, "adapter restarted");
  EXPECT_EQ(adapter_->stats().agents_connected, 1u);
}
