// ProgramArchive: one folder per program, vNNNN.nc + vNNNN.meta per version (see archive.h).
#include "cnc_bridge/programs/archive.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <boost/crc.hpp>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <sstream>

#include "cnc_bridge/common/atomic_file.h"
#include "cnc_bridge/common/error.h"
#include "cnc_bridge/common/program_dir.h"
#include "cnc_bridge/programs/program_store.h"

namespace cnc_bridge::programs
{
namespace fs = std::filesystem;

namespace
{
/// The kept file \p path, "" if it is no regular file (a link is not followed).
std::string readKept(const std::string& path)
{
  try
  {
    return readRegularFile(path);
  }
  catch (const Error&)
  {
    return "";
  }
}

/// Whether \p path is a directory itself, not a link to one.
bool isRealDirectory(const std::string& path)
{
  struct stat info;
  return ::lstat(path.c_str(), &info) == 0 && S_ISDIR(info.st_mode);
}

/// Closes the folder descriptor it holds.
struct FolderDescriptor
{
  explicit FolderDescriptor(const std::string& path)
      : fd(::open(path.c_str(), O_RDONLY | O_DIRECTORY | O_NOFOLLOW | O_CLOEXEC))
  {
    if (fd < 0)
      throw Error("cannot open the archive folder " + path +
                  " (a symbolic link is not followed): " + std::strerror(errno));
  }
  ~FolderDescriptor() { ::close(fd); }
  FolderDescriptor(const FolderDescriptor&) = delete;
  FolderDescriptor& operator=(const FolderDescriptor&) = delete;
  int fd;
};

std::string stem(unsigned number)
{
  char text[16];
  std::snprintf(text, sizeof(text), "v%04u", number);
  return text;
}

/// The file name's extension ("nc" of O01234.nc), kept on the versions so editors recognise them.
std::string extensionOf(const std::string& name)
{
  const auto dot = name.find_last_of('.');
  return dot == std::string::npos || dot == 0 ? "" : name.substr(dot);
}
}  // namespace

std::string crc32Hex(const std::string& data)
{
  boost::crc_32_type crc;
  crc.process_bytes(data.data(), data.size());
  char text[16];
  std::snprintf(text, sizeof(text), "%08x", crc.checksum());
  return text;
}

ProgramArchive::ProgramArchive(std::string root, unsigned keep) : root_(std::move(root)), keep_(std::max(1u, keep))
{
  std::error_code error;
  if (!fs::is_directory(root_))
  {
    const fs::path parent = fs::path(root_).parent_path();
    if (!parent.empty())
      fs::create_directories(parent, error);
    if (::mkdir(root_.c_str(), kArchiveFolderMode) != 0 && errno != EEXIST)
      error = std::error_code(errno, std::generic_category());
  }
  if (!fs::is_directory(root_))
    throw ConfigError("program archive '" + root_ + "' cannot be created: " + error.message());
}

std::string ProgramArchive::folder(const std::string& name) const
{
  checkName(name);
  if (name.find('/') != std::string::npos)
    throw ConfigError("program name '" + name + "' for the archive must not contain '/'");
  return root_ + "/" + name;
}

std::vector<ArchiveVersion> ProgramArchive::history(const std::string& name) const
{
  std::vector<ArchiveVersion> versions;
  const std::string dir = folder(name);
  if (!isRealDirectory(dir))
    return versions;  // none kept (or a link planted in its place: not followed)
  std::error_code error;
  for (const auto& item : fs::directory_iterator(dir, error))
  {
    const std::string file = item.path().filename().string();
    if (file.size() < 10 || file[0] != 'v' || file.compare(file.size() - 5, 5, ".meta") != 0)
      continue;
    ArchiveVersion v;
    v.number = static_cast<unsigned>(std::strtoul(file.c_str() + 1, nullptr, 10));
    std::istringstream in(readKept(item.path().string()));
    for (std::string line; std::getline(in, line);)
    {
      const auto equals = line.find(" = ");
      if (equals == std::string::npos)
        continue;
      const std::string key = line.substr(0, equals), value = line.substr(equals + 3);
      if (key == "time")
        v.time = std::strtoll(value.c_str(), nullptr, 10);
      else if (key == "node")
        v.source.node = value;
      else if (key == "machine")
        v.source.machine = value;
      else if (key == "direction")
        v.source.direction = value;
      else if (key == "size")
        v.size = std::strtoull(value.c_str(), nullptr, 10);
      else if (key == "crc32")
        v.crc32 = value;
      else if (key == "file" && value.find('/') == std::string::npos && value != ".." && value != ".")
        v.path = dir + "/" + value;  // a version's file is in its folder, never elsewhere
    }
    if (v.number > 0 && !v.path.empty())
      versions.push_back(v);
  }
  std::sort(versions.begin(), versions.end(), [](const auto& a, const auto& b) { return a.number < b.number; });
  return versions;
}

ArchiveVersion ProgramArchive::version(const std::string& name, unsigned number) const
{
  const auto versions = history(name);
  for (const auto& v : versions)
  {
    if (v.number == number)
      return v;
  }
  std::string kept;
  for (const auto& v : versions)
    kept += (kept.empty() ? "" : ", ") + std::to_string(v.number);
  throw ConfigError("no version " + std::to_string(number) + " of " + name + " in " + root_ +
                    (kept.empty() ? " (none kept)" : " (kept: " + kept + ")"));
}

std::optional<ArchiveVersion> ProgramArchive::add(const std::string& name, const std::string& content,
                                                  const VersionSource& source, unsigned mode)
{
  const std::lock_guard<std::mutex> lock(add_mutex_);
  const std::string dir = folder(name);
  const std::string crc = crc32Hex(content);
  const auto versions = history(name);
  for (const auto& v : versions)
  {
    if (v.crc32 == crc && v.size == content.size() && readKept(v.path) == content)
      return std::nullopt;  // kept already
  }
  std::error_code error;
  if (::mkdir(dir.c_str(), kArchiveFolderMode) != 0 && errno != EEXIST)
    throw Error("cannot create the archive folder " + dir + ": " + std::strerror(errno));
  const FolderDescriptor folder_fd(dir);  // refuses a link planted in the folder's place
  ArchiveVersion v;
  v.number = versions.empty() ? 1 : versions.back().number + 1;
  v.time = static_cast<int64_t>(std::time(nullptr));
  v.source = source;
  v.size = content.size();
  v.crc32 = crc;
  const std::string file = stem(v.number) + extensionOf(name);
  v.path = dir + "/" + file;
  AtomicFileWriter data(folder_fd.fd, file, v.path, mode);
  data.write(content);
  data.commit();
  std::ostringstream meta;
  meta << "time = " << v.time << "\nnode = " << source.node << "\nmachine = " << source.machine
       << "\ndirection = " << source.direction << "\nsize = " << v.size << "\ncrc32 = " << v.crc32
       << "\nfile = " << file << "\n";
  // last: a version counts once complete
  AtomicFileWriter meta_file(folder_fd.fd, stem(v.number) + ".meta", dir + "/" + stem(v.number) + ".meta");
  meta_file.write(meta.str());
  meta_file.commit();
  // The oldest versions beyond keep_ go.
  auto all = versions;
  all.push_back(v);
  for (size_t i = 0; i + keep_ < all.size(); ++i)
  {
    fs::remove(dir + "/" + stem(all[i].number) + ".meta", error);
    fs::remove(all[i].path, error);
  }
  return v;
}

std::string compareVersions(const ProgramArchive& archive, const std::string& name, unsigned from, unsigned to,
                            const std::string& current_path)
{
  ArchiveVersion older;
  if (from == 0)
  {
    const auto versions = archive.history(name);
    if (versions.empty())
      throw ConfigError("no version of " + name + " is kept in " + archive.root());
    older = versions.back();
  }
  else
  {
    older = archive.version(name, from);
  }
  const std::string older_label = name + " v" + std::to_string(older.number);
  if (to != 0)
  {
    const ArchiveVersion newer = archive.version(name, to);
    return ProgramArchive::diff(older.path, older_label, newer.path, name + " v" + std::to_string(newer.number));
  }
  struct stat info;
  if (::lstat(current_path.c_str(), &info) != 0)
    throw ConfigError("no current file " + current_path + " to compare version " + std::to_string(older.number) +
                      " with");
  if (!S_ISREG(info.st_mode))  // a link is not followed: it could show a file outside the folder
    throw ConfigError("the current file " + current_path + " is " + fileKind(info.st_mode) +
                      ", not a program file: refused");
  return ProgramArchive::diff(older.path, older_label, current_path, current_path);
}

std::string ProgramArchive::diff(const std::string& from_path, const std::string& from_label,
                                 const std::string& to_path, const std::string& to_label)
{
  // GNU diff (diffutils, an Essential package) makes the unified diff; run without a shell.
  int out[2];
  if (::pipe(out) != 0)
    throw Error("diff: cannot make a pipe");
  const pid_t pid = ::fork();
  if (pid == 0)
  {
    ::dup2(out[1], 1);
    ::close(out[0]);
    ::close(out[1]);
    ::execlp("diff", "diff", "-u", "--label", from_label.c_str(), "--label", to_label.c_str(), from_path.c_str(),
             to_path.c_str(), nullptr);
    ::_exit(127);
  }
  ::close(out[1]);
  std::string text;
  char buffer[4096];
  for (ssize_t n = 0; (n = ::read(out[0], buffer, sizeof(buffer))) != 0;)
  {
    if (n < 0)
    {
      if (errno == EINTR)
        continue;
      break;
    }
    text.append(buffer, static_cast<size_t>(n));
  }
  ::close(out[0]);
  int status = 0;
  ::waitpid(pid, &status, 0);
  // diff exits 0 (same), 1 (different), 2 (trouble).
  if (!WIFEXITED(status) || WEXITSTATUS(status) > 1)
    throw Error("diff of " + from_path + " and " + to_path + " failed");
  return text;
}
}  // namespace cnc_bridge::programs
