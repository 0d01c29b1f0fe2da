// Where programs live: a folder the bridge reads programs from and writes them to, whether it is
// a local directory or a control's (or a file server's) SMB share. Nodes and the cnc_dnc tool
// move programs through this interface, so the wire a machine uses does not change their code.
//
// Every implementation writes atomically as the control sees it: the program is written under a
// temporary name in the same folder and renamed to its name only when complete, so a control
// polling the folder never opens a partial program, and a failed write leaves the previous
// version in place.
#pragma once

#include <atomic>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <set>
#include <string>
#include <string_view>
#include <vector>

#include "cnc_bridge/common/error.h"
#include "cnc_bridge/programs/program_name.h"

namespace cnc_bridge::programs
{
/// \brief One file of a program folder.
struct ProgramEntry
{
  std::string name;   ///< relative to the store's folder
  uint64_t size = 0;  ///< bytes
  int64_t mtime = 0;  ///< modification time, seconds since the epoch
};

/// \brief The named file does not exist in the store (other failures are Error/LinkError).
class NotFoundError : public Error
{
 public:
  using Error::Error;
};

/// \brief Bytes moved so far and the total (0 when unknown). Called after each chunk.
using StoreProgress = std::function<void(uint64_t done, uint64_t total)>;
/// \brief Takes the bytes of a file in order, one chunk at a time (readTo()).
using StoreSink = std::function<void(const char* data, size_t size)>;
/// \brief Gives the bytes of an upload in order (writeFrom()): a view of the next \p max bytes
/// (fewer only at the end), valid until the next call; empty when there are no more.
using StoreSource = std::function<std::string_view(size_t max)>;

/// \brief A folder of programs. Names are relative to the folder: '/'-separated, no empty, '.' or
/// '..' component (checkName()). Implementations are thread-safe (calls are serialised).
class ProgramStore
{
 public:
  virtual ~ProgramStore() = default;

  /// \brief Where the store is, for messages ("/srv/programs", "smb://cnc1:445/memory").
  virtual std::string describe() const = 0;
  /// \brief The files of the folder (not its subfolders), temporary files of unfinished writes
  /// left out, sorted by name.
  virtual std::vector<ProgramEntry> list() = 0;
  /// \throws NotFoundError if \p name does not exist.
  virtual ProgramEntry stat(const std::string& name) = 0;
  /// \brief The whole file. \throws NotFoundError, Error, CancelledError (when \p cancel is set).
  virtual std::string read(const std::string& name, const StoreProgress& progress = nullptr,
                           const std::atomic<bool>* cancel = nullptr) = 0;
  /// \brief The whole file handed to \p sink chunk by chunk as it arrives, so that a download is
  /// written out while the next chunk is fetched (getProgram()). This default reads the whole file
  /// first. \throws as read(), and what \p sink throws.
  virtual void readTo(const std::string& name, const StoreSink& sink, const StoreProgress& progress = nullptr,
                      const std::atomic<bool>* cancel = nullptr);
  /// \brief At most the first \p bytes of the file (for listings). \throws as read().
  virtual std::string readHead(const std::string& name, size_t bytes) = 0;
  /// \brief The mode a local copy of \p name gets (getProgram()): kProgramFileMode (0640) unless
  /// the store knows the file's own mode is narrower. Asks the store nothing by default.
  virtual unsigned copyMode(const std::string& name);
  /// \brief Replaces (or creates) \p name with the \p size bytes \p source gives, atomically (see
  /// the file comment), each chunk sent as it comes: an upload of a local file holds one chunk in
  /// memory, not the whole program (putProgram()).
  /// \throws Error (also when \p source ends before \p size bytes), CancelledError, what \p source
  /// throws; the previous version is in place and no temporary file remains unless the server
  /// vanished (then the next connection removes it).
  virtual void writeFrom(const std::string& name, uint64_t size, const StoreSource& source,
                         const StoreProgress& progress = nullptr, const std::atomic<bool>* cancel = nullptr) = 0;
  /// \brief writeFrom() with \p data in memory. \throws as writeFrom().
  void write(const std::string& name, std::string_view data, const StoreProgress& progress = nullptr,
             const std::atomic<bool>* cancel = nullptr);
  /// \brief Renames \p from to \p to, replacing \p to if it exists.
  virtual void rename(const std::string& from, const std::string& to) = 0;
  /// \throws NotFoundError if \p name does not exist.
  virtual void remove(const std::string& name) = 0;
};

/// \brief \throws CancelledError ("<what> cancelled") if \p cancel is set.
void throwIfCancelled(const std::atomic<bool>* cancel, const std::string& what);

/// \brief The loop of every writeFrom(): takes \p size bytes from \p source in chunks of at most
/// \p chunk_size and hands each to \p write, checking \p cancel before each chunk and reporting
/// \p progress after it (once with 0 of 0 for an empty program).
/// \throws CancelledError; Error if \p source ends early (naming \p name, and \p where as keeping the
/// previous version); what \p write throws.
void writeChunks(const std::string& name, uint64_t size, const StoreSource& source, size_t chunk_size,
                 const std::string& where, const std::function<void(std::string_view chunk)>& write,
                 const StoreProgress& progress, const std::atomic<bool>* cancel);

/// \brief Refuses a name that is empty, absolute, has an empty, '.' or '..' component, or a
/// control character. \throws ConfigError naming it.
void checkName(const std::string& name);
/// \brief Whether \p name is one of the temporary names writes use (hidden from list()).
bool isTemporaryName(const std::string& name);
/// \brief A temporary name beside \p name: `.<name>.<tag>.partial` in the same folder.
std::string temporaryName(const std::string& name, const std::string& tag);

/// \brief A local directory (a folder share_node serves, `~serve_dir`, or a `~url` that is a
/// folder). Only regular files are programs, and no symbolic link is followed below \p root, not
/// even one whose target is inside: every name is opened under the folder's descriptor with
/// O_NOFOLLOW (each subfolder too), so a link planted in the folder cannot make the store read,
/// list, copy or replace a file elsewhere. list() skips links, FIFOs, sockets and devices (each
/// named once in the log) and subfolders; read(), readHead() and stat() refuse them by name
/// (ConfigError). Writes create kProgramFileMode (0640) files.
class LocalProgramStore : public ProgramStore
{
 public:
  /// \throws ConfigError if \p root is not a directory.
  explicit LocalProgramStore(std::string root);
  std::string describe() const override { return root_; }
  std::vector<ProgramEntry> list() override;
  ProgramEntry stat(const std::string& name) override;
  std::string read(const std::string& name, const StoreProgress& progress = nullptr,
                   const std::atomic<bool>* cancel = nullptr) override;
  std::string readHead(const std::string& name, size_t bytes) override;
  unsigned copyMode(const std::string& name) override;
  void writeFrom(const std::string& name, uint64_t size, const StoreSource& source,
                 const StoreProgress& progress = nullptr, const std::atomic<bool>* cancel = nullptr) override;
  void rename(const std::string& from, const std::string& to) override;
  void remove(const std::string& name) override;

 private:
  /// The root folder as a new descriptor (-1 and errno if it cannot be opened).
  int openRoot() const;
  /// The folder of \p name (the root, or a subfolder reached without following links) as a new
  /// descriptor the caller closes, and \p base the name in it. \throws NotFoundError, ConfigError.
  int openFolder(const std::string& name, std::string& base) const;
  /// The open regular file \p name (the caller closes it). \throws NotFoundError, ConfigError, Error.
  int openFile(const std::string& name) const;
  /// Logs once per name that list() left \p name out, being \p kind.
  void reportSkipped(const std::string& name, const std::string& kind);
  std::string path(const std::string& name) const;
  std::string root_;
  std::mutex skipped_mutex_;
  std::set<std::string> skipped_;  ///< names list() has reported leaving out
};

/// \brief A program as a listing shows it: the file, and its O number and first comment.
struct ProgramListing
{
  ProgramEntry entry;
  std::optional<uint32_t> name_number;  ///< from the file name (by the store's name pattern)
  ProgramHeader header;                 ///< from the head of the file
};

/// \brief The store's files with their numbers and first comments. \throws as list().
std::vector<ProgramListing> listPrograms(ProgramStore& store, const NamePattern& pattern);

/// \brief Sends the local file \p local_path to \p store as \p name (its base name if empty),
/// refusing a protected program before a byte is written, and reading the file as it is sent.
/// \returns the bytes written.
/// \throws DisabledError (protected), ConfigError, Error, CancelledError.
uint64_t putProgram(ProgramStore& store, const std::string& local_path, std::string name, const ProtectedRange& range,
                    const NamePattern& pattern, const StoreProgress& progress = nullptr,
                    const std::atomic<bool>* cancel = nullptr);
/// \brief Fetches \p name from \p store into \p local_path atomically (a failed fetch leaves the
/// local file as it was). \returns the bytes written.
uint64_t getProgram(ProgramStore& store, const std::string& name, const std::string& local_path,
                    const StoreProgress& progress = nullptr, const std::atomic<bool>* cancel = nullptr);
}  // namespace cnc_bridge::programs
