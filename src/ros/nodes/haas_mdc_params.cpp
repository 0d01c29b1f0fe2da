// haas_mdc_node's parameters (haas_mdc_node.h; docs/haas_mdc_node.md, parameters).
#include <algorithm>
#include <string>
#include <vector>

#include "cnc_bridge/common/error.h"
#include "cnc_bridge/ros/params.h"
#include "haas_mdc_node.h"

namespace cnc_bridge
{
namespace
{
std::vector<int> intList(const ros::NodeHandle& pnh, const std::string& name, const std::vector<int>& fallback)
{
  std::vector<int> values = fallback;
  pnh.param(name, values, fallback);
  for (int v : values)
  {
    if (v < 0)
    {
      throw ConfigError(pnh.resolveName(name) + ": variable numbers must not be negative, not " + std::to_string(v));
    }
  }
  return values;
}

// A poll period: at least 1 ms, so a node never polls a real control back to back.
Milliseconds period(const ros::NodeHandle& pnh, const std::string& name, double fallback_seconds)
{
  return std::max(params::seconds(pnh, name, fallback_seconds), Milliseconds(1));
}

// ~query_periods: {"Q500": 0.25, "Q600 5021": 0.1, "Q303": 0} -> per-query periods (0: not polled).
std::vector<std::pair<mdc::Query, Milliseconds>> queryPeriods(const ros::NodeHandle& pnh)
{
  std::vector<std::pair<mdc::Query, Milliseconds>> periods;
  XmlRpc::XmlRpcValue table;
  if (!pnh.getParam("query_periods", table))
    return periods;
  const std::string name = pnh.resolveName("query_periods");
  if (table.getType() != XmlRpc::XmlRpcValue::TypeStruct)
    throw ConfigError(name + " must be a dictionary of query: seconds, e.g. {Q500: 0.25, \"Q600 5021\": 0.1}");
  for (auto& [key, value] : table)
  {
    if (value.getType() == XmlRpc::XmlRpcValue::TypeDouble)
      periods.push_back(mdc::queryPeriod(name, key, static_cast<double>(value)));
    else if (value.getType() == XmlRpc::XmlRpcValue::TypeInt)
      periods.push_back(mdc::queryPeriod(name, key, static_cast<int>(value)));
    else
      throw ConfigError(name + "/" + key + " must be a number of seconds");
  }
  return periods;
}

// ~port (a Classic's serial port: ~baud, ~data_bits, ~parity, ~stop_bits, ~flow_control, ~lock_dir)
// or ~host, ~tcp_port (the control's MDC port, Haas setting 143), ~connect_timeout (an NGC's).
void readLink(const ros::NodeHandle& pnh, mdc::MdcSettings& settings)
{
  params::TcpLinkDefaults tcp;
  tcp.host_alternative = "nor ~port, the serial device of a Classic control";
  tcp.tcp_port = 5051;
  tcp.connect_timeout = 3.0;
  settings.link = params::link(pnh, 9600, tcp);
  // ~lock_dir: where the serial-port lock shared with dnc_node lives.
  pnh.param<std::string>("lock_dir", settings.lock_dir, kDefaultLockDir);
  // ~forward_dprnt: a Classic's one RS-232 port also carries the DPRNT output of its program:
  // lines that are no (STX/ETB-framed) reply go out on `dprnt/port_lines`, where dprnt_node with
  // input:=topic reads them (docs/dprnt_node.md). Serial only.
  pnh.param("forward_dprnt", settings.forward_dprnt, false);
  if (settings.forward_dprnt && !settings.link.isSerial())
  {
    throw ConfigError(pnh.resolveName("forward_dprnt") +
                      " needs ~port: only a Classic's serial port carries DPRNT between MDC replies (an NGC prints "
                      "DPRNT to its own TCP port: dprnt_node input:=tcp)");
  }
}

// The periods, the variables and the poll limits.
void readPolling(const ros::NodeHandle& pnh, mdc::MdcSettings& settings)
{
  mdc::PollPlan& plan = settings.plan;
  // ~status_period: s between Q500 (program, status, parts) polls, and Q104 (mode).
  plan.status_period = period(pnh, "status_period", 0.25);
  // ~variables_period: s between polls of each position variable and ~variables entry.
  plan.variables_period = period(pnh, "variables_period", 0.25);
  // ~counters_period: s between polls of tool in use, cycle times, M30 counters and #4006.
  plan.counters_period = period(pnh, "counters_period", 2.0);
  // ~max_unanswered: queries unanswered in a row before the link is reopened (0: never).
  int max_unanswered = 5;
  pnh.param("max_unanswered", max_unanswered, max_unanswered);
  plan.max_unanswered = static_cast<unsigned>(std::max(0, max_unanswered));
  mdc::PollVariables& vars = settings.vars;
  // ~position_variables: machine position X Y Z (Haas #5021-#5023); [] to not poll positions.
  vars.position = intList(pnh, "position_variables", {5021, 5022, 5023});
  // ~work_position_variables: work position X Y Z (#5041-#5043) giving the work offset; [] for none.
  vars.work = intList(pnh, "work_position_variables", {5041, 5042, 5043});
  // ~spindle_variable: spindle speed in rpm (#3027); 0 to not poll it.
  pnh.param("spindle_variable", vars.spindle, 3027);
  // ~variables: more macro variables polled via Q600 and shown in diagnostics (#100s, counters).
  vars.extra = intList(pnh, "variables", {});
  // ~watch_variables: macro variables polled like those and published on `variables` when one
  // changes (a robot's orchestration waits on them: the program sets #500 = 1, the part is ready).
  vars.watched = intList(pnh, "watch_variables", {});
  // ~units: linear unit of positions: auto (from G20/G21, #4006), inch or mm.
  vars.units = mdc::parseUnitSetting(pnh.param<std::string>("units", "auto"), pnh.resolveName("units"));
  vars.check(pnh.resolveName("position_variables"));
  vars.addTo(plan);
  // ~query_periods: per-query periods in s overriding the three above, keyed by the query
  // ("Q500", "Q600 5021"); a query not otherwise polled is added, 0 stops polling one.
  plan.query_periods = queryPeriods(pnh);
}
}  // namespace

mdc::MdcSettings haasMdcSettings(const ros::NodeHandle& pnh)
{
  mdc::MdcSettings settings;
  readLink(pnh, settings);
  // ~reply_timeout: s to wait for the reply to one query before counting it unanswered.
  settings.reply_timeout = params::seconds(pnh, "reply_timeout", 1.0);
  readPolling(pnh, settings);
  // ~writable_variables: macro variables ~write_variable may set with the E command; empty
  // (the default) disables writes.
  settings.writable_variables = intList(pnh, "writable_variables", {});
  return settings;
}
}  // namespace cnc_bridge
