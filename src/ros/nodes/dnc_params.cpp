// dnc_node's parameters (dnc_node.h; docs/dnc_node.md, "Parameters"), all read here into the core
// settings the node's session is built from (cnc_bridge/dnc/dnc_settings.h): the port and the
// transfers, the drip-feed and backup (~drip_*, ~backup_*; docs/dnc_drip_feed.md), the program
// requests (~requests, ~request_*). Errors name the parameter. ~enable_motion is the motion
// switch's (RuntimeSwitch, dnc_node.cpp).
#include <algorithm>
#include <string>

#include "cnc_bridge/common/error.h"
#include "cnc_bridge/common/port_lock.h"
#include "cnc_bridge/dnc/dnc_codes.h"
#include "cnc_bridge/ros/params.h"
#include "cnc_bridge/xmodem/network_waits.h"
#include "dnc_node.h"

namespace cnc_bridge
{
namespace
{
// XModem timing (seconds) and limits; defaults are the protocol's (docs/protocols/xmodem.md#timeouts-and-limits).
dnc::XmodemWaits xmodemWaits(const ros::NodeHandle& pnh, bool networked)
{
  dnc::XmodemWaits waits;
  // ~start_timeout: receiving, how long to wait for the control to start sending (the operator
  // starts the punch on the control), NAK repeated every ~nak_interval meanwhile.
  waits.start_timeout = params::seconds(pnh, "start_timeout", 120.0);
  waits.nak_interval = params::seconds(pnh, "nak_interval", 10.0);
  // ~start_wait: sending, how long to wait for the control's NAK (the operator starts the receive).
  waits.start_wait = params::seconds(pnh, "start_wait", 120.0);
  // ~block_timeout: receiving, wait for the next packet before a NAK.
  waits.block_timeout = params::seconds(pnh, "block_timeout", 10.0);
  // ~ack_timeout: sending, wait for ACK/NAK after a packet before sending it again.
  waits.ack_timeout = params::seconds(pnh, "ack_timeout", 10.0);
  // ~eot_quiet: receiving, silence after EOT before it is believed (a garbled SOH looks like EOT).
  waits.eot_quiet = params::seconds(pnh, "eot_quiet", 0.03);
  // ~wait_characters (int), ~wait_floor (s): the longest gap between two bytes of a packet and the
  // silence that ends the purge of a garbled packet before a NAK, in character times of the line,
  // at least wait_floor. 0 (the launch file's) or not set: 30 and 0.03 s on a cable (1 s at 300
  // baud, 30 ms at 9600 and above), 140 and 0.2 s at a device server (xmodem/network_waits.h).
  const int characters = pnh.param("wait_characters", 0);
  waits.wait_characters = characters > 0 ? static_cast<unsigned>(characters)
                          : networked    ? xmodem::kNetworkWaitCharacters
                                         : 30u;
  const double floor = pnh.param("wait_floor", 0.0);
  waits.wait_floor = floor > 0   ? Milliseconds(static_cast<int64_t>(floor * 1000.0))
                     : networked ? xmodem::kNetworkWaitFloor
                                 : Milliseconds(30);
  // ~char_timeout, ~purge_quiet (s, default 0: from the line rate as above): fixed values instead.
  if (pnh.param("char_timeout", 0.0) > 0)
    waits.char_timeout = params::seconds(pnh, "char_timeout", 1.0);
  if (pnh.param("purge_quiet", 0.0) > 0)
    waits.purge_quiet = params::seconds(pnh, "purge_quiet", 1.0);
  // ~max_retries (int, default 10): errors in a row on one block before the transfer aborts.
  const int max_retries = pnh.param("max_retries", 10);
  if (max_retries < 1)
    ROS_WARN("~max_retries %d is below 1; using 10", max_retries);
  waits.max_retries = max_retries < 1 ? 10u : static_cast<unsigned>(max_retries);
  return waits;
}

dnc::TransferSettings transferSettings(const ros::NodeHandle& pnh)
{
  dnc::TransferSettings settings;
  // ~port, ~baud (default 115200), ~data_bits, ~parity, ~stop_bits, ~flow_control (params.h).
  settings.link = params::serialLink(pnh, 115200, InputOnOpen::kKeep);
  // ~lock_dir (string, default /run/lock/cnc_bridge): directory of the serial-port lock shared with a status
  // poller on the same line (haas_mdc_node ~lock_dir; both must name the same directory).
  settings.lock_dir = pnh.param<std::string>("lock_dir", kDefaultLockDir);
  // ~program_dir (string, required): the only directory files are read from and written to;
  // created if it does not exist.
  settings.program_dir = params::required<std::string>(pnh, "program_dir");
  // ~protected_programs (string, default "O08000-O09999"; "" for none): program numbers never
  // sent (by any protocol) unless ~allow_protected_programs (bool, default false) is set. A Haas
  // keeps its probing/WIPS and OEM macros there. The number is taken from the file name (by
  // ~name_pattern, default "O%05d.nc") and from the program's first block.
  settings.protected_programs = pnh.param<std::string>("protected_programs", "O08000-O09999");
  settings.allow_protected_programs = pnh.param("allow_protected_programs", false);
  settings.name_pattern = pnh.param<std::string>("name_pattern", "O%05d.nc");
  // ~archive_dir (string, default <program_dir>.archive), ~archive_keep (int, default 20): every
  // program sent or received is kept there, one folder per program, distinct versions only
  // (docs/share_node.md, "Program archive").
  settings.archive_dir = pnh.param<std::string>("archive_dir", "");
  settings.archive_keep = static_cast<unsigned>(std::max(1, pnh.param("archive_keep", 20)));
  // ~xmodem_mode (string, default "xmodem"): protocol when a request leaves it empty. A Haas
  // speaks XModem checksum only (xmodem); xmodem-crc and xmodem-1k suit PC-based controls.
  settings.default_protocol = pnh.param<std::string>("xmodem_mode", "xmodem");
  xmodem::parseMode(settings.default_protocol);  // fails early on a typo
  // ~keep_open (bool, default false): keep the port open between transfers (otherwise it is opened
  // for each transfer, so other programs can use the port in between).
  settings.keep_open = pnh.param("keep_open", false);
  // ~eob (string, default "lf"): the control's end-of-block pattern, Haas setting 25
  // (lf, cr, crlf, crcr, lflf). Programs are sent with it.
  settings.text.control_eob = xmodem::parseEob(pnh.param<std::string>("eob", "lf"));
  // ~eob_checksum (string, default "wire"): how the control sums a checksum-mode packet holding
  // ends of block: wire (the bytes sent, as every XModem) or lf (each end of block as LF, as one
  // description of the Haas has it). A receive that meets the other reading says so.
  settings.text.eob_checksum = xmodem::parseEobChecksum(pnh.param<std::string>("eob_checksum", "wire"));
  // ~file_eob (string, default "lf"): line ends of programs stored in ~program_dir.
  settings.text.file_eob = xmodem::parseEob(pnh.param<std::string>("file_eob", "lf"));
  // ~binary (bool, default false): move bytes exactly (no EOB conversion; received files keep the
  // SUB padding of the last block).
  settings.text.binary = pnh.param("binary", false);
  settings.xmodem =
      dnc::xmodemConfig(xmodemWaits(pnh, settings.link.networked()), settings.link.serial.charactersPerSecond());
  settings.xmodem.eob_checksum_name = pnh.resolveName("eob_checksum");
  // ~max_program_bytes (int, default 16 MiB): the longest program moved by XModem.
  dnc::setMaxProgramBytes(settings.xmodem,
                          pnh.param("max_program_bytes", static_cast<int>(xmodem::kDefaultMaxProgramBytes)),
                          "~max_program_bytes");
  // ~feedback_rate (Hz, default 20): action feedback at most this often (and after the last block).
  settings.feedback_period = 1.0 / params::positive(pnh, "feedback_rate", 20.0);
  return settings;
}

/// A duration parameter in seconds where 0 means "no limit" (params::seconds() wants > 0).
Milliseconds secondsOrZero(const ros::NodeHandle& pnh, const std::string& name, double fallback)
{
  double value = pnh.param(name, fallback);
  if (!(value >= 0))
  {
    ROS_WARN("%s must be >= 0 seconds, not %g; using %g", pnh.resolveName(name).c_str(), value, fallback);
    value = fallback;
  }
  return Milliseconds(static_cast<int64_t>(value * 1000.0));
}

// ~drip_eob, ~drip_flow, ~drip_pace, ~drip_realtime_priority, ~drip_chunk, ~drip_xoff_allowance,
// ~drip_add_percent, ~drip_leader, ~drip_trailer, ~drip_leader_char, ~dc_codes: what the feed
// sends around and between the program's lines, and how fast.
void readDripFraming(const ros::NodeHandle& pnh, const SerialSettings& serial, dnc::DripOptions& drip)
{
  // ~drip_eob (string, default "lf"): end of block sent after each line: lf (ISO, Fanuc), cr
  // (EIA), crlf (Haas), lfcr, lfcrcr.
  drip.eob = dnc::parseEob(pnh.param<std::string>("drip_eob", "lf"));
  // ~drip_flow (string, default "xonxoff"): xonxoff (DC3/DC1 read by the node, parity bit
  // masked), rtscts (the port's hardware handshake), none.
  drip.flow = dnc::parseDripFlow(pnh.param<std::string>("drip_flow", "xonxoff"));
  // ~drip_pace (bool, default true): write no faster than the line carries (baud / bits per
  // character), so at most ~drip_xoff_allowance characters can follow an XOFF.
  if (pnh.param("drip_pace", true))
    drip.pace_cps = serial.charactersPerSecond();
  // ~drip_realtime_priority (int, default 0): SCHED_FIFO priority of the feeding thread while a
  // feed runs (0 = normal scheduler). Keeps the pacing on time on a loaded machine; needs
  // CAP_SYS_NICE (a warning and the normal scheduler without it).
  drip.realtime_priority = std::max(0, pnh.param("drip_realtime_priority", 0));
  // ~drip_chunk (int, default 4): characters per write.
  drip.chunk = static_cast<size_t>(std::max(1, pnh.param("drip_chunk", 4)));
  // ~drip_xoff_allowance (int, default 10): characters the control takes after its XOFF (Fanuc: 10).
  drip.xoff_allowance = static_cast<size_t>(std::max(1, pnh.param("drip_xoff_allowance", 10)));
  // ~drip_add_percent (bool, default true): frame with '%' when the file does not.
  pnh.param("drip_add_percent", drip.add_percent, true);
  // ~drip_leader, ~drip_trailer (int, default 0): leader/trailer characters (tape feed).
  drip.leader_length = static_cast<size_t>(std::max(0, pnh.param("drip_leader", 0)));
  drip.trailer_length = static_cast<size_t>(std::max(0, pnh.param("drip_trailer", 0)));
  // ~drip_leader_char (string, default "nul"): nul, lf or space.
  const std::string leader_char = pnh.param<std::string>("drip_leader_char", "nul");
  if (leader_char == "nul")
    drip.leader_char = 0;
  else if (leader_char == "lf")
    drip.leader_char = '\n';
  else if (leader_char == "space")
    drip.leader_char = ' ';
  else
    throw ConfigError(pnh.resolveName("drip_leader_char") + " must be nul, lf or space, not '" + leader_char + "'");
  // ~dc_codes (bool, default false): DC2 before and DC4 after the program (Haas setting 14).
  pnh.param("dc_codes", drip.dc_codes, false);
}

// ~drip_allow_lowercase, ~drip_hold_timeout, ~drip_hold_action, ~drip_wait_for_dc1,
// ~drip_start_timeout: what the feed refuses and how long it waits for the control.
void readDripWaits(const ros::NodeHandle& pnh, dnc::DripOptions& drip)
{
  // ~drip_allow_lowercase (bool, default false): lowercase passes the check (8N1 controls that
  // take it in comments); under ISO (7E1) leave it off.
  drip.rules.reject_lowercase = !pnh.param("drip_allow_lowercase", false);
  // ~drip_hold_timeout (s, default 0 = wait forever): longest XOFF before ~drip_hold_action.
  drip.hold_timeout = secondsOrZero(pnh, "drip_hold_timeout", 0.0);
  // ~drip_hold_action (string, default "fail"): fail, or resume (assume the XON was lost).
  const std::string hold_action = pnh.param<std::string>("drip_hold_action", "fail");
  if (hold_action != "fail" && hold_action != "resume")
    throw ConfigError(pnh.resolveName("drip_hold_action") + " must be fail or resume, not '" + hold_action + "'");
  drip.on_hold_timeout = hold_action == "resume" ? dnc::HoldTimeoutAction::kResume : dnc::HoldTimeoutAction::kFail;
  // ~drip_wait_for_dc1 (bool, default false): send nothing until the control asks (DC1);
  // ~drip_start_timeout (s, default 0 = forever) bounds that wait.
  pnh.param("drip_wait_for_dc1", drip.wait_for_dc1, false);
  drip.start_timeout = secondsOrZero(pnh, "drip_start_timeout", 0.0);
}

// The drip-feed (~drip_*) and the backup (~backup_*), docs/dnc_drip_feed.md.
dnc::DripSettings dripSettings(const ros::NodeHandle& pnh, const dnc::TransferSettings& transfer)
{
  dnc::DripSettings settings;
  readDripFraming(pnh, transfer.link.serial, settings.drip);
  readDripWaits(pnh, settings.drip);
  settings.drip.progress_interval = Milliseconds(static_cast<int64_t>(transfer.feedback_period * 1000));
  settings.drip.validate();
  // ~backup_start_timeout (s, default 120; 0 = forever): wait for the control to start punching.
  settings.backup.start_timeout = secondsOrZero(pnh, "backup_start_timeout", 120.0);
  // ~backup_quiet_timeout (s, default 5): silence that ends a program punched without closing '%'.
  settings.backup.quiet_timeout = params::seconds(pnh, "backup_quiet_timeout", 5.0);
  // ~backup_send_dc1 (bool, default true): send DC1 when ready to receive.
  pnh.param("backup_send_dc1", settings.backup.send_dc1, true);
  settings.backup.progress_interval = settings.drip.progress_interval;
  return settings;
}

// Program requests punched by the control (docs/dnc_node.md, "Program requests from the control").
dnc::RequestSettings requestSettings(const ros::NodeHandle& pnh, const dnc::TransferSettings& transfer)
{
  dnc::RequestSettings settings;
  // ~requests (bool, default false): listen for request programs the control punches. Off by
  // default: the node then holds the port open and writes a NAK every ~nak_interval (XModem) on a
  // line that other programs, or a status poller, may share.
  pnh.param("requests", settings.enabled, false);
  // ~request_mode (string, default "xmodem"): how the control punches and takes programs, as its
  // RS-232 is set (Haas setting 14): xmodem (the node NAKs, the control sends blocks; a LOAD is
  // answered by ~xmodem_mode) or drip ('%'-framed text; a LOAD is answered by drip-feed).
  settings.mode = pnh.param<std::string>("request_mode", "xmodem");
  dnc::RequestListenerOptions& listener = settings.listener;
  listener.wire = dnc::parseRequestWire(settings.mode);  // a typo fails at start-up
  listener.mode = xmodem::parseMode(transfer.default_protocol);
  listener.xmodem = transfer.xmodem;
  listener.text = transfer.text;
  if (listener.wire == dnc::RequestWire::kText)
  {
    // Text punches and answers use the drip-feed's end of block where XModem's patterns know it.
    const std::string eob = pnh.param<std::string>("drip_eob", "lf");
    try
    {
      listener.text.control_eob = xmodem::parseEob(eob);
    }
    catch (const ConfigError&)
    {
      ROS_WARN("request answers are sent with ~eob, not ~drip_eob '%s'", eob.c_str());
    }
  }
  // ~backup_quiet_timeout (s, default 5): a text punch without its closing '%' ends after this
  // much silence (as a backup does).
  listener.text_quiet = params::seconds(pnh, "backup_quiet_timeout", 5.0);
  // ~request_load_words (string, default "LOAD SEND"), ~request_save_words (string, default
  // "SAVE"): the words that make a punched program's comment a request, as share_node's.
  settings.words = programs::RequestWords::parse(
      pnh.param<std::string>("request_load_words", "LOAD SEND"), pnh.param<std::string>("request_save_words", "SAVE"),
      pnh.resolveName("request_load_words"), pnh.resolveName("request_save_words"));
  // ~request_answer_number (int, default 1): the O number of an answer program when the request
  // program the operator punched has none (it normally has: the answer then replaces it).
  const int answer = pnh.param("request_answer_number", 1);
  settings.answer_number = answer > 0 && answer <= 99999999 ? static_cast<uint32_t>(answer) : 1;
  return settings;
}
}  // namespace

dnc::DncSettings dncSettings(const ros::NodeHandle& pnh)
{
  dnc::DncSettings settings;
  settings.transfer = transferSettings(pnh);
  settings.drip = dripSettings(pnh, settings.transfer);
  settings.requests = requestSettings(pnh, settings.transfer);
  return settings;
}
}  // namespace cnc_bridge
