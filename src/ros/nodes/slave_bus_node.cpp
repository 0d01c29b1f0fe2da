// slave_bus_node: drives a universal-CNC master board (docs/protocols/slave_bus.md) over
// its serial link. Each step is one serial array frame that carries a payload for every slave, so
// all slaves get their data together; the slaves' answers come back as per-slave topics, and axis
// slaves' positions feed state, joint_states and tf. The parameters are read in
// slave_bus_params.cpp; the bus (its link, step queue, session loop and counters) is the core's
// slave_bus::BusRunner; this class maps ROS inputs to it and its events to ROS.
#include <ros/ros.h>

#include <cmath>
#include <memory>

#include "cnc_bridge/BusFrame.h"
#include "cnc_bridge/SlaveCommand.h"
#include "cnc_bridge/SlaveResponse.h"
#include "cnc_bridge/ros/machine_state_publisher.h"
#include "cnc_bridge/ros/node_main.h"
#include "cnc_bridge/ros/runtime_switch.h"
#include "cnc_bridge/slave_bus/bus_runner.h"
#include "slave_bus_node.h"

namespace cnc_bridge
{
class SlaveBusNode : public slave_bus::BusListener
{
 public:
  SlaveBusNode(ros::NodeHandle nh, ros::NodeHandle pnh)
      : settings_(readBusSettings(pnh)),
        state_(nh, pnh, settings_.link.hardwareId()),
        // ~enable_motion (start-up value) and ~set_motion_enabled (at run time): axis and tool payloads
        // (bus/frame or commands) are refused unless motion is enabled.
        motion_(pnh, "motion", "enable_motion", "set_motion_enabled"),
        bus_(settings_, motion_.core(), *this)
  {
    const slave_bus::SlaveTable& table = bus_.table();
    for (size_t index = 0; index < table.slaves().size(); ++index)
    {
      const std::string& name = table.slaves()[index].name;
      response_pubs_.push_back(nh.advertise<SlaveResponse>("slaves/" + name + "/response", 50));
      command_subs_.push_back(nh.subscribe<SlaveCommand>("slaves/" + name + "/command", 50,
                                                         [this, index](const SlaveCommand::ConstPtr& msg)
                                                         { bus_.submitCommand(index, msg->values, msg->data); }));
    }
    frame_sub_ = nh.subscribe("bus/frame", 50, &SlaveBusNode::onFrame, this);
    state_.update(
        [&](MachineState& s)
        {
          s.mode = MachineState::MODE_DNC;  // the PC feeds every step over the link
          s.execution = MachineState::EXECUTION_READY;
          s.feed_rate = NAN;
          s.spindle_speed = NAN;
        });
    state_.diagnostics().add("slave bus", this, &SlaveBusNode::diagnose);
    bus_.start();
    ROS_INFO_STREAM("slave_bus_node: " << table.slaves().size() << " slaves on a bus of " << table.busSize() << ", "
                                       << slave_bus::toString(settings_.framing) << " framing, WirePacker CRC "
                                       << slave_bus::toString(table.wire().crc) << ", payloads up to "
                                       << table.wire().max_data << " bytes, " << settings_.link.hardwareId()
                                       << (motion_.enabled() ? ", motion enabled" : ", motion disabled"));
  }

  ~SlaveBusNode() override { bus_.stop(); }

 private:
  // ---- ROS inputs -------------------------------------------------------------------------------

  void onFrame(const BusFrame::ConstPtr& msg)
  {
    std::vector<std::pair<uint8_t, std::vector<uint8_t>>> payloads;
    for (const auto& payload : msg->payloads)
    {
      payloads.emplace_back(payload.address, payload.data);
    }
    bus_.submitFrame(payloads);
  }

  // ---- the bus's events ---------------------------------------------------------------------------

  void onLink(LinkState link, const std::string& why) override { state_.setLink(link, why); }

  void onExecution(bool active) override
  {
    state_.update([active](MachineState& s)
                  { s.execution = active ? MachineState::EXECUTION_ACTIVE : MachineState::EXECUTION_READY; });
  }

  void onRefused(const std::string& why) override { ROS_ERROR_STREAM_THROTTLE(1.0, why); }

  void onStepsDropped(size_t steps) override
  {
    ROS_ERROR_STREAM("slave bus link down: " << steps
                                             << " queued steps dropped; they are not sent when the link returns");
  }

  void onMasterStatus(const std::string& what) override { ROS_WARN_STREAM_THROTTLE(1.0, what); }

  void onReply(const slave_bus::SlaveReply& reply) override
  {
    const slave_bus::SlaveConfig& slave = bus_.table().slaves()[reply.index];
    SlaveResponse msg;
    msg.header.stamp = ros::Time::now();
    msg.name = slave.name;
    msg.address = slave.address;
    msg.data = reply.data;
    msg.values = reply.values;
    if (reply.axis_update)
    {
      updateAxis(slave.role, reply.values[0], reply.all_axes_known, msg.header.stamp);
    }
    response_pubs_[reply.index].publish(msg);
  }

  void updateAxis(slave_bus::Role role, double metres, bool all_known, const ros::Time& stamp)
  {
    using slave_bus::Role;
    state_.update(
        [&](MachineState& s)
        {
          s.header.stamp = stamp;
          (role == Role::kAxisX ? s.position.x : role == Role::kAxisY ? s.position.y : s.position.z) = metres;
          s.position_valid = all_known;
        });
  }

  void diagnose(diagnostic_updater::DiagnosticStatusWrapper& status)
  {
    const slave_bus::BusMonitor::Report report = bus_.report();
    status.summary(report.trouble ? diagnostic_msgs::DiagnosticStatus::WARN : diagnostic_msgs::DiagnosticStatus::OK,
                   report.summary);
    status.add("framing", slave_bus::toString(settings_.framing));
    status.add("WirePacker CRC", slave_bus::toString(bus_.table().wire().crc));
    status.add("max payload", bus_.table().wire().max_data);
    status.add("bus size", bus_.table().busSize());
    motion_.addTo(status);
    for (const auto& [key, value] : report.counters)
    {
      status.add(key, value);
    }
  }

  const slave_bus::BusSettings settings_;
  MachineStatePublisher state_;
  RuntimeSwitch motion_;
  std::vector<ros::Publisher> response_pubs_;  // by slave index
  std::vector<ros::Subscriber> command_subs_;
  ros::Subscriber frame_sub_;
  slave_bus::BusRunner bus_;  // last: stopped (no event after) before the rest goes
};
}  // namespace cnc_bridge

int main(int argc, char** argv)
{
  return cnc_bridge::runNode<cnc_bridge::SlaveBusNode>(argc, argv, "slave_bus_node", {2});
}
