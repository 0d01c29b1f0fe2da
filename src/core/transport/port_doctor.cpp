// Port problems explained: stat() and /proc say what open() only numbers.
#include "cnc_bridge/transport/port_doctor.h"

#include <dirent.h>
#include <grp.h>
#include <pwd.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <climits>
#include <cstring>
#include <fstream>
#include <sstream>

namespace cnc_bridge
{
const char* const kNoAnswerHint =
    "the control did not answer: check that it is waiting (the right mode, SEND/PUNCH or the "
    "program started), that the cable is a null-modem one, and that its baud rate, parity, data "
    "bits and stop bits (Haas settings 11, 12, 37, 13; Fanuc parameters 0101-0103) match this "
    "side's; `cnc_dnc doctor --port DEV --listen 10` shows what the control sends";

namespace
{
std::string realPath(const std::string& path)
{
  char buffer[PATH_MAX];
  return ::realpath(path.c_str(), buffer) ? std::string(buffer) : path;
}

std::string readLink(const std::string& path)
{
  char buffer[PATH_MAX];
  const ssize_t n = ::readlink(path.c_str(), buffer, sizeof(buffer) - 1);
  return n > 0 ? std::string(buffer, static_cast<size_t>(n)) : std::string();
}

std::vector<std::string> entries(const std::string& dir)
{
  std::vector<std::string> names;
  if (DIR* d = ::opendir(dir.c_str()))
  {
    while (const dirent* e = ::readdir(d))
    {
      if (std::strcmp(e->d_name, ".") != 0 && std::strcmp(e->d_name, "..") != 0)
        names.emplace_back(e->d_name);
    }
    ::closedir(d);
  }
  std::sort(names.begin(), names.end());
  return names;
}

/// "crw-rw----" of a stat mode.
std::string modeText(mode_t mode)
{
  std::string text = S_ISCHR(mode) ? "c" : S_ISDIR(mode) ? "d" : S_ISLNK(mode) ? "l" : "-";
  const char* letters = "rwxrwxrwx";
  for (int bit = 0; bit < 9; ++bit)
    text += (mode & (0400 >> bit)) ? letters[bit] : '-';
  return text;
}

std::string userName(uid_t uid)
{
  const passwd* pw = ::getpwuid(uid);
  return pw ? pw->pw_name : std::to_string(uid);
}

std::string groupName(gid_t gid)
{
  const group* gr = ::getgrgid(gid);
  return gr ? gr->gr_name : std::to_string(gid);
}

/// Whether this process has \p gid, and whether its user is listed in the group (/etc/group).
void groupMembership(gid_t gid, bool& process_has, bool& user_listed)
{
  process_has = ::getegid() == gid;
  std::vector<gid_t> groups(static_cast<size_t>(std::max(::getgroups(0, nullptr), 0)));
  if (!groups.empty() && ::getgroups(static_cast<int>(groups.size()), groups.data()) >= 0)
    process_has = process_has || std::find(groups.begin(), groups.end(), gid) != groups.end();
  user_listed = false;
  const passwd* pw = ::getpwuid(::geteuid());
  if (!pw)
    return;
  int count = 64;
  std::vector<gid_t> listed(static_cast<size_t>(count));
  if (::getgrouplist(pw->pw_name, pw->pw_gid, listed.data(), &count) < 0)
  {
    listed.resize(static_cast<size_t>(count));
    ::getgrouplist(pw->pw_name, pw->pw_gid, listed.data(), &count);
  }
  listed.resize(static_cast<size_t>(std::max(count, 0)));
  user_listed = std::find(listed.begin(), listed.end(), gid) != listed.end();
}

std::string missingDevice(const std::string& device, const std::string& by_id_dir)
{
  std::ostringstream out;
  struct stat link;
  if (::lstat(device.c_str(), &link) == 0 && S_ISLNK(link.st_mode))
    out << device << " is a link to " << readLink(device) << ", which does not exist (adapter unplugged, or the "
        << "program that made the link has ended)";
  else
    out << device << " does not exist";
  const auto adapters = serialAdaptersById(by_id_dir);
  if (adapters.empty())
  {
    out << "; no USB serial adapter is plugged in (" << by_id_dir << " is empty or missing): plug it in and "
        << "look for it in `dmesg`, or name a built-in port (/dev/ttyS0 ...)";
  }
  else
  {
    out << "; serial adapters present (name them by these stable paths):";
    for (const auto& adapter : adapters)
      out << " " << adapter << ";";
  }
  return out.str();
}

std::string permissionDenied(const std::string& device)
{
  std::ostringstream out;
  struct stat st;
  if (::stat(device.c_str(), &st) != 0)
    return device + ": permission denied";
  const std::string user = userName(::geteuid());
  const std::string owner = userName(st.st_uid), group_name = groupName(st.st_gid);
  out << "permission denied: " << device << " is owned by " << owner << ":" << group_name << " with mode "
      << modeText(st.st_mode) << ", and " << user << " is neither its owner nor in group " << group_name;
  bool process_has = false, user_listed = false;
  groupMembership(st.st_gid, process_has, user_listed);
  if ((st.st_mode & (S_IRGRP | S_IWGRP)) != (S_IRGRP | S_IWGRP))
  {
    out << "; its group may not read and write it, so only " << owner << " can open it: run as " << owner
        << R"(, or give the device to a group (a udev rule with GROUP="dialout", MODE="0660") and join it)";
  }
  else if (user_listed && !process_has)
  {
    out << " in this login: " << user << " was added to " << group_name
        << " after logging in; log out and in again (or `newgrp " << group_name << "`)";
  }
  else
  {
    out << ": `sudo usermod -aG " << group_name << " " << user << "`, then log out and in again (group "
        << "membership is read at login)";
  }
  return out.str();
}

std::string busyDevice(const std::string& device)
{
  const auto holders = processesHolding(device, ::getpid());
  std::ostringstream out;
  out << device << " is busy";
  if (holders.empty())
  {
    out << " (opened exclusively; no process of this user holds it: another user's, or a driver, e.g. "
        << "ModemManager probing a new adapter)";
  }
  else
  {
    out << ", held by";
    for (const auto& holder : holders)
      out << " " << holder;
    out << ": stop that program (or its node) first";
  }
  return out.str();
}
}  // namespace

std::string describeHolder(const std::string& holder)
{
  // "PID (command)": /proc/PID/comm, cut to 15 characters by the kernel.
  const size_t open = holder.find(" (");
  const std::string pid = holder.substr(0, open);
  const std::string command = open == std::string::npos ? "" : holder.substr(open + 2, holder.size() - open - 3);
  const bool node = command.size() > 5 && command.compare(command.size() - 5, 5, "_node") == 0;
  if (node)
    return holder +
           ": a node of cnc_bridge (stop it with `rosnode kill` or its launch file, or give it "
           "another port)";
  if (command == "cnc_dnc" || command == "cnc_plan")
    return holder + ": cnc_bridge's " + command + " (let it finish, or end it: kill " + pid + ")";
  if (command.rfind("sim_", 0) == 0)
    return holder + ": a simulator of cnc_bridge (kill " + pid + ")";
  return holder + ": another program (a terminal program, a DNC package, ModemManager; end it: kill " + pid + ")";
}

std::vector<std::string> serialAdaptersById(const std::string& by_id_dir)
{
  std::vector<std::string> adapters;
  for (const auto& name : entries(by_id_dir))
  {
    const std::string path = by_id_dir + "/" + name;
    adapters.push_back(path + " -> " + realPath(path));
  }
  return adapters;
}

std::vector<std::string> processesHolding(const std::string& device, pid_t except)
{
  const std::string target = realPath(device);
  std::vector<std::string> holders;
  for (const auto& pid_text : entries("/proc"))
  {
    if (pid_text.find_first_not_of("0123456789") != std::string::npos)
      continue;
    const pid_t pid = static_cast<pid_t>(std::stol(pid_text));
    if (pid == except)
      continue;
    const std::string fd_dir = "/proc/" + pid_text + "/fd";
    for (const auto& fd : entries(fd_dir))
    {
      if (readLink(fd_dir + "/" + fd) != target)
        continue;
      std::string command;
      std::ifstream comm("/proc/" + pid_text + "/comm");
      std::getline(comm, command);
      holders.push_back(pid_text + " (" + command + ")");
      break;
    }
  }
  return holders;
}

namespace
{
/// The index N of /dev/pts/N that \p device resolves to, or -1 for any other device.
long ptsIndex(const std::string& device)
{
  const std::string path = realPath(device);
  const std::string prefix = "/dev/pts/";
  if (path.compare(0, prefix.size(), prefix) != 0 || path.size() == prefix.size() ||
      path.find_first_not_of("0123456789", prefix.size()) != std::string::npos)
    return -1;
  return std::stol(path.substr(prefix.size()));
}

/// Whether process \p pid holds the master of /dev/pts/\p index (its fdinfo's tty-index).
bool holdsPtyMaster(const std::string& pid, long index)
{
  const std::string fd_dir = "/proc/" + pid + "/fd";
  for (const auto& fd : entries(fd_dir))
  {
    if (readLink(fd_dir + "/" + fd) != "/dev/ptmx")
      continue;
    std::ifstream info("/proc/" + pid + "/fdinfo/" + fd);
    for (std::string line; std::getline(info, line);)
      if (line.rfind("tty-index:", 0) == 0 && std::stol(line.substr(10)) == index)
        return true;
  }
  return false;
}
}  // namespace

std::vector<std::string> processesCompetingFor(const std::string& device, pid_t except)
{
  const long index = ptsIndex(device);
  std::vector<std::string> competing;
  for (const auto& holder : processesHolding(device, except))
    if (index < 0 || !holdsPtyMaster(holder.substr(0, holder.find(' ')), index))
      competing.push_back(holder);
  return competing;
}

std::string explainOpenFailure(const std::string& device, int error_number, const std::string& by_id_dir)
{
  switch (error_number)
  {
    case ENOENT:
      return missingDevice(device, by_id_dir);
    case EACCES:
    case EPERM:
      return permissionDenied(device);
    case EBUSY:
      return busyDevice(device);
    case ENXIO:
    case ENODEV:
      return device +
             " names no device any more (a USB adapter unplugged while its file stayed): plug it in "
             "again or name the port by /dev/serial/by-id";
    case ENOTTY:
      return device + " is not a serial port";
    default:
      return device + ": " + std::strerror(error_number);
  }
}

std::string explainConnectFailure(const std::string& where, int error_number)
{
  const std::string servers =
      "the control's server is on and on this port (Haas NGC: Setting 143 for MDC, 263 for DPRNT; qCNC: "
      "INET_PORT of the board's settings file; '@' controller: its command and report ports)";
  switch (error_number)
  {
    case ECONNREFUSED:
      return "nothing listens on " + where + ": check that " + servers;
    case EHOSTUNREACH:
    case ENETUNREACH:
      return "no route to " + where +
             ": check the address, the cable or switch, and this computer's address "
             "on the control's network";
    case 0:
    case ETIMEDOUT:
      return "no answer from " + where + ": check the address (`ping` it), the network, a firewall, and that " +
             servers;
    default:
      return where + ": " + std::strerror(error_number);
  }
}

const std::vector<ProfileLine>& serialProfiles()
{
  static const std::vector<ProfileLine> kProfiles = {
      {"haas_classic_rs232", 115200, 8, 'N', 1}, {"haas_classic_rs232_7e1", 9600, 7, 'E', 1},
      {"fanuc_0i_rs232", 9600, 7, 'E', 2},       {"fanuc_0i_rs232_7n2", 9600, 7, 'N', 2},
      {"grbl_class_board", 115200, 8, 'N', 1},
  };
  return kProfiles;
}

namespace
{
bool evenParityBit(uint8_t byte)
{
  return __builtin_popcount(byte & 0x7f) % 2 != 0;  // bit 7 that makes the count of ones even
}

bool programText(uint8_t low7)
{
  return (low7 >= 0x20 && low7 < 0x7f) || low7 == '\r' || low7 == '\n' || low7 == '\t' ||
         (low7 >= 0x11 && low7 <= 0x14);  // DC1-DC4 around punched programs
}

/// The protocol a peer speaks when nearly all of its characters (low 7 bits) are one control
/// character that means "waiting", else empty. A baud rate that differs would garble them into
/// varied bytes, so many of one kind, intact, show a good line.
std::string recognizePeer(const std::vector<uint8_t>& bytes, size_t counted)
{
  if (counted == 0)
    return "";
  size_t nak = 0, crc = 0, dc1 = 0;
  for (const uint8_t b : bytes)
  {
    const uint8_t low7 = b & 0x7f;
    nak += low7 == 0x15 ? 1 : 0;
    crc += low7 == 'C' ? 1 : 0;
    dc1 += low7 == 0x11 ? 1 : 0;
  }
  // An XModem receiver repeats its request every few seconds (lrzsz rx every 10 s), a control
  // sends one DC1 when it is ready for a drip-feed: a lone NAK or DC1 counts, with a word that
  // it was one (a garbled character is seldom exactly one of them).
  const auto most = [&](size_t n) { return n * 10 >= counted * 9; };
  if (counted == 1 && dc1 == 1)
    return "a control asking for a drip-feed (one DC1, the reader start): the line looks good; start the feed "
           "now (cnc_dnc drip --port DEV FILE, or the node's transfer with protocol drip)";
  if (counted == 1 && nak == 1)
    return "an XModem receiver waiting for a program (one NAK so far; a receiver repeats it every few seconds): "
           "the line looks good; send the program now (cnc_dnc send --port DEV FILE, or the node's send_program)";
  if (counted == 1)
    return "";
  if (most(nak))
    return "an XModem receiver waiting for a program (it repeats NAK, checksum mode): the line is good; send the "
           "program now (cnc_dnc send --port DEV FILE, or the node's send_program)";
  if (most(crc))
    return "an XModem receiver waiting for a program (it repeats 'C', CRC mode): the line is good; send the program "
           "now (cnc_dnc send --port DEV FILE, or the node's send_program)";
  if (most(dc1))
    return "a control asking for a drip-feed (DC1): the line is good; start the feed now (cnc_dnc drip --port DEV "
           "FILE, or the node's transfer with protocol drip)";
  return "";
}
}  // namespace

LineGuess guessLineSettings(const std::vector<uint8_t>& bytes, size_t framing_errors, unsigned baud)
{
  LineGuess guess;
  guess.framing_errors = framing_errors;
  size_t text = 0, high = 0, even = 0, odd = 0;
  for (const uint8_t b : bytes)
  {
    if ((b & 0x7f) == 0)
      continue;  // NUL leader and trailer: no information about parity
    ++guess.bytes;
    text += programText(b & 0x7f) ? 1 : 0;
    high += (b & 0x80) ? 1 : 0;
    const bool bit7 = (b & 0x80) != 0;
    (bit7 == evenParityBit(b) ? even : odd) += 1;
  }
  if (guess.bytes == 0)
  {
    guess.line = framing_errors ? "only framing errors: the baud rate differs" : "nothing received";
    guess.baud_suspect = framing_errors > 0;
    return guess;
  }
  guess.text_share = static_cast<double>(text) / static_cast<double>(guess.bytes);
  guess.peer = framing_errors * 50 > guess.bytes ? "" : recognizePeer(bytes, guess.bytes);
  guess.baud_suspect = guess.peer.empty() && (guess.text_share < 0.9 || framing_errors * 50 > guess.bytes);
  const auto share = [&](size_t n) { return static_cast<double>(n) / static_cast<double>(guess.bytes); };
  std::ostringstream line;
  if (guess.baud_suspect)
  {
    line << "the characters are not program text (" << static_cast<int>(guess.text_share * 100) << "% text, "
         << framing_errors << " framing errors): the control's baud rate is likely not " << baud
         << "; try 4800, 9600, 19200, 38400, 57600 and 115200";
  }
  else if (high == 0)
  {
    guess.data_bits = 8;
    guess.parity = 'N';
    line << "8 data bits, no parity (8N1): bit 7 is never set";
  }
  else if (share(even) >= 0.98)
  {
    guess.data_bits = 7;
    guess.parity = 'E';
    line << "7 data bits, even parity (7E1; 7E2 looks the same from here): bit 7 of every byte is its even "
            "parity bit";
  }
  else if (share(odd) >= 0.98)
  {
    guess.data_bits = 7;
    guess.parity = 'O';
    line << "7 data bits, odd parity (7O1): bit 7 of every byte is its odd parity bit";
  }
  else if (high == guess.bytes)
  {
    guess.data_bits = 7;
    guess.parity = 'M';
    line << "7 data bits with bit 7 always set (7N2, or mark parity): set 7 data bits, no parity, 2 stop bits";
  }
  else
  {
    line << "bit 7 follows no parity (" << high << " of " << guess.bytes
         << " bytes have it set): 8-bit data, or a baud rate that garbles some characters";
  }
  if (!guess.baud_suspect)
    line << "; " << baud << " baud looks right ("
         << (guess.peer.empty() ? "the characters are program text" : "the peer's characters arrive intact") << ")";
  guess.line = line.str();
  for (const auto& profile : serialProfiles())
  {
    // Read 8 bits at a time, a 7N2 character's first stop bit is bit 7: always set, like mark parity.
    const bool seven_n2 = profile.data_bits == 7 && profile.parity == 'N' && profile.stop_bits == 2;
    if (profile.data_bits == guess.data_bits && (seven_n2 ? 'M' : profile.parity) == guess.parity)
      guess.profiles.push_back(std::string(profile.name) +
                               (profile.baud == baud ? "" : " (at " + std::to_string(profile.baud) + " baud there)"));
  }
  return guess;
}
}  // namespace cnc_bridge
