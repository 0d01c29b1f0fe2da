// dnc_node's settings as its parameters give them (docs/dnc_node.md, "Parameters"): the port, the
// program directory, the protected range and the archive, the default protocol and the XModem
// text handling, waits and limits; the drip-feed's and the backup's options; the program requests
// punched by the control. ROS-free: the node reads them in one place (dnc_params.cpp) and hands
// them to its core session (dnc/transfer_session.h).
#pragma once

#include <string>

#include "cnc_bridge/dnc/backup.h"
#include "cnc_bridge/dnc/drip_feed.h"
#include "cnc_bridge/dnc/program_requests.h"
#include "cnc_bridge/programs/program_request.h"
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

/// \brief The protocols `drip` (send) and `backup` (receive): ~drip_* and ~backup_* parameters.
struct DripSettings
{
  DripOptions drip;  ///< validated; progress_interval is the feedback period
  BackupOptions backup;
};

/// \brief Program requests punched by the control (~requests, ~request_*).
struct RequestSettings
{
  bool enabled = false;         ///< ~requests: listen on the idle port (holds it open, as ~keep_open)
  std::string mode = "xmodem";  ///< ~request_mode as given, for messages
  /// How a punch is read and an answer sent (its XModem config and text options are the transfers').
  RequestListenerOptions listener;
  programs::RequestWords words;
  uint32_t answer_number = 1;  ///< the answer's O number when the request program has none
};

/// \brief Everything dnc_node is built from.
struct DncSettings
{
  TransferSettings transfer;
  DripSettings drip;
  RequestSettings requests;
};
}  // namespace cnc_bridge::dnc
