// cnc_dnc's transfers to and from a program folder over the network (an SMB share) or on disk:
//
//   cnc_dnc send    --share URL [--credentials FILE] [--name NAME] [--allow-protected] FILE
//   cnc_dnc receive --share URL [--credentials FILE] NAME OUT
//   cnc_dnc list    --share URL [--credentials FILE]
//
// URL is smb://[user@]host[:port]/share[/folder] or a local directory. Credentials only come from
// a file in smbclient's authentication-file format (mode 0600); without one the share is opened as
// guest. Exit status 0 only when the whole program arrived; otherwise one error line, status 1
// (2 for a bad command line), as for the serial transfers.
#include <boost/program_options.hpp>
#include <chrono>
#include <cstdio>
#include <ctime>
#include <iostream>
#include <string>
#include <vector>

#include "cnc_bridge/common/error.h"
#include "cnc_bridge/common/stop_handler.h"
#include "cnc_bridge/programs/archive.h"
#include "cnc_bridge/programs/fan_out.h"
#include "cnc_bridge/share/share_settings.h"
#include "cnc_bridge/share/smb_store.h"
#include "progress_line.h"
#include "protected_options.h"

namespace po = boost::program_options;

namespace cnc_bridge
{
namespace cli
{
namespace
{
po::options_description shareOptions()
{
  po::options_description options("program folder");
  options.add_options()("help,h", "this help")("share,s", po::value<std::vector<std::string>>(),
                                               "smb://[user@]host[:port]/share[/folder], or a local directory "
                                               "(send: give it once per machine to publish to several)")(
      "credentials,A", po::value<std::string>()->default_value(""),
      "smbclient authentication file (username = ..., password = ..., domain = ...; mode 0600); guest if none")(
      "timeout,t", po::value<double>()->default_value(10.0), "seconds allowed for each SMB request");
  return options;
}

/// Parses; \returns false after printing usage (\p status 0 for --help, 2 for an error).
bool parse(const std::string& command, const std::string& operands, const std::vector<std::string>& args,
           po::options_description options, const std::vector<std::string>& positional_names, po::variables_map& vm,
           int& status)
{
  po::options_description all(options);
  po::positional_options_description positional;
  for (const auto& name : positional_names)
  {
    all.add_options()(name.c_str(), po::value<std::string>(), "");
    positional.add(name.c_str(), 1);
  }
  const std::string usage = "usage: cnc_dnc " + command + " --share URL [options] " + operands + "\n";
  try
  {
    po::store(po::command_line_parser(args).options(all).positional(positional).run(), vm);
    po::notify(vm);
  }
  catch (const po::error& e)
  {
    std::cerr << "cnc_dnc " << command << ": " << e.what() << "\n" << usage << options;
    status = 2;
    return false;
  }
  if (vm.count("help"))
  {
    std::cout << usage << options;
    status = 0;
    return false;
  }
  bool complete = vm.count("share") > 0;
  for (const auto& name : positional_names)
    complete = complete && vm.count(name) > 0;
  if (!complete)
  {
    std::cerr << "cnc_dnc " << command << ": --share and " << operands << " are required\n" << usage << options;
    status = 2;
    return false;
  }
  return true;
}

std::unique_ptr<programs::ProgramStore> openStore(const po::variables_map& vm, const std::string& address)
{
  const double timeout = vm["timeout"].as<double>();
  if (timeout <= 0)
    throw ConfigError("--timeout must be positive");
  share::refusePassword(address, "--share");
  return share::openStore(address, vm["credentials"].as<std::string>(),
                          std::chrono::milliseconds(static_cast<int64_t>(timeout * 1000)));
}

/// The one share of receive and list.
std::unique_ptr<programs::ProgramStore> openStore(const po::variables_map& vm)
{
  const auto& shares = vm["share"].as<std::vector<std::string>>();
  if (shares.size() != 1)
    throw ConfigError("give one --share here (several only for send)");
  return openStore(vm, shares.front());
}

/// "1048576 bytes in 0.052 s (20.2 MB/s)"
std::string rate(uint64_t bytes, std::chrono::steady_clock::time_point start)
{
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  char text[96];
  std::snprintf(text, sizeof(text), "%llu bytes in %.3f s (%.1f MB/s)", static_cast<unsigned long long>(bytes), seconds,
                seconds > 0 ? bytes / seconds / 1e6 : 0.0);
  return text;
}

programs::StoreProgress showOn(ProgressLine& line)
{
  return [&line](uint64_t done, uint64_t total) { line.show(done, total, "", total > 0 && done >= total); };
}

/// Ctrl-C cancels between chunks (the previous version stays on the share).
const std::atomic<bool>* cancelOnStop()
{
  static std::atomic<bool> cancel{false};
  installStopHandler();
  onStop([] { cancel = true; });
  return &cancel;
}
}  // namespace

int runShareSend(const std::vector<std::string>& args)
{
  po::options_description options = shareOptions();
  options.add_options()("name", po::value<std::string>()->default_value(""),
                        "the program's name in the folder (default: FILE's base name)");
  addProtectedOptions(options);
  po::variables_map vm;
  int status = 0;
  if (!parse("send", "FILE", args, options, {"file"}, vm, status))
    return status;
  const std::string file = vm["file"].as<std::string>();
  const std::string name = vm["name"].as<std::string>();
  const programs::NamePattern pattern(vm["name-pattern"].as<std::string>());
  const programs::ProtectedRange range = protectedRange(vm);
  checkProtected(vm, file, name);  // once, before any share is touched
  const std::string sent_name = name.empty() ? file.substr(file.find_last_of('/') + 1) : name;
  // Fan-out: each share (machine) is reported on its own line; one that fails does not stop the
  // others, and the exit status is 1 if any failed.
  const auto results = programs::fanOut(
      vm["share"].as<std::vector<std::string>>(),
      [&](const std::string& address)
      {
        auto store = openStore(vm, address);
        const auto start = std::chrono::steady_clock::now();
        ProgressLine progress("send " + file + " to " + store->describe());
        const uint64_t bytes =
            programs::putProgram(*store, file, name, range, pattern, showOn(progress), cancelOnStop());
        progress.finish();
        return "sent " + file + " to " + store->describe() + "/" + sent_name + ": " + rate(bytes, start);
      },
      [](const programs::TargetResult& result)
      {
        if (result.success)
          std::cout << result.message << std::endl;
        else
          std::cerr << "cnc_dnc send: error: " << result.message << std::endl;
      });
  return programs::allSucceeded(results) ? 0 : 1;
}

int runShareReceive(const std::vector<std::string>& args)
{
  po::variables_map vm;
  int status = 0;
  if (!parse("receive", "NAME OUT", args, shareOptions(), {"name", "out"}, vm, status))
    return status;
  const std::string name = vm["name"].as<std::string>();
  const std::string out = vm["out"].as<std::string>();
  auto store = openStore(vm);
  const auto start = std::chrono::steady_clock::now();
  ProgressLine progress("receive " + name);
  const uint64_t bytes = programs::getProgram(*store, name, out, showOn(progress), cancelOnStop());
  progress.finish();
  std::cout << "received " << store->describe() << "/" << name << " as " << out << ": " << rate(bytes, start)
            << std::endl;
  return 0;
}

int runList(const std::vector<std::string>& args)
{
  po::options_description options = shareOptions();
  options.add_options()("name-pattern", po::value<std::string>()->default_value("O%05d.nc"),
                        "how the control names program files (printf style, one %d or %0Nd)");
  po::variables_map vm;
  int status = 0;
  if (!parse("list", "", args, options, {}, vm, status))
    return status;
  auto store = openStore(vm);
  const programs::NamePattern pattern(vm["name-pattern"].as<std::string>());
  // One program a line: name, O number (from the program, else from the name; "-" if none),
  // bytes, modification time (UTC), first comment. Tab-separated for scripts.
  for (const programs::ProgramListing& item : programs::listPrograms(*store, pattern))
  {
    const auto number = item.header.number ? item.header.number : item.name_number;
    char when[32];
    const std::time_t mtime = static_cast<std::time_t>(item.entry.mtime);
    std::tm tm{};
    ::gmtime_r(&mtime, &tm);
    std::strftime(when, sizeof(when), "%Y-%m-%dT%H:%M:%SZ", &tm);
    std::cout << item.entry.name << "\t" << (number ? programs::programLabel(*number) : "-") << "\t" << item.entry.size
              << "\t" << when << "\t" << item.header.comment << "\n";
  }
  return 0;
}

namespace
{
po::options_description archiveOptions()
{
  po::options_description options("program archive");
  options.add_options()("help,h", "this help")(
      "archive,a", po::value<std::string>(),
      "the archive folder (a node's ~archive_dir; default <program_dir>.archive)")(
      "program-dir,d", po::value<std::string>(), "the program directory; its archive is <program-dir>.archive");
  return options;
}

/// The archive folder and the program directory from --archive / --program-dir.
std::pair<std::string, std::string> archiveFolders(const po::variables_map& vm)
{
  std::string archive = vm.count("archive") ? vm["archive"].as<std::string>() : "";
  std::string dir = vm.count("program-dir") ? vm["program-dir"].as<std::string>() : "";
  while (dir.size() > 1 && dir.back() == '/')
    dir.pop_back();
  if (archive.empty() && dir.empty())
    throw ConfigError("give --archive DIR or --program-dir DIR");
  if (archive.empty())
    archive = dir + ".archive";
  const std::string suffix = ".archive";
  if (dir.empty() && archive.size() > suffix.size() &&
      archive.compare(archive.size() - suffix.size(), suffix.size(), suffix) == 0)
    dir = archive.substr(0, archive.size() - suffix.size());
  return {archive, dir};
}
}  // namespace

int runHistory(const std::vector<std::string>& args)
{
  po::options_description options = archiveOptions();
  po::variables_map vm;
  po::options_description all(options);
  all.add_options()("name", po::value<std::string>(), "");
  po::positional_options_description positional;
  positional.add("name", 1);
  const std::string usage = "usage: cnc_dnc history (--archive DIR | --program-dir DIR) NAME\n";
  try
  {
    po::store(po::command_line_parser(args).options(all).positional(positional).run(), vm);
    po::notify(vm);
  }
  catch (const po::error& e)
  {
    std::cerr << "cnc_dnc history: " << e.what() << "\n" << usage << options;
    return 2;
  }
  if (vm.count("help") || !vm.count("name"))
  {
    (vm.count("help") ? std::cout : std::cerr) << usage << options;
    return vm.count("help") ? 0 : 2;
  }
  const programs::ProgramArchive archive(archiveFolders(vm).first);
  // One version a line, tab-separated: number, time (UTC), node, machine, direction, bytes, crc32.
  for (const programs::ArchiveVersion& v : archive.history(vm["name"].as<std::string>()))
  {
    char when[32];
    const std::time_t time = static_cast<std::time_t>(v.time);
    std::tm tm{};
    ::gmtime_r(&time, &tm);
    std::strftime(when, sizeof(when), "%Y-%m-%dT%H:%M:%SZ", &tm);
    std::cout << v.number << "\t" << when << "\t" << v.source.node << "\t" << v.source.machine << "\t"
              << v.source.direction << "\t" << v.size << "\t" << v.crc32 << "\n";
  }
  return 0;
}

int runDiff(const std::vector<std::string>& args)
{
  po::options_description options = archiveOptions();
  po::variables_map vm;
  po::options_description all(options);
  all.add_options()("name", po::value<std::string>(), "")("from", po::value<unsigned>(), "")("to",
                                                                                             po::value<unsigned>(), "");
  po::positional_options_description positional;
  positional.add("name", 1).add("from", 1).add("to", 1);
  const std::string usage =
      "usage: cnc_dnc diff (--archive DIR | --program-dir DIR) NAME [V1 [V2]]\n"
      "  no version: the newest kept version against the current file; V1: that version against the\n"
      "  current file; V1 V2: two kept versions\n";
  try
  {
    po::store(po::command_line_parser(args).options(all).positional(positional).run(), vm);
    po::notify(vm);
  }
  catch (const po::error& e)
  {
    std::cerr << "cnc_dnc diff: " << e.what() << "\n" << usage << options;
    return 2;
  }
  if (vm.count("help") || !vm.count("name"))
  {
    (vm.count("help") ? std::cout : std::cerr) << usage << options;
    return vm.count("help") ? 0 : 2;
  }
  const auto [archive_dir, program_dir] = archiveFolders(vm);
  const std::string name = vm["name"].as<std::string>();
  const programs::ProgramArchive archive(archive_dir);
  std::cout << programs::compareVersions(archive, name, vm.count("from") ? vm["from"].as<unsigned>() : 0,
                                         vm.count("to") ? vm["to"].as<unsigned>() : 0, program_dir + "/" + name);
  return 0;
}

bool namesShare(const std::vector<std::string>& args)
{
  for (const auto& arg : args)
  {
    if (arg == "--share" || arg == "-s" || arg.rfind("--share=", 0) == 0)
      return true;
  }
  return false;
}
}  // namespace cli
}  // namespace cnc_bridge
