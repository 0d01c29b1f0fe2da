// The two ends of an XModem transfer, as state machines over a Transport: the sender (PC -> CNC
// upload) and the receiver (CNC -> PC download). They follow Forsberg's reference and lrzsz on
// timeouts, retries and duplicates, and a real Haas's capture on its quirks (docs/protocols/xmodem.md#haas-specifics).
#pragma once

#include <atomic>
#include <chrono>
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "cnc_bridge/transport/buffered_input.h"
#include "cnc_bridge/transport/transport.h"
#include "cnc_bridge/xmodem/packet.h"

namespace cnc_bridge
{
namespace xmodem
{
/// \brief Which XModem the local side asks for (receiver) or offers (sender).
enum class Mode
{
  kChecksum,  ///< 128-byte blocks, 8-bit sum. The receiver starts with NAK (what a Haas needs).
  kCrc,       ///< 128-byte blocks, CRC-16. The receiver starts with 'C', falls back to NAK.
  k1K         ///< 1024-byte blocks, CRC-16 (a sender falls back to 128/checksum on a NAK start).
};
const char* toString(Mode mode);
/// \brief "checksum"|"xmodem", "crc"|"xmodem-crc", "1k"|"xmodem-1k". \throws ConfigError.
Mode parseMode(const std::string& text);

/// \brief Timeouts and limits (docs/protocols/xmodem.md#timeouts-and-limits). Defaults are the protocol's; tests
/// shorten them.
/// The default cap of a program moved by XModem: 16 MiB, far above a control's program memory.
constexpr uint64_t kDefaultMaxProgramBytes = 16ull * 1024 * 1024;

struct Config
{
  /// Receiver: NAK (or 'C') again after this long without the first packet.
  Milliseconds nak_interval{10000};
  /// Receiver: give up when no first packet arrived within this long (0 = nak_interval * max_retries).
  Milliseconds start_timeout{0};
  /// Receiver: 'C' requests sent before falling back to checksum mode (CRC mode only).
  unsigned crc_attempts = 3;
  /// Receiver: wait for the next packet's first byte (then NAK it).
  Milliseconds block_timeout{10000};
  /// Both: the longest gap between two bytes inside a packet (fitToLine sets it from the line rate).
  Milliseconds char_timeout{1000};
  /// Receiver: before a NAK the line is read until this long passes in silence (the rest of a
  /// garbled packet must not be taken for the next one; fitToLine sets it from the line rate).
  Milliseconds purge_quiet{1000};
  /// fitToLine: char_timeout and purge_quiet in character times of the line. The protocol's one
  /// second is 30 character times at 300 baud, where it comes from; at 115200 it is 3500, and a
  /// retry would cost two seconds of silence.
  unsigned wait_characters = 30;
  /// fitToLine: the least char_timeout and purge_quiet, whatever the line rate: twice a USB serial
  /// adapter's 16 ms latency timer, which can hold the rest of a packet that long.
  Milliseconds wait_floor{30};
  /// Receiver: an EOT counts only if this long passes without another byte (a garbled SOH can look
  /// like EOT, and the rest of its packet follows within a character time; lrzsz waits 1 s). The
  /// default is twice a USB serial adapter's 16 ms latency timer and 12 character times at 4800
  /// baud; slower lines need more (fitToLine).
  Milliseconds eot_quiet{30};
  /// Sender: wait this long for the receiver's start character (NAK or 'C').
  Milliseconds start_wait{60000};
  /// Sender: wait this long for ACK/NAK after a packet or EOT.
  Milliseconds ack_timeout{10000};
  /// Sender, block 1 only: a NAK is answered only after this long without an ACK, because the NAKs a
  /// receiver repeats while it waits may still be queued when block 1 goes out (see OpenDNC's Haas
  /// capture, test/data/xmodem/haas_xmodem_capture.json).
  Milliseconds stale_nak_settle{100};
  /// Sender: after a NAK or the start request, wait until the line has been quiet this long before
  /// sending (what arrives meanwhile is dropped). lrzsz `rx` flushes its input right after it
  /// writes NAK, so a packet sent the instant the NAK arrives can be thrown away by the receiver.
  Milliseconds turnaround{10};
  /// Sender: pause this long after each ACK before the next packet (0: none). lrzsz `rx` also
  /// flushes its input right after every ACK; on a pty (no line delay) a packet sent the instant
  /// the ACK arrives can be lost to that flush and cost a 10 s timeout. A real serial line needs 0.
  Milliseconds ack_turnaround{0};
  /// Both: errors in a row on one block (NAKs, timeouts, garbled packets) before the transfer aborts.
  unsigned max_retries = 10;
  /// Sender: wait this long for the answer to EOT (lrzsz `rx` answers after 1 s of silence).
  Milliseconds eot_timeout{5000};
  /// Sender: EOT sent at most this many times (twice when the first met silence and
  /// eot_silence_completes: a lone EOT may have been lost).
  unsigned eot_retries = 10;
  /// Receiver: do not send the first NAK/'C' (the caller saw the sender start already; the simulator).
  bool skip_initial_request = false;
  /// Receiver: answer EOT with CAN CAN CAN as a Haas control does (the simulator), not with ACK.
  bool answer_eot_with_can = false;
  /// Sender: take the Haas's answer to EOT, CAN CAN CAN after every block was ACKed, as a completed
  /// transfer (OpenDNC's Haas capture). Only in checksum mode (a Haas knows no other) and only for at most
  /// three CANs: a receiver that aborts sends more (lrzsz ten, sendCancel() eight), and an abort
  /// must not pass for success (the receiver stored nothing). Off: any CANs after EOT fail the
  /// transfer. On by default because the Haas path (dnc_node, cnc_dnc send --mode checksum) needs it.
  bool eot_can_completes = true;
  /// Sender: take silence after every EOT (two EOTs at least), once every block was ACKed, as a
  /// completed transfer whose end went unconfirmed (Stats::eot_unanswered; the summary says so).
  /// The receiver holds every block; a receiver that leaves as soon as it has the EOT loses its
  /// last ACK (lrzsz rx flushes its tty as it exits). A NAK or anything else in answer to EOT
  /// still fails. Off: an unanswered EOT fails the transfer.
  bool eot_silence_completes = true;
  /// Receiver: the most payload taken; a sender that goes past it is cancelled (CAN CAN) and the
  /// transfer fails naming max_bytes_name. sendFile() refuses a larger file the same way. XModem
  /// has no length field, so without a cap a peer that keeps sending fills memory.
  uint64_t max_bytes = kDefaultMaxProgramBytes;
  /// How the user sets max_bytes, named in the error ("~max_program_bytes", "--max-bytes").
  std::string max_bytes_name = "max_program_bytes";
  /// Both, checksum mode: how the control sums a packet that holds ends of block, and its
  /// end-of-block pattern (Haas setting 25); sendFile() and receiveFile() take them from
  /// TextOptions. A receiver whose packets fail this reading and pass the other says so when it
  /// gives up.
  EobChecksum eob_checksum = EobChecksum::kWire;
  Eob eob = Eob::kLf;
  /// How the user sets eob_checksum, named in that advice ("~eob_checksum", "--eob-checksum").
  std::string eob_checksum_name = "eob_checksum";
};

/// \brief Fits the waits to a line moving \p characters_per_second: char_timeout and purge_quiet
/// become wait_characters character times (at least wait_floor), and eot_quiet is raised to at
/// least 12 character times, so that slow lines keep their margin and fast ones do not idle.
void fitToLine(Config& config, double characters_per_second);

/// \brief Where a transfer is; given to the progress callback after every block.
struct Progress
{
  uint64_t bytes = 0;    ///< payload bytes acknowledged (sender) or accepted (receiver)
  uint64_t total = 0;    ///< payload bytes in all (sender; 0 for the receiver)
  uint32_t block = 0;    ///< blocks done, counting from 1, not wrapped at 256
  uint32_t retries = 0;  ///< blocks sent again / NAKed so far
};
using ProgressCallback = std::function<void(const Progress&)>;

/// \brief Counters of one transfer, valid after success or failure (diagnostics read them).
struct Stats
{
  uint64_t bytes = 0;
  uint32_t blocks = 0;                     ///< blocks acknowledged / accepted
  uint32_t retries = 0;                    ///< packets sent again or NAKed
  uint32_t timeouts = 0;                   ///< waits that ran out
  uint32_t duplicates = 0;                 ///< receiver: repeats of the previous block (lost ACK), ACKed and dropped
  uint32_t garbled = 0;                    ///< receiver: packets that failed a check
  CheckType check = CheckType::kChecksum;  ///< what was negotiated
  bool used_1k = false;                    ///< at least one 1024-byte block went across
  /// The peer answered our EOT with CANs after every block was ACKed (a Haas does): complete.
  bool eot_answered_with_can = false;
  /// Receiver, checksum mode: packets failed the configured end-of-block checksum reading and
  /// passed the other one (the control uses the other reading: Config::eob_checksum).
  bool other_eob_checksum_seen = false;
  /// EOTs sent without any answer after every block was ACKed (Config::eot_silence_completes): the
  /// end of the transfer is unconfirmed; 0 when the receiver answered.
  uint32_t eot_unanswered = 0;
  /// From the first block (sent, or its first byte received) to the last block's ACK: the time
  /// the data took, without the start handshake and the EOT exchange.
  std::chrono::microseconds block_time{0};
  std::string summary() const;
};

/// \brief Sends one payload by XModem. Not thread-safe, except that cancel may be set (and the
/// transport interrupted) from another thread.
class Sender
{
 public:
  /// \param link must outlive the sender.
  /// \param cancel if given, set it and call link.interrupt() to abort (CANs are sent).
  Sender(Transport& link, Mode mode, Config config = Config(), const std::atomic<bool>* cancel = nullptr);

  /// \brief Waits for the receiver's start, sends every block, ends with EOT.
  /// \returns the counters of the completed transfer (check eot_answered_with_can).
  /// \throws TimeoutError (no start, too many retries), ProtocolError (receiver cancelled),
  ///         CancelledError, LinkError. CANs are sent to the peer before a local abort.
  Stats send(const std::vector<uint8_t>& payload, const ProgressCallback& progress = nullptr);

  const Stats& stats() const { return stats_; }

 private:
  enum class Reply
  {
    kAck,
    kNak,
    kCancel,
    kTimeout
  };
  uint8_t waitForStart();
  /// Sends one block until it is acknowledged; aborts after too many tries. \returns when it was.
  std::chrono::steady_clock::time_point sendBlock(const std::vector<uint8_t>& packet, uint32_t block, size_t block_size,
                                                  Progress& state);
  /// Ends the transfer: EOT until acknowledged (or answered as a Haas does, or met by silence).
  void sendEot();
  /// \param after_eot the reply to EOT is awaited (no data packet outstanding).
  Reply waitForReply(bool first_block, Milliseconds timeout, bool after_eot = false);
  /// Reads what follows a CAN CAN until the line is quiet; \returns the further CANs among it.
  size_t countCans();
  void checkCancel();
  [[noreturn]] void abort(const std::string& why, bool send_can, bool timeout);
  /// The checksum of a checksum-mode packet under the configured reading (it differs from the
  /// wire sum only in the LF reading, and only for a block that holds an end of block).
  void applyReading(std::vector<uint8_t>& packet, size_t block_size);
  /// What to check when a block holding an end of block was never acknowledged: the control may
  /// sum it under the other reading. Empty when the readings agree on it.
  std::string readingAdvice(const std::vector<uint8_t>& packet, size_t block_size) const;

  Transport& link_;
  BufferedInput input_;  ///< replies are read through this, never from link_ directly
  Mode mode_;
  Config config_;
  const std::atomic<bool>* cancel_;
  Stats stats_;
  ChecksumReading reading_;
};

/// \brief Receives one payload by XModem. Threading as Sender.
class Receiver
{
 public:
  Receiver(Transport& link, Mode mode, Config config = Config(), const std::atomic<bool>* cancel = nullptr);

  /// \brief Asks for the transfer (NAK or 'C'), accepts 128 and 1024-byte packets, ACKs the EOT.
  /// \returns every data byte received, padding included (see stripSubPadding()).
  /// \throws TimeoutError (sender never started, too many errors), ProtocolError (out-of-sequence
  ///         block, sender cancelled), CancelledError, LinkError.
  std::vector<uint8_t> receive(const ProgressCallback& progress = nullptr);

  const Stats& stats() const { return stats_; }

 private:
  void nak(uint8_t request, Milliseconds purge_limit, Milliseconds already_quiet);
  void checkCancel();
  [[noreturn]] void abort(const std::string& why, bool send_can, bool timeout);
  /// Notes a packet that failed the checksum: if it passes the other end-of-block reading, the
  /// control uses that one, which the failure message says (every block holding an end of block
  /// fails alike, so the transfer does fail).
  void noteOtherReading(const Packet& packet);

  // The steps of receive(), one per thing the sender can do next.
  struct ReceiveState;
  /// The next byte: one read ahead, else from the line within the wait of the receive's stage (-1: none).
  int nextByte(ReceiveState& r);
  /// Nothing came: repeat the start request on its schedule, or NAK the block awaited.
  void onSilence(ReceiveState& r);
  /// SOH or STX: reads and checks the packet.
  void onPacket(ReceiveState& r, uint8_t first);
  /// A packet that passed its check: the next block, a repeat, or out of sequence.
  void onGoodPacket(ReceiveState& r, const Packet& packet, CheckType check,
                    std::chrono::steady_clock::time_point packet_start);
  void acceptBlock(ReceiveState& r, const Packet& packet, CheckType check,
                   std::chrono::steady_clock::time_point packet_start);
  /// \returns true when the EOT ends the transfer (answered).
  bool onEot(ReceiveState& r);
  void onCan(ReceiveState& r);
  void onNoise(ReceiveState& r, uint8_t c);
  /// A damaged packet or noise: counted, NAKed after a purge; aborts after too many in a row.
  void receiveError(ReceiveState& r, const std::string& what, Milliseconds already_quiet = Milliseconds(0));

  Transport& link_;
  BufferedInput input_;  ///< packets are read through this (a whole packet per read when it is there)
  Mode mode_;
  Config config_;
  const std::atomic<bool>* cancel_;
  Stats stats_;
  ChecksumReading reading_;
};

/// \brief CANs sendCancel() writes: more than the three a Haas answers EOT with, so that a sender can
/// tell an abort from that answer (lrzsz writes ten); two are what a peer needs to stop.
constexpr size_t kCancelLength = 8;
/// \brief The most CANs in answer to EOT that can still be a Haas's "complete" (Config::eot_can_completes).
constexpr size_t kHaasEotCans = 3;

/// \brief Sends kCancelLength CANs and does not throw.
void sendCancel(Transport& link) noexcept;
}  // namespace xmodem
}  // namespace cnc_bridge
