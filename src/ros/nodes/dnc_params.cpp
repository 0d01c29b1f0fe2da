// dnc_node's parameters (dnc_node.h; docs/dnc_node.md, "Parameters"), read in one place into the
// core settings the node is built from. The drip-feed's and the program requests' own parameters
// are read where those are set up (dnc_drip_handlers.cpp, dnc_requests.cpp).
#include <algorithm>
#include <string>

#include "cnc_bridge/common/port_lock.h"
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
}  // namespace

dnc::TransferSettings dncSettings(const ros::NodeHandle& pnh)
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
}  // namespace cnc_bridge
