// The PC side of the slave bus: sends step frames to the master and collects the slaves' replies
// from the uplink, over any Transport (serial port, pty, fake). The ROS node and the benchmark use
// it; it knows nothing of ROS.
#pragma once

#include <chrono>
#include <cstdint>
#include <vector>

#include "cnc_bridge/slave_bus/array_protocol.h"
#include "cnc_bridge/transport/transport.h"

namespace cnc_bridge
{
namespace slave_bus
{
/// \brief One PC <-> master link: step frames down, uplink records up. Not thread-safe: one thread
/// calls send/poll/step (Transport::interrupt() may stop it from another).
///
/// Timing: the master of the universal-CNC paper (docs/protocols/slave_bus.md#source) polls its slaves only while
/// idle between frames, and a slave answers once after each payload it got (its requestEvent sends what it has,
/// then clears `requested`).
/// So step() expects one reply from every slave that got a non-empty payload, and counts a timeout
/// for each that does not answer within the reply timeout. A partial uplink record followed by a
/// silence of \p resync_gap is dropped, so a torn record cannot swallow the next one.
class BusSession
{
 public:
  struct Stats
  {
    uint64_t steps_sent = 0;
    uint64_t bytes_sent = 0;
    uint64_t bytes_received = 0;
    uint64_t replies = 0;        ///< slave records received
    uint64_t master_status = 0;  ///< address-0 records received
    uint64_t resyncs = 0;        ///< partial records abandoned after a silence
    UplinkParser::Stats link;    ///< CRC/framing errors and garbage on the uplink
  };

  struct StepResult
  {
    std::vector<UplinkRecord> replies;        ///< every slave record that arrived, in order
    std::vector<UplinkRecord> master_status;  ///< address-0 records that arrived
    std::vector<uint8_t> missing;             ///< addresses that got a payload but did not answer in time
  };

  /// \param link must outlive the session.
  /// \param bus_size slaves on the bus: every frame carries this many lengths (the universal-CNC paper sends 8).
  /// \param format the master's WirePacker dialect: CRC coverage of framed mode, and the most data
  /// one frame carries (each payload becomes one I2C frame; in framed mode so does the whole step).
  /// \throws ProtocolError if bus_size is 0 or over kMaxSlaves.
  BusSession(Transport& link, Framing framing, size_t bus_size, Milliseconds resync_gap = std::chrono::milliseconds(50),
             const WireFormat& format = {});

  /// \brief Sends one step frame. Payloads beyond the given ones are empty (length 0).
  /// \throws ProtocolError if more payloads than bus_size, or a payload (or a framed step) is longer
  /// than format.max_data, naming the limit; LinkError.
  void send(const StepPayloads& payloads);

  /// \brief Reads what the link has (waiting up to \p timeout for the first byte) and parses it.
  /// \returns complete records, slaves and master alike, in order (possibly none).
  /// \throws LinkError, CancelledError.
  std::vector<UplinkRecord> poll(Milliseconds timeout);

  /// \brief send() then poll() until every slave with a non-empty payload has answered or
  /// \p reply_timeout has passed since the frame was written.
  StepResult step(const StepPayloads& payloads, Milliseconds reply_timeout);

  const Stats& stats() const;
  Framing framing() const { return framing_; }
  const WireFormat& format() const { return format_; }
  size_t busSize() const { return bus_size_; }

 private:
  void count(const std::vector<UplinkRecord>& records);

  using Clock = std::chrono::steady_clock;
  Transport& link_;
  Framing framing_;
  WireFormat format_;
  size_t bus_size_;
  Milliseconds resync_gap_;
  UplinkParser parser_;
  StepPayloads scratch_;
  std::vector<uint8_t> read_buffer_;
  Clock::time_point last_byte_;
  mutable Stats stats_;
};
}  // namespace slave_bus
}  // namespace cnc_bridge
