// ethernut_node's parameters, every one read here (ethernut_node.h; docs/ethernut_node.md,
// parameters) into the core's settings: the board's link and the client's options
// (ethernut::SessionSettings), how jobs are loaded (ethernut::JobSettings), the board's serial debug
// channel (ethernut::DebugChannelSettings).
#include "ethernut_node.h"

#include <algorithm>
#include <string>

#include "cnc_bridge/common/error.h"
#include "cnc_bridge/ros/gcode_params.h"
#include "cnc_bridge/ros/params.h"

namespace cnc_bridge
{
namespace ethernut_params
{
namespace
{
/// ~host, ~tcp_port, ~connect_timeout through the link factory: empty / 0 fall back on the qCNC
/// settings file's INET_ADD / INET_PORT (else 6666).
LinkSettings boardLink(const ros::NodeHandle& pnh, const ethernut::Settings& file)
{
  params::TcpLinkDefaults defaults;
  defaults.host = file.address.value_or("");  // ~host (string, ""): the board's address
  defaults.host_alternative = "nor INET_ADD in ~settings_file";
  defaults.tcp_port = file.port.value_or(6666);  // ~tcp_port (int, 0): the board's TCP port
  defaults.zero_port_is_default = true;
  defaults.connect_timeout = 3.0;  // ~connect_timeout (s, 3): TCP connection timeout
  return params::tcpLink(pnh, defaults);
}

ethernut::ClientOptions clientOptions(const ros::NodeHandle& pnh, const ethernut::Settings& file)
{
  ethernut::ClientOptions options;
  // ~dead_link_timeout (s, 0): silence after which the link is dead and is reconnected;
  // 0: INET_DEL (ms) of the settings file, else 2 s.
  const double dead = pnh.param("dead_link_timeout", 0.0);
  options.dead_link_timeout =
      dead > 0 ? Milliseconds(static_cast<long>(dead * 1000)) : Milliseconds(file.dead_link_ms.value_or(2000));
  // ~keepalive_period (s, 0.5): silence after which an alive request is sent.
  options.keepalive_period = params::seconds(pnh, "keepalive_period", 0.5);
  if (options.dead_link_timeout <= options.keepalive_period)
  {
    throw ConfigError(pnh.resolveName("dead_link_timeout") + " must be longer than " +
                      pnh.resolveName("keepalive_period"));
  }
  // ~rtt_probe_period (s, 5): an alive request also goes out when none did for this long, so the
  // link round trip is measured on a busy link too; 0: only when the board is silent.
  const double probe = pnh.param("rtt_probe_period", 5.0);
  if (probe < 0)
  {
    throw ConfigError(pnh.resolveName("rtt_probe_period") + " must be >= 0");
  }
  options.rtt_probe_period = Milliseconds(static_cast<long>(probe * 1000));
  // ~reply_timeout (s, 2): how long a command waits for the board's answer.
  options.reply_timeout = params::seconds(pnh, "reply_timeout", 2.0);
  // ~max_resends (int, 5): RESENDs accepted for one set of coordinates before the job fails.
  options.max_resends = static_cast<unsigned>(std::max(0, pnh.param("max_resends", 5)));
  // ~ack_position_reports (bool, true): answer the board's position reports with an ack (Table 1).
  pnh.param("ack_position_reports", options.ack_position_reports, true);
  // ~mode (string, "file"): board mode selected on every connection: file, gui-control, standalone.
  const std::string mode = pnh.param<std::string>("mode", "file");
  if (!ethernut::parseBoardMode(mode, options.initial_mode))
  {
    throw ConfigError(pnh.resolveName("mode") + " must be file, gui-control or standalone, not '" + mode + "'");
  }
  return options;
}

int intIn(const ros::NodeHandle& pnh, const std::string& name, int fallback, int low, int high)
{
  const int value = pnh.param(name, fallback);
  if (value < low || value > high)
  {
    throw ConfigError(pnh.resolveName(name) + " must be from " + std::to_string(low) + " to " + std::to_string(high) +
                      ", not " + std::to_string(value));
  }
  return value;
}

/// The board's serial debug channel (qCNC's SERIAL_DEV): none when ~debug_port is empty. qCNC's
/// documentation names only the device; the line settings default to 9600 8N1, set them to the board's.
std::optional<ethernut::DebugChannelSettings> debugChannel(const ros::NodeHandle& pnh)
{
  // ~debug_port (string, ""): the port the board prints its debug messages on: a device path,
  // tcp://host:port or rfc2217://host:port (a device server); empty: no debug channel.
  SerialSettings serial;
  serial.device = pnh.param<std::string>("debug_port", "");
  if (serial.device.empty())
  {
    return std::nullopt;
  }
  params::naming(pnh, "debug_port", [&] { return parseSerialAddress(serial.device); });
  // ~debug_baud (int, 9600), ~debug_data_bits (int, 8), ~debug_parity (none|even|odd),
  // ~debug_stop_bits (int, 1): the debug port's line settings.
  serial.baud = static_cast<unsigned>(intIn(pnh, "debug_baud", 9600, 1, 4000000));
  serial.data_bits = static_cast<unsigned>(intIn(pnh, "debug_data_bits", 8, 5, 8));
  serial.parity =
      params::naming(pnh, "debug_parity", [&] { return parseParity(pnh.param<std::string>("debug_parity", "none")); });
  serial.stop_bits = static_cast<unsigned>(intIn(pnh, "debug_stop_bits", 1, 1, 2));
  params::naming(pnh, "debug_port", [&] { serial.validate(); });
  ethernut::DebugChannelSettings debug;
  // Input held before the port was opened is what the board said meanwhile: kept.
  debug.link = LinkSettings::serialLine(serial, InputOnOpen::kKeep);
  // ~debug_max_line (int, 256): longest debug line published, in characters; a longer one is cut.
  debug.max_line = static_cast<size_t>(intIn(pnh, "debug_max_line", 256, 8, 65536));
  return debug;
}

ethernut::JobSettings jobSettings(const ros::NodeHandle& pnh)
{
  ethernut::JobSettings jobs;
  // ~program_dir (string, ""): directory G-code jobs are read from; empty: only point jobs.
  jobs.program_dir = pnh.param<std::string>("program_dir", "");
  // ~chord_tolerance (m, 0.00001): largest deviation of the streamed chords from a G02/G03 arc.
  jobs.parser.chord_tolerance_mm = params::positive(pnh, "chord_tolerance", 1e-5) / EthernutNode::kMetresPerMm;
  // ~gcode_dialect (string, "haas"): haas, fanuc or linuxcnc, where the controls read G-code
  // differently (docs/gcode.md); ~tool_table (string, ""): tool diameters for G41/G42.
  params::gcodeOptions(pnh, jobs.parser);
  // ~g53_moves (string, "refuse"): G53 moves (machine coordinates) in G-code jobs, which the
  // board cannot carry out (it knows one coordinate system): refuse (the job is refused before
  // anything is sent) or skip (left out of the stream and the preview).
  const bool skip_g53 = params::choice(pnh, "g53_moves", "refuse", {"refuse", "skip"}) == "skip";
  jobs.g53 = ethernut::G53Policy{skip_g53 ? ethernut::G53Moves::kSkip : ethernut::G53Moves::kRefuse,
                                 pnh.resolveName("g53_moves")};
  // ~max_preview_points (int, 100000): job/path is thinned to at most this many poses.
  jobs.max_preview_points = static_cast<size_t>(std::max(pnh.param("max_preview_points", 100000), 2));
  // ~soft_limits ({x: [min, max], ...} m, machine frame): every coordinate of a job is checked
  // against them before the job's first set is sent; not set: no soft limits.
  jobs.soft_limits = params::softLimits(pnh);
  return jobs;
}
}  // namespace

Settings read(const ros::NodeHandle& pnh)
{
  Settings settings;
  // ~settings_file (string, ""): a qCNC settings file (TSS, NAME|value); its INET_ADD, INET_PORT,
  // INET_DEL and PROG_CNCkill are used where the ROS parameters are left empty/zero.
  const std::string settings_file = pnh.param<std::string>("settings_file", "");
  ethernut::Settings file;
  if (!settings_file.empty())
  {
    file = ethernut::readSettingsFile(settings_file);
  }
  settings.session.link = boardLink(pnh, file);
  settings.session.client = clientOptions(pnh, file);
  // PROG_CNCkill|1 in the settings file enables ~kill as ~enable_kill does (qCNC enabled it by
  // default; we do not).
  if (file.kill_enabled.value_or(false))
  {
    settings.kill_enabled_by = "PROG_CNCkill|1 in " + settings_file;
  }
  settings.jobs = jobSettings(pnh);
  // ~transform_timeout (s, 0.5): how long a points goal in another frame waits for its transform
  // into the machine frame.
  settings.transform_timeout = params::positive(pnh, "transform_timeout", 0.5);
  settings.debug = debugChannel(pnh);
  return settings;
}
}  // namespace ethernut_params
}  // namespace cnc_bridge
