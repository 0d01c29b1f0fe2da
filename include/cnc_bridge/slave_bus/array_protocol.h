// The serial array protocol of the universal-CNC paper (docs/protocols/slave_bus.md#source; its
// "Equation 1 serial array protocol" and its state machine), in both directions: the PC's step
// frame to the master, the master's receive state machine, and the uplink from the master to the
// PC that the universal-CNC paper leaves loose and cnc_bridge defines here. Raw and framed (WirePacker + CRC) links.
#pragma once

#include <cstddef>
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "cnc_bridge/slave_bus/wire_packer.h"

namespace cnc_bridge
{
namespace slave_bus
{
/// \brief Largest slave count of one frame: I2C has 7-bit addresses, and the universal-CNC paper numbers slaves 1..N.
constexpr size_t kMaxSlaves = 127;
/// \brief Largest payload per slave: the length is one byte, and the master repacks it into one
/// WirePacker frame for the I2C bus (at most 251 data bytes; a master built on the ESP32 library
/// takes at most WireFormat::kLibraryMaxData, 124, and WireFormat::max_data says what one takes).
constexpr size_t kMaxPayload = WirePacker::kMaxData;

/// \brief How bytes travel on the PC <-> master serial link.
enum class Framing
{
  kRaw,    ///< the universal-CNC paper's bytes as they are: byte-compatible with its master firmware; no error check
  kFramed  ///< every step frame and every uplink record inside a WirePacker frame (CRC-8, resync)
};
Framing parseFraming(const std::string& text);  ///< "raw" | "framed"; \throws ConfigError
const char* toString(Framing framing);

/// \brief One step: payloads[i] goes to slave address i + 1; an empty payload sends nothing to it.
using StepPayloads = std::vector<std::vector<uint8_t>>;

/// \brief Encodes the PC -> master step frame of the universal-CNC paper:
/// \code
///   [number of slaves N, len_1, payload_1..., len_2, payload_2..., ..., len_N, payload_N...]
/// \endcode
/// every field one byte; a slave that gets nothing this step has length 0 and no payload bytes.
/// The universal-CNC paper's examples: [3, 2, x, y, 1, a, 3, f, g, h] and [8, 1, x, 1, y, 1, z, 0, 0, 1, data, 0, 0]
/// (slave 6 gets data). The frame carries all slaves so that they get their data at nearly the same
/// time (the tool fires only once X and Y are in place).
/// \throws ProtocolError if there are no slaves, more than kMaxSlaves, or a payload over
/// \p max_payload (the most one I2C frame of the master carries; at most kMaxPayload).
std::vector<uint8_t> encodeStep(const StepPayloads& payloads, size_t max_payload = kMaxPayload);

/// \brief The step frame for the link: raw as encodeStep(); framed inside one WirePacker frame of
/// \p format. Payloads are limited to format.max_data (each becomes one I2C frame).
/// \throws ProtocolError as encodeStep(), and if a framed step exceeds format.max_data bytes.
std::vector<uint8_t> encodeStepForLink(const StepPayloads& payloads, Framing framing, const WireFormat& format = {});

/// \brief The master's receive state machine, as the universal-CNC paper's firmware runs it (states RS_SLAVES_NUM,
/// RS_SLAVE_LEN, RS_SLAVE_BYTES), fed one byte or a chunk at a time. Not thread-safe.
///
/// Each completed payload is delivered at once (the universal-CNC paper's master sends it to its slave over I2C as
/// soon as it is complete, before the rest of the frame arrives). Zero-length payloads deliver
/// nothing. Deviations from the universal-CNC paper's code, all for frames the universal-CNC paper's PC never sends:
/// - a slave count of 0 is an empty frame (the universal-CNC paper's code would wrap its counter and lose sync);
/// - addresses above \p bus_size still consume their bytes (so the stream stays in sync) but are
///   delivered with known = false, for the master to report (the universal-CNC paper's I2C write gets a NAK).
/// The raw protocol cannot resynchronise by itself: call reset() after a silence inside a frame.
class StepReceiver
{
 public:
  enum class State
  {
    kSlavesNum,  ///< RS_SLAVES_NUM: idle, waiting for the slave count
    kSlaveLen,   ///< RS_SLAVE_LEN: waiting for the next payload length
    kSlaveBytes  ///< RS_SLAVE_BYTES: collecting payload bytes
  };

  struct Delivery
  {
    uint8_t address;
    std::vector<uint8_t> payload;
    bool known;  ///< address <= bus_size
  };
  /// Called for every non-empty payload as soon as it is complete.
  using DeliverFn = std::function<void(const Delivery&)>;
  /// Called when a frame is complete (the state is back to kSlavesNum).
  using FrameDoneFn = std::function<void()>;

  /// \param bus_size how many slaves the master has (addresses 1..bus_size).
  explicit StepReceiver(size_t bus_size, DeliverFn deliver, FrameDoneFn frame_done = nullptr);

  void feed(uint8_t byte);
  void feed(const uint8_t* data, size_t size);

  /// \brief Back to kSlavesNum, dropping a partial frame. \returns true if a frame was in progress.
  bool reset();

  State state() const { return state_; }
  /// \returns true while between frames (the universal-CNC paper's master polls its slaves only then).
  bool idle() const { return state_ == State::kSlavesNum; }
  uint64_t framesCompleted() const { return frames_; }

 private:
  void slaveDone();

  size_t bus_size_;
  DeliverFn deliver_;
  FrameDoneFn frame_done_;
  State state_ = State::kSlavesNum;
  unsigned slaves_left_ = 0;  // slave_n
  unsigned address_ = 1;      // slave_addr
  size_t length_ = 0;         // slave_ln
  std::vector<uint8_t> payload_;
  uint64_t frames_ = 0;
};

/// \brief One record of the master -> PC uplink.
///
/// The universal-CNC paper's master writes the slave address and then what it read from the slave, with no
/// length, so the PC cannot tell where a reply ends. cnc_bridge defines:
/// \code
///   raw:     [address, length, payload...]                 length 0..255
///   framed:  WirePacker([address, payload...])             payload 0..250
/// \endcode
/// address 1..127 is a slave's reply (the payload it sent when polled). address 0 is the master
/// speaking for itself: payload[0] is a MasterStatus code, payload[1..] its arguments. In framed
/// mode the uplink's WirePacker frames use the same WireFormat as the downlink.
struct UplinkRecord
{
  uint8_t address = 0;
  std::vector<uint8_t> payload;
};

/// \brief Codes of master status records (address 0).
enum class MasterStatus : uint8_t
{
  kBadFrame = 1,     ///< framed mode: a downlink frame failed its CRC or framing; the step was dropped
  kNoSuchSlave = 2,  ///< payload[1] = address: a payload for a slave the master does not have
  /// payload[1] = address: the master's I2C read of the slave failed (WireSlaveRequest::request()
  /// returned false: no acknowledge, or the answer failed its length, end byte or CRC check); the
  /// answer is lost
  kSlaveNoAnswer = 3,
  /// payload[1] = address: the payload is longer than one I2C frame of the master carries (its
  /// WireFormat::max_data: 251, or 124 with the library's buffers); not delivered
  kPayloadTooLong = 4,
};
const char* toString(MasterStatus status);

/// \brief Encodes one uplink record for the link. \throws ProtocolError if the payload is too long.
std::vector<uint8_t> encodeUplink(const UplinkRecord& record, Framing framing, const WireFormat& format = {});

/// \brief Parses the uplink stream on the PC side, raw or framed, from arbitrary chunks.
/// Not thread-safe.
///
/// Raw mode has no error detection: a record whose address is 0 with an empty payload, or above
/// \p max_address, is counted as garbage and that byte skipped (the only check possible). Framed
/// mode drops corrupted frames (counted) and resynchronises on the next good one. After a silence
/// the caller should resync() so that a torn record cannot swallow the next one.
class UplinkParser
{
 public:
  struct Stats
  {
    uint64_t records = 0;
    uint64_t crc_errors = 0;
    uint64_t framing_errors = 0;
    uint64_t garbage_bytes = 0;
  };

  explicit UplinkParser(Framing framing, uint8_t max_address = kMaxSlaves, const WireFormat& format = {});

  /// \returns every record the bytes complete, in order.
  std::vector<UplinkRecord> feed(const uint8_t* data, size_t size);
  /// \brief After a silence: drops a partial record (raw), or abandons a partial frame and
  /// rescans behind it (framed). \returns records found behind it (framed only).
  std::vector<UplinkRecord> resync();
  /// \brief Bytes of a record not yet complete.
  size_t pending() const;
  Stats stats() const;

 private:
  Framing framing_;
  uint8_t max_address_;
  // raw state: what has been read of the current record
  std::vector<uint8_t> raw_;
  uint64_t raw_records_ = 0;
  uint64_t raw_garbage_ = 0;
  uint64_t framed_empty_ = 0;  // framed records with no address byte
  WireStreamUnpacker unpacker_;

  std::vector<UplinkRecord> toRecords(std::vector<std::vector<uint8_t>> frames);
};
}  // namespace slave_bus
}  // namespace cnc_bridge
