// XModem packets and program text: the framing, the two check codes, the packet parser the
// receiver (and the fuzzer) runs on every block, and the end-of-block conversion a Haas control
// needs (setting 25). Everything here is pure: bytes in, plain structs out, no I/O.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace cnc_bridge
{
namespace xmodem
{
// Control characters (ASCII names as in Forsberg's XMODEM/YMODEM reference).
constexpr uint8_t kSoh = 0x01;  ///< start of a 128-byte packet
constexpr uint8_t kStx = 0x02;  ///< start of a 1024-byte packet (XModem-1K)
constexpr uint8_t kEot = 0x04;  ///< end of transmission
constexpr uint8_t kAck = 0x06;
constexpr uint8_t kNak = 0x15;      ///< also the receiver's "start, checksum mode please"
constexpr uint8_t kCan = 0x18;      ///< two in a row abort the transfer
constexpr uint8_t kSub = 0x1A;      ///< pads the last block (CP/M end of file)
constexpr uint8_t kCrcStart = 'C';  ///< the receiver's "start, CRC mode please"

constexpr size_t kBlockSize = 128;
constexpr size_t kBlockSize1K = 1024;

/// \brief How a packet ends: XModem's original 8-bit sum or XModem-CRC's CRC-16.
enum class CheckType
{
  kChecksum,  ///< 1 byte: sum of the data bytes modulo 256 (the only mode a Haas speaks)
  kCrc16      ///< 2 bytes: CRC-16/XMODEM of the data, high byte first
};
const char* toString(CheckType check);

/// \brief 8-bit arithmetic sum of \p size bytes.
uint8_t checksum8(const uint8_t* data, size_t size);
/// \brief CRC-16/XMODEM: polynomial 0x1021, initial value 0, no reflection (check value of
/// "123456789" is 0x31C3).
uint16_t crc16Xmodem(const uint8_t* data, size_t size, uint16_t crc = 0);

/// \brief Bytes on the wire for a packet of \p data_size data bytes.
constexpr size_t packetSize(size_t data_size, CheckType check)
{
  return 3 + data_size + (check == CheckType::kCrc16 ? 2 : 1);
}

/// \brief Builds one packet.
///
/// Wire format (Forsberg; OpenDNC, "Standard", figure 8; docs/protocols/xmodem.md#packet):
///
///     SOH|STX  blk  255-blk  data[128|1024]  sum8 | crc16-hi crc16-lo
///
/// blk counts from 1 and wraps 255 -> 0. Data shorter than the block is padded with SUB (0x1A).
/// \param block the block number (only the low 8 bits go on the wire).
/// \param data at most \p block_size bytes.
/// \param block_size kBlockSize or kBlockSize1K.
/// \throws std::invalid_argument on an invalid size.
std::vector<uint8_t> encodePacket(uint32_t block, const uint8_t* data, size_t size, size_t block_size, CheckType check);

/// \brief End-of-block pattern of a Haas control (setting 25 "EOB PATTERN") or of a stored file.
enum class Eob
{
  kLf,
  kCr,
  kCrLf,
  kCrCr,
  kLfLf
};

/// \brief How a control sums a checksum-mode packet that carries ends of block.
///
/// OpenDNC's description of the Haas says that whatever setting 25 sends for an end of block, the
/// control computes the checksum as if it were LF (docs/protocols/xmodem.md#haas-end-of-block).
/// Every other XModem sums the bytes on the wire. With setting 25 on LF ONLY both agree.
enum class EobChecksum
{
  kWire,  ///< the sum of the bytes on the wire
  kLf,    ///< each end of block counted as one LF (0x0A): its first byte as LF, the rest as nothing
};
/// \brief "wire", "lf".
const char* toString(EobChecksum reading);
/// \throws ConfigError naming the accepted values.
EobChecksum parseEobChecksum(const std::string& text);

/// \brief The checksum of packet after packet under one reading. An end of block cut by a
/// packet's end (CR at the end of one, LF at the start of the next) is read on in the next, so the
/// reading keeps where the packets accepted so far left off. Not thread-safe.
class ChecksumReading
{
 public:
  ChecksumReading() = default;  ///< the wire reading
  ChecksumReading(EobChecksum reading, Eob eob);

  /// \brief The sum of the next packet's data under this reading.
  uint8_t sum(const uint8_t* data, size_t size) const { return sumAs(reading_, data, size, nullptr); }
  /// \brief The sum of the same data under the other reading: a packet that fails this reading
  /// and passes the other tells which one the control uses.
  uint8_t otherSum(const uint8_t* data, size_t size) const;
  /// \brief Moves past a packet's data once it was accepted (or acknowledged).
  void accept(const uint8_t* data, size_t size);
  EobChecksum reading() const { return reading_; }
  EobChecksum other() const { return reading_ == EobChecksum::kWire ? EobChecksum::kLf : EobChecksum::kWire; }

 private:
  uint8_t sumAs(EobChecksum reading, const uint8_t* data, size_t size, bool* inside_after) const;

  EobChecksum reading_ = EobChecksum::kWire;
  Eob eob_ = Eob::kLf;
  bool inside_pattern_ = false;  ///< the last byte accepted began a two-byte end of block
};

/// \brief What the parser made of one packet.
enum class PacketStatus
{
  kOk,
  kTruncated,      ///< fewer bytes than the header promises
  kBadHeader,      ///< first byte neither SOH nor STX
  kBadComplement,  ///< blk and 255-blk disagree (a garbled header)
  kBadCheck        ///< checksum or CRC mismatch (garbled data)
};
const char* toString(PacketStatus status);

struct Packet
{
  PacketStatus status = PacketStatus::kTruncated;
  uint8_t block = 0;     ///< block number as on the wire (valid when the complement matched)
  size_t data_size = 0;  ///< 128 or 1024 (from the header byte)
  /// Points into the parsed buffer, data_size bytes, followed by the check (valid when kOk or
  /// kBadCheck).
  const uint8_t* data = nullptr;
};

/// \brief Parses and checks one complete packet starting at its SOH/STX. Bounds-checked: any
/// \p size is safe, bytes beyond the packet are ignored.
/// \param reading how a checksum is computed (nullptr: over the bytes on the wire).
Packet decodePacket(const uint8_t* bytes, size_t size, CheckType check, const ChecksumReading* reading = nullptr);
/// \brief "lf", "cr", "crlf", "crcr", "lflf".
const char* toString(Eob eob);
/// \throws ConfigError naming the accepted values.
Eob parseEob(const std::string& text);
/// \brief The bytes of the pattern ("\r\n" for kCrLf).
std::string eobBytes(Eob eob);

/// \brief Rewrites the line ends of a program file for the control: every LF, CR LF or lone CR
/// in \p text becomes \p control's pattern. Other bytes are kept exactly.
std::string toControlEob(const std::string& text, Eob control);

/// \brief Rewrites a program received from a control whose EOB pattern is \p control into a file
/// with line ends \p file. The doubled patterns (CR CR, LF LF) are read as one end of block, so
/// an empty block in the program is a pattern followed directly by another. Bytes that are not
/// part of a pattern are kept exactly.
std::string fromControlEob(const std::string& text, Eob control, Eob file);

/// \brief Removes trailing SUB padding (XModem pads the last block; a text program never ends
/// in SUB). Returns the new size.
size_t stripSubPadding(std::vector<uint8_t>& data);
}  // namespace xmodem
}  // namespace cnc_bridge
