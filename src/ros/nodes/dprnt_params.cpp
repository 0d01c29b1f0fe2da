// dprnt_node's parameters (docs/dprnt_node.md, parameters), read in one place into the core's
// settings.
#include <string>
#include <vector>

#include "cnc_bridge/common/error.h"
#include "cnc_bridge/dprnt/rules.h"
#include "cnc_bridge/ros/params.h"
#include "dprnt_node.h"

namespace cnc_bridge
{
namespace
{
dprnt::InputSettings inputSettings(const ros::NodeHandle& pnh)
{
  dprnt::InputSettings input;
  // ~input: where DPRNT output arrives: serial (Haas Classic, NGC with RS-232), tcp (NGC setting 261
  // = TCP, the control listens on setting 263), file (NGC setting 261 = file, path in 262) or
  // topic (the lines haas_mdc_node reads on a Classic's port it shares: its ~forward_dprnt).
  const std::string kind = params::choice(pnh, "input", "serial", {"serial", "tcp", "file", "topic"});
  // ~reconnect_min, ~reconnect_max: s, backoff between attempts to (re)open the link.
  input.backoff = Backoff(params::seconds(pnh, "reconnect_min", 0.25), params::seconds(pnh, "reconnect_max", 10.0));
  if (kind == "serial")
  {
    input.link = params::serialLink(pnh, 9600);
  }
  else if (kind == "tcp")
  {
    // ~host, ~tcp_port (required: the control's DPRNT port, Haas NGC setting 263), ~connect_timeout.
    params::TcpLinkDefaults tcp;
    tcp.connect_timeout = 3.0;
    input.link = params::tcpLink(pnh, tcp);
  }
  else if (kind == "file")
  {
    input.kind = dprnt::InputSettings::Kind::kFile;
    // ~file: the file the control appends DPRNT output to (Haas NGC setting 262), e.g. on a share.
    input.file = params::required<std::string>(pnh, "file");
    // ~from_start: publish what the file already holds when the node starts (else only new lines).
    pnh.param("from_start", input.from_start, false);
    // ~poll_period: s between looks at the file (inotify does not see writes over SMB).
    input.poll_period = params::seconds(pnh, "poll_period", 0.05);
  }
  else
  {
    input.kind = dprnt::InputSettings::Kind::kTopic;
    // ~input_topic: where haas_mdc_node publishes the port's DPRNT lines (relative: the machine's namespace).
    input.topic = pnh.param<std::string>("input_topic", input.topic);
  }
  return input;
}
}  // namespace

dprnt::DprntSettings dprntSettings(const ros::NodeHandle& pnh)
{
  dprnt::DprntSettings settings;
  settings.input = inputSettings(pnh);
  // ~max_line_length: characters; longer lines are reported (diagnostics) and skipped.
  int length = 256;
  pnh.param("max_line_length", length, length);
  if (length < 8)
  {
    ROS_WARN("~max_line_length %d is too short: using 256", length);
    length = 256;
  }
  settings.max_line_length = static_cast<size_t>(length);
  // ~mask_parity: clear bit 7 of every byte (7-bit even/odd parity lines read as 8N1).
  pnh.param("mask_parity", settings.mask_parity, true);
  // ~program_units: length unit of the macro programs (inch under G20, mm under G21); rules
  // without their own `units` convert point coordinates from it.
  pnh.param<std::string>("program_units", settings.program_units, "inch");
  // ~rules: YAML file of rules (format in config/dprnt_rules.yaml); empty: raw and values only.
  pnh.param<std::string>("rules", settings.rules_file, "");
  if (settings.rules_file.empty())
  {
    dprnt::RuleSet::unitScale(settings.program_units);  // still validate the parameter
  }
  // ~work_offset: [x, y, z] m, the work zero (G54) in <tf_prefix>machine, published as the static
  // transform <tf_prefix>machine -> <tf_prefix>work so points of `frame: work` rules can be placed
  // when nothing else publishes that frame. Empty (default): not published (haas_mdc_node
  // publishes it from the control's work offset variables).
  if (pnh.getParam("work_offset", settings.work_offset) && !settings.work_offset.empty() &&
      settings.work_offset.size() != 3)
  {
    throw ConfigError("Parameter " + pnh.resolveName("work_offset") + " needs [x, y, z] (m) or [].");
  }
  return settings;
}
}  // namespace cnc_bridge
