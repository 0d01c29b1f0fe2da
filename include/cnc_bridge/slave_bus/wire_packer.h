// WirePacker framing: the packet format of the ESP32 I2C slave library that the universal-CNC paper
// (docs/protocols/slave_bus.md#wirepacker-frame) uses between the master and its
// slaves. cnc_bridge uses the same framing on the serial link in its optional framed mode, so one
// codec serves the simulated I2C bus and the PC <-> master link.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace cnc_bridge
{
namespace slave_bus
{
/// \brief CRC-8/MAXIM (Dallas 1-Wire): reflected polynomial 0x8C (0x31 unreflected), init 0, no final
/// XOR. Check value over "123456789" is 0xA1.
uint8_t crc8Maxim(const uint8_t* data, size_t size, uint8_t crc = 0);

/// \brief Which bytes of a frame the CRC covers.
///
/// The packet format (the library's header comment, the universal-CNC paper's figure 17, protocols/slave_bus.md) says
/// "CRC8 of packet length and data". The released code of the library the universal-CNC paper cites
/// (gutierrezps/ESP32_I2C_Slave, src/WirePacker.cpp and src/WireCrc.h) computes something else:
/// end() calls `crc8.calc(&length, 1)` and then returns `crc8.update(data, n)`, but update() starts
/// from the member `seed` (0, set by calc()) and never stores its result, so the length byte's CRC
/// is thrown away and the CRC covers the data only. Its WireUnpacker checks the same way, so two
/// library boards agree with each other and disagree with the documented format: for data 31 32 33
/// the library sends 02 07 31 32 33 95 04, the documented format 02 07 31 32 33 13 04.
enum class WireCrc
{
  kSpec,    ///< length byte then data, as the packet format documents it (cnc_bridge's default)
  kLibrary  ///< data only, as the library's released code computes it (firmware built on the library)
};
WireCrc parseWireCrc(const std::string& text);  ///< "spec" | "library"; \throws ConfigError
const char* toString(WireCrc crc);

/// \brief The dialect of WirePacker a master and its slaves speak: CRC coverage and the most data
/// one frame may carry.
struct WireFormat
{
  /// Largest data of any frame: the length byte counts data + 4 and is one byte.
  static constexpr size_t kMaxData = 255 - 4;
  /// Largest data of a frame of the library: its buffers hold PACKER_BUFFER_LENGTH and
  /// UNPACKER_BUFFER_LENGTH = 128 bytes of frame (WirePacker.h, WireUnpacker.h), so 124 of data;
  /// WirePacker::write() drops bytes beyond that and WireUnpacker rejects a longer length byte.
  static constexpr size_t kLibraryMaxData = 128 - 4;

  WireCrc crc = WireCrc::kSpec;
  size_t max_data = kMaxData;  ///< 1..kMaxData

  /// \brief The format for \p crc with \p max_data (0: that variant's default, kMaxData for spec,
  /// kLibraryMaxData for library). \throws ConfigError if max_data is over kMaxData.
  static WireFormat of(WireCrc crc, size_t max_data = 0);

  /// \brief The CRC of a frame whose length byte is \p length and data \p data.
  uint8_t crcOf(uint8_t length, const uint8_t* data, size_t size) const;
};

/// \brief Packs and unpacks WirePacker frames.
///
/// Wire format (the universal-CNC paper's figure 17; docs/protocols/slave_bus.md#wirepacker-frame):
/// \code
///   [0]     0x02            start byte (STX)
///   [1]     total length    every byte of the frame: data + 4, so 4..255
///   [2..]   data            0..251 bytes (0..124 in the library's buffers)
///   [n+2]   CRC-8/MAXIM     over the length byte then the data (WireCrc::kSpec), or the data
///                           only (WireCrc::kLibrary, what the library's code computes)
///   [n+3]   0x04            end byte (EOT)
/// \endcode
/// The start and end bytes are not escaped: 0x02 and 0x04 may appear inside the data, so a receiver
/// finds frame boundaries from the length byte and trusts a frame only when the end byte and the CRC
/// match. All functions are pure.
struct WirePacker
{
  static constexpr uint8_t kStart = 0x02;
  static constexpr uint8_t kEnd = 0x04;
  static constexpr size_t kOverhead = 4;
  static constexpr size_t kMaxData = WireFormat::kMaxData;

  /// \brief Frames \p data.
  /// \throws ProtocolError if \p data is longer than format.max_data bytes (the message says which
  /// limit: a frame's 251, or the configured one).
  static std::vector<uint8_t> pack(const uint8_t* data, size_t size, const WireFormat& format = {});
  static std::vector<uint8_t> pack(const std::vector<uint8_t>& data, const WireFormat& format = {})
  {
    return pack(data.data(), data.size(), format);
  }

  /// \brief Unpacks one complete frame (nothing before or after it).
  /// \throws ProtocolError naming what is wrong: start, length, CRC or end byte.
  static std::vector<uint8_t> unpack(const uint8_t* frame, size_t size, const WireFormat& format = {});
  static std::vector<uint8_t> unpack(const std::vector<uint8_t>& frame, const WireFormat& format = {})
  {
    return unpack(frame.data(), frame.size(), format);
  }
};

/// \brief Finds WirePacker frames in a byte stream that may hold garbage, torn frames and
/// corrupted bytes (a serial link with no other framing). Not thread-safe.
///
/// Resynchronisation: bytes before a start byte are dropped and counted as garbage. A candidate
/// frame (start, a length of 4..max_data + 4, that many bytes) is accepted only if its end byte is
/// 0x04 and its CRC matches; a length byte outside that range rejects the candidate at once. Otherwise the candidate's
/// start byte alone is dropped and the search restarts at the byte after it, so a real frame that began inside the
/// rejected candidate is still found and nothing valid is lost. A frame split across feed() calls is kept until it
/// completes. A stray start byte with a large length holds the frames behind it until that many bytes arrived; the
/// owner calls resync() when the line has been silent, which abandons such a candidate and
/// delivers the frames it was hiding.
class WireStreamUnpacker
{
 public:
  struct Stats
  {
    uint64_t frames = 0;          ///< good frames delivered
    uint64_t crc_errors = 0;      ///< candidates whose end byte matched but CRC did not
    uint64_t framing_errors = 0;  ///< candidates with a bad length or end byte
    uint64_t garbage_bytes = 0;   ///< bytes dropped while searching for a frame
  };

  explicit WireStreamUnpacker(WireFormat format = {}) : format_(format) {}

  /// \brief Adds bytes from the link.
  /// \returns the data of every complete, valid frame they finish, in order.
  std::vector<std::vector<uint8_t>> feed(const uint8_t* data, size_t size);

  /// \brief After a silence: the peer will not finish a partial frame. Abandons every incomplete
  /// candidate (one start byte at a time, counted as framing errors) and rescans what follows it.
  /// \returns complete frames found behind the abandoned candidates; pending() is 0 afterwards.
  std::vector<std::vector<uint8_t>> resync();

  /// \brief Bytes held of a frame not yet complete.
  size_t pending() const { return buffer_.size(); }
  const Stats& stats() const { return stats_; }

 private:
  void scan(std::vector<std::vector<uint8_t>>& frames, bool abandon_incomplete);

  WireFormat format_;
  std::vector<uint8_t> buffer_;
  Stats stats_;
};
}  // namespace slave_bus
}  // namespace cnc_bridge
