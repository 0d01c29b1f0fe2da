// slave_bus_node: drives a universal-CNC master board (docs/protocols/slave_bus.md) over
// its serial link. Each step is one serial array frame that carries a payload for every slave, so
// all slaves get their data together; the slaves' answers come back as per-slave topics, and axis
// slaves' positions feed state, joint_states and tf. The protocol, the slave table, the step queue
// and the bus counters live in the core (cnc_bridge/slave_bus); this class maps them to ROS.
#include <ros/ros.h>

#include <cmath>
#include <memory>
#include <set>
#include <type_traits>

#include "cnc_bridge/BusFrame.h"
#include "cnc_bridge/SlaveCommand.h"
#include "cnc_bridge/SlaveResponse.h"
#include "cnc_bridge/common/error.h"
#include "cnc_bridge/ros/machine_state_publisher.h"
#include "cnc_bridge/ros/node_main.h"
#include "cnc_bridge/ros/params.h"
#include "cnc_bridge/ros/runtime_switch.h"
#include "cnc_bridge/slave_bus/bus_monitor.h"
#include "cnc_bridge/slave_bus/bus_session.h"
#include "cnc_bridge/slave_bus/slave_table.h"
#include "cnc_bridge/slave_bus/step_queue.h"
#include "cnc_bridge/transport/reconnecting_link.h"
#include "cnc_bridge/transport/serial_line.h"

namespace cnc_bridge
{
namespace
{
using slave_bus::Role;
using slave_bus::StepPayloads;
using slave_bus::UplinkRecord;

template <class T>
T member(XmlRpc::XmlRpcValue& item, const std::string& key, const T& fallback, const std::string& where)
{
  if (!item.hasMember(key))
  {
    return fallback;
  }
  XmlRpc::XmlRpcValue& value = item[key];
  if constexpr (std::is_same<T, double>::value)
  {
    if (value.getType() == XmlRpc::XmlRpcValue::TypeInt)
      return static_cast<int>(value);
    if (value.getType() == XmlRpc::XmlRpcValue::TypeDouble)
      return static_cast<double>(value);
  }
  else if constexpr (std::is_same<T, int>::value)
  {
    if (value.getType() == XmlRpc::XmlRpcValue::TypeInt)
      return static_cast<int>(value);
  }
  else
  {
    if (value.getType() == XmlRpc::XmlRpcValue::TypeString)
      return static_cast<std::string>(value);
  }
  throw ConfigError(where + "." + key + " has the wrong type");
}

/// ~framing and ~wirepacker_crc / ~max_payload: the master's dialect.
slave_bus::WireFormat wireFormat(const ros::NodeHandle& pnh)
{
  // ~wirepacker_crc: spec (CRC-8 over the length byte and the data, as the packet format documents
  // it) or library (data only, as the released ESP32_I2C_Slave library computes it): framed mode.
  const std::string crc = pnh.param<std::string>("wirepacker_crc", "spec");
  // ~max_payload: most data bytes of one WirePacker frame of the master (each slave's payload is
  // one I2C frame; in framed mode so is the whole step); 0 = 251 (spec) or 124 (library buffers).
  const int max_payload = pnh.param("max_payload", 0);
  if (max_payload < 0 || max_payload > static_cast<int>(slave_bus::kMaxPayload))
  {
    throw ConfigError(pnh.resolveName("max_payload") + " must be 0 (the default of ~wirepacker_crc) or 1.." +
                      std::to_string(slave_bus::kMaxPayload));
  }
  return slave_bus::WireFormat::of(slave_bus::parseWireCrc(crc), static_cast<size_t>(max_payload));
}

/// ~slaves: list of {address, name, role (x|y|z|tool|generic), encoding (bytes|hundreds|be16|be16s),
/// scale (device units per metre, axes only)}; ~bus_size: slaves in every frame (the universal-CNC paper's master
/// firmware is built for a fixed count, e.g. 8); 0 (default): the highest configured address.
slave_bus::SlaveTable slaveTable(const ros::NodeHandle& pnh, const slave_bus::WireFormat& wire)
{
  XmlRpc::XmlRpcValue list;
  const std::string where = pnh.resolveName("slaves");
  if (!pnh.getParam("slaves", list))
  {
    throw ConfigError("Required parameter " + where + " not given.");
  }
  if (list.getType() != XmlRpc::XmlRpcValue::TypeArray)
  {
    throw ConfigError(where + " must be a non-empty list");
  }
  std::vector<slave_bus::SlaveConfig> slaves;
  for (int i = 0; i < list.size(); ++i)
  {
    const std::string entry = where + "[" + std::to_string(i) + "]";
    if (list[i].getType() != XmlRpc::XmlRpcValue::TypeStruct)
    {
      throw ConfigError(entry + " is not a {address, name, role, ...} map");
    }
    slave_bus::SlaveConfig slave;
    const int address = member<int>(list[i], "address", 0, entry);
    slave.address = static_cast<uint8_t>(address >= 0 && address <= 255 ? address : 0);
    slave.name = member<std::string>(list[i], "name", "", entry);
    try
    {
      slave.role = slave_bus::parseRole(member<std::string>(list[i], "role", "generic", entry));
      slave.encoding = slave_bus::parseEncoding(member<std::string>(list[i], "encoding", "bytes", entry));
    }
    catch (const ConfigError& e)
    {
      throw ConfigError(entry + ": " + e.what());
    }
    slave.scale = member<double>(list[i], "scale", 1.0, entry);
    slaves.push_back(slave);
  }
  const int bus_size = pnh.param("bus_size", 0);
  return slave_bus::SlaveTable(std::move(slaves), static_cast<size_t>(std::max(0, bus_size)), wire, where,
                               pnh.resolveName("bus_size"));
}
}  // namespace

class SlaveBusNode
{
 public:
  SlaveBusNode(ros::NodeHandle nh, ros::NodeHandle pnh)
      : settings_(params::serialSettings(pnh, 115200)),
        state_(nh, pnh, settings_.describe()),
        // ~framing: raw (the universal-CNC paper's bytes, for its stock master firmware) or framed (every frame in
        // a WirePacker frame with CRC-8, both directions; recommended where the firmware supports it).
        framing_(slave_bus::parseFraming(pnh.param<std::string>("framing", "raw"))),
        table_(slaveTable(pnh, wireFormat(pnh))),
        // ~max_queued_steps: steps waiting for the link; more are refused (and counted), not dropped
        // silently. ~command_delay (s): a step of queued commands leaves this long after its first
        // command, so that commands published together (x, y, then the tool) travel in one frame.
        queue_(table_.busSize(), static_cast<size_t>(std::max(1, pnh.param("max_queued_steps", 100))),
               params::seconds(pnh, "command_delay", 0.005)),
        monitor_(table_),
        // ~enable_motion (start-up value) and ~set_motion_enabled (at run time): axis and tool payloads
        // (bus/frame or commands) are refused unless motion is enabled.
        motion_(pnh, "motion", "enable_motion", "set_motion_enabled")
  {
    // ~reply_timeout (s): how long a slave that got a payload has to answer before it counts a timeout.
    reply_timeout_ = params::seconds(pnh, "reply_timeout", 0.5);
    // ~resync_gap (s): a partial uplink record followed by this much silence is dropped.
    resync_gap_ = params::seconds(pnh, "resync_gap", 0.05);
    for (const auto& slave : table_.slaves())
    {
      const size_t index = response_pubs_.size();
      response_pubs_.push_back(nh.advertise<SlaveResponse>("slaves/" + slave.name + "/response", 50));
      command_subs_.push_back(nh.subscribe<SlaveCommand>("slaves/" + slave.name + "/command", 50,
                                                         [this, index](const SlaveCommand::ConstPtr& msg)
                                                         { onCommand(index, *msg); }));
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
    link_ = std::make_unique<ReconnectingLink>("slave bus " + settings_.describe(),
                                               [this] { return openSerialLine(settings_); });
    queue_.close();  // until the link is up: nothing waits to be sent when it opens
    link_->start([this](Transport& port) { ioLoop(port); },
                 [this](LinkState link, const std::string& why) { onLinkState(link, why); });
    ROS_INFO_STREAM("slave_bus_node: " << table_.slaves().size() << " slaves on a bus of " << table_.busSize() << ", "
                                       << slave_bus::toString(framing_) << " framing, WirePacker CRC "
                                       << slave_bus::toString(table_.wire().crc) << ", payloads up to "
                                       << table_.wire().max_data << " bytes, " << settings_.describe()
                                       << (motion_.enabled() ? ", motion enabled" : ", motion disabled"));
  }

  ~SlaveBusNode()
  {
    queue_.stop();  // ends the I/O thread's wait for a step
    link_->stop();  // interrupts the port, ends the session, joins the thread
  }

 private:
  // ---- ROS inputs -------------------------------------------------------------------------------

  void onFrame(const BusFrame::ConstPtr& msg)
  {
    std::vector<std::pair<uint8_t, std::vector<uint8_t>>> payloads;
    for (const auto& payload : msg->payloads)
    {
      payloads.emplace_back(payload.address, payload.data);
    }
    StepPayloads step;
    try
    {
      step = table_.framePayloads(payloads);
    }
    catch (const ProtocolError& e)
    {
      return refuse(std::string("bus/frame refused: ") + e.what());
    }
    for (const auto& [address, data] : payloads)
    {
      if (!data.empty() && !motion_.enabled() && table_.startsMotion(address))
      {
        return refuse("bus/frame refused: " +
                      motion_.refusal("address " + std::to_string(address) + " (an axis, tool or unconfigured slave)"));
      }
    }
    if (!queue_.pushFrame(std::move(step)))
    {
      refuseNotQueued("bus/frame");
    }
  }

  void onCommand(size_t index, const SlaveCommand& msg)
  {
    const slave_bus::SlaveConfig& slave = table_.slaves()[index];
    if (slave_bus::startsMotion(slave.role) && !motion_.enabled())
    {
      return refuse("slaves/" + slave.name +
                    "/command refused: " + motion_.refusal("slave " + slave.name + " (it moves or cuts)"));
    }
    std::vector<uint8_t> payload;
    try
    {
      payload = table_.commandPayload(index, msg.values, msg.data);
    }
    catch (const Error& e)
    {
      return refuse("slaves/" + slave.name + "/command refused: " + e.what());
    }
    if (!queue_.pushCommand(slave.address - 1u, std::move(payload)))
    {
      refuseNotQueued("slaves/" + slave.name + "/command");
    }
  }

  void refuse(const std::string& why)
  {
    monitor_.refused();
    ROS_ERROR_STREAM_THROTTLE(1.0, why);
  }

  /// The queue took nothing: the link is down (closed queue), or it is full.
  void refuseNotQueued(const std::string& input)
  {
    if (!queue_.isOpen())
    {
      return refuse(input + " refused: the slave bus link is not up (" + settings_.describe() +
                    "); nothing is kept to be sent when it returns");
    }
    refuse(input + " refused: " + std::to_string(queue_.size()) +
           " steps already queued (~max_queued_steps): step refused");
  }

  // ---- link -------------------------------------------------------------------------------------

  /// The link's state changes. The queue is open only while the link is up: steps that waited
  /// through an outage would move the machine when the link returns, long after they were asked
  /// for, so they are dropped (counted and logged) and inputs meanwhile are refused.
  void onLinkState(LinkState link, const std::string& why)
  {
    if (link == LinkState::kUp)
    {
      queue_.open();
    }
    else
    {
      dropQueuedSteps();
    }
    state_.setLink(link, why);
  }

  void dropQueuedSteps()
  {
    const size_t dropped = queue_.close();
    if (dropped > 0)
    {
      monitor_.droppedWithLink(dropped);
      ROS_ERROR_STREAM("slave bus link down: " << dropped
                                               << " queued steps dropped; they are not sent when the link returns");
    }
  }

  /// The session on the open port (the link's thread): sends queued steps one at a time and
  /// publishes what comes back, until the port fails or the node stops.
  void ioLoop(Transport& port)
  {
    slave_bus::BusSession session(port, framing_, table_.busSize(), resync_gap_, table_.wire());
    StepPayloads step;
    for (;;)
    {
      // Idle, the thread waits on the queue, not on the port: a new step leaves at once. What the
      // master writes meanwhile (late answers, status) waits in the port and is read right after.
      if (queue_.take(step, Milliseconds(20)))
      {
        sendStep(session, step);
        continue;
      }
      if (queue_.stopped())
      {
        return;
      }
      try
      {
        handle(session.poll(Milliseconds(0)));
      }
      catch (const Error&)
      {
        monitor_.sessionStats(session.stats());  // the bytes up to the failure count too
        throw;                                   // the link reopens the port after a backoff
      }
      monitor_.sessionStats(session.stats());
    }
  }

  void sendStep(slave_bus::BusSession& session, const StepPayloads& step)
  {
    state_.update([](MachineState& s) { s.execution = MachineState::EXECUTION_ACTIVE; });
    slave_bus::BusSession::StepResult result;
    try
    {
      result = session.step(step, reply_timeout_);
    }
    catch (const ProtocolError& e)
    {
      return refuse(std::string("step not sent: ") + e.what());
    }
    catch (const Error& e)
    {
      refuse(std::string("step lost with the link (send it again once the link is up): ") + e.what());
      throw;  // the link reopens the port after a backoff
    }
    handle(result.replies);
    handle(result.master_status);
    monitor_.stepSent(step, result.missing, session.stats());
    if (queue_.size() == 0)
    {
      state_.update([](MachineState& s) { s.execution = MachineState::EXECUTION_READY; });
    }
  }

  void handle(const std::vector<UplinkRecord>& records)
  {
    for (const auto& record : records)
    {
      if (record.address == 0)
      {
        const std::string what = monitor_.masterStatus(record);  // counted whether or not it is logged
        ROS_WARN_STREAM_THROTTLE(1.0, what);
        continue;
      }
      const int index = table_.indexOf(record.address);
      if (index < 0)
      {
        monitor_.reply(-1, true);
        continue;
      }
      publishResponse(static_cast<size_t>(index), record);
    }
  }

  void publishResponse(size_t index, const UplinkRecord& record)
  {
    const slave_bus::SlaveConfig& slave = table_.slaves()[index];
    SlaveResponse msg;
    msg.header.stamp = ros::Time::now();
    msg.name = slave.name;
    msg.address = slave.address;
    msg.data = record.payload;
    bool decoded = true;
    try
    {
      msg.values = table_.replyValues(index, record.payload);
    }
    catch (const ProtocolError&)
    {
      decoded = false;
    }
    monitor_.reply(static_cast<int>(index), decoded);
    if (slave_bus::isAxis(slave.role) && msg.values.size() == 1)
    {
      updateAxis(slave.role, msg.values[0], msg.header.stamp);
    }
    response_pubs_[index].publish(msg);
  }

  void updateAxis(Role role, double metres, const ros::Time& stamp)
  {
    axis_seen_.insert(role);
    const bool all_known = axis_seen_.size() == table_.axisCount();
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
    const slave_bus::BusMonitor::Report report = monitor_.report();
    status.summary(report.trouble ? diagnostic_msgs::DiagnosticStatus::WARN : diagnostic_msgs::DiagnosticStatus::OK,
                   report.summary);
    status.add("framing", slave_bus::toString(framing_));
    status.add("WirePacker CRC", slave_bus::toString(table_.wire().crc));
    status.add("max payload", table_.wire().max_data);
    status.add("bus size", table_.busSize());
    motion_.addTo(status);
    for (const auto& [key, value] : report.counters)
    {
      status.add(key, value);
    }
  }

  SerialSettings settings_;
  MachineStatePublisher state_;
  slave_bus::Framing framing_;
  const slave_bus::SlaveTable table_;
  slave_bus::StepQueue queue_;
  slave_bus::BusMonitor monitor_;
  RuntimeSwitch motion_;
  Milliseconds reply_timeout_{500};
  Milliseconds resync_gap_{50};
  std::vector<ros::Publisher> response_pubs_;  // by slave index
  std::vector<ros::Subscriber> command_subs_;
  ros::Subscriber frame_sub_;
  std::set<Role> axis_seen_;  // link thread only
  std::unique_ptr<ReconnectingLink> link_;
};
}  // namespace cnc_bridge

int main(int argc, char** argv)
{
  return cnc_bridge::runNode<cnc_bridge::SlaveBusNode>(argc, argv, "slave_bus_node", {2});
}
