// A simulated universal-CNC master with its I2C slaves, for tests, benchmarks and sim_slave_bus.
// The master runs the receive state machine of the universal-CNC paper (docs/protocols/slave_bus.md#source) on its
// serial link, hands every payload to its slave as a real WirePacker frame (CRC-8 checked by the slave), and while idle
// polls the slaves and writes their answers on the uplink. Slaves act on what they get: axes move, the tool toggles,
// generic slaves echo (as the universal-CNC paper's slave sketch does).
#pragma once

#include <chrono>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "cnc_bridge/slave_bus/array_protocol.h"
#include "cnc_bridge/slave_bus/value_codec.h"
#include "cnc_bridge/transport/backoff.h"
#include "cnc_bridge/transport/transport.h"

namespace cnc_bridge
{
namespace slave_bus
{
/// \brief The most a master reads from one slave: the universal-CNC paper's master calls read_I2C(addr, 32).
constexpr size_t kMaxReply = 32;

/// \brief What a slave board does with its payload.
enum class SimRole
{
  kAxis,    ///< payload: target position (one value, device units); moves there; answers its position
  kTool,    ///< payload: one value, non-zero = on; answers its state (1/0)
  kGeneric  ///< echoes every payload back (its first kMaxReply bytes)
};
SimRole parseSimRole(const std::string& text);  ///< axis|tool|generic; \throws ConfigError

/// \brief One simulated I2C slave. Not thread-safe.
class SimSlave
{
 public:
  SimSlave(uint8_t address, SimRole role, Encoding encoding);

  /// \brief The bus's WirePacker dialect (CRC coverage, frame size); SimMaster sets its own.
  void setWireFormat(const WireFormat& format) { wire_ = format; }
  /// \brief A noisy slave: every answer it gives is corrupted on the bus (one bit flipped), so the
  /// master's CRC check fails and it reports MasterStatus::kSlaveNoAnswer for this address.
  void setNoisy(bool noisy) { noisy_ = noisy; }

  /// \brief The master's I2C write: one WirePacker frame. A frame that fails its CRC is ignored
  /// (counted), as the ESP32 library's unpacker rejects it.
  void receive(const std::vector<uint8_t>& i2c_frame);
  /// \brief The master's I2C read: the slave's answer as a WirePacker frame, once per payload it
  /// acted on; empty if it has nothing to say.
  std::vector<uint8_t> request();

  uint8_t address() const { return address_; }
  SimRole role() const { return role_; }
  int32_t position() const { return position_; }  ///< axis: device units
  bool toolOn() const { return tool_on_; }
  uint64_t rejected() const { return rejected_; }

 private:
  uint8_t address_;
  SimRole role_;
  Encoding encoding_;
  WireFormat wire_;
  bool noisy_ = false;
  int32_t position_ = 0;
  bool tool_on_ = false;
  bool has_reply_ = false;
  std::vector<uint8_t> reply_;
  uint64_t rejected_ = 0;
};

/// \brief The master board: serial link on one side, slaves on the other. Not thread-safe; stop
/// run() from another thread by stopping its StopSignal and interrupting the link.
class SimMaster
{
 public:
  struct Options
  {
    Framing framing = Framing::kRaw;
    /// Raw mode: drop a partial frame after this much silence (0 = never, as the universal-CNC paper's firmware).
    /// Framed mode always resynchronises after a silence inside a frame: after this gap, or
    /// kFramedResyncGap if it is 0.
    Milliseconds resync_gap{0};
    /// The WirePacker dialect of the master and its slaves: I2C frames and, in framed mode, the
    /// serial link. Payloads longer than wire.max_data are reported (MasterStatus::kPayloadTooLong).
    WireFormat wire;
    /// Corrupt one byte of every Nth uplink write (0 = never): exercises the PC's CRC check.
    unsigned corrupt_uplink_every = 0;
    /// Told of every payload handed to a slave (address, payload), e.g. to log what the machine
    /// received; empty: nobody is told.
    std::function<void(uint8_t address, const std::vector<uint8_t>& payload)> on_delivery;
  };
  struct Stats
  {
    uint64_t frames = 0;             ///< step frames completed
    uint64_t deliveries = 0;         ///< payloads handed to slaves
    uint64_t bad_frames = 0;         ///< framed mode: bursts of corrupted or malformed step frames
    uint64_t unknown_slaves = 0;     ///< payloads for addresses the master does not have
    uint64_t oversize_payloads = 0;  ///< payloads longer than one I2C frame carries (not delivered)
    uint64_t resyncs = 0;            ///< partial frames dropped (raw) or abandoned (framed) after a silence
    uint64_t slave_errors = 0;       ///< I2C reads whose answer failed its check (MasterStatus::kSlaveNoAnswer)
    uint64_t uplink_records = 0;
  };

  /// \brief Framed mode's silence before a partial frame is abandoned when Options::resync_gap is 0.
  /// Long against the gaps inside one frame from a healthy PC (a USB adapter's 16 ms latency timer;
  /// a sender descheduled between two paced slices on a loaded machine: 20 ms gaps made the
  /// benchmark lose a step in a thousand), short against the node's 0.5 s reply timeout.
  static constexpr Milliseconds kFramedResyncGap{100};

  SimMaster(Transport& link, std::vector<SimSlave> slaves, Options options);

  /// \brief Serves the link until \p stop is stopped (or the link fails: LinkError propagates).
  void run(StopSignal& stop);
  /// \brief Processes bytes from the PC as if they had arrived on the link.
  void processInput(const uint8_t* data, size_t size);
  /// \brief Polls every slave once and writes what they answer (the universal-CNC paper's idle loop).
  void pollSlaves();
  /// \brief The link has been silent for the resync gap: raw mode drops a partial frame if a gap is
  /// configured; framed mode always abandons a partial candidate (a stray start byte with a large
  /// length) and runs the frames it was hiding. run() calls it; tests call it directly.
  void onSilence();

  const std::vector<SimSlave>& slaves() const { return slaves_; }
  const Stats& stats() const { return stats_; }

 private:
  void serveOnce(std::vector<uint8_t>& buffer, std::chrono::steady_clock::time_point& last_byte);
  /// The silence after which onSilence() runs; 0 = never (raw mode without a gap).
  Milliseconds resyncGap() const;
  void deliver(const StepReceiver::Delivery& delivery);
  void processFrames(const std::vector<std::vector<uint8_t>>& frames, const WireStreamUnpacker::Stats& before);
  void sendStatus(MasterStatus status, int address = -1);
  void queueUplink(const UplinkRecord& record);
  void flushUplink();

  Transport& link_;
  std::vector<SimSlave> slaves_;
  Options options_;
  StepReceiver receiver_;
  WireStreamUnpacker unpacker_;
  std::vector<uint8_t> uplink_;
  unsigned uplink_writes_ = 0;
  Stats stats_;
};
}  // namespace slave_bus
}  // namespace cnc_bridge
