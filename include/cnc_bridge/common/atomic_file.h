// Files that appear complete or not at all. A received NC program is written to a temporary file
// in the destination directory, flushed to disk, and renamed over the destination only when the
// transfer has been verified. A failed or cancelled transfer leaves the destination as it was.
//
// The temporary file is created under the destination folder's descriptor with O_CREAT | O_EXCL |
// O_NOFOLLOW: a link or file planted at its name is never opened or followed (the name is random and
// another is tried). The rename replaces a link at the destination itself, never the file it points
// to. Files are created with kProgramFileMode (0640: owner read/write, group read, nothing for
// others; the process umask can only narrow it), or a narrower mode the caller gives.
#pragma once

#include <sys/types.h>

#include <cstddef>
#include <cstdint>
#include <string>

namespace cnc_bridge
{
/// \brief The mode of every program, copy and archived version the bridge writes (before the umask).
constexpr mode_t kProgramFileMode = 0640;

/// \brief Writes one file atomically. Not thread-safe (one writer per object).
class AtomicFileWriter
{
 public:
  /// \brief Creates `<dir>/.<name>.partial.XXXXXX` next to \p path, with \p mode (bits beyond
  /// kProgramFileMode are dropped).
  /// \throws ConfigError if the directory does not exist or cannot be written.
  explicit AtomicFileWriter(std::string path, mode_t mode = kProgramFileMode);
  /// \brief As above, \p name in the folder open as \p dir_fd (not taken over; it must stay open
  /// until commit() or discard()); \p shown is how messages name the file.
  AtomicFileWriter(int dir_fd, const std::string& name, std::string shown, mode_t mode = kProgramFileMode);
  /// Discards the temporary file unless commit() succeeded.
  ~AtomicFileWriter();
  AtomicFileWriter(const AtomicFileWriter&) = delete;
  AtomicFileWriter& operator=(const AtomicFileWriter&) = delete;

  /// \brief Appends bytes to the temporary file, and starts the disk writing each further 1 MB
  /// without waiting for it, so that commit()'s fsync mostly finds it done (a download written as it
  /// arrives). \throws Error on a write failure (disk full).
  void write(const uint8_t* data, size_t size);
  void write(const std::string& text) { write(reinterpret_cast<const uint8_t*>(text.data()), text.size()); }

  /// \brief fsyncs the temporary file, renames it over the destination and fsyncs the directory.
  void commit();
  /// \brief Removes the temporary file; the destination is untouched. Safe to call twice.
  void discard();

  size_t bytesWritten() const { return bytes_written_; }
  const std::string& path() const { return path_; }

 private:
  /// Bytes written before the disk is asked to start writing them (startWriteback()).
  static constexpr size_t kWritebackStep = size_t{1024} * 1024;
  void startWriteback();
  void create(const std::string& name, mode_t mode);
  std::string tempShown() const;

  std::string path_;       ///< as shown in messages
  std::string name_;       ///< the destination's name in the folder
  std::string temp_name_;  ///< the temporary file's name in the folder ("" once removed)
  int dir_fd_ = -1;
  bool own_dir_fd_ = false;
  int fd_ = -1;
  size_t bytes_written_ = 0;
  size_t writeback_from_ = 0;  ///< the first byte whose writeback has not been started
  bool committed_ = false;
};
}  // namespace cnc_bridge
