// share_node's settings (docs/share_node.md), one struct per part of the node: the node reads them
// from its parameters (src/ros/nodes/share_params.cpp) and builds the core objects from them. What can
// be checked without ROS is checked here: ~url against ~serve_dir, the requests folder's name,
// the archive's version count.
#pragma once

#include <chrono>
#include <map>
#include <optional>
#include <string>

#include "cnc_bridge/programs/daily_time.h"
#include "cnc_bridge/programs/program_name.h"
#include "cnc_bridge/programs/program_request.h"

namespace cnc_bridge::share
{
/// \brief The share and how it is reached.
struct StoreSettings
{
  std::string address;           ///< smb://... or a local folder (~url or ~serve_dir)
  std::string credentials_file;  ///< smbclient authentication file; "" for guest
  std::chrono::milliseconds timeout{10000};
};

/// \brief The local side: the program folder, how the control names programs, the protected
/// range and the archive every transfer keeps its program in.
struct ProgramSettings
{
  std::string program_dir;
  programs::NamePattern pattern;
  programs::ProtectedRange protected_range{"O08000-O09999", false, "~allow_protected_programs"};
  std::optional<std::string> archive_dir;  ///< none: beside the program folder (archiveDir())
  unsigned archive_keep = 20;
  std::string machine;  ///< named in each archived version
};

/// \brief Program requests from the control: in request files of a folder of the share, and in
/// DPRNT lines.
struct RequestSettings
{
  programs::RequestWords words;
  std::string folder = "requests";  ///< a folder of the share; "" for none
  bool dprnt = true;
};

/// \brief The rest of the node: removal, withdrawals and the periods of its checks and answers.
struct NodeSettings
{
  bool enable_remove = false;
  std::optional<programs::DailyTime> withdraw_at;  ///< none: never
  double feedback_rate = 20;                       ///< Hz
  double publish_timeout = 60;                     ///< s, each machine of ~publish_to_machines
  double check_period = 5;                         ///< s
};

/// \brief The hybrid share (hybrid_share.h): the share of this node is the NAS; programs dropped
/// onto it are pushed to the machines of drop_to, and what the machines of collect_from write on
/// their shares is collected into the NAS folder of each (machine name -> share address).
struct HubSettings
{
  std::map<std::string, std::string> drop_to;
  std::map<std::string, std::string> collect_from;
  double period = 5;                       ///< s between polls
  std::chrono::milliseconds settle{2000};  ///< a file unchanged this long is complete
  bool enabled() const { return !drop_to.empty() || !collect_from.empty(); }
};

/// \brief Refuses a machine name that cannot be a folder of the NAS (empty, '/', '.', '..', a
/// control character): \p given_as names the parameter. \throws ConfigError.
void checkMachineName(const std::string& name, const std::string& given_as);

/// \brief Refuses an address (\p given_as names it: "~url", "--share") whose user information holds
/// a password (`smb://user:secret@host/...`): credentials come only from the credentials file. The
/// error names the parameter, never the address or the password.
/// \throws ConfigError.
void refusePassword(const std::string& address, const std::string& given_as);

/// \brief \p address for messages: its user information (between `://` and `@`) replaced by `***`
/// when it holds a ':' (a password), otherwise as given.
std::string shownAddress(const std::string& address);

/// \brief The share's address from ~url and ~serve_dir, of which exactly one is given (\p url_name
/// and \p serve_dir_name are how the user sets them, named in the errors). A served folder is
/// written like a local ~url; it must be an existing folder, not an smb:// address. An address with
/// a password in it is refused (refusePassword()).
/// \throws ConfigError naming what is wrong.
std::string shareAddress(const std::string& url, const std::string& serve_dir, const std::string& url_name,
                         const std::string& serve_dir_name);

/// \brief The address of the requests folder \p folder of the share at \p address.
/// \throws ConfigError if \p folder is no plain name inside the share (programs::checkName()).
std::string requestsAddress(const std::string& address, const std::string& folder);

/// \brief ~archive_dir if given, else `<program_root>.archive` beside the program folder
/// (\p program_root its resolved path, ProgramDirectory::root()).
std::string archiveDir(const std::optional<std::string>& given, const std::string& program_root);

/// \brief ~archive_keep as given: at least one version is kept.
unsigned archiveKeep(int given);
}  // namespace cnc_bridge::share
