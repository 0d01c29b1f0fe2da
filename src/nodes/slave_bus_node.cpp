// slave_bus_node: drives a universal-CNC master board (docs/protocols/slave_bus.md) over
// its serial link. Each step is one serial array frame that carries a payload for every slave, so
// all slaves get their data together; the slaves' answers come back as per-slave topics, and axis
// slaves' positions feed state, joint_states and tf. The protocol lives in the core
// (cnc_bridge/slave_bus); this class turns it into ROS.
#include <ros/ros.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <deque>
#include <map>
#include <memory>
#include <mutex>
#include <set>
#include <thread>
#include <type_traits>

#include "cnc_bridge/BusFrame.h"
#include "cnc_bridge/SlaveCommand.h"
#include "cnc_bridge/SlaveResponse.h"
#include "cnc_bridge/common/error.h"
#include "cnc_bridge/ros/machine_state_publisher.h"
#include "cnc_bridge/ros/node_main.h"
#include "cnc_bridge/ros/params.h"
#include "cnc_bridge/ros/runtime_switch.h"
#include "cnc_bridge/slave_bus/bus_session.h"
#include "cnc_bridge/slave_bus/value_codec.h"
#include "cnc_bridge/transport/backoff.h"
#include "cnc_bridge/transport/serial_port.h"

namespace cnc_bridge
{
namespace
{
using slave_bus::Encoding;
using slave_bus::StepPayloads;
using slave_bus::UplinkRecord;

enum class Role
{
  kAxisX,
  kAxisY,
  kAxisZ,
  kTool,
  kGeneric
};

Role parseRole(const std::string& text)
{
  if (text == "x" || text == "axis_x")
    return Role::kAxisX;
  if (text == "y" || text == "axis_y")
    return Role::kAxisY;
  if (text == "z" || text == "axis_z")
    return Role::kAxisZ;
  if (text == "tool")
    return Role::kTool;
  if (text == "generic")
    return Role::kGeneric;
  throw ConfigError("role '" + text + "' is not one of x, y, z, tool, generic");
}

bool isAxis(Role role)
{
  return role == Role::kAxisX || role == Role::kAxisY || role == Role::kAxisZ;
}

/// Roles whose payloads make the machine move or cut: refused unless ~enable_motion.
bool startsMotion(Role role)
{
  return role != Role::kGeneric;
}

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
}  // namespace

class SlaveBusNode
{
 public:
  SlaveBusNode(ros::NodeHandle nh, ros::NodeHandle pnh)
      : nh_(nh), settings_(params::serialSettings(pnh, 115200)), state_(nh, pnh, settings_.describe())
  {
    std::string framing = "raw";
    // ~framing: raw (the paper's bytes, for its stock master firmware) or framed (every frame in a
    // WirePacker frame with CRC-8, both directions; recommended where the firmware supports it).
    pnh.param("framing", framing, framing);
    framing_ = slave_bus::parseFraming(framing);
    std::string crc = "spec";
    // ~wirepacker_crc: spec (CRC-8 over the length byte and the data, as the packet format documents
    // it) or library (data only, as the released ESP32_I2C_Slave library computes it): framed mode.
    pnh.param("wirepacker_crc", crc, crc);
    int max_payload = 0;
    // ~max_payload: most data bytes of one WirePacker frame of the master (each slave's payload is
    // one I2C frame; in framed mode so is the whole step); 0 = 251 (spec) or 124 (library buffers).
    pnh.param("max_payload", max_payload, max_payload);
    if (max_payload < 0 || max_payload > static_cast<int>(slave_bus::kMaxPayload))
    {
      throw ConfigError(pnh.resolveName("max_payload") + " must be 0 (the default of ~wirepacker_crc) or 1.." +
                        std::to_string(slave_bus::kMaxPayload));
    }
    wire_ = slave_bus::WireFormat::of(slave_bus::parseWireCrc(crc), static_cast<size_t>(max_payload));
    // ~enable_motion (start-up value) and ~set_motion_enabled (at run time): axis and tool payloads
    // (bus/frame or commands) are refused unless motion is enabled.
    motion_ = std::make_unique<RuntimeSwitch>(pnh, "motion", "enable_motion", "set_motion_enabled");
    // ~reply_timeout (s): how long a slave that got a payload has to answer before it counts a timeout.
    reply_timeout_ = params::seconds(pnh, "reply_timeout", 0.5);
    // ~command_delay (s): a step of queued commands leaves this long after its first command, so
    // that commands published together (x, y, then the tool) travel in one frame.
    command_delay_ = params::seconds(pnh, "command_delay", 0.005);
    // ~resync_gap (s): a partial uplink record followed by this much silence is dropped.
    resync_gap_ = params::seconds(pnh, "resync_gap", 0.05);
    int max_queued = 100;
    // ~max_queued_steps: steps waiting for the link; more are refused (and counted), not dropped silently.
    pnh.param("max_queued_steps", max_queued, max_queued);
    max_queued_ = static_cast<size_t>(std::max(1, max_queued));
    loadSlaves(pnh);
    int bus_size = 0;
    // ~bus_size: slaves in every frame (the paper's master firmware is built for a fixed count, e.g.
    // 8); 0 (default): the highest configured address.
    pnh.param("bus_size", bus_size, bus_size);
    if (bus_size == 0)
    {
      bus_size = static_cast<int>(highest_address_);
    }
    if (bus_size < static_cast<int>(highest_address_) || bus_size > static_cast<int>(slave_bus::kMaxSlaves))
    {
      throw ConfigError(pnh.resolveName("bus_size") + " must be between the highest slave address (" +
                        std::to_string(highest_address_) + ") and " + std::to_string(slave_bus::kMaxSlaves));
    }
    bus_size_ = static_cast<size_t>(bus_size);

    for (auto& slave : slaves_)
    {
      slave.response_pub = nh.advertise<SlaveResponse>("slaves/" + slave.name + "/response", 50);
      const size_t index = static_cast<size_t>(&slave - slaves_.data());
      slave.command_sub =
          nh.subscribe<SlaveCommand>("slaves/" + slave.name + "/command", 50,
                                     [this, index](const SlaveCommand::ConstPtr& msg) { onCommand(index, *msg); });
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

    Reconnector::Callbacks callbacks;
    callbacks.connect = [this] { connect(); };
    callbacks.session = [this] { ioLoop(); };
    callbacks.on_state = [this](LinkState link, const std::string& why) { state_.setLink(link, why); };
    callbacks.disconnect = [this] { disconnect(); };
    reconnector_ = std::make_unique<Reconnector>("slave bus", callbacks);
    reconnector_->start();
    ROS_INFO_STREAM("slave_bus_node: " << slaves_.size() << " slaves on a bus of " << bus_size_ << ", "
                                       << slave_bus::toString(framing_) << " framing, WirePacker CRC "
                                       << slave_bus::toString(wire_.crc) << ", payloads up to " << wire_.max_data
                                       << " bytes, " << settings_.describe()
                                       << (motion_->enabled() ? ", motion enabled" : ", motion disabled"));
  }

  ~SlaveBusNode()
  {
    shutting_down_ = true;
    reconnector_->stop();  // stops its loop, then calls disconnect(), which ends ioLoop()
  }

 private:
  struct Slave
  {
    uint8_t address = 0;
    std::string name;
    Role role = Role::kGeneric;
    Encoding encoding = Encoding::kBytes;
    double scale = 1.0;  // device units per metre (axes)
    ros::Publisher response_pub;
    ros::Subscriber command_sub;
    // Counters, under stats_mutex_.
    uint64_t payloads_sent = 0;  ///< non-empty payloads in frames that went out
    uint64_t replies = 0;
    uint64_t timeouts = 0;
    uint64_t decode_errors = 0;
    uint64_t read_failures = 0;  ///< master status 3: its I2C read of this slave failed
    uint64_t too_long = 0;       ///< master status 4: the payload did not fit its I2C frame
  };

  struct Step
  {
    StepPayloads payloads;
    bool from_commands = false;
    std::chrono::steady_clock::time_point first_command;
  };

  void loadSlaves(ros::NodeHandle& pnh)
  {
    XmlRpc::XmlRpcValue list;
    // ~slaves: list of {address, name, role (x|y|z|tool|generic), encoding (bytes|hundreds|be16|be16s),
    // scale (device units per metre, axes only)}.
    if (!pnh.getParam("slaves", list))
    {
      throw ConfigError("Required parameter " + pnh.resolveName("slaves") + " not given.");
    }
    if (list.getType() != XmlRpc::XmlRpcValue::TypeArray || list.size() == 0)
    {
      throw ConfigError(pnh.resolveName("slaves") + " must be a non-empty list");
    }
    std::set<int> addresses;
    std::set<std::string> names;
    std::set<Role> axes;
    for (int i = 0; i < list.size(); ++i)
    {
      const std::string where = pnh.resolveName("slaves") + "[" + std::to_string(i) + "]";
      if (list[i].getType() != XmlRpc::XmlRpcValue::TypeStruct)
      {
        throw ConfigError(where + " is not a {address, name, role, ...} map");
      }
      Slave slave;
      const int address = member<int>(list[i], "address", 0, where);
      if (address < 1 || address > static_cast<int>(slave_bus::kMaxSlaves) || !addresses.insert(address).second)
      {
        throw ConfigError(where + ".address must be unique and in 1.." + std::to_string(slave_bus::kMaxSlaves));
      }
      slave.address = static_cast<uint8_t>(address);
      slave.name = member<std::string>(list[i], "name", "", where);
      std::string error;
      if (slave.name.empty() || !ros::names::validate(slave.name, error) || slave.name.find('/') != std::string::npos ||
          !names.insert(slave.name).second)
      {
        throw ConfigError(where + ".name '" + slave.name + "' must be a unique, valid topic name part");
      }
      try
      {
        slave.role = parseRole(member<std::string>(list[i], "role", "generic", where));
        slave.encoding = slave_bus::parseEncoding(member<std::string>(list[i], "encoding", "bytes", where));
      }
      catch (const ConfigError& e)
      {
        throw ConfigError(where + ": " + e.what());
      }
      slave.scale = member<double>(list[i], "scale", 1.0, where);
      if (!(std::isfinite(slave.scale) && slave.scale != 0.0))
      {
        throw ConfigError(where + ".scale must be a finite, non-zero number of device units per metre");
      }
      if (isAxis(slave.role) && !axes.insert(slave.role).second)
      {
        throw ConfigError(where + ": a second slave for the same axis");
      }
      highest_address_ = std::max<size_t>(highest_address_, slave.address);
      slaves_.push_back(slave);
    }
    axis_count_ = axes.size();
    for (size_t i = 0; i < slaves_.size(); ++i)
    {
      by_address_[slaves_[i].address] = i;
    }
  }

  // ---- ROS inputs -------------------------------------------------------------------------------

  void onFrame(const BusFrame::ConstPtr& msg)
  {
    Step step;
    step.payloads.resize(bus_size_);
    std::set<uint8_t> seen;
    for (const auto& payload : msg->payloads)
    {
      std::string why;
      if (payload.address < 1 || payload.address > bus_size_)
      {
        why =
            "address " + std::to_string(payload.address) + " is outside the bus (1.." + std::to_string(bus_size_) + ")";
      }
      else if (!seen.insert(payload.address).second)
      {
        why = "two payloads for address " + std::to_string(payload.address);
      }
      else if (payload.data.size() > wire_.max_data)
      {
        why = "payload for address " + std::to_string(payload.address) + " has " + std::to_string(payload.data.size()) +
              " bytes: " + payloadLimit();
      }
      else if (!payload.data.empty() && !motionAllowed(payload.address))
      {
        why = motion_->refusal("address " + std::to_string(payload.address) + " (an axis, tool or unconfigured slave)");
      }
      if (!why.empty())
      {
        refuse("bus/frame refused: " + why);
        return;
      }
      step.payloads[payload.address - 1] = payload.data;
    }
    enqueue(std::move(step), false);
  }

  void onCommand(size_t index, const SlaveCommand& msg)
  {
    const Slave& slave = slaves_[index];
    std::vector<uint8_t> payload;
    try
    {
      payload = commandPayload(slave, msg);
    }
    catch (const Error& e)
    {
      refuse("slaves/" + slave.name + "/command refused: " + e.what());
      return;
    }
    Step step;
    step.payloads.resize(bus_size_);
    step.payloads[slave.address - 1] = std::move(payload);
    enqueue(std::move(step), true);
  }

  std::vector<uint8_t> commandPayload(const Slave& slave, const SlaveCommand& msg) const
  {
    if (startsMotion(slave.role) && !motion_->enabled())
    {
      throw DisabledError(motion_->refusal("slave " + slave.name + " (it moves or cuts)"));
    }
    if (msg.values.empty() == msg.data.empty())
    {
      throw ProtocolError("give either values or data");
    }
    if (!msg.data.empty())
    {
      if (msg.data.size() > wire_.max_data)
      {
        throw ProtocolError(std::to_string(msg.data.size()) + " bytes: " + payloadLimit());
      }
      return msg.data;
    }
    std::vector<int32_t> values;
    if (isAxis(slave.role))
    {
      if (msg.values.size() != 1)
      {
        throw ProtocolError("an axis takes one value, its position in m");
      }
      // m -> device units (steps, pulses, 1/100 mm...: whatever ~scale says per metre).
      const double device = std::round(msg.values[0] * slave.scale);
      if (!std::isfinite(device) || device < slave_bus::minValue(slave.encoding) ||
          device > slave_bus::maxValue(slave.encoding))
      {
        throw ProtocolError("position " + std::to_string(msg.values[0]) + " m is " + std::to_string(device) +
                            " device units, outside what " + slave_bus::toString(slave.encoding) + " carries");
      }
      values.push_back(static_cast<int32_t>(device));
    }
    else
    {
      for (const double value : msg.values)
      {
        if (!std::isfinite(value) || std::fabs(value - std::round(value)) > 1e-9 || std::fabs(value) > 1e9)
        {
          throw ProtocolError("value " + std::to_string(value) + " is not an integer");
        }
        values.push_back(static_cast<int32_t>(std::round(value)));
      }
    }
    auto payload = slave_bus::encodeValues(values, slave.encoding);
    if (payload.size() > wire_.max_data)
    {
      throw ProtocolError("too many values for one payload: " + payloadLimit());
    }
    return payload;
  }

  /// Why a payload is too long, in words an operator can act on.
  std::string payloadLimit() const
  {
    return "one I2C frame of the master carries at most " + std::to_string(wire_.max_data) + " bytes (~max_payload" +
           (wire_.crc == slave_bus::WireCrc::kLibrary && wire_.max_data == slave_bus::WireFormat::kLibraryMaxData
                ? "; the ESP32_I2C_Slave library's 128-byte buffers)"
                : ")");
  }

  bool motionAllowed(uint8_t address) const
  {
    if (motion_->enabled())
    {
      return true;
    }
    const auto found = by_address_.find(address);
    return found != by_address_.end() && !startsMotion(slaves_[found->second].role);
  }

  void refuse(const std::string& why)
  {
    {
      std::lock_guard<std::mutex> lock(stats_mutex_);
      ++refused_;
    }
    ROS_ERROR_STREAM_THROTTLE(1.0, why);
  }

  /// Explicit frames queue as they are; commands join the last queued command step if their slot is
  /// still free there (so a second command to the same slave waits for the following step: none is lost).
  void enqueue(Step step, bool from_commands)
  {
    std::lock_guard<std::mutex> lock(queue_mutex_);
    if (from_commands)
    {
      const size_t slot = static_cast<size_t>(std::find_if(step.payloads.begin(), step.payloads.end(),
                                                           [](const std::vector<uint8_t>& p) { return !p.empty(); }) -
                                              step.payloads.begin());
      for (auto it = queue_.rbegin(); it != queue_.rend(); ++it)
      {
        if (!it->from_commands)
        {
          break;  // do not reorder commands across an explicit frame
        }
        if (it->payloads[slot].empty())
        {
          it->payloads[slot] = std::move(step.payloads[slot]);
          return;
        }
        break;
      }
      step.from_commands = true;
      step.first_command = std::chrono::steady_clock::now();
    }
    if (queue_.size() >= max_queued_)
    {
      std::lock_guard<std::mutex> stats_lock(stats_mutex_);
      ++refused_;
      ROS_ERROR_STREAM_THROTTLE(
          1.0, "slave bus: " << queue_.size() << " steps already queued (~max_queued_steps): step refused");
      return;
    }
    queue_.push_back(std::move(step));
    queue_cv_.notify_all();
  }

  /// Waits up to \p idle for a step that may leave now (woken at once by enqueue() and by
  /// disconnect()). \returns false if there is none yet.
  bool takeStep(Step& step, Milliseconds idle)
  {
    std::unique_lock<std::mutex> lock(queue_mutex_);
    const auto deadline = std::chrono::steady_clock::now() + idle;
    for (;;)
    {
      if (stopping_)
      {
        return false;
      }
      auto wait_until = deadline;
      if (!queue_.empty())
      {
        Step& front = queue_.front();
        const auto age = std::chrono::steady_clock::now() - front.first_command;
        if (!front.from_commands || queue_.size() > 1 || age >= command_delay_)
        {
          step = std::move(front);
          queue_.pop_front();
          return true;
        }
        // A step of commands: more commands may still join it until command_delay has passed.
        wait_until = std::min(deadline, front.first_command + command_delay_);
      }
      if (std::chrono::steady_clock::now() >= deadline)
      {
        return false;
      }
      queue_cv_.wait_until(lock, wait_until);
    }
  }

  // ---- link -------------------------------------------------------------------------------------

  void connect()
  {
    auto port = std::make_unique<SerialPort>(settings_);
    std::lock_guard<std::mutex> lock(link_mutex_);
    session_.reset();
    port_ = std::move(port);
    session_ = std::make_unique<slave_bus::BusSession>(*port_, framing_, bus_size_, resync_gap_, wire_);
  }

  void disconnect()
  {
    if (shutting_down_)
    {
      std::lock_guard<std::mutex> lock(queue_mutex_);
      stopping_ = true;
      queue_cv_.notify_all();
    }
    std::lock_guard<std::mutex> lock(link_mutex_);
    if (port_)
    {
      port_->interrupt();
    }
  }

  /// The I/O thread: sends queued steps one at a time and publishes what comes back.
  void ioLoop()
  {
    try
    {
      while (!stopping_)
      {
        Step step;
        // Idle, the thread waits on the queue, not on the link: a new step leaves at once. What the
        // master writes meanwhile (late answers, status) waits in the port and is read right after.
        if (takeStep(step, Milliseconds(20)))
        {
          state_.update([](MachineState& s) { s.execution = MachineState::EXECUTION_ACTIVE; });
          slave_bus::BusSession::StepResult result;
          try
          {
            result = session_->step(step.payloads, reply_timeout_);
          }
          catch (const ProtocolError& e)
          {
            refuse(std::string("step not sent: ") + e.what());
            continue;
          }
          handle(result.replies);
          handle(result.master_status);
          recordStep(step.payloads, result.missing);
          std::lock_guard<std::mutex> lock(queue_mutex_);
          if (queue_.empty())
          {
            state_.update([](MachineState& s) { s.execution = MachineState::EXECUTION_READY; });
          }
          continue;
        }
        handle(session_->poll(Milliseconds(0)));
        snapshotStats();
      }
    }
    catch (const CancelledError&)
    {
      if (!stopping_)
      {
        throw LinkError(settings_.describe() + ": interrupted");
      }
    }
    catch (const Error&)
    {
      snapshotStats();
      std::lock_guard<std::mutex> lock(link_mutex_);
      session_.reset();
      port_.reset();  // the Reconnector opens it again after a backoff
      throw;
    }
  }

  void handle(const std::vector<UplinkRecord>& records)
  {
    for (const auto& record : records)
    {
      if (record.address == 0)
      {
        onMasterStatus(record);
        continue;
      }
      const auto found = by_address_.find(record.address);
      if (found == by_address_.end())
      {
        std::lock_guard<std::mutex> lock(stats_mutex_);
        ++unknown_replies_;
        continue;
      }
      publishResponse(slaves_[found->second], record);
    }
  }

  void publishResponse(Slave& slave, const UplinkRecord& record)
  {
    SlaveResponse msg;
    msg.header.stamp = ros::Time::now();
    msg.name = slave.name;
    msg.address = slave.address;
    msg.data = record.payload;
    bool decoded = true;
    try
    {
      for (const int32_t value : slave_bus::decodeValues(record.payload, slave.encoding))
      {
        // Axis answers are device units: back to metres with the same scale.
        msg.values.push_back(isAxis(slave.role) ? value / slave.scale : value);
      }
    }
    catch (const ProtocolError&)
    {
      decoded = false;
      msg.values.clear();
    }
    {
      std::lock_guard<std::mutex> lock(stats_mutex_);
      ++slave.replies;
      slave.decode_errors += decoded ? 0 : 1;
    }
    if (isAxis(slave.role) && msg.values.size() == 1)
    {
      updateAxis(slave.role, msg.values[0], msg.header.stamp);
    }
    slave.response_pub.publish(msg);
  }

  void updateAxis(Role role, double metres, const ros::Time& stamp)
  {
    axis_seen_.insert(role);
    const bool all_known = axis_seen_.size() == axis_count_;
    state_.update(
        [&](MachineState& s)
        {
          s.header.stamp = stamp;
          (role == Role::kAxisX ? s.position.x : role == Role::kAxisY ? s.position.y : s.position.z) = metres;
          s.position_valid = all_known;
        });
  }

  void onMasterStatus(const UplinkRecord& record)
  {
    const auto code = record.payload.empty() ? 0 : record.payload[0];
    std::lock_guard<std::mutex> lock(stats_mutex_);
    ++master_reports_[code];
    // Codes 3 and 4 name the slave: count them against it (an unconfigured address stays bus-wide).
    const auto found = record.payload.size() > 1 ? by_address_.find(record.payload[1]) : by_address_.end();
    if (found != by_address_.end())
    {
      Slave& slave = slaves_[found->second];
      if (code == static_cast<uint8_t>(slave_bus::MasterStatus::kSlaveNoAnswer))
      {
        ++slave.read_failures;
      }
      else if (code == static_cast<uint8_t>(slave_bus::MasterStatus::kPayloadTooLong))
      {
        ++slave.too_long;
      }
    }
    if (code == static_cast<uint8_t>(slave_bus::MasterStatus::kBadFrame))
    {
      ROS_WARN_STREAM_THROTTLE(1.0, "slave bus master: a step frame arrived corrupted and was dropped");
    }
    else
    {
      ROS_WARN_STREAM_THROTTLE(
          1.0,
          "slave bus master: " << slave_bus::toString(static_cast<slave_bus::MasterStatus>(code))
                               << (record.payload.size() > 1 ? " (address " + std::to_string(record.payload[1]) + ")"
                                                             : std::string()));
    }
  }

  /// After a step went out: its payloads per slave, its timeouts and the session's counters, in one
  /// critical section so that one diagnostics message shows them consistently.
  void recordStep(const StepPayloads& payloads, const std::vector<uint8_t>& missing)
  {
    std::lock_guard<std::mutex> lock(stats_mutex_);
    for (size_t i = 0; i < payloads.size(); ++i)
    {
      const auto found = by_address_.find(static_cast<uint8_t>(i + 1));
      if (!payloads[i].empty() && found != by_address_.end())
      {
        ++slaves_[found->second].payloads_sent;
      }
    }
    session_stats_ = session_->stats();
    for (const uint8_t address : missing)
    {
      const auto found = by_address_.find(address);
      if (found != by_address_.end())
      {
        ++slaves_[found->second].timeouts;
      }
      else
      {
        ++unconfigured_timeouts_;
      }
    }
  }

  void snapshotStats()
  {
    std::lock_guard<std::mutex> lock(stats_mutex_);
    session_stats_ = session_->stats();
  }

  // ---- diagnostics ------------------------------------------------------------------------------

  void diagnose(diagnostic_updater::DiagnosticStatusWrapper& status)
  {
    std::lock_guard<std::mutex> lock(stats_mutex_);
    const auto& s = session_stats_;
    uint64_t timeouts = unconfigured_timeouts_;
    for (const auto& slave : slaves_)
    {
      timeouts += slave.timeouts;
    }
    const uint64_t link_errors = s.link.crc_errors + s.link.framing_errors;
    const uint64_t bad_frames = master_reports_[static_cast<uint8_t>(slave_bus::MasterStatus::kBadFrame)];
    const uint64_t read_failures = master_reports_[static_cast<uint8_t>(slave_bus::MasterStatus::kSlaveNoAnswer)];
    const uint64_t too_long = master_reports_[static_cast<uint8_t>(slave_bus::MasterStatus::kPayloadTooLong)];
    const uint64_t slave_errors = read_failures + too_long;
    if (timeouts > last_timeouts_ || link_errors > last_link_errors_ || bad_frames > last_bad_frames_ ||
        slave_errors > last_slave_errors_)
    {
      status.summary(diagnostic_msgs::DiagnosticStatus::WARN,
                     "slaves timed out, frames were corrupted, or the master reported a slave error");
    }
    else
    {
      status.summary(diagnostic_msgs::DiagnosticStatus::OK, "steps flowing");
    }
    last_timeouts_ = timeouts;
    last_link_errors_ = link_errors;
    last_bad_frames_ = bad_frames;
    last_slave_errors_ = slave_errors;
    status.add("framing", slave_bus::toString(framing_));
    status.add("WirePacker CRC", slave_bus::toString(wire_.crc));
    status.add("max payload", wire_.max_data);
    status.add("bus size", bus_size_);
    motion_->addTo(status);
    status.add("frames sent", s.steps_sent);
    status.add("bytes sent", s.bytes_sent);
    status.add("bytes received", s.bytes_received);
    status.add("replies", s.replies);
    status.add("timeouts", timeouts);
    status.add("uplink CRC errors", s.link.crc_errors);
    status.add("uplink framing errors", s.link.framing_errors);
    status.add("uplink garbage bytes", s.link.garbage_bytes);
    status.add("uplink resyncs", s.resyncs);
    status.add("frames the master dropped (bad CRC)", bad_frames);
    status.add("payloads for absent slaves",
               master_reports_[static_cast<uint8_t>(slave_bus::MasterStatus::kNoSuchSlave)]);
    status.add("slave reads that failed (master status 3)", read_failures);
    status.add("payloads too long for the master (status 4)", too_long);
    status.add("replies from unconfigured addresses", unknown_replies_);
    status.add("refused inputs", refused_);
    // Per slave, one numeric key each, "<name>: <counter>", so that tools and tests can read them.
    for (const auto& slave : slaves_)
    {
      const std::string prefix = slave.name + ": ";
      status.add(prefix + "address", static_cast<int>(slave.address));
      status.add(prefix + "payloads sent", slave.payloads_sent);
      status.add(prefix + "replies", slave.replies);
      status.add(prefix + "timeouts", slave.timeouts);
      status.add(prefix + "undecodable replies", slave.decode_errors);
      status.add(prefix + "failed reads (status 3)", slave.read_failures);
      status.add(prefix + "payloads too long (status 4)", slave.too_long);
    }
  }

  ros::NodeHandle nh_;
  SerialSettings settings_;
  MachineStatePublisher state_;
  slave_bus::Framing framing_ = slave_bus::Framing::kRaw;
  slave_bus::WireFormat wire_;
  std::unique_ptr<RuntimeSwitch> motion_;
  Milliseconds reply_timeout_{500};
  Milliseconds command_delay_{5};
  Milliseconds resync_gap_{50};
  size_t max_queued_ = 100;
  size_t bus_size_ = 0;
  size_t highest_address_ = 0;
  size_t axis_count_ = 0;
  std::vector<Slave> slaves_;  // fixed after construction: subscribers keep indices into it
  std::map<uint8_t, size_t> by_address_;
  std::set<Role> axis_seen_;  // I/O thread only
  ros::Subscriber frame_sub_;

  std::mutex queue_mutex_;
  std::condition_variable queue_cv_;
  std::deque<Step> queue_;
  std::atomic<bool> shutting_down_{false};
  std::atomic<bool> stopping_{false};  // set under queue_mutex_ so that a waiting takeStep() sees it

  std::mutex link_mutex_;  // guards port_ against disconnect() from another thread
  std::unique_ptr<SerialPort> port_;
  std::unique_ptr<slave_bus::BusSession> session_;  // I/O thread only
  std::unique_ptr<Reconnector> reconnector_;

  std::mutex stats_mutex_;  // lock order: queue_mutex_ before stats_mutex_
  slave_bus::BusSession::Stats session_stats_;
  std::map<uint8_t, uint64_t> master_reports_;
  uint64_t unknown_replies_ = 0;
  uint64_t unconfigured_timeouts_ = 0;
  uint64_t refused_ = 0;
  uint64_t last_timeouts_ = 0, last_link_errors_ = 0, last_bad_frames_ = 0, last_slave_errors_ = 0;
};
}  // namespace cnc_bridge

int main(int argc, char** argv)
{
  return cnc_bridge::runNode<cnc_bridge::SlaveBusNode>(argc, argv, "slave_bus_node", {2});
}
