// dnc_node's settings as its parameters give them (docs/dnc_node.md, "Parameters"): the port, the
// program directory, the protected range and the archive, the default protocol and the XModem
// text handling, waits and limits. ROS-free: the node reads them in one place (dnc_params.cpp) and
// builds the core objects from them.
#pragma once

#include <string>

#include "cnc_bridge/transport/link_factory.h"
#include "cnc_bridge/xmodem/file_transfer.h"
#include "cnc_bridge/xmodem/session.h"

namespace cnc_bridge::dnc
{
struct TransferSettings
{
  /// The control's serial line (a port or a device server), opened keeping what the control sent
  /// while it was closed (InputOnOpen::kKeep: a receiving control's NAK is its start request).
  LinkSettings link;
  std::string lock_dir;  ///< of the port lock shared with a status poller on the same line
  std::string program_dir;
  std::string protected_programs = "O08000-O09999";  ///< "" for none
  bool allow_protected_programs = false;
  std::string name_pattern = "O%05d.nc";
  std::string archive_dir;  ///< "": <program_dir>.archive
  unsigned archive_keep = 20;
  std::string default_protocol = "xmodem";  ///< when a request leaves it empty
  bool keep_open = false;                   ///< the port stays open between transfers
  xmodem::TextOptions text;
  xmodem::Config xmodem;
  double feedback_period = 0.05;  ///< s, action feedback at most this often
};
}  // namespace cnc_bridge::dnc
