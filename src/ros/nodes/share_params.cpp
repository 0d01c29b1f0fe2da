// share_node's parameters (docs/share_node.md), each part read, checked and returned as the
// core's settings (cnc_bridge/share/share_settings.h); src/ros/nodes/share_node.h declares them.
#include "share_node.h"

#include "cnc_bridge/ros/params.h"

namespace cnc_bridge
{
namespace
{
/// ~withdraw_at, which YAML reads as a number (minutes in base 60) unless it is quoted.
std::optional<programs::DailyTime> withdrawAt(const ros::NodeHandle& pnh)
{
  XmlRpc::XmlRpcValue given;
  if (pnh.getParam("withdraw_at", given) && given.getType() != XmlRpc::XmlRpcValue::TypeString)
    throw ConfigError(pnh.resolveName("withdraw_at") + " must be a string \"HH:MM\": quote it in YAML ('18:00'), " +
                      "which otherwise reads 18:00 as a number");
  return programs::DailyTime::parse(pnh.param<std::string>("withdraw_at", ""), pnh.resolveName("withdraw_at"));
}

/// A map parameter of machine name -> share address (\p name), each checked; empty when unset.
std::map<std::string, std::string> machineShares(const ros::NodeHandle& pnh, const std::string& name)
{
  std::map<std::string, std::string> shares;
  XmlRpc::XmlRpcValue given;
  if (!pnh.getParam(name, given))
    return shares;
  const std::string where = pnh.resolveName(name);
  if (given.getType() != XmlRpc::XmlRpcValue::TypeStruct)
    throw ConfigError(where + " must map each machine to its share: {haas_vf2: smb://10.0.0.5/memory, ...}");
  for (auto& [machine, address] : given)
  {
    share::checkMachineName(machine, where);
    if (address.getType() != XmlRpc::XmlRpcValue::TypeString || static_cast<std::string>(address).empty())
      throw ConfigError(where + "/" + machine + " must be the machine's share address (smb://host/share or a folder)");
    share::refusePassword(address, where + "/" + machine);
    shares[machine] = static_cast<std::string>(address);
  }
  return shares;
}
}  // namespace

share::StoreSettings readStoreSettings(const ros::NodeHandle& pnh)
{
  share::StoreSettings settings;
  // ~url (smb://[user@]host[:port]/share[/folder], or a local directory) or ~serve_dir (a local
  // folder the PC's Samba serves to the controls): exactly one.
  settings.address = share::shareAddress(pnh.param<std::string>("url", ""), pnh.param<std::string>("serve_dir", ""),
                                         pnh.resolveName("url"), pnh.resolveName("serve_dir"));
  // ~credentials_file (string, default "": guest): smbclient authentication file, mode 0600.
  settings.credentials_file = pnh.param<std::string>("credentials_file", "");
  // ~timeout (s, default 10): limit of every SMB request.
  settings.timeout = params::seconds(pnh, "timeout", 10.0);
  return settings;
}

share::ProgramSettings readProgramSettings(const ros::NodeHandle& pnh)
{
  share::ProgramSettings settings;
  // ~program_dir (string, required): the local folder programs are sent from and received into;
  // created if missing.
  settings.program_dir = params::required<std::string>(pnh, "program_dir");
  // ~name_pattern (string, default "O%05d.nc"): how the control names program files.
  settings.pattern = programs::NamePattern(pnh.param<std::string>("name_pattern", "O%05d.nc"));
  // ~protected_programs (default "O08000-O09999", "none"), ~allow_protected_programs (default
  // false): as dnc_node's.
  settings.protected_range =
      programs::ProtectedRange(pnh.param<std::string>("protected_programs", "O08000-O09999"),
                               pnh.param("allow_protected_programs", false), "~allow_protected_programs");
  // ~archive_dir (string, default <program_dir>.archive): every program sent or received is kept
  // there, one folder per program; ~archive_keep (int, default 20) versions each.
  std::string archive_dir;
  if (pnh.getParam("archive_dir", archive_dir))
    settings.archive_dir = archive_dir;
  settings.archive_keep = share::archiveKeep(pnh.param("archive_keep", 20));
  settings.machine = pnh.param<std::string>("machine", ros::this_node::getName());
  return settings;
}

share::RequestSettings readRequestSettings(const ros::NodeHandle& pnh)
{
  share::RequestSettings settings;
  // ~request_load_words (string, default "LOAD SEND"), ~request_save_words (string, default
  // "SAVE"): the words that make a comment or DPRNT line a request, as dnc_node's.
  settings.words = programs::RequestWords::parse(
      pnh.param<std::string>("request_load_words", "LOAD SEND"), pnh.param<std::string>("request_save_words", "SAVE"),
      pnh.resolveName("request_load_words"), pnh.resolveName("request_save_words"));
  // ~requests_folder (string, default "requests"; "" for none): a folder of the share where the
  // control drops request files ((LOAD O1234), (SEND O1234), (SAVE O1234)), served at each check.
  settings.folder = pnh.param<std::string>("requests_folder", "requests");
  // ~dprnt_requests (bool, default true): a DPRNT line `LOAD O1234` on dprnt/raw (dprnt_node in
  // the same machine namespace) is a request too.
  settings.dprnt = pnh.param("dprnt_requests", true);
  return settings;
}

share::NodeSettings readNodeSettings(const ros::NodeHandle& pnh)
{
  share::NodeSettings settings;
  // ~enable_remove (bool, default false): ~remove_program deletes from the share only when set.
  settings.enable_remove = pnh.param("enable_remove", false);
  // ~feedback_rate (Hz, default 20): action feedback at most this often.
  settings.feedback_rate = params::positive(pnh, "feedback_rate", 20.0);
  // ~publish_timeout (s, default 60): how long ~publish_to_machines waits for each machine's
  // ~send_program to answer.
  settings.publish_timeout = params::positive(pnh, "publish_timeout", 60.0);
  // ~withdraw_at (string "HH:MM", local time, default "": never): every day at that time every
  // program in the share is withdrawn (kept in the archive, then removed); ~withdraw_all does it
  // on request.
  settings.withdraw_at = withdrawAt(pnh);
  // ~check_period (s, default 5): how often the share is listed to keep the link state.
  settings.check_period = params::positive(pnh, "check_period", 5.0);
  return settings;
}

share::HubSettings readHubSettings(const ros::NodeHandle& pnh)
{
  share::HubSettings settings;
  // ~drop_to ({machine: share address}, default none): programs dropped onto this node's share
  // (the NAS) are pushed to each of these machines once complete.
  settings.drop_to = machineShares(pnh, "drop_to");
  // ~collect_from ({machine: share address}, default none): what these machines write on their
  // own shares is collected into the NAS folder named after the machine, each version archived.
  settings.collect_from = machineShares(pnh, "collect_from");
  // ~hub_period (s, default 5): how often the NAS and the machines are listed.
  settings.period = params::positive(pnh, "hub_period", 5.0);
  // ~hub_settle (s, default 2): a file unchanged this long is complete (a copy onto the NAS still
  // running is not pushed half-written).
  settings.settle = params::seconds(pnh, "hub_settle", 2.0);
  return settings;
}
}  // namespace cnc_bridge
