// XModem sender and receiver state machines (see session.h for the contract).
//
// Protocol as implemented (Forsberg's XMODEM/YMODEM reference, lrzsz, and OpenDNC's Haas capture,
// test/data/xmodem/haas_xmodem_capture.json; docs/protocols/xmodem.md#source):
//
//   receiver                         sender
//   NAK | 'C'  (again every nak_interval; 'C' crc_attempts times, then NAK)
//                                    SOH|STX blk ~blk data check
//   ACK (good, expected block)       next block
//   ACK (repeat of the previous block: our ACK was lost; data dropped)
//   NAK (garbled, short or timed out; the line is purged until purge_quiet of silence first)
//   CAN CAN (block number out of sequence: the two sides disagree, nothing can repair it)
//                                    EOT  (resent on NAK or timeout, eot_retries times)
//   ACK  (only after eot_quiet of silence: a garbled SOH must not end the file)
//   CAN CAN (an abort: kCancelLength CANs from this code, ten from lrzsz)
//
// Haas quirks handled: the control NAKs several times before the PC starts sending, so NAKs may be
// queued when block 1 goes out (the sender discards queued input after the start character and
// waits stale_nak_settle for an ACK before honouring a NAK of block 1); and it answers EOT with
// CAN CAN CAN instead of ACK, which after every block was ACKed means "complete" (checksum mode,
// at most three CANs, Config::eot_can_completes).
#include "cnc_bridge/xmodem/session.h"

#include <algorithm>
#include <cmath>
#include <sstream>
#include <utility>

#include "cnc_bridge/common/error.h"
#include "cnc_bridge/common/log.h"
#include "cnc_bridge/transport/port_doctor.h"

namespace cnc_bridge
{
namespace xmodem
{
namespace
{
using Clock = std::chrono::steady_clock;

Milliseconds remainingUntil(Clock::time_point deadline)
{
  const auto left = std::chrono::duration_cast<Milliseconds>(deadline - Clock::now());
  return left.count() > 0 ? left : Milliseconds(0);
}

std::string seconds(Milliseconds ms)
{
  std::ostringstream out;
  out << static_cast<double>(ms.count()) / 1000.0 << " s";
  return out.str();
}
}  // namespace

const char* toString(Mode mode)
{
  switch (mode)
  {
    case Mode::kChecksum:
      return "xmodem";
    case Mode::kCrc:
      return "xmodem-crc";
    case Mode::k1K:
      return "xmodem-1k";
  }
  return "?";
}

Mode parseMode(const std::string& text)
{
  if (text == "checksum" || text == "xmodem")
    return Mode::kChecksum;
  if (text == "crc" || text == "xmodem-crc")
    return Mode::kCrc;
  if (text == "1k" || text == "xmodem-1k")
    return Mode::k1K;
  throw ConfigError("XModem mode '" + text + "' is not one of checksum (xmodem), crc (xmodem-crc), 1k (xmodem-1k)");
}

void fitToLine(Config& config, double characters_per_second)
{
  if (characters_per_second <= 0)
    return;
  const auto character_times = [characters_per_second](double characters)
  { return Milliseconds(static_cast<int64_t>(std::ceil(characters * 1000.0 / characters_per_second))); };
  constexpr double kEotCharacters = 12;
  config.eot_quiet = std::max(config.eot_quiet, character_times(kEotCharacters));
  config.char_timeout = config.purge_quiet = std::max(config.wait_floor, character_times(config.wait_characters));
}

std::string Stats::summary() const
{
  std::ostringstream out;
  out << bytes << " bytes in " << blocks << " blocks (" << toString(check) << (used_1k ? ", 1K" : "") << "), "
      << retries << " retries";
  if (eot_answered_with_can)
  {
    out << "; the receiver answered EOT with CAN after the last block was acknowledged (as a Haas does)";
  }
  if (eot_unanswered > 0)
  {
    out << "; every block was acknowledged but the end was not (EOT sent " << eot_unanswered
        << " times, no answer): the receiver holds the whole program, check that it stored it (a receiver that "
           "leaves as it gets the EOT, as lrzsz rx does, loses its last acknowledgement)";
  }
  return out.str();
}

void sendCancel(Transport& link) noexcept
{
  const std::vector<uint8_t> cans(kCancelLength, kCan);
  // Two tries: the first write may meet the interrupt() that stopped the transfer and throw.
  for (int attempt = 0; attempt < 2; ++attempt)
  {
    try
    {
      link.write(cans.data(), cans.size(), Milliseconds(1000));
      return;
    }
    catch (const CancelledError&)
    {
      continue;
    }
    catch (const std::exception&)
    {
      return;  // the link is gone or stuck: nothing more can be told to the peer
    }
  }
}

// ------------------------------------------------------------------------------------------------
// Replies are single bytes; a few queued start requests (a Haas repeats NAK) fit in one read.
constexpr size_t kReplyReadSize = 64;
// After an ACK on a line that has damaged bytes before: long enough for a doubled ACK to arrive
// (a character time is 87 us at 115200, 1 ms at 9600), short beside a block's time on the line.
constexpr Milliseconds kDoubleReplyQuiet{1};
// Receiver, the same for the byte that follows a packet shifted by a doubled byte.
constexpr Milliseconds kDoubledByteQuiet{1};
// Sender: EOTs that must meet silence before silence is taken as a receiver that has left. One
// is not enough: lrzsz rx flushes its input right after it ACKs the last block, and an EOT that
// crosses that flush is thrown away while rx waits on for it (and then fails the transfer).
constexpr unsigned kSilentEotsToComplete = 2;

Sender::Sender(Transport& link, Mode mode, Config config, const std::atomic<bool>* cancel)
    : link_(link),
      input_(link, kReplyReadSize),
      mode_(mode),
      config_(std::move(config)),
      cancel_(cancel),
      reading_(config_.eob_checksum, config_.eob)
{
}

void Sender::applyReading(std::vector<uint8_t>& packet, size_t block_size)
{
  if (stats_.check == CheckType::kChecksum && reading_.reading() != EobChecksum::kWire)
    packet[3 + block_size] = reading_.sum(packet.data() + 3, block_size);
}

std::string Sender::readingAdvice(const std::vector<uint8_t>& packet, size_t block_size) const
{
  const uint8_t* data = packet.data() + 3;
  if (stats_.check != CheckType::kChecksum || reading_.sum(data, block_size) == reading_.otherSum(data, block_size))
    return "";
  return "; the block holds an end of block, which controls sum in two ways: if the control's end-of-block "
         "pattern (Haas setting 25) is not LF ONLY, try " +
         config_.eob_checksum_name + " " + toString(reading_.other());
}

void Sender::checkCancel()
{
  if (cancel_ && cancel_->load())
  {
    throw CancelledError(link_.describe() + ": XModem send cancelled");
  }
}

void Sender::abort(const std::string& why, bool send_can, bool timeout)
{
  if (send_can)
  {
    sendCancel(link_);
  }
  const std::string message = link_.describe() + ": XModem send failed: " + why;
  if (timeout)
    throw TimeoutError(message);
  throw ProtocolError(message);
}

uint8_t Sender::waitForStart()
{
  const auto deadline = Clock::now() + config_.start_wait;
  bool saw_can = false;
  for (;;)
  {
    checkCancel();
    const Milliseconds left = remainingUntil(deadline);
    const int c = left.count() > 0 ? input_.readByte(left) : -1;
    if (c < 0)
    {
      ++stats_.timeouts;
      abort("the receiver did not start (no NAK or 'C' within " + seconds(config_.start_wait) + "): " + kNoAnswerHint,
            true, true);
    }
    if (c == kNak || c == kCrcStart)
    {
      return static_cast<uint8_t>(c);
    }
    if (c == kCan)
    {
      if (saw_can)
        abort("the receiver cancelled (CAN CAN) before the first block", false, false);
      saw_can = true;
      continue;
    }
    saw_can = false;  // line noise or a terminal's chatter: wait on
  }
}

Sender::Reply Sender::waitForReply(bool first_block, Milliseconds timeout, bool after_eot)
{
  const auto deadline = Clock::now() + timeout;
  for (;;)
  {
    checkCancel();
    const Milliseconds left = remainingUntil(deadline);
    const int c = left.count() > 0 ? input_.readByte(left) : -1;
    if (c < 0)
    {
      return Reply::kTimeout;
    }
    if (c == kAck)
    {
      // While part of a data packet is still in the port's output queue the receiver cannot have
      // taken it all: this ACK answers an earlier packet (doubled on the line). Not after EOT: every
      // block was ACKed and what was queued behind the last ACK dropped, so an ACK now answers the EOT,
      // even while the port still counts that one byte as pending (a pty whose reader has just
      // read it and left: lrzsz rx ACKs EOT and exits). Dropping it failed complete transfers.
      if (!after_eot && link_.pendingOutput() > 0)
        continue;
      return Reply::kAck;
    }
    // A byte that is none of the replies is a reply damaged on the line (lrzsz sx resends on one
    // as well): an ACK, and the receiver takes the block again as a duplicate, or a NAK.
    const bool damaged = c != kAck && c != kNak && c != kCan && c != kCrcStart;
    // After block 1, a CRC receiver asks again with 'C' when block 1 arrived damaged (it has no
    // block yet to NAK); it may also be a start request still in flight: as a NAK of block 1.
    const bool repeated_start = first_block && c == kCrcStart;
    if (c == kNak || damaged || repeated_start)
    {
      if (!first_block)
      {
        return Reply::kNak;
      }
      // A NAK right after block 1 is most likely one the receiver sent while it still waited for
      // us to start. If block 1 arrived, its ACK follows: wait for it before sending block 1 again.
      const auto settle = Clock::now() + config_.stale_nak_settle;
      for (;;)
      {
        const Milliseconds wait = remainingUntil(settle);
        const int next = wait.count() > 0 ? input_.readByte(wait) : -1;
        if (next < 0)
          return Reply::kNak;
        if (next == kAck)
          return Reply::kAck;
        if (next == kCan && input_.readByte(config_.char_timeout) == kCan)
          return Reply::kCancel;
      }
    }
    if (c == kCan)
    {
      const int next = input_.readByte(config_.char_timeout);
      if (next == kCan)
        return Reply::kCancel;
      if (next == kAck)
        return Reply::kAck;
      if (next == kNak)
        return Reply::kNak;
      continue;
    }
    // 'C' after later blocks is a start request long in flight: dropped.
  }
}

size_t Sender::countCans()
{
  // The rest of a burst of CANs follows within a character time; other bytes (a control's next
  // NAK) are dropped uncounted.
  const Milliseconds quiet = std::min(config_.char_timeout, Milliseconds(100));
  const auto limit = Clock::now() + Milliseconds(500);
  size_t cans = 0;
  for (int c = 0; Clock::now() < limit && (c = input_.readByte(quiet)) >= 0;)
  {
    if (c == kCan)
      ++cans;
  }
  return cans;
}

Stats Sender::send(const std::vector<uint8_t>& payload, const ProgressCallback& progress)
{
  stats_ = Stats();
  try
  {
    const uint8_t start = waitForStart();
    // NAKs (or 'C's) the receiver repeated while it waited are still queued: drop them so that
    // none of them is read as the answer to block 1 (the PC in OpenDNC's Haas capture,
    // test/data/xmodem/haas_xmodem_capture.json, sent block 1 twice for this).
    input_.discard();
    input_.purge(config_.turnaround, config_.turnaround * 10);
    const bool crc = start == kCrcStart;
    stats_.check = crc ? CheckType::kCrc16 : CheckType::kChecksum;
    // XModem-1K needs CRC (Forsberg): a receiver that asks for checksum mode gets 128-byte blocks.
    const bool use_1k = mode_ == Mode::k1K && crc;
    CNC_LOG_DEBUG("xmodem: " << link_.describe() << " started the transfer with "
                             << (crc ? "'C' (CRC)" : "NAK (checksum)") << "; sending " << payload.size() << " bytes");

    Progress state;
    state.total = payload.size();
    size_t offset = 0;
    uint32_t block = 1;
    const auto blocks_start = Clock::now();
    while (offset < payload.size())
    {
      const size_t left = payload.size() - offset;
      // A 1K block for the tail only if it is more than 7 short blocks' worth: padding the same, 6
      // packets' overhead saved, and a short file still goes in 128-byte blocks as lrzsz does.
      const size_t block_size = use_1k && left > 7 * kBlockSize ? kBlockSize1K : kBlockSize;
      const size_t n = std::min(left, block_size);
      std::vector<uint8_t> packet = encodePacket(block, payload.data() + offset, n, block_size, stats_.check);
      applyReading(packet, block_size);
      const auto acked = sendBlock(packet, block, block_size, state);
      stats_.block_time = std::chrono::duration_cast<std::chrono::microseconds>(acked - blocks_start);
      stats_.used_1k = stats_.used_1k || block_size == kBlockSize1K;
      reading_.accept(packet.data() + 3, block_size);
      offset += n;
      stats_.bytes = offset;
      stats_.blocks = block;
      state.bytes = offset;
      state.block = block;
      ++block;
      if (progress)
        progress(state);
    }
    sendEot();
    return stats_;
  }
  catch (const CancelledError&)
  {
    sendCancel(link_);
    throw CancelledError(link_.describe() + ": XModem send cancelled after " + std::to_string(stats_.blocks) +
                         " blocks (CAN sent)");
  }
}

std::chrono::steady_clock::time_point Sender::sendBlock(const std::vector<uint8_t>& packet, uint32_t block,
                                                        size_t block_size, Progress& state)
{
  for (unsigned errors = 0;;)
  {
    checkCancel();
    link_.write(packet);
    const Reply reply = waitForReply(block == 1, config_.ack_timeout);
    if (reply == Reply::kAck)
    {
      const auto acked = Clock::now();
      // Nothing the receiver sends before the next block is an answer to it: a doubled ACK
      // taken as the next block's would put the two sides a block apart. Once the line has
      // shown damage, wait a little for such a double (it follows within a character time).
      if (config_.ack_turnaround.count() > 0)
        input_.purge(config_.ack_turnaround, config_.ack_turnaround * 4);
      else if (stats_.retries > 0)
        input_.purge(kDoubleReplyQuiet, kDoubleReplyQuiet * 4);
      else
        input_.discard();
      return acked;
    }
    if (reply == Reply::kCancel)
      abort("the receiver cancelled (CAN CAN) at block " + std::to_string(block) +
                (errors > 0 ? readingAdvice(packet, block_size) : ""),
            false, false);
    if (reply == Reply::kTimeout)
      ++stats_.timeouts;
    else
      input_.purge(config_.turnaround, config_.turnaround * 10);
    ++stats_.retries;
    ++state.retries;
    if (++errors > config_.max_retries)
    {
      abort("block " + std::to_string(block) + " not acknowledged after " + std::to_string(errors) + " tries" +
                (reply == Reply::kNak ? readingAdvice(packet, block_size) : ""),
            true, reply == Reply::kTimeout);
    }
    CNC_LOG_DEBUG("xmodem: block " << block << (reply == Reply::kTimeout ? " not answered" : " NAKed")
                                   << ", sending it again");
  }
}

void Sender::sendEot()
{
  bool eot_met_only_silence = true;
  for (unsigned attempt = 1;; ++attempt)
  {
    checkCancel();
    link_.writeByte(kEot);
    const Reply reply = waitForReply(false, config_.eot_timeout, true);
    if (reply == Reply::kAck)
      return;
    if (reply == Reply::kCancel)
    {
      // A Haas answers EOT with CAN CAN CAN; every block was ACKed, so the data is there. A
      // receiver that aborts (cancelled, or out of step with us) sends more CANs, and its abort
      // must not pass for success: count them.
      const size_t cans = 2 + countCans();
      if (config_.eot_can_completes && stats_.check == CheckType::kChecksum && cans <= kHaasEotCans)
      {
        stats_.eot_answered_with_can = true;
        return;
      }
      abort("the receiver cancelled (" + std::to_string(cans) + " CANs) in answer to EOT after " +
                std::to_string(stats_.blocks) + " acknowledged blocks; it may not have stored the file" +
                (config_.eot_can_completes ? "" : " (CAN after EOT is not taken as complete)"),
            false, false);
    }
    if (reply == Reply::kTimeout)
      ++stats_.timeouts;
    else
      input_.purge(config_.turnaround, config_.turnaround * 10);
    eot_met_only_silence = eot_met_only_silence && reply == Reply::kTimeout;
    const bool silence_needs_another_eot =
        config_.eot_silence_completes && eot_met_only_silence && attempt < kSilentEotsToComplete;
    if (attempt >= config_.eot_retries && !silence_needs_another_eot)
    {
      // Every block was ACKed, so the receiver holds the whole payload; only the end went
      // unconfirmed. Silence is what a receiver that has left leaves behind; anything else
      // (NAKs, garbage) is a receiver that is still there and did not take the EOT.
      if (config_.eot_silence_completes && eot_met_only_silence)
      {
        stats_.eot_unanswered = attempt;
        CNC_LOG_WARN("xmodem: " << link_.describe() << ": every block was acknowledged, the end (EOT, sent " << attempt
                                << " times) was not: taken as complete");
        return;
      }
      abort("every block was acknowledged but EOT was not (sent " + std::to_string(attempt) + " times)", false, true);
    }
  }
}

// ------------------------------------------------------------------------------------------------
Receiver::Receiver(Transport& link, Mode mode, Config config, const std::atomic<bool>* cancel)
    : link_(link),
      input_(link, packetSize(kBlockSize1K, CheckType::kCrc16)),
      mode_(mode),
      config_(std::move(config)),
      cancel_(cancel),
      reading_(config_.eob_checksum, config_.eob)
{
}

void Receiver::checkCancel()
{
  if (cancel_ && cancel_->load())
  {
    throw CancelledError(link_.describe() + ": XModem receive cancelled");
  }
}

void Receiver::noteOtherReading(const Packet& packet)
{
  const uint8_t check = packet.data[packet.data_size];
  if (stats_.other_eob_checksum_seen || reading_.otherSum(packet.data, packet.data_size) != check)
    return;
  stats_.other_eob_checksum_seen = true;  // said in the failure message: every such block fails
}

void Receiver::abort(const std::string& why, bool send_can, bool timeout)
{
  if (send_can)
  {
    sendCancel(link_);
  }
  std::string message = link_.describe() + ": XModem receive failed: " + why;
  if (stats_.other_eob_checksum_seen)
  {
    message += "; its packets pass the other end-of-block checksum reading: the control sums each end of block " +
               std::string(reading_.other() == EobChecksum::kLf ? "as LF" : "as the bytes on the wire") + ", so set " +
               config_.eob_checksum_name + " to " + toString(reading_.other());
  }
  if (timeout)
    throw TimeoutError(message);
  throw ProtocolError(message);
}

void Receiver::nak(uint8_t request, Milliseconds purge_limit, Milliseconds already_quiet)
{
  // Whatever is left of a garbled packet must not be read as the start of the next one. A line
  // that has just been quiet for a while (a short packet's character timeout) needs only the rest.
  const Milliseconds quiet = std::max(Milliseconds(1), config_.purge_quiet - already_quiet);
  input_.purge(quiet, purge_limit);
  link_.writeByte(request);
}

// Where a receive is, between the steps of receive().
struct Receiver::ReceiveState
{
  ReceiveState(const Config& config, Mode mode, const ProgressCallback& progress)
      : crc(mode != Mode::kChecksum),
        request(crc ? kCrcStart : kNak),
        start_timeout(config.start_timeout.count() > 0 ? config.start_timeout
                                                       : config.nak_interval * config.max_retries),
        start_deadline(Clock::now() + start_timeout),
        next_request(Clock::now() + config.nak_interval),
        buffer(packetSize(kBlockSize1K, CheckType::kCrc16)),
        progress(progress)
  {
  }

  bool crc;         ///< CRC-16 packets (else the checksum)
  uint8_t request;  ///< the start request: 'C' or NAK
  const Milliseconds start_timeout;
  const Clock::time_point start_deadline;
  Clock::time_point next_request;  ///< when the start request is repeated
  unsigned requests = 1;
  bool started = false;  ///< a good packet arrived: the check type is settled
  uint8_t expected = 1;
  Progress state;
  unsigned errors = 0;  ///< in a row
  std::vector<uint8_t> buffer;
  std::vector<uint8_t> data;
  int pending = -1;  ///< a byte read ahead (after a lone CAN) that starts the next round
  /// A whole packet after the last good block was NAKed (bad check, or followed by a doubled
  /// byte): a sender must now send that block again. One that sends EOT instead took a stray byte
  /// (a doubled or delayed ACK) for our ACK, and the block it believes delivered is missing.
  bool block_to_resend = false;
  Clock::time_point first_block_start;  ///< when the first byte of block 1 arrived
  const ProgressCallback& progress;
};

std::vector<uint8_t> Receiver::receive(const ProgressCallback& progress)
{
  stats_ = Stats();
  try
  {
    ReceiveState r(config_, mode_, progress);
    if (!config_.skip_initial_request)
      link_.writeByte(r.request);
    for (;;)
    {
      checkCancel();
      const int c = nextByte(r);
      if (c < 0)
        onSilence(r);
      else if (c == kSoh || c == kStx)
        onPacket(r, static_cast<uint8_t>(c));
      else if (c == kEot && onEot(r))
        return std::move(r.data);
      else if (c == kCan)
        onCan(r);
      else if (c != kEot && (r.started || (c != kNak && c != kCrcStart && c != kAck)))
        onNoise(r, static_cast<uint8_t>(c));
      // Before the first packet NAK, 'C' and ACK are a peer's own start requests (a control that
      // NAKs while it waits, a loopback): not a damaged packet, so nothing to purge.
    }
  }
  catch (const CancelledError&)
  {
    sendCancel(link_);
    throw CancelledError(link_.describe() + ": XModem receive cancelled after " + std::to_string(stats_.blocks) +
                         " blocks (CAN sent)");
  }
}

int Receiver::nextByte(ReceiveState& r)
{
  if (r.pending >= 0)
  {
    const int c = r.pending;
    r.pending = -1;
    return c;
  }
  // Before the first packet the request is repeated on a fixed schedule: bytes that are not a
  // packet (a control's own NAKs) must not postpone it.
  const Milliseconds wait =
      r.started ? config_.block_timeout : std::min(remainingUntil(r.next_request), remainingUntil(r.start_deadline));
  return wait.count() > 0 ? input_.readByte(wait) : -1;
}

void Receiver::receiveError(ReceiveState& r, const std::string& what, Milliseconds already_quiet)
{
  ++stats_.retries;
  ++r.state.retries;
  if (++r.errors > config_.max_retries)
  {
    abort(
        what + " (" + std::to_string(r.errors) + " errors in a row at block " + std::to_string(r.state.block + 1) + ")",
        true, false);
  }
  CNC_LOG_DEBUG("xmodem: " << what << " at block " << r.state.block + 1 << ", NAK");
  // Before the first packet the purge ends after one nak_interval at most: a control that is
  // itself waiting to receive NAKs more often than purge_quiet, and would keep the line from
  // ever going quiet (the rest of a block it sent before a cancel, then its NAKs).
  nak(r.started ? kNak : r.request, r.started ? Milliseconds(10000) : config_.nak_interval, already_quiet);
}

void Receiver::onSilence(ReceiveState& r)
{
  ++stats_.timeouts;
  if (!r.started)
  {
    if (Clock::now() >= r.start_deadline)
      abort("the sender did not start within " + seconds(r.start_timeout) + ": " + kNoAnswerHint, true, true);
    if (r.crc && r.requests >= config_.crc_attempts)
    {
      r.crc = false;  // the sender does not know 'C': fall back to checksum mode
      r.request = kNak;
    }
    if (Clock::now() < r.next_request)
      return;
    ++r.requests;
    link_.writeByte(r.request);
    r.next_request = Clock::now() + config_.nak_interval;
    return;
  }
  ++stats_.retries;
  ++r.state.retries;
  if (++r.errors > config_.max_retries)
    abort("nothing from the sender for " + seconds(config_.block_timeout) + ", " + std::to_string(r.errors) +
              " times in a row",
          true, true);
  link_.writeByte(kNak);
}

void Receiver::onPacket(ReceiveState& r, uint8_t first)
{
  const auto packet_start = Clock::now();
  const CheckType check = r.crc ? CheckType::kCrc16 : CheckType::kChecksum;
  const size_t data_size = first == kSoh ? kBlockSize : kBlockSize1K;
  const size_t need = packetSize(data_size, check);
  r.buffer[0] = first;
  const size_t got = input_.readExactly(r.buffer.data() + 1, need - 1, config_.char_timeout);
  if (got < need - 1)
  {
    ++stats_.garbled;
    ++stats_.timeouts;
    receiveError(r, "short packet (" + std::to_string(got + 1) + " of " + std::to_string(need) + " bytes)",
                 config_.char_timeout);
    return;
  }
  const Packet packet = decodePacket(r.buffer.data(), need, check, r.crc ? nullptr : &reading_);
  if (packet.status == PacketStatus::kBadCheck && !r.crc)
    noteOtherReading(packet);
  if (packet.status != PacketStatus::kOk)
  {
    ++stats_.garbled;
    r.block_to_resend = r.started;
    receiveError(r, toString(packet.status));
    return;
  }
  // A byte doubled on the line shifts the packet by one: its check is then read from the
  // data, which an 8-bit sum passes one time in 256, and the real check byte follows. Once
  // the line has shown damage, a packet followed at once by more bytes is taken as garbled.
  if (stats_.retries > 0 && input_.readByte(kDoubledByteQuiet) >= 0)
  {
    ++stats_.garbled;
    r.block_to_resend = r.started;
    receiveError(r, "packet followed by more bytes (a doubled byte on the line)");
    return;
  }
  r.block_to_resend = false;
  onGoodPacket(r, packet, check, packet_start);
}

void Receiver::onGoodPacket(ReceiveState& r, const Packet& packet, CheckType check,
                            std::chrono::steady_clock::time_point packet_start)
{
  if (packet.block == r.expected)
  {
    acceptBlock(r, packet, check, packet_start);
    return;
  }
  if (r.started && packet.block == static_cast<uint8_t>(r.expected - 1))
  {
    // The sender did not get our ACK and sent the block again: ACK it, keep the first copy.
    ++stats_.duplicates;
    link_.writeByte(kAck);
    return;
  }
  if (!r.started)
  {
    // No block taken yet, so no position to disagree on: this is the rest of an earlier
    // transfer (a control that was still sending a block when that transfer was cancelled).
    ++stats_.garbled;
    receiveError(r, "block " + std::to_string(packet.block) + " before block 1 (left from an earlier transfer)");
    return;
  }
  abort("block " + std::to_string(packet.block) + " out of sequence (expected " + std::to_string(r.expected) +
            "): the two sides disagree on the position in the file",
        true, false);
}

void Receiver::acceptBlock(ReceiveState& r, const Packet& packet, CheckType check,
                           std::chrono::steady_clock::time_point packet_start)
{
  if (r.data.size() + packet.data_size > config_.max_bytes)
  {
    // XModem has no length field: only the cap stops a peer that keeps sending.
    abort("the program is longer than " + config_.max_bytes_name + " (" + std::to_string(config_.max_bytes) +
              " bytes) allows; transfer cancelled, nothing stored (raise " + config_.max_bytes_name +
              " for a longer program)",
          true, false);
  }
  if (!r.started)
    r.first_block_start = packet_start;
  r.started = true;
  stats_.check = check;
  stats_.used_1k = stats_.used_1k || packet.data_size == kBlockSize1K;
  r.data.insert(r.data.end(), packet.data, packet.data + packet.data_size);
  reading_.accept(packet.data, packet.data_size);
  link_.writeByte(kAck);
  stats_.block_time = std::chrono::duration_cast<std::chrono::microseconds>(Clock::now() - r.first_block_start);
  r.errors = 0;
  ++r.expected;
  ++r.state.block;
  r.state.bytes = r.data.size();
  stats_.blocks = r.state.block;
  stats_.bytes = r.data.size();
  if (r.progress)
    r.progress(r.state);
}

bool Receiver::onEot(ReceiveState& r)
{
  // A real EOT is followed by silence; a garbled SOH is followed by the rest of its packet.
  if (input_.readByte(config_.eot_quiet) >= 0)
  {
    ++stats_.garbled;
    receiveError(r, "EOT followed by more data (line noise)");
    return false;
  }
  if (r.block_to_resend)
  {
    abort("the sender ended the transfer instead of sending block " + std::to_string(r.expected) +
              " again after its NAK (it took a stray byte for an ACK): the end of the file is missing",
          true, false);
  }
  if (config_.answer_eot_with_can)
  {
    const uint8_t cans[] = {kCan, kCan, kCan};
    link_.write(cans, sizeof(cans));
  }
  else
  {
    link_.writeByte(kAck);
  }
  stats_.check = r.crc ? CheckType::kCrc16 : CheckType::kChecksum;
  return true;
}

void Receiver::onCan(ReceiveState& r)
{
  const int next = input_.readByte(config_.char_timeout);
  if (next == kCan)
    abort("the sender cancelled (CAN CAN) after " + std::to_string(r.state.block) + " blocks", false, false);
  r.pending = next;  // a lone CAN is line noise; what follows it is looked at as usual
}

void Receiver::onNoise(ReceiveState& r, uint8_t c)
{
  // Noise between packets: drop the rest of the burst and ask again.
  ++stats_.garbled;
  static const char kHex[] = "0123456789abcdef";
  receiveError(r, std::string("unexpected byte 0x") + kHex[(c >> 4) & 0xF] + kHex[c & 0xF]);
}
}  // namespace xmodem
}  // namespace cnc_bridge
