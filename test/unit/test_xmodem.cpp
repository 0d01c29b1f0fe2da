// XModem core: packet codec and check codes, end-of-block conversion, the sender and receiver
// against the real Haas bytes of OpenDNC's capture (test/data/xmodem/haas_xmodem_capture.json),
// protocol corner cases on a scripted FakeTransport, sender <-> receiver over an in-memory link,
// and >= 200 transfers through the seeded FaultyTransport. No sleeps: every wait is a read with a
// timeout or a FakeTransport condition variable.
#include <gtest/gtest.h>
#include <sys/stat.h>
#include <yaml-cpp/yaml.h>

#include <dirent.h>

#include <atomic>
#include <cstdlib>
#include <fstream>
#include <future>
#include <memory>
#include <random>
#include <thread>

#include "cnc_bridge/common/error.h"
#include "cnc_bridge/transport/buffered_input.h"
#include "cnc_bridge/transport/forwarding_transport.h"
#include "cnc_bridge/xmodem/file_transfer.h"
#include "cnc_bridge/xmodem/packet.h"
#include "cnc_bridge/xmodem/session.h"
#include "haas_capture.h"
#include "temp_dir.h"
#include "testing/fake_transport.h"
#include "testing/faulty_transport.h"

using namespace cnc_bridge;
using namespace cnc_bridge::xmodem;
using namespace cnc_bridge::test;

namespace
{
using Bytes = std::vector<uint8_t>;

/// A scripted peer: each write to \p link is answered with the next transmission of \p script
/// (a receiver's NAK or ACK gets the sender's next packet), until the script runs out.
void answerEachWriteWith(FakeTransport& link, std::vector<Bytes> script)
{
  auto next = std::make_shared<size_t>(0);
  link.onWrite(
      [script = std::move(script), next](FakeTransport& t, const Bytes&)
      {
        if (*next < script.size())
          t.feed(script[(*next)++]);
      });
}

size_t filesIn(const std::string& dir)
{
  size_t n = 0;
  if (DIR* d = ::opendir(dir.c_str()))
  {
    while (dirent* e = ::readdir(d))
      if (std::string(e->d_name) != "." && std::string(e->d_name) != "..")
        ++n;
    ::closedir(d);
  }
  return n;
}

/// Timeouts short enough for tests on an in-memory link, long enough for a loaded machine.
Config fastConfig()
{
  Config c;
  c.nak_interval = Milliseconds(200);
  c.start_timeout = Milliseconds(3000);
  c.block_timeout = Milliseconds(300);
  c.char_timeout = Milliseconds(100);
  c.purge_quiet = Milliseconds(20);
  c.eot_quiet = Milliseconds(20);
  c.start_wait = Milliseconds(3000);
  c.ack_timeout = Milliseconds(300);
  c.stale_nak_settle = Milliseconds(50);
  c.turnaround = Milliseconds(2);
  return c;
}

/// Two FakeTransports wired back to back: what one side writes, the other reads.
struct LinkPair
{
  FakeTransport a{"fake-a"};
  FakeTransport b{"fake-b"};
  LinkPair()
  {
    a.onWrite([this](FakeTransport&, const Bytes& bytes) { b.feed(bytes); });
    b.onWrite([this](FakeTransport&, const Bytes& bytes) { a.feed(bytes); });
  }
};

Bytes randomBytes(size_t n, uint32_t seed, bool avoid_trailing_sub = true)
{
  std::mt19937 random(seed);
  Bytes out(n);
  for (auto& b : out)
    b = static_cast<uint8_t>(random());
  if (avoid_trailing_sub && !out.empty() && out.back() == kSub)
    out.back() = 'x';
  return out;
}
/// A text program of about \p size bytes: N-numbered blocks with LF line ends, as a CAM system writes.
std::string ncProgram(size_t size, uint32_t seed)
{
  std::mt19937 random(seed);
  std::string out = "%\nO1234 (TEST)\n";
  for (unsigned n = 10; out.size() < size; n += 5)
  {
    // Drawn one after the other: the operands of one + have no order, and every build must make
    // the same program.
    const auto x = random() % 10000;
    const auto y = random() % 999;
    out += "N" + std::to_string(n) + "G01X" + std::to_string(x) + "Y" + std::to_string(y) + "\n";
  }
  return out + "M30\n%\n";
}
}  // namespace

// ---------------------------------------------------------------------------------------------
TEST(XmodemCodec, CheckCodesMatchTheirReferenceValues)
{
  const std::string check = "123456789";
  EXPECT_EQ(crc16Xmodem(reinterpret_cast<const uint8_t*>(check.data()), check.size()), 0x31C3);
  const Bytes ones(128, 0xFF);
  EXPECT_EQ(checksum8(ones.data(), ones.size()), static_cast<uint8_t>(128 * 0xFF));
}

TEST(XmodemCodec, EncodesAndDecodesEveryKindOfPacket)
{
  const Bytes data = randomBytes(1000, 3);
  for (CheckType check : {CheckType::kChecksum, CheckType::kCrc16})
  {
    for (size_t block_size : {kBlockSize, kBlockSize1K})
    {
      const Bytes packet = encodePacket(257, data.data(), 100, block_size, check);
      ASSERT_EQ(packet.size(), packetSize(block_size, check));
      EXPECT_EQ(packet[0], block_size == kBlockSize ? kSoh : kStx);
      EXPECT_EQ(packet[1], 1);  // 257 wraps to 1
      EXPECT_EQ(packet[2], 0xFE);
      EXPECT_EQ(packet[3 + 100], kSub);  // padding
      const Packet parsed = decodePacket(packet.data(), packet.size(), check);
      ASSERT_EQ(parsed.status, PacketStatus::kOk);
      EXPECT_EQ(parsed.block, 1);
      EXPECT_EQ(parsed.data_size, block_size);
      EXPECT_TRUE(std::equal(data.begin(), data.begin() + 100, parsed.data));
    }
  }
}

TEST(XmodemCodec, RejectsDamagedPackets)
{
  const Bytes data = randomBytes(128, 4);
  const Bytes good = encodePacket(5, data.data(), data.size(), kBlockSize, CheckType::kCrc16);
  EXPECT_EQ(decodePacket(good.data(), good.size() - 1, CheckType::kCrc16).status, PacketStatus::kTruncated);
  EXPECT_EQ(decodePacket(good.data(), 0, CheckType::kCrc16).status, PacketStatus::kTruncated);
  Bytes bad = good;
  bad[0] = 0x33;
  EXPECT_EQ(decodePacket(bad.data(), bad.size(), CheckType::kCrc16).status, PacketStatus::kBadHeader);
  bad = good;
  bad[2] ^= 0x10;
  EXPECT_EQ(decodePacket(bad.data(), bad.size(), CheckType::kCrc16).status, PacketStatus::kBadComplement);
  for (size_t i = 3; i < good.size(); i += 17)
  {
    bad = good;
    bad[i] ^= 0x01;
    EXPECT_EQ(decodePacket(bad.data(), bad.size(), CheckType::kCrc16).status, PacketStatus::kBadCheck) << i;
  }
  EXPECT_THROW(encodePacket(1, data.data(), 129, kBlockSize, CheckType::kCrc16), std::invalid_argument);
  EXPECT_THROW(encodePacket(1, data.data(), 10, 256, CheckType::kCrc16), std::invalid_argument);
}

TEST(XmodemText, ConvertsEndOfBlockBothWays)
{
  const std::string file = "%\nO1000\r\nG00 X1\rM30\n%\n";
  EXPECT_EQ(toControlEob(file, Eob::kLf), "%\nO1000\nG00 X1\nM30\n%\n");
  EXPECT_EQ(toControlEob(file, Eob::kCrLf), "%\r\nO1000\r\nG00 X1\r\nM30\r\n%\r\n");
  EXPECT_EQ(toControlEob(file, Eob::kCrCr), "%\r\rO1000\r\rG00 X1\r\rM30\r\r%\r\r");
  EXPECT_EQ(toControlEob("a\nb", Eob::kLfLf), "a\n\nb");
  for (Eob eob : {Eob::kLf, Eob::kCr, Eob::kCrLf, Eob::kCrCr, Eob::kLfLf})
  {
    const std::string unix_file = "%\nO1000\n\nG00 X1\nM30\n%\n";
    EXPECT_EQ(fromControlEob(toControlEob(unix_file, eob), eob, Eob::kLf), unix_file) << toString(eob);
    EXPECT_EQ(parseEob(toString(eob)), eob);
  }
  EXPECT_EQ(fromControlEob("A\nB\n", Eob::kLf, Eob::kCrLf), "A\r\nB\r\n");
  EXPECT_THROW(parseEob("semicolon"), ConfigError);

  Bytes padded = {'M', '3', '0', '\n', kSub, kSub, kSub};
  EXPECT_EQ(stripSubPadding(padded), 4u);
  TextOptions binary;
  binary.binary = true;
  EXPECT_EQ(fromWire({'a', kSub}, binary), std::string("a\x1a"));
  EXPECT_EQ(fromWire({'a', '\n', kSub}, TextOptions()), "a\n");
}

// ---------------------------------------------------------------------------------------------
// The Haas end-of-block checksum (docs/protocols/xmodem.md#haas-end-of-block): each end of block
// summed as LF, whatever setting 25 sends.

/// The LF reading of a whole wire stream, computed the plain way: every end of block replaced by
/// one LF (left to right), the rest summed as it is.
uint8_t lfReadingOfStream(const std::string& wire, Eob eob)
{
  const std::string pattern = eobBytes(eob);
  uint8_t sum = 0;
  for (size_t i = 0; i < wire.size();)
  {
    if (wire.compare(i, pattern.size(), pattern) == 0)
    {
      sum = static_cast<uint8_t>(sum + '\n');
      i += pattern.size();
    }
    else
    {
      sum = static_cast<uint8_t>(sum + static_cast<uint8_t>(wire[i++]));
    }
  }
  return sum;
}

TEST(XmodemEobChecksum, PacketByPacketSumsAddUpToTheStreamReadWithLfForEveryPattern)
{
  // Ends of block cut by packet ends (blank blocks included: doubled patterns). A first line of
  // 127 characters puts its end of block on bytes 127 and 128: the first cut by a packet's end.
  std::string text = "(" + std::string(125, 'C') + ")\n" + ncProgram(2000, 3);
  text.insert(400, "\n\n\n");
  size_t cut_patterns = 0;
  for (Eob eob : {Eob::kLf, Eob::kCr, Eob::kCrLf, Eob::kCrCr, Eob::kLfLf})
  {
    SCOPED_TRACE(toString(eob));
    std::string wire = toControlEob(text, eob);
    wire.append((kBlockSize - wire.size() % kBlockSize) % kBlockSize, static_cast<char>(kSub));
    ChecksumReading lf(EobChecksum::kLf, eob), on_wire(EobChecksum::kWire, eob);
    uint8_t total = 0;
    for (size_t at = 0; at < wire.size(); at += kBlockSize)
    {
      const auto* block = reinterpret_cast<const uint8_t*>(wire.data() + at);
      EXPECT_EQ(on_wire.sum(block, kBlockSize), checksum8(block, kBlockSize));
      EXPECT_EQ(lf.otherSum(block, kBlockSize), checksum8(block, kBlockSize));
      total = static_cast<uint8_t>(total + lf.sum(block, kBlockSize));
      lf.accept(block, kBlockSize);
      const std::string pattern = eobBytes(eob);
      cut_patterns += pattern.size() == 2 && at > 0 && wire[at - 1] == pattern[0] && wire[at] == pattern[1];
    }
    EXPECT_EQ(total, lfReadingOfStream(wire, eob));
    if (eob == Eob::kLf)
    {
      EXPECT_EQ(total, checksum8(reinterpret_cast<const uint8_t*>(wire.data()), wire.size()));  // both agree
    }
  }
  EXPECT_GT(cut_patterns, 0u) << "no end of block was cut by a packet end: the case is not covered";
  EXPECT_EQ(parseEobChecksum("lf"), EobChecksum::kLf);
  EXPECT_EQ(parseEobChecksum("wire"), EobChecksum::kWire);
  EXPECT_THROW(parseEobChecksum("as-lf"), ConfigError);
}

TEST(XmodemEobChecksum, APatternCutByThePacketEndIsReadOnInTheNext)
{
  // "A\r" | "\nB": the CR ends packet 1 (summed as LF), the LF opens packet 2 (summed as nothing).
  ChecksumReading lf(EobChecksum::kLf, Eob::kCrLf);
  const Bytes first = {'A', '\r'}, second = {'\n', 'B'};
  EXPECT_EQ(lf.sum(first.data(), first.size()), static_cast<uint8_t>('A' + '\n'));
  // Not accepted yet (NAKed, sent again): the next packet is still read from the same place.
  EXPECT_EQ(lf.sum(second.data(), second.size()), static_cast<uint8_t>('\n' + 'B'));
  lf.accept(first.data(), first.size());
  EXPECT_EQ(lf.sum(second.data(), second.size()), static_cast<uint8_t>('B'));
  EXPECT_EQ(lf.otherSum(second.data(), second.size()), static_cast<uint8_t>('\n' + 'B'));
}

namespace
{
/// Sends \p text from one side to the other over an in-memory link, each side with its reading.
/// \returns the sender's error ("" when it succeeded) and the receiver's (or the file received).
std::pair<std::string, std::string> transferWithReadings(const std::string& text, Eob eob, EobChecksum sender_reading,
                                                         EobChecksum receiver_reading, const TempDir& dir)
{
  writeFile(dir.path + "/source.nc", text);
  Config config;
  config.start_timeout = config.start_wait = Milliseconds(5000);
  config.ack_timeout = config.block_timeout = Milliseconds(2000);
  config.char_timeout = config.purge_quiet = Milliseconds(30);
  config.max_retries = 3;
  config.eot_timeout = Milliseconds(500);
  TextOptions sending, receiving;
  sending.control_eob = receiving.control_eob = eob;
  sending.eob_checksum = sender_reading;
  receiving.eob_checksum = receiver_reading;
  LinkPair link;
  auto sent = std::async(std::launch::async,
                         [&]() -> std::string
                         {
                           try
                           {
                             sendFile(link.a, dir.path + "/source.nc", Mode::kChecksum, config, sending);
                             return "";
                           }
                           catch (const Error& e)
                           {
                             return e.what();
                           }
                         });
  std::string received;
  try
  {
    receiveFile(link.b, dir.path + "/received.nc", Mode::kChecksum, config, receiving);
    received = readFile(dir.path + "/received.nc");
  }
  catch (const Error& e)
  {
    received = std::string("error: ") + e.what();
  }
  return {sent.get(), received};
}
}  // namespace

TEST(XmodemEobChecksum, BothSidesOnOneReadingMoveTheProgramExactlyForEveryPattern)
{
  TempDir dir("test_xmodem_eob");
  const std::string text = ncProgram(1500, 8);
  for (EobChecksum reading : {EobChecksum::kWire, EobChecksum::kLf})
  {
    for (Eob eob : {Eob::kLf, Eob::kCr, Eob::kCrLf, Eob::kCrCr, Eob::kLfLf})
    {
      SCOPED_TRACE(std::string(toString(eob)) + " " + toString(reading));
      const auto [sender_error, received] = transferWithReadings(text, eob, reading, reading, dir);
      EXPECT_EQ(sender_error, "");
      EXPECT_EQ(received, text);
    }
  }
}

TEST(XmodemEobChecksum, AReceiverOnTheOtherReadingNamesTheOneTheControlUsesAndStoresNothing)
{
  TempDir dir("test_xmodem_eob");
  const std::string text = ncProgram(1500, 9);
  const auto [sender_error, received] =
      transferWithReadings(text, Eob::kCrLf, EobChecksum::kLf, EobChecksum::kWire, dir);
  EXPECT_NE(received.find("set eob_checksum to lf"), std::string::npos) << received;
  EXPECT_NE(received.find("sums each end of block as LF"), std::string::npos) << received;
  EXPECT_FALSE(exists(dir.path + "/received.nc"));
  // The sender, NAKed on a block holding an end of block, says what to try.
  EXPECT_NE(sender_error.find("try eob_checksum wire"), std::string::npos) << sender_error;
}

// ---------------------------------------------------------------------------------------------
// OpenDNC's Haas capture, CNC -> PC: the receiver, asking in checksum mode with NAK as a Haas needs, gets the
// control's eight packets and must rebuild haas_O05555.nc byte for byte.
TEST(XmodemCapture, ReceiverReproducesTheProgramTheHaasSent)
{
  const auto events = capture("cnc_to_pc");
  std::vector<Bytes> from_cnc;
  for (const auto& e : events)
    if (!e.from_pc)
      from_cnc.push_back(e.bytes);
  ASSERT_EQ(from_cnc.size(), 9u);  // 8 packets + EOT

  FakeTransport cnc("haas");
  // The control answers each byte the PC writes with its next transmission, as in OpenDNC's Haas capture.
  answerEachWriteWith(cnc, from_cnc);
  Receiver receiver(cnc, Mode::kChecksum, fastConfig());
  const Bytes payload = receiver.receive();
  const std::string program = fromWire(payload, TextOptions());
  EXPECT_EQ(program, readFile(std::string(XMODEM_TEST_DATA) + "/haas_O05555.nc"));
  EXPECT_EQ(receiver.stats().blocks, 8u);
  EXPECT_EQ(receiver.stats().retries, 0u);

  // What the PC wrote: NAK to start (not 'C': a Haas knows checksum mode only), ACK x 8, ACK the EOT.
  Bytes expected = {kNak};
  expected.insert(expected.end(), 9, kAck);
  EXPECT_EQ(cnc.written(), expected);
}

// OpenDNC's Haas capture, PC -> CNC: the control NAKs once, then twice more before the PC starts.
// The PC of that capture sent block 1 twice (the stale NAKs) and the Haas then NAKed block 2. Our
// sender's packets must equal the packets of that capture for that file, block 1 once, and a CAN CAN CAN
// answer to EOT is a completed transfer.
TEST(XmodemCapture, SenderPacketsEqualTheCaptureAndStaleNaksDoNotRepeatBlockOne)
{
  const auto events = capture("pc_to_cnc");
  Bytes expected;  // the distinct packets the PC wrote, then EOT
  for (const auto& e : events)
  {
    if (!e.from_pc)
      continue;
    const Bytes& b = e.bytes;
    if (b.size() == 264)
      expected.insert(expected.end(), b.begin(), b.begin() + 132);  // block 1, once
    else if (!(b.size() == 132 && expected.size() >= 132 && std::equal(b.begin(), b.end(), expected.end() - 132)))
      expected.insert(expected.end(), b.begin(), b.end());  // skip the resent block 2
  }
  ASSERT_EQ(expected.size(), 8 * 132 + 1u);

  const std::string file = readFile(std::string(XMODEM_TEST_DATA) + "/haas_O05555.nc");
  FakeTransport cnc("haas");
  cnc.feed(Bytes{kNak, kNak, kNak});  // one NAK, then two more queued before the PC starts
  cnc.onWrite(
      [&](FakeTransport& t, const Bytes& bytes)
      {
        if (bytes.size() == 1 && bytes[0] == kEot)
          t.feed(Bytes{kCan, kCan, kCan});  // the Haas answer to EOT
        else if (bytes.size() == 132)
          t.feed(Bytes{kAck});
      });
  Sender sender(cnc, Mode::kChecksum, fastConfig());
  const Stats stats = sender.send(toWire(file, TextOptions()));
  EXPECT_EQ(cnc.written(), expected);
  EXPECT_EQ(stats.blocks, 8u);
  EXPECT_EQ(stats.retries, 0u);
  EXPECT_TRUE(stats.eot_answered_with_can);
  EXPECT_NE(stats.summary().find("CAN"), std::string::npos);
}

// A NAK the control sent while block 1 was already on its way arrives after block 1: the ACK
// that follows it must be taken, not the NAK.
TEST(XmodemSender, NakInFlightBeforeTheAckOfBlockOneDoesNotResendIt)
{
  FakeTransport rx;
  rx.feed(Bytes{kNak});
  rx.onWrite(
      [](FakeTransport& t, const Bytes& bytes)
      {
        if (bytes.size() == 132 && bytes[1] == 1)
          t.feed(Bytes{kNak, kAck});
        else
          t.feed(Bytes{kAck});
      });
  Sender sender(rx, Mode::kChecksum, fastConfig());
  const Stats stats = sender.send(Bytes(200, 'A'));
  EXPECT_EQ(stats.retries, 0u);
  EXPECT_EQ(rx.written().size(), 2 * 132 + 1u);
}

TEST(XmodemSender, ResendsANakedBlockAndGivesUpAfterMaxRetriesWithCan)
{
  FakeTransport rx;
  rx.feed(Bytes{kNak});
  int naks = 0;
  rx.onWrite(
      [&](FakeTransport& t, const Bytes& bytes)
      {
        if (bytes.size() == 132 && bytes[1] == 2 && naks < 2)
        {
          ++naks;
          t.feed(Bytes{kNak});
        }
        else if (bytes.size() == 132 || bytes[0] == kEot)
          t.feed(Bytes{kAck});
      });
  Sender sender(rx, Mode::kChecksum, fastConfig());
  const Stats stats = sender.send(Bytes(300, 'B'));
  EXPECT_EQ(stats.retries, 2u);
  EXPECT_EQ(stats.blocks, 3u);
  EXPECT_EQ(rx.written().size(), 5 * 132 + 1u);

  FakeTransport deaf;
  deaf.feed(Bytes{'C'});
  Config config = fastConfig();
  config.ack_timeout = Milliseconds(10);
  config.max_retries = 3;
  Sender quitter(deaf, Mode::kCrc, config);
  EXPECT_THROW(quitter.send(Bytes(10, 'x')), TimeoutError);
  const Bytes written = deaf.written();
  ASSERT_EQ(written.size(), 4 * 133 + kCancelLength);  // 1 + 3 retries, then the CANs
  EXPECT_EQ(written.back(), kCan);
}

TEST(XmodemSender, StopsWhenTheReceiverCancelsAndWhenNobodyStarts)
{
  FakeTransport rx;
  rx.feed(Bytes{kNak});
  rx.onWrite([](FakeTransport& t, const Bytes&) { t.feed(Bytes{kCan, kCan}); });
  Sender sender(rx, Mode::kChecksum, fastConfig());
  try
  {
    sender.send(Bytes(10, 'x'));
    FAIL() << "no error";
  }
  catch (const ProtocolError& e)
  {
    EXPECT_NE(std::string(e.what()).find("cancelled"), std::string::npos) << e.what();
  }

  FakeTransport silent;
  Config config = fastConfig();
  config.start_wait = Milliseconds(30);
  EXPECT_THROW(Sender(silent, Mode::kChecksum, config).send(Bytes(10, 'x')), TimeoutError);
}

namespace
{
/// Sends 200 bytes to a scripted receiver that starts with \p start, ACKs every block and answers
/// EOT with \p cans CANs. \returns "" on success (eot_answered_with_can must then be set), else the error.
std::string sendWithCanAnswerToEot(uint8_t start, size_t cans, bool eot_can_completes)
{
  FakeTransport rx;
  rx.feed(Bytes{start});
  rx.onWrite(
      [cans](FakeTransport& t, const Bytes& bytes)
      {
        if (bytes == Bytes{kEot})
          t.feed(Bytes(cans, kCan));
        else if (bytes.size() > 1)
          t.feed(Bytes{kAck});
      });
  Config config = fastConfig();
  config.eot_can_completes = eot_can_completes;
  try
  {
    const Stats stats = Sender(rx, start == kNak ? Mode::kChecksum : Mode::kCrc, config).send(Bytes(200, 'h'));
    EXPECT_TRUE(stats.eot_answered_with_can);
    return "";
  }
  catch (const ProtocolError& e)
  {
    return e.what();
  }
}
}  // namespace

// CAN CAN CAN after EOT is the Haas's "complete" only where it can be the Haas: checksum mode, at
// most three CANs, the rule on. Our own receiver aborting (kCancelLength CANs), a CRC receiver's
// CANs, or any CANs with the rule off fail the transfer.
TEST(XmodemSender, CanAfterEotCompletesOnlyForTheHaasAnswer)
{
  EXPECT_EQ(sendWithCanAnswerToEot(kNak, 3, true), "");
  EXPECT_EQ(sendWithCanAnswerToEot(kNak, 2, true), "");
  const std::string aborted = sendWithCanAnswerToEot(kNak, kCancelLength, true);
  EXPECT_NE(aborted.find("8 CANs) in answer to EOT"), std::string::npos) << aborted;
  EXPECT_NE(sendWithCanAnswerToEot(kNak, 10, true), "");  // lrzsz's abort
  const std::string off = sendWithCanAnswerToEot(kNak, 3, false);
  EXPECT_NE(off.find("not taken as complete"), std::string::npos) << off;
  EXPECT_NE(sendWithCanAnswerToEot('C', 3, true), "");  // a CRC receiver is no Haas
}

// A receiver cancelled just as the EOT arrives sends CANs and stores nothing: the sender must not
// report success, with the Haas rule on or off.
TEST(XmodemSender, AReceiverCancelledAtEotFailsTheSend)
{
  /// The receiver's side of the link: the read that brings the EOT also cancels the receiver.
  class CancelAtEot : public ForwardingTransport
  {
   public:
    CancelAtEot(Transport& inner, std::atomic<bool>& cancel) : ForwardingTransport(inner), cancel_(cancel) {}
    size_t read(uint8_t* buffer, size_t size, Milliseconds timeout) override
    {
      const size_t n = inner_.read(buffer, size, timeout);
      if (n == 1 && buffer[0] == kEot)
      {
        cancel_ = true;
        inner_.interrupt();  // the receiver's next read (its wait for quiet after EOT) ends
      }
      return n;
    }

   private:
    std::atomic<bool>& cancel_;
  };
  for (const bool rule : {true, false})
  {
    TempDir dir("test_xmodem");
    const std::string target = dir.path + "/O1000.nc";
    LinkPair link;
    std::atomic<bool> cancel{false};
    CancelAtEot receiver_side(link.b, cancel);
    Config config = fastConfig();
    config.eot_can_completes = rule;
    auto sent =
        std::async(std::launch::async, [&] { return Sender(link.a, Mode::kChecksum, config).send(Bytes(300, 'e')); });
    EXPECT_THROW(receiveFile(receiver_side, target, Mode::kChecksum, config, TextOptions(), nullptr, &cancel),
                 CancelledError);
    EXPECT_FALSE(exists(target));
    try
    {
      sent.get();
      ADD_FAILURE() << "the sender reported success for a receive that was cancelled at EOT (rule " << rule << ")";
    }
    catch (const ProtocolError& e)
    {
      EXPECT_NE(std::string(e.what()).find("in answer to EOT"), std::string::npos) << e.what();
    }
  }
}

TEST(XmodemSender, OneKModeFollowsAChecksumReceiverWith128ByteBlocks)
{
  FakeTransport rx;
  rx.feed(Bytes{kNak});
  rx.onWrite([](FakeTransport& t, const Bytes&) { t.feed(Bytes{kAck}); });
  Sender sender(rx, Mode::k1K, fastConfig());
  const Stats stats = sender.send(Bytes(2048, 'k'));
  EXPECT_FALSE(stats.used_1k);
  EXPECT_EQ(stats.blocks, 16u);
  EXPECT_EQ(rx.written()[0], kSoh);

  FakeTransport crc_rx;
  crc_rx.feed(Bytes{'C'});
  crc_rx.onWrite([](FakeTransport& t, const Bytes&) { t.feed(Bytes{kAck}); });
  const Stats one_k = Sender(crc_rx, Mode::k1K, fastConfig()).send(Bytes(2048 + 100, 'k'));
  EXPECT_TRUE(one_k.used_1k);
  EXPECT_EQ(one_k.blocks, 3u);  // 1024 + 1024 + 128 (a short tail goes in a 128-byte block)
  EXPECT_EQ(crc_rx.written()[0], kStx);
}

// ---------------------------------------------------------------------------------------------
TEST(XmodemReceiver, AcksAndDropsADuplicateBlock)
{
  FakeTransport tx;
  const Bytes one = encodePacket(1, Bytes(128, '1').data(), 128, kBlockSize, CheckType::kChecksum);
  const Bytes two = encodePacket(2, Bytes(5, '2').data(), 5, kBlockSize, CheckType::kChecksum);
  std::vector<Bytes> script = {one, one, two, {kEot}};
  answerEachWriteWith(tx, script);
  Receiver receiver(tx, Mode::kChecksum, fastConfig());
  Bytes data = receiver.receive();
  stripSubPadding(data);
  EXPECT_EQ(data.size(), 133u);
  EXPECT_EQ(receiver.stats().duplicates, 1u);
  EXPECT_EQ(tx.written(), (Bytes{kNak, kAck, kAck, kAck, kAck}));
}

TEST(XmodemReceiver, AbortsWithCanOnABlockOutOfSequence)
{
  FakeTransport tx;
  const Bytes one = encodePacket(1, nullptr, 0, kBlockSize, CheckType::kChecksum);
  const Bytes three = encodePacket(3, nullptr, 0, kBlockSize, CheckType::kChecksum);
  std::vector<Bytes> script = {one, three};
  answerEachWriteWith(tx, script);
  Receiver receiver(tx, Mode::kChecksum, fastConfig());
  try
  {
    receiver.receive();
    FAIL() << "no error";
  }
  catch (const ProtocolError& e)
  {
    EXPECT_NE(std::string(e.what()).find("out of sequence"), std::string::npos) << e.what();
  }
  const Bytes written = tx.written();
  ASSERT_GE(written.size(), 4u);
  EXPECT_EQ(Bytes(written.end() - 3, written.end()), (Bytes{kCan, kCan, kCan}));
}

// A packet other than block 1 before any block was taken is the rest of an earlier, cancelled
// transfer: NAKed and dropped, not an abort. After block 1 it is out of sequence (above).
TEST(XmodemReceiver, ABlockLeftFromAnEarlierTransferIsNotTheStart)
{
  FakeTransport tx;
  const Bytes stale = encodePacket(2, Bytes(128, 's').data(), 128, kBlockSize, CheckType::kChecksum);
  const Bytes one = encodePacket(1, Bytes(3, '1').data(), 3, kBlockSize, CheckType::kChecksum);
  std::vector<Bytes> script = {stale, one, {kEot}};
  answerEachWriteWith(tx, script);
  Receiver receiver(tx, Mode::kChecksum, fastConfig());
  Bytes data = receiver.receive();
  stripSubPadding(data);
  EXPECT_EQ(data, Bytes(3, '1'));
  EXPECT_EQ(receiver.stats().garbled, 1u);
  EXPECT_EQ(tx.written(), (Bytes{kNak, kNak, kAck, kAck}));
}

// A sender that takes a stray byte (a doubled or late ACK) for the ACK of the last block, after
// the receiver NAKed it, sends EOT while the receiver waits for that block again. Taking the EOT
// would deliver the file without its end (an NC program without its last lines): the receive
// fails instead, and CANs tell the sender.
TEST(XmodemReceiver, AnEotInsteadOfTheBlockItNakedIsAFailureNotATruncatedFile)
{
  FakeTransport tx;
  const Bytes one = encodePacket(1, Bytes(128, '1').data(), 128, kBlockSize, CheckType::kChecksum);
  Bytes two = encodePacket(2, Bytes(20, '2').data(), 20, kBlockSize, CheckType::kChecksum);
  two[40] ^= 0x01;  // damaged on the line: NAKed
  std::vector<Bytes> script = {one, two, {kEot}};
  answerEachWriteWith(tx, script);
  Receiver receiver(tx, Mode::kChecksum, fastConfig());
  try
  {
    receiver.receive();
    FAIL() << "a file without its last block was taken as complete";
  }
  catch (const ProtocolError& e)
  {
    EXPECT_NE(std::string(e.what()).find("end of the file is missing"), std::string::npos) << e.what();
  }
  const Bytes written = tx.written();
  ASSERT_GE(written.size(), 6u);
  EXPECT_EQ(Bytes(written.begin(), written.begin() + 3), (Bytes{kNak, kAck, kNak}));
  EXPECT_EQ(Bytes(written.end() - 3, written.end()), (Bytes{kCan, kCan, kCan}));
}

// A damaged packet that the sender then sends again, followed by EOT, is an ordinary retry.
TEST(XmodemReceiver, AnEotAfterTheResentBlockEndsTheFile)
{
  FakeTransport tx;
  const Bytes one = encodePacket(1, Bytes(128, '1').data(), 128, kBlockSize, CheckType::kChecksum);
  const Bytes two = encodePacket(2, Bytes(20, '2').data(), 20, kBlockSize, CheckType::kChecksum);
  Bytes damaged = two;
  damaged[40] ^= 0x01;
  std::vector<Bytes> script = {one, damaged, two, {kEot}};
  answerEachWriteWith(tx, script);
  Receiver receiver(tx, Mode::kChecksum, fastConfig());
  Bytes data = receiver.receive();
  stripSubPadding(data);
  EXPECT_EQ(data.size(), 148u);
  EXPECT_EQ(tx.written(), (Bytes{kNak, kAck, kNak, kAck, kAck}));
}

TEST(XmodemReceiver, NaksGarbledPacketsAndIgnoresALoneCan)
{
  FakeTransport tx;
  Bytes good = encodePacket(1, Bytes(128, 'g').data(), 128, kBlockSize, CheckType::kCrc16);
  Bytes bad = good;
  bad[50] ^= 0x20;
  Bytes short_packet(good.begin(), good.begin() + 60);
  std::vector<Bytes> script = {bad, short_packet, Bytes{kCan}, good, {kEot}};
  size_t next = 0;
  tx.onWrite(
      [&](FakeTransport& t, const Bytes&)
      {
        if (next == 2)  // a lone CAN (noise) right before the good packet
        {
          t.feed(script[next++]);
        }
        if (next < script.size())
          t.feed(script[next++]);
      });
  Receiver receiver(tx, Mode::kCrc, fastConfig());
  const Bytes data = receiver.receive();
  EXPECT_EQ(data, Bytes(128, 'g'));
  EXPECT_EQ(receiver.stats().garbled, 2u);
  EXPECT_EQ(receiver.stats().check, CheckType::kCrc16);
  // 'C' to start, 'C' again for the garbled first packet (mode not settled yet), ACK, ACK EOT.
  EXPECT_EQ(tx.written(), (Bytes{'C', 'C', 'C', kAck, kAck}));
}

TEST(XmodemReceiver, FallsBackToChecksumWhenTheSenderIgnoresC)
{
  FakeTransport tx;
  tx.onWrite(
      [&](FakeTransport& t, const Bytes& bytes)
      {
        if (bytes[0] == kNak)
          t.feed(encodePacket(1, Bytes(3, 'n').data(), 3, kBlockSize, CheckType::kChecksum));
        else if (bytes[0] == kAck)
          t.feed(Bytes{kEot});
      });
  Config config = fastConfig();
  config.nak_interval = Milliseconds(10);
  Receiver receiver(tx, Mode::kCrc, config);
  Bytes data = receiver.receive();
  stripSubPadding(data);
  EXPECT_EQ(data, Bytes(3, 'n'));
  EXPECT_EQ(receiver.stats().check, CheckType::kChecksum);
  EXPECT_EQ(tx.written(), (Bytes{'C', 'C', 'C', kNak, kAck, kAck}));
}

TEST(XmodemReceiver, AcceptsOneKBlocksInChecksumModeAndAGarbledEotIsNotTheEnd)
{
  FakeTransport tx;
  Bytes big = encodePacket(1, Bytes(1024, 'K').data(), 1024, kBlockSize1K, CheckType::kChecksum);
  Bytes fake_eot = encodePacket(2, Bytes(1, 'e').data(), 1, kBlockSize, CheckType::kChecksum);
  fake_eot[0] = kEot;  // SOH garbled into EOT: the rest of the packet follows at once
  const Bytes two = encodePacket(2, Bytes(1, 'e').data(), 1, kBlockSize, CheckType::kChecksum);
  std::vector<Bytes> script = {big, fake_eot, two, {kEot}};
  answerEachWriteWith(tx, script);
  Receiver receiver(tx, Mode::kChecksum, fastConfig());
  Bytes data = receiver.receive();
  stripSubPadding(data);
  EXPECT_EQ(data.size(), 1025u);
  EXPECT_TRUE(receiver.stats().used_1k);
  EXPECT_EQ(receiver.stats().garbled, 1u);
}

TEST(XmodemConfig, SlowLinesGetTwelveCharacterTimesOfSilenceBeforeEotIsBelieved)
{
  Config fast;
  fitToLine(fast, 11520);  // 115200 8N1: 12 characters take 1 ms, the default is longer
  EXPECT_EQ(fast.eot_quiet, Config().eot_quiet);
  Config slow;
  fitToLine(slow, 30);  // 300 baud 8N1: a character every 33 ms
  EXPECT_EQ(slow.eot_quiet, Milliseconds(400));
  Config just_under;
  fitToLine(just_under, 240);  // 2400 baud 8N1: 12 characters take 50 ms, more than the default
  EXPECT_EQ(just_under.eot_quiet, Milliseconds(50));
  Config unknown;
  fitToLine(unknown, 0);
  EXPECT_EQ(unknown.eot_quiet, Config().eot_quiet);
}

// The character timeout and the purge's quiet are character times of the line, with a floor: the
// protocol's second at 300 baud, 30 ms (the floor) at 9600 and 115200.
TEST(XmodemConfig, CharacterTimeoutAndPurgeQuietFollowTheLineRateWithAFloor)
{
  Config fast;
  fitToLine(fast, 11520);  // 115200 8N1: 30 characters take 2.6 ms, below the floor
  EXPECT_EQ(fast.char_timeout, Milliseconds(30));
  EXPECT_EQ(fast.purge_quiet, Milliseconds(30));
  Config slow;
  fitToLine(slow, 30);  // 300 baud 8N1
  EXPECT_EQ(slow.char_timeout, Milliseconds(1000));
  EXPECT_EQ(slow.purge_quiet, Milliseconds(1000));
  Config mid;
  fitToLine(mid, 120);  // 1200 baud 8N1: 30 characters take 250 ms
  EXPECT_EQ(mid.char_timeout, Milliseconds(250));
  Config tuned;
  tuned.wait_characters = 100;
  tuned.wait_floor = Milliseconds(5);
  fitToLine(tuned, 11520);  // 100 characters: 8.7 ms
  EXPECT_EQ(tuned.char_timeout, Milliseconds(9));
  Config unknown;
  fitToLine(unknown, 0);  // no line rate: the protocol's values stay
  EXPECT_EQ(unknown.char_timeout, Config().char_timeout);
  EXPECT_EQ(unknown.purge_quiet, Config().purge_quiet);
}

// A reply damaged on the line (neither ACK, NAK nor CAN) is answered with the block again, not
// with a wait for the ACK timeout; a doubled ACK is not taken as the next block's ACK.
TEST(XmodemSender, ADamagedReplyResendsTheBlockAndADoubledAckIsNotTheNextBlocks)
{
  FakeTransport rx;
  rx.feed(Bytes{kNak});
  const Bytes damaged_ack{kAck ^ 0x80};
  answerEachWriteWith(rx, {damaged_ack, Bytes{kAck, kAck}, Bytes{kNak}, Bytes{kAck}, Bytes{kAck}});
  Config config = fastConfig();
  config.ack_timeout = Milliseconds(5000);  // a wait for it would show in stats.timeouts
  Sender sender(rx, Mode::kChecksum, config);
  const Stats stats = sender.send(Bytes(200, 'D'));
  EXPECT_EQ(stats.timeouts, 0u);
  EXPECT_EQ(stats.retries, 2u);  // block 1 after the damaged ACK, block 2 after its NAK
  const Bytes written = rx.written();
  ASSERT_EQ(written.size(), 4 * 132 + 1u) << "a block went too few or too many times";
  EXPECT_EQ(written[1], 1);
  EXPECT_EQ(written[132 + 1], 1);
  EXPECT_EQ(written[2 * 132 + 1], 2);
  EXPECT_EQ(written[3 * 132 + 1], 2) << "the second ACK was taken as block 2's";
  EXPECT_EQ(written.back(), kEot);
}

// A CRC receiver that got block 1 damaged asks again with 'C' (it has no block to NAK yet): block 1
// goes again at once, not after the ACK timeout.
TEST(XmodemSender, ACAfterBlockOneResendsItWithoutWaitingForTheTimeout)
{
  FakeTransport rx;
  rx.feed(Bytes{kCrcStart});
  answerEachWriteWith(rx, {Bytes{kCrcStart}, Bytes{kAck}, Bytes{kAck}});
  Config config = fastConfig();
  config.ack_timeout = Milliseconds(5000);
  Sender sender(rx, Mode::kCrc, config);
  const Stats stats = sender.send(Bytes(100, 'E'));
  EXPECT_EQ(stats.timeouts, 0u);
  EXPECT_EQ(stats.retries, 1u);
  EXPECT_EQ(rx.written().size(), 2 * 133 + 1u);
}

// A byte doubled inside a checksum packet shifts it by one; with these data the shifted packet's
// check passes (its last data byte equals the sum of the others), and the real check byte follows.
// Once the line has shown damage, such a packet is NAKed, not stored.
TEST(XmodemReceiver, APacketFollowedAtOnceByMoreBytesIsNakedOnceTheLineShowedDamage)
{
  Bytes data(127, 'A');
  data.push_back(0x80);  // 128 x 'A' sum to 0x80
  const Bytes good = encodePacket(1, data.data(), data.size(), kBlockSize, CheckType::kChecksum);
  Bytes shifted = good;
  shifted.insert(shifted.begin() + 3, 'A');  // the first data byte doubled: 133 bytes
  ASSERT_EQ(decodePacket(shifted.data(), 132, CheckType::kChecksum).status, PacketStatus::kOk);
  Bytes garbled = good;
  garbled[40] ^= 0x04;
  FakeTransport tx;
  answerEachWriteWith(tx, {garbled, shifted, good, Bytes{kEot}});
  Receiver receiver(tx, Mode::kChecksum, fastConfig());
  EXPECT_EQ(receiver.receive(), data);
  EXPECT_EQ(receiver.stats().garbled, 2u);
  EXPECT_EQ(tx.written(), (Bytes{kNak, kNak, kNak, kAck, kAck}));
}

// The noisy wire of bench/xmodem (a byte in 500 flipped, in 1000 lost, in 2000 doubled, both
// directions) with the waits cnc_dnc uses at 115200: a 16 KB program arrives exact.
TEST(XmodemFaults, ASixteenKilobyteProgramCrossesTheNoisyWireExactWithTheLineWaits)
{
  TempDir dir("test_xmodem");
  const std::string program = ncProgram(16384, 3);
  writeFile(dir.path + "/source", program);
  Config config;
  fitToLine(config, 11520);
  config.block_timeout = Milliseconds(1000);  // cnc_dnc receive --block-timeout
  config.start_timeout = config.start_wait = Milliseconds(10000);
  config.nak_interval = Milliseconds(3000);
  FaultSettings faults;
  faults.flip = 0.002;
  faults.drop = 0.001;
  faults.duplicate = 0.0005;
  faults.seed = 11;
  LinkPair pair;
  FaultyTransport sender_side(pair.a, faults);
  faults.seed = 12;
  FaultyTransport receiver_side(pair.b, faults);
  config.eot_timeout = Milliseconds(500);  // the receiver has returned when its ACK of EOT is lost
  config.eot_retries = 2;
  Stats sender_stats;
  auto sent = std::async(std::launch::async,
                         [&]() -> std::string
                         {
                           try
                           {
                             sendFile(sender_side, dir.path + "/source", Mode::kCrc, config, TextOptions(), nullptr,
                                      nullptr, &sender_stats);
                             return "";
                           }
                           catch (const Error& e)
                           {
                             return e.what();
                           }
                         });
  const FileResult received = receiveFile(receiver_side, dir.path + "/received", Mode::kCrc, config, TextOptions());
  const std::string sender_error = sent.get();
  // Every block was acknowledged; only the ACK of EOT may have been lost on the wire.
  EXPECT_TRUE(sender_error.empty() || sender_error.find("every block was acknowledged") != std::string::npos)
      << sender_error;
  EXPECT_EQ(readFile(dir.path + "/received"), program);
  const FaultCounts a = sender_side.counts(), b = receiver_side.counts();
  EXPECT_GT(a.flipped + a.dropped + a.duplicated, 20u) << "the wire was not noisy";
  EXPECT_GT(received.stats.retries, 20u);
  EXPECT_EQ(sender_stats.blocks, received.stats.blocks);
  std::cout << "noisy wire: " << received.stats.retries << " retries, faults sender side "
            << a.flipped + a.dropped + a.duplicated << ", receiver side " << b.flipped + b.dropped + b.duplicated
            << "\n";
}

TEST(XmodemReceiver, StopsOnTwoCansAndWhenTheSenderNeverStarts)
{
  FakeTransport tx;
  tx.onWrite([](FakeTransport& t, const Bytes&) { t.feed(Bytes{kCan, kCan}); });
  EXPECT_THROW(Receiver(tx, Mode::kChecksum, fastConfig()).receive(), ProtocolError);

  FakeTransport silent;
  Config config = fastConfig();
  config.nak_interval = Milliseconds(5);
  config.start_timeout = Milliseconds(40);
  EXPECT_THROW(Receiver(silent, Mode::kChecksum, config).receive(), TimeoutError);
  const Bytes written = silent.written();
  EXPECT_GE(written.size(), 2u + 3u);  // NAKs repeated every nak_interval, then CANs
  EXPECT_EQ(written.front(), kNak);
}

TEST(XmodemReceiver, CancelFromAnotherThreadSendsCanAndLeavesNoFile)
{
  TempDir dir("test_xmodem");
  const std::string target = dir.path + "/O1000.nc";
  writeFile(target, "previous version\n");
  FakeTransport tx;
  std::atomic<bool> cancel{false};
  tx.onWrite(
      [](FakeTransport& t, const Bytes& bytes)
      {
        if (bytes[0] == kNak || bytes[0] == kAck)
          t.feed(encodePacket(1, Bytes(128, 'c').data(), 128, kBlockSize, CheckType::kChecksum));
      });
  std::promise<void> got_block;
  bool told = false;
  auto result = std::async(std::launch::async,
                           [&]
                           {
                             return receiveFile(
                                 tx, target, Mode::kChecksum, Config(), TextOptions(),
                                 [&](const Progress&)
                                 {
                                   if (!told)
                                   {
                                     told = true;
                                     got_block.set_value();
                                   }
                                 },
                                 &cancel);
                           });
  got_block.get_future().wait();
  cancel = true;
  tx.interrupt();
  EXPECT_THROW(result.get(), CancelledError);
  const Bytes written = tx.written();
  EXPECT_EQ(Bytes(written.end() - 3, written.end()), (Bytes{kCan, kCan, kCan}));
  EXPECT_EQ(readFile(target), "previous version\n");
  EXPECT_EQ(filesIn(dir.path), 1u);  // no temporary file left behind
}

TEST(XmodemSender, CancelFromAnotherThreadSendsCan)
{
  FakeTransport rx;
  rx.feed(Bytes{kNak});
  std::atomic<bool> cancel{false};
  auto result = std::async(std::launch::async,
                           [&]
                           {
                             Sender sender(rx, Mode::kChecksum, Config(),
                                           &cancel);  // default 10 s ACK wait: only a cancel ends it
                             return sender.send(Bytes(1000, 's'));
                           });
  ASSERT_TRUE(rx.waitForWritten(132, Milliseconds(5000)));
  cancel = true;
  rx.interrupt();
  EXPECT_THROW(result.get(), CancelledError);
  const Bytes written = rx.written();
  EXPECT_EQ(Bytes(written.end() - 3, written.end()), (Bytes{kCan, kCan, kCan}));
}

// ---------------------------------------------------------------------------------------------
// Bulk reads: the sessions read whatever has arrived (up to one packet) into a buffer. Packets
// split over many reads and several packets in one read must give the same bytes and replies.
namespace
{
/// A FakeTransport that counts the read() calls made on it.
class CountingTransport : public FakeTransport
{
 public:
  size_t read(uint8_t* buffer, size_t size, Milliseconds timeout) override
  {
    ++reads;
    return FakeTransport::read(buffer, size, timeout);
  }
  size_t reads = 0;
};

/// \p payload as packets of \p block_size numbered from \p first_block, one after another.
Bytes packetsOf(const Bytes& payload, size_t block_size, CheckType check, uint32_t first_block = 1)
{
  Bytes out;
  for (size_t offset = 0, block = first_block; offset < payload.size(); offset += block_size, ++block)
  {
    const size_t n = std::min(block_size, payload.size() - offset);
    const Bytes packet = encodePacket(static_cast<uint32_t>(block), payload.data() + offset, n, block_size, check);
    out.insert(out.end(), packet.begin(), packet.end());
  }
  return out;
}
}  // namespace

TEST(BufferedInput, PurgeAndDiscardDropBufferedBytesToo)
{
  FakeTransport link;
  BufferedInput input(link, 8);
  link.feed("abcdefghij");
  EXPECT_EQ(input.readByte(Milliseconds(100)), 'a');
  EXPECT_EQ(input.buffered(), 7u);  // one read took what fits, the rest is still in the link
  EXPECT_EQ(input.purge(Milliseconds(5)), 9u);
  EXPECT_EQ(input.readByte(Milliseconds(5)), -1);
  link.feed("xyz");
  EXPECT_EQ(input.readByte(Milliseconds(100)), 'x');
  input.discard();
  EXPECT_EQ(input.buffered(), 0u);
  EXPECT_EQ(input.readByte(Milliseconds(5)), -1);
}

TEST(BufferedInput, ReadExactlyJoinsPiecesAndStopsAtATimeout)
{
  FakeTransport link;
  link.setMaxReadChunk(3);
  BufferedInput input(link, 16);
  link.feed("0123456789");
  uint8_t out[16] = {};
  EXPECT_EQ(input.readExactly(out, 7, Milliseconds(100)), 7u);
  EXPECT_EQ(std::string(out, out + 7), "0123456");
  EXPECT_EQ(input.readByte(Milliseconds(100)), '7');
  EXPECT_EQ(input.readExactly(out, 5, Milliseconds(20)), 2u);  // "89", then nothing more came
  EXPECT_EQ(std::string(out, out + 2), "89");
}

TEST(XmodemReceiver, PacketsSplitOverManyReadsAreReassembled)
{
  const Bytes payload = randomBytes(3 * 1024 + 2 * 128, 11);
  for (const size_t chunk : {size_t(1), size_t(7), size_t(1000)})
  {
    FakeTransport tx;
    tx.setMaxReadChunk(chunk);
    // Three 1K packets, then two 128-byte ones (a receiver accepts mixed sizes), then EOT.
    const Bytes head(payload.begin(), payload.begin() + 3 * 1024);
    const Bytes tail(payload.begin() + 3 * 1024, payload.end());
    Bytes packets = packetsOf(head, kBlockSize1K, CheckType::kCrc16);
    const Bytes small = packetsOf(tail, kBlockSize, CheckType::kCrc16, 4);
    packets.insert(packets.end(), small.begin(), small.end());
    std::vector<Bytes> script;
    for (size_t at = 0, size; at < packets.size(); at += size)
    {
      size = packets[at] == kStx ? 1029 : 133;
      script.emplace_back(packets.begin() + at, packets.begin() + at + size);
    }
    script.push_back({kEot});
    answerEachWriteWith(tx, script);
    Receiver receiver(tx, Mode::kCrc, fastConfig());
    EXPECT_EQ(receiver.receive(), payload) << "read chunk " << chunk;
    EXPECT_EQ(receiver.stats().garbled, 0u) << "read chunk " << chunk;
    EXPECT_EQ(tx.written(), (Bytes{'C', kAck, kAck, kAck, kAck, kAck, kAck})) << "read chunk " << chunk;
  }
}

TEST(XmodemReceiver, SeveralPacketsInOneReadAreAllTaken)
{
  // A sender that does not wait for ACKs: every packet and the EOT are there before the first read.
  CountingTransport tx;
  const Bytes payload = randomBytes(3 * 128, 12);
  Bytes everything = packetsOf(payload, kBlockSize, CheckType::kChecksum);
  everything.push_back(kEot);
  tx.feed(everything);
  Receiver receiver(tx, Mode::kChecksum, fastConfig());
  EXPECT_EQ(receiver.receive(), payload);
  EXPECT_EQ(tx.written(), (Bytes{kNak, kAck, kAck, kAck, kAck}));
  // One read took all three packets and the EOT; the second is the silence that confirms the EOT.
  EXPECT_EQ(tx.reads, 2u);
}

TEST(XmodemSender, RepliesQueuedBehindAnAckAreNotTakenForLaterBlocks)
{
  // A stop-and-wait receiver answers one packet at a time: whatever arrives with an ACK (a doubled
  // ACK, noise) cannot answer a block not yet sent. Taken for the next blocks' ACKs, it would put
  // the sender ahead of the receiver, and the next NAK would be read as the wrong block's.
  FakeTransport rx;
  const Bytes payload = randomBytes(3 * 128, 13);
  size_t packets = 0;
  rx.onWrite(
      [&](FakeTransport& t, const Bytes& bytes)
      {
        ++packets;
        if (packets == 1)
          t.feed(Bytes{kAck, 'x', kAck, 'y', kAck});  // block 1's ACK, then a burst of stale bytes
        else if (packets == 2)
          t.feed(Bytes{kNak});  // block 2 arrived damaged
        else
          t.feed(Bytes{kAck});
        (void)bytes;
      });
  rx.feed(Bytes{kNak});
  Config config = fastConfig();
  config.ack_timeout = Milliseconds(5000);
  Sender sender(rx, Mode::kChecksum, config);
  const Stats stats = sender.send(payload);
  EXPECT_EQ(stats.blocks, 3u);
  EXPECT_EQ(stats.retries, 1u);
  EXPECT_EQ(stats.timeouts, 0u);
  const Bytes written = rx.written();
  ASSERT_EQ(written.size(), 4 * 132 + 1u);
  EXPECT_EQ(written[132 + 1], 2);
  EXPECT_EQ(written[2 * 132 + 1], 2) << "block 2 was not sent again after its NAK";
  EXPECT_EQ(written[3 * 132 + 1], 3);
}

// ---------------------------------------------------------------------------------------------
struct PairCase
{
  Mode send_mode;
  Mode receive_mode;
  size_t size;
};

class XmodemPair : public ::testing::TestWithParam<PairCase>
{
};

TEST_P(XmodemPair, MovesTheExactBytes)
{
  const PairCase c = GetParam();
  LinkPair link;
  const Bytes payload = randomBytes(c.size, static_cast<uint32_t>(c.size));
  auto sent = std::async(std::launch::async, [&] { return Sender(link.a, c.send_mode, fastConfig()).send(payload); });
  Receiver receiver(link.b, c.receive_mode, fastConfig());
  Bytes got = receiver.receive();
  const Stats stats = sent.get();
  stripSubPadding(got);
  EXPECT_EQ(got, payload);
  EXPECT_EQ(stats.bytes, c.size);
  EXPECT_EQ(stats.check, c.receive_mode == Mode::kChecksum ? CheckType::kChecksum : CheckType::kCrc16);
  EXPECT_EQ(stats.retries, 0u);
}

INSTANTIATE_TEST_SUITE_P(Sizes, XmodemPair,
                         ::testing::Values(PairCase{Mode::kChecksum, Mode::kChecksum, 0},
                                           PairCase{Mode::kChecksum, Mode::kChecksum, 1},
                                           PairCase{Mode::kChecksum, Mode::kChecksum, 127},
                                           PairCase{Mode::kCrc, Mode::kCrc, 128}, PairCase{Mode::kCrc, Mode::kCrc, 129},
                                           PairCase{Mode::k1K, Mode::kCrc, 1024}, PairCase{Mode::k1K, Mode::kCrc, 1025},
                                           PairCase{Mode::k1K, Mode::kChecksum, 5000},
                                           PairCase{Mode::k1K, Mode::kCrc, 1 << 20}));

// ---------------------------------------------------------------------------------------------
// Fault injection: every transfer either delivers the exact file or fails with an error and leaves
// no file (and no temporary file) behind, and the sender never reports success for a transfer the
// receiver did not complete (it may report failure where the receiver succeeded: the last ACK was
// lost). CRC mode with every fault kind; checksum mode without duplicated bytes, because an 8-bit
// sum misses a shifted packet 1 time in 256 (a limit of the protocol, not of this code: a Haas line
// should be clean).
namespace
{
struct Campaign
{
  int transfers = 0;
  int delivered = 0;
  int failed = 0;
  int sender_succeeded = 0;
  int eot_answered_with_can = 0;
  uint64_t faults = 0;
};

/// \p haas: the receiver answers EOT with CAN CAN CAN as the control does, checksum mode only, and
/// the sender takes that answer as complete. Otherwise the receiver ACKs EOT and the sender's
/// Config::eot_can_completes alternates (a CAN after EOT from this receiver is always an abort).
Campaign faultCampaign(const std::string& dir, int transfers, uint32_t seed_base, bool haas)
{
  Config config = fastConfig();
  config.nak_interval = Milliseconds(25);
  config.block_timeout = Milliseconds(30);
  config.ack_timeout = Milliseconds(30);
  config.eot_timeout = Milliseconds(30);
  config.char_timeout = Milliseconds(10);
  config.purge_quiet = Milliseconds(5);
  config.eot_quiet = Milliseconds(5);
  config.stale_nak_settle = Milliseconds(5);
  config.turnaround = Milliseconds(1);
  config.start_wait = Milliseconds(500);
  config.start_timeout = Milliseconds(500);
  config.eot_retries = 4;

  Campaign result;
  result.transfers = transfers;
  for (int i = 0; i < transfers; ++i)
  {
    const bool crc = !haas && i % 3 != 0;
    FaultSettings settings;
    settings.seed = seed_base + i;
    settings.flip = 0.0006;
    settings.drop = 0.0006;
    settings.duplicate = crc ? 0.0004 : 0.0;
    settings.lose_write = 0.01;
    LinkPair pair;
    FaultyTransport sender_side(pair.a, settings);
    settings.seed += 50000;
    FaultyTransport receiver_side(pair.b, settings);
    const std::string contents = ncProgram(200 + (i * 37) % 1500, i);
    const std::string source = dir + "/source_" + std::to_string(i);
    writeFile(source, contents);
    const std::string target = dir + "/received_" + std::to_string(i);
    TextOptions options;
    options.binary = false;
    const Mode mode = crc ? (i % 2 ? Mode::k1K : Mode::kCrc) : Mode::kChecksum;
    Config sender_config = config;
    sender_config.eot_can_completes = haas || i % 2 == 0;
    Config receiver_config = config;
    receiver_config.answer_eot_with_can = haas;
    // The sender's verdict: "" for success, else its error.
    bool can_answer = false;
    auto sent = std::async(
        std::launch::async,
        [&]() -> std::string
        {
          try
          {
            can_answer = sendFile(sender_side, source, mode, sender_config, options).stats.eot_answered_with_can;
            return "";
          }
          catch (const Error& e)
          {
            return e.what();
          }
        });
    bool received = false;
    try
    {
      receiveFile(receiver_side, target, crc ? Mode::kCrc : Mode::kChecksum, receiver_config, options);
      EXPECT_EQ(readFile(target), contents) << "transfer " << i << " delivered a wrong file";
      received = true;
      ++result.delivered;
    }
    catch (const Error& e)
    {
      EXPECT_FALSE(exists(target)) << "transfer " << i << " failed but left " << target;
      EXPECT_GT(std::string(e.what()).size(), 20u);
      ++result.failed;
    }
    const std::string sender_error = sent.get();
    if (sender_error.empty())
    {
      ++result.sender_succeeded;
      result.eot_answered_with_can += can_answer;
      EXPECT_TRUE(received) << "transfer " << i << ": the sender reported success but the receiver failed";
    }
    else
    {
      EXPECT_GT(sender_error.size(), 20u);
    }
    const FaultCounts a = sender_side.counts(), b = receiver_side.counts();
    result.faults +=
        a.flipped + a.dropped + a.duplicated + a.lost_writes + b.flipped + b.dropped + b.duplicated + b.lost_writes;
  }
  std::cout << "fault injection" << (haas ? " (Haas answer to EOT)" : "") << ": " << result.delivered << " delivered, "
            << result.failed << " failed cleanly, " << result.faults << " faults injected; the sender reported "
            << result.sender_succeeded << " successes\n";
  return result;
}
}  // namespace

TEST(XmodemFaults, EveryTransferIsExactOrAClearErrorWithNoFile)
{
  TempDir dir("test_xmodem");
  const Campaign c = faultCampaign(dir.path, 220, 1000, false);
  // Only sources and delivered files remain: no temporary file of a failed transfer.
  EXPECT_EQ(filesIn(dir.path), static_cast<size_t>(c.transfers + c.delivered));
  EXPECT_EQ(c.delivered + c.failed, c.transfers);
  EXPECT_GT(c.faults, 200u);                // the link really was damaged
  EXPECT_GT(c.delivered, c.transfers / 2);  // and XModem repaired most of it
  EXPECT_GT(c.sender_succeeded, c.transfers / 2);
  EXPECT_EQ(c.eot_answered_with_can, 0);  // this receiver ACKs EOT
}

// The Haas path: the control answers EOT with CAN CAN CAN, the sender takes that as complete. A
// receiver that aborts near the end (too many errors, a block out of step) must still fail the send.
TEST(XmodemFaults, HaasAnswerToEotNeverHidesAFailedReceive)
{
  TempDir dir("test_xmodem");
  const Campaign c = faultCampaign(dir.path, 80, 7000, true);
  EXPECT_EQ(filesIn(dir.path), static_cast<size_t>(c.transfers + c.delivered));
  EXPECT_EQ(c.delivered + c.failed, c.transfers);
  EXPECT_GT(c.faults, 60u);
  EXPECT_GT(c.delivered, c.transfers / 2);
  EXPECT_GT(c.eot_answered_with_can, c.transfers / 2);
}

TEST(FaultyTransport, ParsesSettingsAndInjectsReproducibly)
{
  const FaultSettings s = FaultSettings::parse("flip=0.5,drop=0.1,dup=0.1,lose=0,seed=9,read=1");
  EXPECT_DOUBLE_EQ(s.flip, 0.5);
  EXPECT_TRUE(s.on_read);
  EXPECT_EQ(s.seed, 9u);
  EXPECT_THROW(FaultSettings::parse("flip=2"), ConfigError);
  EXPECT_THROW(FaultSettings::parse("zap=0.1"), ConfigError);
  Bytes outputs[2];
  for (auto& out : outputs)
  {
    FakeTransport inner;
    FaultSettings w = s;
    w.on_read = false;
    FaultyTransport faulty(inner, w);
    faulty.write(Bytes(1000, 0x55));
    out = inner.written();
    EXPECT_GT(faulty.counts().flipped, 100u);
  }
  EXPECT_EQ(outputs[0], outputs[1]);
  EXPECT_NE(outputs[0], Bytes(1000, 0x55));
}

// The ACK of EOT may arrive while the port still counts output as pending (lrzsz rx on a pty: it
// read the EOT, ACKed it and left). It answers the EOT (no data packet is outstanding), so the
// transfer is complete; dropping it as a stale ACK failed complete transfers ("every block was
// acknowledged but EOT was not").
TEST(XmodemSender, TheAckOfEotCountsWhileThePortStillReportsOutputPending)
{
  class OutputStillQueuedAfterEot : public FakeTransport
  {
   public:
    std::atomic<bool> eot_written{false};
    size_t pendingOutput() const override { return eot_written ? 1 : 0; }
  };
  OutputStillQueuedAfterEot rx;
  rx.feed(Bytes{kNak});
  rx.onWrite(
      [&rx](FakeTransport& t, const Bytes& bytes)
      {
        if (bytes.size() == 1 && bytes[0] == kEot)
          rx.eot_written = true;  // before the ACK is fed: the sender sees output pending with it
        t.feed(Bytes{kAck});
      });
  Config config = fastConfig();
  config.eot_retries = 3;
  Sender sender(rx, Mode::kChecksum, config);
  const Stats stats = sender.send(Bytes(1025, 'A'));
  EXPECT_EQ(stats.blocks, 9u);
  EXPECT_EQ(stats.timeouts, 0u);
  const Bytes written = rx.written();
  EXPECT_EQ(written.size(), 9 * 132 + 1u);  // one EOT, answered at once
  EXPECT_EQ(written.back(), kEot);
}

// A receiver that ACKs every block and then leaves (lrzsz rx flushing its tty as it exits loses
// its ACK of EOT): the payload is all there, so the transfer completes, and its summary says the
// end went unconfirmed. A receiver still there that NAKs the EOT, or the option off, still fails.
TEST(XmodemSender, SilenceAfterEveryBlockWasAckedCompletesWithTheEndUnconfirmed)
{
  const auto receiver = [](Bytes answer_to_eot)
  {
    auto rx = std::make_unique<FakeTransport>();
    rx->feed(Bytes{kNak});
    rx->onWrite(
        [answer_to_eot](FakeTransport& t, const Bytes& bytes)
        {
          if (bytes.size() == 1 && bytes[0] == kEot)
            t.feed(answer_to_eot);  // nothing: the receiver has left
          else
            t.feed(Bytes{kAck});
        });
    return rx;
  };
  Config config = fastConfig();
  config.eot_retries = 3;
  config.eot_timeout = Milliseconds(100);
  auto gone = receiver({});
  Sender sender(*gone, Mode::kChecksum, config);
  const Stats stats = sender.send(Bytes(1025, 'A'));
  EXPECT_EQ(stats.blocks, 9u);
  EXPECT_EQ(stats.eot_unanswered, 3u);
  EXPECT_NE(stats.summary().find("every block was acknowledged but the end was not (EOT sent 3 times, no answer)"),
            std::string::npos)
      << stats.summary();
  const Bytes written = gone->written();
  EXPECT_EQ(written.size(), 9 * 132 + 3u);
  EXPECT_EQ(written.back(), kEot);

  auto naks = receiver(Bytes{kNak});
  Sender refused(*naks, Mode::kChecksum, config);
  EXPECT_THROW(refused.send(Bytes(1025, 'A')), TimeoutError);

  config.eot_silence_completes = false;
  auto gone_again = receiver({});
  Sender strict(*gone_again, Mode::kChecksum, config);
  EXPECT_THROW(strict.send(Bytes(1025, 'A')), TimeoutError);

  // Even when one EOT is all it may send, the sender sends a second before it takes silence for
  // a receiver that has left: the first may have been lost.
  config.eot_silence_completes = true;
  config.eot_retries = 1;
  auto gone_at_once = receiver({});
  Sender once(*gone_at_once, Mode::kChecksum, config);
  EXPECT_EQ(once.send(Bytes(1025, 'A')).eot_unanswered, 2u);
  EXPECT_EQ(gone_at_once->written().size(), 9 * 132 + 2u);
}

// lrzsz rx flushes its input right after it ACKs the last block: an EOT that crosses that flush is
// lost, and rx waits on for it (5 s, then NAKs until it gives up and deletes the file). A sender
// allowed a single EOT that took the silence for the end fooled itself; it asks again and is answered.
TEST(XmodemSender, AnEotLostToTheReceiversFlushIsSentAgainAndAnswered)
{
  FakeTransport rx;
  rx.feed(Bytes{kNak});
  int eots = 0;
  rx.onWrite(
      [&eots](FakeTransport& t, const Bytes& bytes)
      {
        if (bytes.size() == 1 && bytes[0] == kEot)
        {
          if (++eots == 2)
            t.feed(Bytes{kAck});  // the first was flushed away unread
        }
        else
          t.feed(Bytes{kAck});
      });
  Config config = fastConfig();
  config.eot_retries = 1;
  config.eot_timeout = Milliseconds(100);
  Sender sender(rx, Mode::kChecksum, config);
  const Stats stats = sender.send(Bytes(1025, 'A'));
  EXPECT_EQ(stats.blocks, 9u);
  EXPECT_EQ(eots, 2);
  EXPECT_EQ(stats.eot_unanswered, 0u) << "the second EOT was answered: the end is confirmed";
  EXPECT_EQ(stats.summary().find("the end was not"), std::string::npos) << stats.summary();
}

// XModem has no length field: a sender that goes on past Config::max_bytes is cancelled with CANs,
// nothing is stored, and the error names the setting.
TEST(XmodemReceiver, ASenderGoingPastMaxBytesIsCancelledAndNothingIsStored)
{
  TempDir dir("test_xmodem");
  writeFile(dir.path + "/source", ncProgram(64 * 1024, 5));
  LinkPair pair;
  Config config = fastConfig();
  config.max_bytes = 4096;
  config.max_bytes_name = "~max_program_bytes";
  Config sender_config = fastConfig();
  sender_config.max_bytes = 1024 * 1024;
  auto sent = std::async(std::launch::async,
                         [&]() -> std::string
                         {
                           try
                           {
                             sendFile(pair.a, dir.path + "/source", Mode::kChecksum, sender_config, TextOptions());
                             return "";
                           }
                           catch (const Error& e)
                           {
                             return e.what();
                           }
                         });
  const std::string target = dir.path + "/in/O01234.nc";
  ::mkdir((dir.path + "/in").c_str(), 0700);
  try
  {
    receiveFile(pair.b, target, Mode::kChecksum, config, TextOptions());
    FAIL() << "a 64 KB program was taken with a 4 KB cap";
  }
  catch (const ProtocolError& e)
  {
    EXPECT_NE(std::string(e.what()).find("~max_program_bytes (4096 bytes)"), std::string::npos) << e.what();
  }
  const std::string sender_error = sent.get();
  EXPECT_NE(sender_error.find("cancelled"), std::string::npos) << sender_error;  // CAN CAN reached it
  EXPECT_EQ(filesIn(dir.path + "/in"), 0u);                                      // no file, no temporary file

  // A file larger than the cap is not sent: the receiver sees nothing.
  FakeTransport rx;
  rx.feed(Bytes{kNak});
  try
  {
    sendFile(rx, dir.path + "/source", Mode::kChecksum, config, TextOptions());
    FAIL();
  }
  catch (const ConfigError& e)
  {
    EXPECT_NE(std::string(e.what()).find("~max_program_bytes"), std::string::npos) << e.what();
  }
  EXPECT_TRUE(rx.written().empty());
}

// Only a regular file is sent: a FIFO is refused at once (it would block the open or the read)
// and nothing goes on the line; the contents check runs on the bytes that are then sent.
TEST(XmodemFile, OnlyARegularFileIsSentAndTheCheckSeesTheBytesSent)
{
  TempDir dir("test_xmodem");
  ASSERT_EQ(::mkfifo((dir.path + "/fifo.nc").c_str(), 0600), 0);
  FakeTransport rx;
  rx.feed(Bytes{kNak});
  try
  {
    sendFile(rx, dir.path + "/fifo.nc", Mode::kChecksum, fastConfig(), TextOptions());
    FAIL();
  }
  catch (const ConfigError& e)
  {
    EXPECT_NE(std::string(e.what()).find("is a FIFO"), std::string::npos) << e.what();
  }
  EXPECT_THROW(sendFile(rx, dir.path, Mode::kChecksum, fastConfig(), TextOptions()), ConfigError);
  EXPECT_TRUE(rx.written().empty());

  writeFile(dir.path + "/O00001.nc", "%\n(NOTE)\nO09010\nM99\n%\n");
  std::string checked;
  EXPECT_THROW(
      sendFile(rx, dir.path + "/O00001.nc", Mode::kChecksum, fastConfig(), TextOptions(), nullptr, nullptr, nullptr,
               [&checked](const std::string& contents)
               {
                 checked = contents;
                 throw DisabledError("refused: protected");
               }),
      DisabledError);
  EXPECT_EQ(checked, "%\n(NOTE)\nO09010\nM99\n%\n");
  EXPECT_TRUE(rx.written().empty());
}
