// Name checks shared by every store, and the local-directory store (AtomicFileWriter for writes).
#include "cnc_bridge/programs/program_store.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <utility>

#include "cnc_bridge/common/atomic_file.h"
#include "cnc_bridge/common/regular_file.h"

namespace cnc_bridge::programs
{
namespace fs = std::filesystem;

namespace
{
constexpr size_t kChunk = size_t{64} * 1024;
}  // namespace

void throwIfCancelled(const std::atomic<bool>* cancel, const std::string& what)
{
  if (cancel != nullptr && cancel->load())
    throw CancelledError(what + " cancelled");
}

void checkName(const std::string& name)
{
  if (name.empty() || name[0] == '/')
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
  std::error_code error;
  if (!fs::is_directory(root_, error))
    throw ConfigError("program directory '" + root_ + "' does not exist or is not a directory");
}

std::string LocalProgramStore::path(const std::string& name) const
{
  checkName(name);
  return root_ + "/" + name;
}

std::vector<ProgramEntry> LocalProgramStore::list()
{
  std::vector<ProgramEntry> entries;
  std::error_code error;
  for (const auto& item : fs::directory_iterator(root_, error))
  {
    const std::string name = item.path().filename().string();
    if (!item.is_regular_file(error) || isTemporaryName(name))
      continue;
    entries.push_back(stat(name));
  }
  if (error)
    throw Error("cannot list " + root_ + ": " + error.message());
  std::sort(entries.begin(), entries.end(), [](const auto& a, const auto& b) { return a.name < b.name; });
  return entries;
}

ProgramEntry LocalProgramStore::stat(const std::string& name)
{
  struct stat info;
  if (::stat(path(name).c_str(), &info) != 0)
  {
    if (errno == ENOENT)
      throw NotFoundError("no program '" + name + "' in " + root_);
    throw Error("cannot stat " + path(name) + ": " + std::strerror(errno));
  }
  ProgramEntry entry;
  entry.name = name;
  entry.size = static_cast<uint64_t>(info.st_size);
  entry.mtime = info.st_mtime;
  return entry;
}

std::string LocalProgramStore::read(const std::string& name, const StoreProgress& progress,
                                    const std::atomic<bool>* cancel)
{
  const uint64_t total = stat(name).size;
  std::ifstream in(path(name), std::ios::binary);
  if (!in)
    throw Error("cannot read " + path(name));
  std::string data;
  std::string chunk(kChunk, '\0');
  while (in)
  {
    throwIfCancelled(cancel, "reading " + name);
    in.read(chunk.data(), static_cast<std::streamsize>(chunk.size()));
    data.append(chunk.data(), static_cast<size_t>(in.gcount()));
    if (progress)
      progress(data.size(), total);
  }
  if (in.bad())
    throw Error("reading " + path(name) + " failed");
  return data;
}

void LocalProgramStore::writeFrom(const std::string& name, uint64_t size, const StoreSource& source,
                                  const StoreProgress& progress, const std::atomic<bool>* cancel)
{
  AtomicFileWriter writer(path(name));
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
  if (::rename(path(from).c_str(), path(to).c_str()) != 0)
  {
    if (errno == ENOENT)
      throw NotFoundError("no program '" + from + "' in " + root_);
    throw Error("cannot rename " + path(from) + " to " + path(to) + ": " + std::strerror(errno));
  }
}

void LocalProgramStore::remove(const std::string& name)
{
  if (::unlink(path(name).c_str()) != 0)
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
  stat(name);                    // NotFoundError
  RegularFile file(path(name));  // a FIFO or a directory is refused, never waited on
  std::string head(static_cast<size_t>(std::min<uint64_t>(bytes, file.size())), '\0');
  head.resize(file.readAt(0, head.data(), head.size()));
  return head;
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
  explicit LocalFileSource(const std::string& path) : path_(path), fd_(::open(path.c_str(), O_RDONLY | O_CLOEXEC))
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
      throw ConfigError("cannot read " + path + ": not a file");
    }
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
  size_t readAt(uint64_t offset, char* data, size_t size) const
  {
    size_t got = 0;
    while (got < size)
    {
      const ssize_t n = ::pread(fd_, data + got, size - got, static_cast<off_t>(offset + got));
      if (n < 0 && errno == EINTR)
        continue;
      if (n < 0)
        throw Error("reading " + path_ + ": " + std::strerror(errno));
      if (n == 0)
        break;
      got += static_cast<size_t>(n);
    }
    return got;
  }

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
  AtomicFileWriter writer(local_path);
  // Each chunk goes to the temporary file as it arrives; the writer starts its writeback at once,
  // so commit()'s fsync has little left to wait for (docs/share_node.md, "cnc_dnc").
  store.readTo(
      name, [&](const char* data, size_t size) { writer.write(reinterpret_cast<const uint8_t*>(data), size); },
      progress, cancel);
  writer.commit();
  return writer.bytesWritten();
}
}  // namespace cnc_bridge::programs
