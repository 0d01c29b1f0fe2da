// dprnt_node: DPRNT output of a CNC control as stamped, typed ROS data. Bytes come from the serial
// port (Haas Classic), the NGC's DPRNT TCP port (setting 263) or a file the control appends to
// (setting 262); every line goes to dprnt/raw, its numbers to dprnt/values, and YAML rules turn
// matching lines into probe points, numbers and cycle events on their own topics.
#include <diagnostic_updater/diagnostic_updater.h>
#include <geometry_msgs/PointStamped.h>
#include <ros/ros.h>
#include <std_msgs/Float64.h>
#include <std_srvs/Trigger.h>
#include <tf2_ros/static_transform_broadcaster.h>

#include <cmath>
#include <limits>
#include <memory>
#include <mutex>

#include "cnc_bridge/CycleEvent.h"
#include "cnc_bridge/DprntLine.h"
#include "cnc_bridge/DprntValues.h"
#include "cnc_bridge/common/error.h"
#include "cnc_bridge/dprnt/input.h"
#include "cnc_bridge/dprnt/line_assembler.h"
#include "cnc_bridge/dprnt/parser.h"
#include "cnc_bridge/dprnt/rules.h"
#include "cnc_bridge/ros/machine_state_publisher.h"
#include "cnc_bridge/ros/node_main.h"
#include "cnc_bridge/ros/request_boundary.h"
#include "dprnt_node.h"

namespace cnc_bridge
{
namespace
{
/// \brief DPRNT lines another node read: haas_mdc_node forwards the lines of a Classic control's
/// one RS-232 port that are no MDC reply (its ~forward_dprnt), since only one reader may take the
/// port's bytes. Lines arrive whole, in the order read, stamped when read.
class TopicInput : public dprnt::DprntInput
{
 public:
  using LineHandler = std::function<void(const DprntLine&)>;
  TopicInput(ros::NodeHandle nh, std::string topic, LineHandler on_line)
      : nh_(nh), topic_(nh.resolveName(topic)), on_line_(std::move(on_line))
  {
  }
  void start(BytesHandler, StateHandler on_state, RestartHandler) override
  {
    // A deep queue: a program printing in a burst must not lose lines to a busy spinner.
    sub_ = nh_.subscribe<DprntLine>(topic_, 10000, [this](const DprntLine::ConstPtr& line) { on_line_(*line); });
    on_state(LinkState::kUp, "lines from " + topic_);
  }
  void stop() override { sub_.shutdown(); }
  std::string describe() const override { return "topic " + topic_; }
  unsigned reconnects() const override { return 0; }

 private:
  ros::NodeHandle nh_;
  std::string topic_;
  LineHandler on_line_;
  ros::Subscriber sub_;
};

// The input the settings name; a topic input is this layer's.
std::unique_ptr<dprnt::DprntInput> makeInput(const ros::NodeHandle& nh, const dprnt::InputSettings& settings,
                                             const TopicInput::LineHandler& on_line)
{
  if (settings.kind == dprnt::InputSettings::Kind::kTopic)
  {
    return std::make_unique<TopicInput>(nh, settings.topic, on_line);
  }
  return dprnt::makeInput(settings);
}
}  // namespace

/// \brief The ROS side of the DPRNT core: lines in, messages out. Thread-safe: the input thread
/// processes lines while the spinner serves ~clear and diagnostics, all under one mutex.
class DprntNode
{
 public:
  DprntNode(ros::NodeHandle nh, ros::NodeHandle pnh);
  DprntNode(ros::NodeHandle nh, ros::NodeHandle pnh, const dprnt::DprntSettings& settings);
  ~DprntNode();

 private:
  struct RulePublishers
  {
    ros::Publisher live;
    ros::Publisher last;  // latched dprnt/last/<rule>, for late subscribers
    uint64_t matches = 0;
  };

  void onBytes(const uint8_t* data, size_t size);
  void onForwardedLine(const DprntLine& line);
  void onLine(const dprnt::LineEvent& event, const ros::Time& stamp);
  void publishRule(const dprnt::RuleOutput& output, const std::string& line, const ros::Time& stamp);
  void onLinkState(LinkState state, const std::string& why);
  void onRestart(const std::string& why);
  void publishWorkOffset(const std::vector<double>& offset);
  void advertise(const ros::NodeHandle& pnh);
  bool clear(std_srvs::Trigger::Request& request, std_srvs::Trigger::Response& response);
  void diagnose(diagnostic_updater::DiagnosticStatusWrapper& status);

  ros::NodeHandle nh_;
  std::unique_ptr<dprnt::DprntInput> input_;
  std::unique_ptr<MachineStatePublisher> state_;
  dprnt::RuleSet rules_;
  std::string rules_file_;

  std::mutex mutex_;  // everything below; taken by the input thread per chunk
  dprnt::LineAssembler assembler_;
  std::vector<dprnt::LabeledValue> values_;
  std::vector<dprnt::RuleOutput> outputs_;
  std::vector<RulePublishers> rule_pubs_;
  ros::Time chunk_stamp_;
  uint64_t line_number_ = 0;
  uint64_t value_lines_ = 0;
  uint64_t link_failures_ = 0;
  LinkState link_ = LinkState::kDown;

  ros::Publisher raw_pub_;
  ros::Publisher values_pub_;
  ros::ServiceServer clear_srv_;
  std::unique_ptr<tf2_ros::StaticTransformBroadcaster> work_frame_;
};

DprntNode::DprntNode(ros::NodeHandle nh, ros::NodeHandle pnh) : DprntNode(nh, pnh, dprntSettings(pnh)) {}

DprntNode::DprntNode(ros::NodeHandle nh, ros::NodeHandle pnh, const dprnt::DprntSettings& settings)
    : nh_(nh), rules_file_(settings.rules_file), assembler_(settings.max_line_length, settings.mask_parity)
{
  input_ = makeInput(nh, settings.input, [this](const DprntLine& line) { onForwardedLine(line); });
  if (!rules_file_.empty())
  {
    rules_ = dprnt::RuleSet::fromFile(rules_file_, settings.program_units);
  }

  state_ = std::make_unique<MachineStatePublisher>(nh, pnh, input_->describe());
  state_->diagnostics().add("dprnt", this, &DprntNode::diagnose);
  publishWorkOffset(settings.work_offset);

  advertise(pnh);
  ROS_INFO("DPRNT from %s, %zu rules%s%s", input_->describe().c_str(), rules_.rules().size(),
           rules_file_.empty() ? "" : " from ", rules_file_.c_str());
  // Not under mutex_: an input may report its state from start() (the topic input does).
  input_->start([this](const uint8_t* data, size_t size) { onBytes(data, size); },
                [this](LinkState state, const std::string& why) { onLinkState(state, why); },
                [this](const std::string& why) { onRestart(why); });
}

void DprntNode::advertise(const ros::NodeHandle& pnh)
{
  // Publishers exist before the input thread can call into them.
  std::lock_guard<std::mutex> lock(mutex_);
  raw_pub_ = nh_.advertise<DprntLine>("dprnt/raw", 100);
  values_pub_ = nh_.advertise<DprntValues>("dprnt/values", 100);
  for (const auto& rule : rules_.rules())
  {
    RulePublishers pubs;
    const std::string last = "dprnt/last/" + rule.name;
    switch (rule.type)
    {
      case dprnt::OutputType::kPoint:
        pubs.live = nh_.advertise<geometry_msgs::PointStamped>(rule.topic, 100);
        pubs.last = nh_.advertise<geometry_msgs::PointStamped>(last, 1, true);
        break;
      case dprnt::OutputType::kFloat64:
        pubs.live = nh_.advertise<std_msgs::Float64>(rule.topic, 100);
        pubs.last = nh_.advertise<std_msgs::Float64>(last, 1, true);
        break;
      case dprnt::OutputType::kCycleEvent:
        pubs.live = nh_.advertise<CycleEvent>(rule.topic, 100);
        pubs.last = nh_.advertise<CycleEvent>(last, 1, true);
        break;
    }
    rule_pubs_.push_back(pubs);
  }
  clear_srv_ = advertiseGuardedService(pnh, "clear", &DprntNode::clear, this);
}

void DprntNode::publishWorkOffset(const std::vector<double>& offset)
{
  // ~work_offset (dprnt_params.cpp): the static transform <tf_prefix>machine -> <tf_prefix>work.
  if (offset.empty())
    return;
  geometry_msgs::TransformStamped t;
  t.header.stamp = ros::Time::now();
  t.header.frame_id = state_->frame("machine");
  t.child_frame_id = state_->frame("work");
  t.transform.translation.x = offset[0];
  t.transform.translation.y = offset[1];
  t.transform.translation.z = offset[2];
  t.transform.rotation.w = 1.0;
  work_frame_ = std::make_unique<tf2_ros::StaticTransformBroadcaster>();
  work_frame_->sendTransform(t);
  ROS_INFO("work frame %s at (%g, %g, %g) m in %s", t.child_frame_id.c_str(), offset[0], offset[1], offset[2],
           t.header.frame_id.c_str());
}

DprntNode::~DprntNode()
{
  input_->stop();
}

void DprntNode::onBytes(const uint8_t* data, size_t size)
{
  const ros::Time stamp = ros::Time::now();
  std::lock_guard<std::mutex> lock(mutex_);
  assembler_.feed(data, size, [&](const dprnt::LineEvent& event) { onLine(event, stamp); });
}

void DprntNode::onForwardedLine(const DprntLine& line)
{
  // The same path as bytes from a port (noise, parity and length checks, counters), stamped when
  // the forwarding node read the line.
  const std::string bytes = line.text + "\n";
  std::lock_guard<std::mutex> lock(mutex_);
  assembler_.feed(reinterpret_cast<const uint8_t*>(bytes.data()), bytes.size(),
                  [&](const dprnt::LineEvent& event) { onLine(event, line.header.stamp); });
}

void DprntNode::onLine(const dprnt::LineEvent& event, const ros::Time& stamp)
{
  if (event.kind == dprnt::LineEvent::Kind::kOverlong)
  {
    ROS_WARN_THROTTLE(5.0, "DPRNT line longer than %zu characters skipped (starts \"%.40s\")", assembler_.maxLength(),
                      std::string(event.text).c_str());
    return;
  }
  const std::string text(event.text);
  ++line_number_;
  DprntLine raw;
  raw.header.stamp = stamp;
  raw.machine = state_->machineName();
  raw.line_number = line_number_;
  raw.text = text;
  raw_pub_.publish(raw);

  if (dprnt::LineParser::parse(event.text, values_) > 0)
  {
    ++value_lines_;
    DprntValues values;
    values.header.stamp = stamp;
    values.machine = raw.machine;
    values.line_number = line_number_;
    values.text = text;
    values.values.resize(values_.size());
    for (size_t i = 0; i < values_.size(); ++i)
    {
      values.values[i].label = values_[i].label;
      values.values[i].value = values_[i].value;
    }
    values_pub_.publish(values);
  }
  rules_.evaluate(event.text, values_, outputs_);
  for (const auto& output : outputs_)
  {
    publishRule(output, text, stamp);
  }
}

void DprntNode::publishRule(const dprnt::RuleOutput& output, const std::string& line, const ros::Time& stamp)
{
  const dprnt::Rule& rule = rules_.rules()[output.rule];
  RulePublishers& pubs = rule_pubs_[output.rule];
  ++pubs.matches;
  switch (rule.type)
  {
    case dprnt::OutputType::kPoint:
    {
      geometry_msgs::PointStamped point;
      point.header.stamp = stamp;
      // "machine" and "work" are this machine's frames (docs/ROS_INTERFACE.md); anything else is taken as is.
      point.header.frame_id = rule.frame == "machine" || rule.frame == "work" ? state_->frame(rule.frame) : rule.frame;
      point.point.x = output.x;  // m (the core converted from rule.units)
      point.point.y = output.y;
      point.point.z = output.z;
      pubs.live.publish(point);
      pubs.last.publish(point);
      // The state's positions are what the control printed, no more: valid from the first such
      // line on, in the machine frame (the rule says which of the two it is).
      if (rule.state == dprnt::StateField::kPosition)
        state_->setPosition(output.x, output.y, output.z);
      else if (rule.state == dprnt::StateField::kCommandedPosition)
        state_->setCommandedPosition(output.x, output.y, output.z);
      break;
    }
    case dprnt::OutputType::kFloat64:
    {
      std_msgs::Float64 value;
      value.data = output.value;
      pubs.live.publish(value);
      pubs.last.publish(value);
      break;
    }
    case dprnt::OutputType::kCycleEvent:
    {
      const CycleEvent event = state_->cycleEvent(stamp, static_cast<uint8_t>(rule.event), output.program,
                                                  output.part_count, output.cycle_time, line);
      pubs.live.publish(event);
      pubs.last.publish(event);
      state_->update(
          [&](MachineState& s)
          {
            if (rule.event == dprnt::CycleEventKind::kStart)
              s.execution = MachineState::EXECUTION_ACTIVE;
            else if (rule.event == dprnt::CycleEventKind::kEnd)
              s.execution = MachineState::EXECUTION_READY;
            else if (rule.event == dprnt::CycleEventKind::kAlarm)
              s.execution = MachineState::EXECUTION_ALARM;
            if (output.part_count >= 0)
              s.part_count = output.part_count;
            if (!output.program.empty())
              s.program = output.program;
            s.message = line;
          });
      break;
    }
  }
}

void DprntNode::onLinkState(LinkState state, const std::string& why)
{
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (state == LinkState::kDown && link_ == LinkState::kUp)
    {
      ++link_failures_;
    }
    if (state != LinkState::kUp)
    {
      // A line cut by the link going away is incomplete: drop it (counted), never publish half.
      assembler_.reset();
    }
    link_ = state;
  }
  state_->setLink(state, why);
}

void DprntNode::onRestart(const std::string& why)
{
  std::lock_guard<std::mutex> lock(mutex_);
  // The file started over under a link that stays UP: an unfinished line belongs to the old
  // content. Drop it (counted in "partial lines dropped") rather than glue it to the new bytes.
  if (assembler_.pending() > 0)
  {
    ROS_WARN("%s: unfinished line dropped (\"%.60s\")", why.c_str(), std::string(assembler_.pendingText()).c_str());
  }
  assembler_.reset();
}

bool DprntNode::clear(std_srvs::Trigger::Request&, std_srvs::Trigger::Response& response)
{
  std::lock_guard<std::mutex> lock(mutex_);
  assembler_.clearStats();
  line_number_ = 0;
  value_lines_ = 0;
  link_failures_ = 0;
  for (auto& pubs : rule_pubs_)
  {
    pubs.matches = 0;
  }
  response.success = true;
  response.message = "DPRNT counters cleared";
  return true;
}

void DprntNode::diagnose(diagnostic_updater::DiagnosticStatusWrapper& status)
{
  std::lock_guard<std::mutex> lock(mutex_);
  const dprnt::AssemblerStats& stats = assembler_.stats();
  if (link_ != LinkState::kUp)
    status.summary(diagnostic_msgs::DiagnosticStatus::ERROR, "no DPRNT link");
  else if (stats.overlong > 0 || stats.garbage_bytes > 0)
    status.summary(diagnostic_msgs::DiagnosticStatus::WARN, "over-long lines or line noise seen");
  else
    status.summary(diagnostic_msgs::DiagnosticStatus::OK, "receiving");
  status.add("input", input_->describe());
  status.add("lines", stats.lines);
  status.add("lines with values", value_lines_);
  status.add("overlong", stats.overlong);
  status.add("garbage bytes", stats.garbage_bytes);
  status.add("control bytes", stats.control_bytes);
  status.add("empty lines", stats.empty_lines);
  status.add("partial lines dropped", stats.partial_dropped);
  status.add("bytes", stats.bytes);
  status.add("link failures", link_failures_);
  status.add("reconnects", input_->reconnects());
  for (size_t i = 0; i < rule_pubs_.size(); ++i)
  {
    status.add("rule " + rules_.rules()[i].name, rule_pubs_[i].matches);
  }
}
}  // namespace cnc_bridge

int main(int argc, char** argv)
{
  return cnc_bridge::runNode<cnc_bridge::DprntNode>(argc, argv, "dprnt_node");
}
