// One NC program file moved by XModem, as cnc_dnc, dnc_node and sim_haas_serial all need it:
// read the file and give it the control's end-of-block pattern before sending; strip the padding,
// convert the line ends and write the file atomically after receiving.
#pragma once

#include <atomic>
#include <functional>
#include <string>
#include <vector>

#include "cnc_bridge/xmodem/session.h"

namespace cnc_bridge
{
namespace xmodem
{
/// \brief How file bytes relate to the bytes on the wire.
struct TextOptions
{
  /// Keep the bytes exact: no end-of-block conversion, and the received file keeps the SUB padding
  /// of the last block (XModem has no length field, so padding cannot be told from data).
  bool binary = false;
  /// The control's end-of-block pattern (Haas setting 25, "EOB PATTERN"); LF ONLY is the advice.
  Eob control_eob = Eob::kLf;
  /// Line ends of the files on this side (what received programs are stored with).
  Eob file_eob = Eob::kLf;
  /// How the control sums a checksum-mode packet holding ends of block (packet.h, EobChecksum).
  /// A binary transfer has no ends of block: its packets are summed as on the wire.
  EobChecksum eob_checksum = EobChecksum::kWire;
};

/// \brief \p config with the end-of-block checksum reading of \p options (Config::eob_checksum).
Config withEobReading(Config config, const TextOptions& options);

/// \brief A finished file transfer.
struct FileResult
{
  Stats stats;
  uint64_t file_bytes = 0;  ///< bytes of the file read or written
  std::string path;
  std::string message;  ///< one line for a log or a ROS result
};

/// \brief The wire payload for a file's contents. Text: line ends rewritten to the control's EOB.
std::vector<uint8_t> toWire(const std::string& file_contents, const TextOptions& options);
/// \brief The file contents for a received payload. Text: padding stripped, EOB rewritten.
std::string fromWire(std::vector<uint8_t> payload, const TextOptions& options);

/// \brief A check of the contents about to be sent (the protected range); throws to refuse them.
using ContentCheck = std::function<void(const std::string& contents)>;

/// \brief Reads \p path (opened once, a regular file of at most Config::max_bytes) and sends it.
/// \param stats if given, receives the counters, also when the transfer fails.
/// \param check if given, is run on the contents read, before the first byte is written: the bytes
/// sent are the bytes checked, whatever happens to the file meanwhile.
/// \throws ConfigError if the file cannot be read, is not a regular file or is larger than the cap;
/// what \p check throws; the errors of Sender::send().
FileResult sendFile(Transport& link, const std::string& path, Mode mode, const Config& config,
                    const TextOptions& options, const ProgressCallback& progress = nullptr,
                    const std::atomic<bool>* cancel = nullptr, Stats* stats = nullptr,
                    const ContentCheck& check = nullptr);

/// \brief Receives into \p path atomically: on any failure the destination is left as it was.
/// \throws ConfigError if the directory cannot be written; the errors of Receiver::receive().
FileResult receiveFile(Transport& link, const std::string& path, Mode mode, const Config& config,
                       const TextOptions& options, const ProgressCallback& progress = nullptr,
                       const std::atomic<bool>* cancel = nullptr, Stats* stats = nullptr);
}  // namespace xmodem
}  // namespace cnc_bridge
