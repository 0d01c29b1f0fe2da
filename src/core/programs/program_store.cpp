// Name checks shared by every store, and the local-directory store (AtomicFileWriter for writes).
#include "cnc_bridge/programs/program_store.h"

#include <dirent.h>
#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <iterator>
#include <utility>

#include "cnc_bridge/common/atomic_file.h"
#include "cnc_bridge/common/log.h"
#include "cnc_bridge/common/program_dir.h"
#include "cnc_bridge/common/regular_file.h"

namespace cnc_bridge::programs
{
namespace
{
constexpr size_t kChunk = size_t{64} * 1024;

/// Closes the descriptor it holds.
struct FileDescriptor
{
  explicit FileDescriptor(int held) : fd(held) {}
  ~FileDescriptor()
  {
    if (fd >= 0)
      ::close(fd);
  }
  FileDescriptor(const FileDescriptor&) = delete;
  FileDescriptor& operator=(const FileDescriptor&) = delete;
  int fd;
};
}  // namespace

void throwIfCancelled(const std::atomic<bool>* cancel, const std::string& what)
{
  if (cancel != nullptr && cancel->load())
    throw CancelledError(what + " cancelled");
}

void checkName(const std::string& name)
{
  checkRequestedName(name);
  if (name[0] == '/')
    throw ConfigError("program name '" + name + "' must be a relative name inside the program folder");
  size_t start = 0;
  while (start <= name.size())
  {
    size_t end = name.find('/', start);
    if (end == std::string::npos)
      end = name.size();
    const std::string part = name.substr(start, end - start);
    if (part.empty() || part == "." || part == "..")
      throw ConfigError("program name '" + name + "' has an empty, '.' or '..' part: refused");
    start = end + 1;
  }
  for (const char c : name)
  {
    if (static_cast<unsigned char>(c) < 0x20 || c == 0x7f || c == '\\')
      throw ConfigError("program name '" + name + "' holds a control character or a backslash: refused");
  }
}

bool isTemporaryName(const std::string& name)
{
  const auto slash = name.find_last_of('/');
  const std::string base = slash == std::string::npos ? name : name.substr(slash + 1);
  // `.<name>.<tag>.partial` (temporaryName) or `.<name>.partial.XXXXXX` (AtomicFileWriter)
  return base.size() > 1 && base[0] == '.' && base.find(".partial") != std::string::npos;
}

std::string temporaryName(const std::string& name, const std::string& tag)
{
  const auto slash = name.find_last_of('/');
  const std::string folder = slash == std::string::npos ? "" : name.substr(0, slash + 1);
  const std::string base = slash == std::string::npos ? name : name.substr(slash + 1);
  return folder + "." + base + "." + tag + ".partial";
}

LocalProgramStore::LocalProgramStore(std::string root) : root_(std::move(root))
{
  const FileDescriptor folder(openRoot());
  if (folder.fd < 0)
    throw ConfigError("program directory '" + root_ + "' does not exist or is not a directory");
}

int LocalProgramStore::openRoot() const
{
  // The root is the configured folder (it may be a link, or a mount point remounted since): it is
  // opened by its path each time; nothing below it is followed.
  return ::open(root_.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
}

std::string LocalProgramStore::path(const std::string& name) const
{
  return root_ + "/" + name;
}

int LocalProgramStore::openFolder(const std::string& name, std::string& base) const
{
  checkName(name);
  int folder = openRoot();
  size_t start = 0;
  for (size_t slash = name.find('/'); folder >= 0 && slash != std::string::npos; slash = name.find('/', start))
  {
    const std::string part = name.substr(0, slash);
    const int next =
        ::openat(folder, name.substr(start, slash - start).c_str(), O_RDONLY | O_DIRECTORY | O_NOFOLLOW | O_CLOEXEC);
    const int error = errno;
    ::close(folder);
    if (next < 0 && error == ENOENT)
      throw NotFoundError("no program '" + name + "' in " + root_ + " (no folder '" + part + "')");
    if (next < 0)
      throw ConfigError("'" + part + "' in " + root_ + " is a symbolic link or not a folder: refused");
    folder = next;
    start = slash + 1;
  }
  if (folder < 0)
    throw Error("cannot open " + root_ + ": " + std::strerror(errno));
  base = name.substr(start);
  return folder;
}

int LocalProgramStore::openFile(const std::string& name) const
{
  std::string base;
  const FileDescriptor folder(openFolder(name, base));
  const int fd = openRegularFile(folder.fd, base, path(name));
  if (fd < 0)
    throw NotFoundError("no program '" + name + "' in " + root_);
  return fd;
}

void LocalProgramStore::reportSkipped(const std::string& name, const std::string& kind)
{
  std::lock_guard<std::mutex> lock(skipped_mutex_);
  if (skipped_.insert(name).second)
    CNC_LOG_WARN(path(name) << " is " << kind << ": not listed, read or sent (only regular files are programs)");
}

std::vector<ProgramEntry> LocalProgramStore::list()
{
  const int root = openRoot();
  DIR* folder = root < 0 ? nullptr : ::fdopendir(root);
  if (folder == nullptr)
  {
    const int error = errno;
    if (root >= 0)
      ::close(root);
    throw Error("cannot list " + root_ + ": " + std::strerror(error));
  }
  std::vector<ProgramEntry> entries;
  for (;;)
  {
    errno = 0;
    const dirent* item = ::readdir(folder);
    if (item == nullptr)
      break;
    const std::string name = item->d_name;
    struct stat info;
    if (name == "." || name == ".." || isTemporaryName(name) ||
        ::fstatat(::dirfd(folder), name.c_str(), &info, AT_SYMLINK_NOFOLLOW) != 0 || S_ISDIR(info.st_mode))
      continue;  // gone since readdir, or a subfolder
    if (!S_ISREG(info.st_mode))
    {
      reportSkipped(name, fileKind(info.st_mode));
      continue;
    }
    entries.push_back({name, static_cast<uint64_t>(info.st_size), info.st_mtime});
  }
  const int error = errno;
  ::closedir(folder);
  if (error != 0)
    throw Error("cannot list " + root_ + ": " + std::strerror(error));
  std::sort(entries.begin(), entries.end(), [](const auto& a, const auto& b) { return a.name < b.name; });
  return entries;
}

ProgramEntry LocalProgramStore::stat(const std::string& name)
{
  std::string base;
  const FileDescriptor folder(openFolder(name, base));
  struct stat info;
  if (::fstatat(folder.fd, base.c_str(), &info, AT_SYMLINK_NOFOLLOW) != 0)
  {
    if (errno == ENOENT)
      throw NotFoundError("no program '" + name + "' in " + root_);
    throw Error("cannot stat " + path(name) + ": " + std::strerror(errno));
  }
  if (!S_ISREG(info.st_mode))
    throw ConfigError(path(name) + " is " + fileKind(info.st_mode) + ", not a program file: refused");
  ProgramEntry entry;
  entry.name = name;
  entry.size = static_cast<uint64_t>(info.st_size);
  entry.mtime = info.st_mtime;
  return entry;
}

unsigned LocalProgramStore::copyMode(const std::string& name)
{
  const FileDescriptor file(openFile(name));
  struct stat info;
  if (::fstat(file.fd, &info) != 0)
    throw Error("cannot stat " + path(name) + ": " + std::strerror(errno));
  return info.st_mode & kProgramFileMode;
}

std::string LocalProgramStore::read(const std::string& name, const StoreProgress& progress,
                                    const std::atomic<bool>* cancel)
{
  const FileDescriptor file(openFile(name));
  struct stat info;
  const uint64_t total = ::fstat(file.fd, &info) == 0 ? static_cast<uint64_t>(info.st_size) : 0;
  std::string data;
  std::string chunk(kChunk, '\0');
  for (;;)
  {
    throwIfCancelled(cancel, "reading " + name);
    const ssize_t n = ::read(file.fd, chunk.data(), chunk.size());
    if (n < 0 && errno == EINTR)
      continue;
    if (n < 0)
      throw Error("reading " + path(name) + ": " + std::strerror(errno));
    data.append(chunk.data(), static_cast<size_t>(n));
    if (progress)
      progress(data.size(), total);
    if (n == 0)
      return data;
  }
}

void LocalProgramStore::writeFrom(const std::string& name, uint64_t size, const StoreSource& source,
                                  const StoreProgress& progress, const std::atomic<bool>* cancel)
{
  std::string base;
  const FileDescriptor folder(openFolder(name, base));
  AtomicFileWriter writer(folder.fd, base, path(name));
  writeChunks(
      name, size, source, kChunk, root_,
      [&writer](std::string_view chunk) { writer.write(reinterpret_cast<const uint8_t*>(chunk.data()), chunk.size()); },
      progress, cancel);
  writer.commit();
}

void writeChunks(const std::string& name, uint64_t size, const StoreSource& source, size_t chunk_size,
                 const std::string& where, const std::function<void(std::string_view chunk)>& write,
                 const StoreProgress& progress, const std::atomic<bool>* cancel)
{
  for (uint64_t done = 0; done < size;)
  {
    throwIfCancelled(cancel, "writing " + name);
    const std::string_view chunk = source(static_cast<size_t>(std::min<uint64_t>(chunk_size, size - done)));
    if (chunk.empty())
      throw Error("writing " + name + ": its data ended after " + std::to_string(done) + " of " + std::to_string(size) +
                  " bytes; " + where + " keeps its previous version");
    write(chunk);
    done += chunk.size();
    if (progress)
      progress(done, size);
  }
  if (size == 0 && progress)
    progress(0, 0);
}

void LocalProgramStore::rename(const std::string& from, const std::string& to)
{
  std::string from_base, to_base;
  const FileDescriptor from_folder(openFolder(from, from_base));
  const FileDescriptor to_folder(openFolder(to, to_base));
  if (::renameat(from_folder.fd, from_base.c_str(), to_folder.fd, to_base.c_str()) != 0)
  {
    if (errno == ENOENT)
      throw NotFoundError("no program '" + from + "' in " + root_);
    throw Error("cannot rename " + path(from) + " to " + path(to) + ": " + std::strerror(errno));
  }
}

void LocalProgramStore::remove(const std::string& name)
{
  std::string base;
  const FileDescriptor folder(openFolder(name, base));
  // unlinkat removes a link itself, never the file it points to.
  if (::unlinkat(folder.fd, base.c_str(), 0) != 0)
  {
    if (errno == ENOENT)
      throw NotFoundError("no program '" + name + "' in " + root_);
    throw Error("cannot remove " + path(name) + ": " + std::strerror(errno));
  }
}
}  // namespace cnc_bridge::programs

namespace cnc_bridge::programs
{
std::string LocalProgramStore::readHead(const std::string& name, size_t bytes)
{
  const FileDescriptor file(openFile(name));
  std::string head(bytes, '\0');
  size_t got = 0;
  while (got < bytes)
  {
    const ssize_t n = ::read(file.fd, head.data() + got, bytes - got);
    if (n < 0 && errno == EINTR)
      continue;
    if (n < 0)
      throw Error("reading " + path(name) + ": " + std::strerror(errno));
    if (n == 0)
      break;
    got += static_cast<size_t>(n);
  }
  head.resize(got);
  return head;
}

unsigned ProgramStore::copyMode(const std::string& /*name*/)
{
  return kProgramFileMode;
}

std::vector<ProgramListing> listPrograms(ProgramStore& store, const NamePattern& pattern)
{
  std::vector<ProgramListing> listing;
  for (const ProgramEntry& entry : store.list())
  {
    ProgramListing item;
    item.entry = entry;
    item.name_number = pattern.number(entry.name);
    try
    {
      item.header = readHeader(store.readHead(entry.name, kHeaderBytes));
    }
    catch (const NotFoundError&)
    {
      continue;  // removed since the listing
    }
    listing.push_back(item);
  }
  return listing;
}

namespace
{
/// A local program read as it is sent, into one buffer of the size the store asks for: memory
/// stays at one chunk whatever the program's size, and no buffer of the program's size is filled
/// first (reading a 20 MB program whole took 25 ms, in 1 MB chunks into one buffer 12 ms). The
/// head that was checked (its O number against the protected range) is the head that is sent.
class LocalFileSource
{
 public:
  // O_NONBLOCK: a FIFO given as the program is refused below instead of waiting for a writer.
  explicit LocalFileSource(const std::string& path)
      : path_(path), fd_(::open(path.c_str(), O_RDONLY | O_NONBLOCK | O_CLOEXEC))
  {
    struct stat info;
    if (fd_ < 0 || ::fstat(fd_, &info) != 0)
    {
      const int error = errno;
      if (fd_ >= 0)
        ::close(fd_);
      throw ConfigError("cannot read " + path + ": " + std::strerror(error));
    }
    if (!S_ISREG(info.st_mode))
    {
      ::close(fd_);
      throw ConfigError("cannot read " + path + ": it is " + fileKind(info.st_mode) + ", not a program file");
    }
    ::fcntl(fd_, F_SETFL, ::fcntl(fd_, F_GETFL) & ~O_NONBLOCK);
    size_ = static_cast<uint64_t>(info.st_size);
  }
  ~LocalFileSource() { ::close(fd_); }
  LocalFileSource(const LocalFileSource&) = delete;
  LocalFileSource& operator=(const LocalFileSource&) = delete;

  uint64_t size() const { return size_; }

  /// The program's number and first comment, read up to its first block however far that is.
  const ProgramHeader& header()
  {
    HeaderScanner scanner;
    char piece[16384];
    for (uint64_t at = 0; !scanner.done() && at < size_;)
    {
      const size_t got = readAt(at, piece, static_cast<size_t>(std::min<uint64_t>(sizeof piece, size_ - at)));
      if (got == 0)
        break;
      scanner.feed(piece, got);
      at += got;
    }
    scanner.finish();
    checked_ = scanner.header();
    return checked_;
  }

  /// The next \p max bytes (fewer only at the end of the size it had when opened).
  std::string_view next(size_t max)
  {
    max = static_cast<size_t>(std::min<uint64_t>(max, size_ - offset_));
    if (buffer_.size() < max)
      buffer_.resize(max);
    const size_t got = readAt(offset_, buffer_.data(), max);
    if (got < max)
    {
      throw Error(path_ + " got shorter while it was sent (" + std::to_string(offset_ + got) + " of " +
                  std::to_string(size_) + " bytes); nothing was replaced");
    }
    const std::string_view chunk(buffer_.data(), got);
    offset_ += got;
    // The bytes sent are read again as they go: their number must be the one checked.
    if (!sent_.done())
    {
      sent_.feed(chunk.data(), chunk.size());
      if (offset_ == size_)
        sent_.finish();
      if (sent_.done() &&
          (sent_.header().number != checked_.number || sent_.header().number_unreadable != checked_.number_unreadable))
        throw Error(path_ + " changed while it was sent (its start is not the one checked); nothing was replaced");
    }
    return chunk;
  }

 private:
  size_t readAt(uint64_t offset, char* data, size_t size) const { return readFully(fd_, offset, data, size, path_); }

  std::string path_;
  int fd_;
  uint64_t size_ = 0;
  uint64_t offset_ = 0;
  std::vector<char> buffer_;  // one chunk, reused
  ProgramHeader checked_;     // as checked
  HeaderScanner sent_;        // the header of the bytes sent so far
};
}  // namespace

uint64_t putProgram(ProgramStore& store, const std::string& local_path, std::string name, const ProtectedRange& range,
                    const NamePattern& pattern, const StoreProgress& progress, const std::atomic<bool>* cancel)
{
  if (name.empty())
  {
    const auto slash = local_path.find_last_of('/');
    name = slash == std::string::npos ? local_path : local_path.substr(slash + 1);
  }
  checkName(name);
  LocalFileSource file(local_path);
  range.checkHeader(local_path + " (as " + name + ")", pattern.number(name), file.header());
  store.writeFrom(
      name, file.size(), [&file](size_t max) { return file.next(max); }, progress, cancel);
  return file.size();
}

void ProgramStore::write(const std::string& name, std::string_view data, const StoreProgress& progress,
                         const std::atomic<bool>* cancel)
{
  size_t done = 0;
  writeFrom(
      name, data.size(),
      [&data, &done](size_t max)
      {
        const std::string_view chunk = data.substr(done, max);
        done += chunk.size();
        return chunk;
      },
      progress, cancel);
}

void ProgramStore::readTo(const std::string& name, const StoreSink& sink, const StoreProgress& progress,
                          const std::atomic<bool>* cancel)
{
  const std::string data = read(name, progress, cancel);
  sink(data.data(), data.size());
}

uint64_t getProgram(ProgramStore& store, const std::string& name, const std::string& local_path,
                    const StoreProgress& progress, const std::atomic<bool>* cancel)
{
  AtomicFileWriter writer(local_path, store.copyMode(name));
  // Each chunk goes to the temporary file as it arrives; the writer starts its writeback at once,
  // so commit()'s fsync has little left to wait for (docs/share_node.md, "cnc_dnc").
  store.readTo(
      name, [&](const char* data, size_t size) { writer.write(reinterpret_cast<const uint8_t*>(data), size); },
      progress, cancel);
  writer.commit();
  return writer.bytesWritten();
}
}  // namespace cnc_bridge::programs
