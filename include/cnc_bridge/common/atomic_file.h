// Files that appear complete or not at all. A received NC program is written to a temporary file
// in the destination directory, flushed to disk, and renamed over the destination only when the
// transfer has been verified. A failed or cancelled transfer leaves the destination as it was.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>

namespace cnc_bridge
{
/// \brief Writes one file atomically. Not thread-safe (one writer per object).
class AtomicFileWriter
{
 public:
  /// \brief Creates `<dir>/.<name>.XXXXXX` next to \p path.
  /// \throws ConfigError if the directory does not exist or cannot be written.
  explicit AtomicFileWriter(std::string path);
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

  std::string path_;
  std::string temp_path_;
  int fd_ = -1;
  size_t bytes_written_ = 0;
  size_t writeback_from_ = 0;  ///< the first byte whose writeback has not been started
  bool committed_ = false;
};
}  // namespace cnc_bridge
