// XModem against independent implementations over a pty pair: lrzsz (`sx`, `sx -k`, `rx`, `rx -c`)
// and the python3-xmodem package (test/data/xmodem/pyxmodem_peer.py), in both directions, files of
// 0, 1, 127, 128, 129, 1024, 1025 bytes and 1 MB. The peer runs as a child process with its
// stdin/stdout (or its device argument) on the pty slave; this process is the other end on the
// master. The cnc_dnc tool itself against lrzsz, both ways (rx started before cnc_dnc send, sx
// into cnc_dnc receive), is in test_xmodem_cli.cpp.
#include <fcntl.h>
#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <poll.h>

#include <condition_variable>
#include <fstream>
#include <future>
#include <memory>
#include <mutex>
#include <random>
#include <thread>

#include "cnc_bridge/common/error.h"
#include "cnc_bridge/transport/forwarding_transport.h"
#include "cnc_bridge/transport/serial_port.h"
#include "cnc_bridge/xmodem/file_transfer.h"
#include "cnc_bridge/xmodem/session.h"
#include "peer_process.h"
#include "temp_dir.h"
#include "testing/pty.h"

using namespace cnc_bridge;
using cnc_bridge::test::Peer;
using cnc_bridge::test::TempDir;
using namespace cnc_bridge::xmodem;

namespace
{
using Bytes = std::vector<uint8_t>;

Bytes randomBytes(size_t n, uint32_t seed)
{
  std::mt19937 random(seed);
  Bytes out(n);
  for (auto& b : out)
    b = static_cast<uint8_t>(random());
  if (!out.empty() && out.back() == kSub)
    out.back() = 'x';
  return out;
}

void writeFile(const std::string& path, const Bytes& data)
{
  std::ofstream(path, std::ios::binary).write(reinterpret_cast<const char*>(data.data()), data.size());
}

Bytes readFile(const std::string& path)
{
  std::ifstream in(path, std::ios::binary);
  return Bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}

/// What a padding-keeping receiver wrote: the payload byte for byte, then SUB up to the end of its
/// last block. \p last_block: the size of the last block (our sender sends a short tail in a
/// 128-byte block; a peer sender may use 1K blocks to the end).
void expectPaddedCopy(const Bytes& got, const Bytes& payload, size_t last_block = kBlockSize)
{
  ASSERT_GE(got.size(), payload.size());
  EXPECT_TRUE(std::equal(payload.begin(), payload.end(), got.begin())) << "data differs";
  EXPECT_LT(got.size() - payload.size(), last_block) << "more padding than one block";
  EXPECT_EQ(got.size() % kBlockSize, 0u) << "not whole blocks: " << got.size() << " bytes";
  EXPECT_TRUE(std::all_of(got.begin() + payload.size(), got.end(), [](uint8_t b) { return b == kSub; }));
}

const std::string kPython = std::string(XMODEM_TEST_DATA) + "/pyxmodem_peer.py";
const std::vector<size_t> kSizes = {0, 1, 127, 128, 129, 1024, 1025};
constexpr size_t kLarge = 1 << 20;

TextOptions binary()
{
  TextOptions t;
  t.binary = true;
  return t;
}

/// Our sender to a peer receiver.
void sendTo(const std::vector<std::string>& peer_argv, bool peer_on_stdio, Mode mode, size_t size, bool expect_1k)
{
  TempDir dir("test_xmodem_interop");
  PtyMaster pty;
  const Bytes payload = randomBytes(size, static_cast<uint32_t>(size + 1));
  std::vector<std::string> argv = peer_argv;
  if (!peer_on_stdio)
    argv.push_back(pty.slavePath());
  argv.push_back(dir.path + "/received");
  Peer peer(argv, dir.path, peer_on_stdio ? pty.slavePath() : "");
  Config config;
  config.eot_timeout = Milliseconds(1500);  // rx answers EOT after 1 s of silence
  // rx writes NAK and then flushes its tty input; a packet that crosses before that flush is lost.
  // A generous quiet time before answering keeps this deterministic on a loaded machine.
  config.turnaround = Milliseconds(250);
  config.ack_turnaround = Milliseconds(5);  // rx flushes its input after every ACK as well
  config.eot_retries = 1;
  Sender sender(pty, mode, config);
  const bool lrzsz = argv[0] == "/usr/bin/rx";
  // Complete, always: lrzsz `rx` writes its ACK of EOT and at once flushes its tty (TCIOFLUSH) as
  // it exits, so on a pty that ACK is often thrown away before it crosses; every block was ACKed,
  // so the sender completes and says the end went unconfirmed. Only rx may leave it unconfirmed.
  const Stats stats = sender.send(payload);
  EXPECT_EQ(stats.bytes, payload.size());
  if (!lrzsz)
    EXPECT_EQ(stats.eot_unanswered, 0u) << argv[0] << " answers EOT";
  ASSERT_EQ(peer.wait(), 0) << argv[0] << " failed";
  expectPaddedCopy(readFile(dir.path + "/received"), payload);
  EXPECT_EQ(sender.stats().used_1k, expect_1k && size > 7 * 128);
}

/// A peer sender to our receiver.
void receiveFrom(const std::vector<std::string>& peer_argv, bool peer_on_stdio, Mode mode, size_t size)
{
  TempDir dir("test_xmodem_interop");
  PtyMaster pty;
  const Bytes payload = randomBytes(size, static_cast<uint32_t>(size + 7));
  writeFile(dir.path + "/source", payload);
  std::vector<std::string> argv = peer_argv;
  if (!peer_on_stdio)
    argv.push_back(pty.slavePath());
  argv.push_back(dir.path + "/source");
  Peer peer(argv, dir.path, peer_on_stdio ? pty.slavePath() : "");
  Config config;
  config.nak_interval = Milliseconds(3000);
  const FileResult result = receiveFile(pty, dir.path + "/received", mode, config, binary());
  EXPECT_EQ(peer.wait(), 0) << argv[0] << " failed";
  expectPaddedCopy(readFile(dir.path + "/received"), payload, kBlockSize1K);
  EXPECT_EQ(result.stats.check, mode == Mode::kChecksum ? CheckType::kChecksum : CheckType::kCrc16);
}
}  // namespace

class LrzszInterop : public ::testing::TestWithParam<size_t>
{
};

TEST_P(LrzszInterop, OurSenderToRxChecksum)
{
  sendTo({"/usr/bin/rx"}, true, Mode::k1K, GetParam(), false);
}

TEST_P(LrzszInterop, OurSenderToRxCrc)
{
  sendTo({"/usr/bin/rx", "-c"}, true, Mode::k1K, GetParam(), true);
}

TEST_P(LrzszInterop, SxToOurChecksumReceiver)
{
  receiveFrom({"/usr/bin/sx"}, true, Mode::kChecksum, GetParam());
}

TEST_P(LrzszInterop, SxOneKToOurCrcReceiver)
{
  receiveFrom({"/usr/bin/sx", "-k"}, true, Mode::kCrc, GetParam());
}

// Plain sx (no -k) answers our 'C' with 128-byte CRC blocks.
TEST_P(LrzszInterop, SxCrcToOurCrcReceiver)
{
  receiveFrom({"/usr/bin/sx"}, true, Mode::kCrc, GetParam());
}

INSTANTIATE_TEST_SUITE_P(Sizes, LrzszInterop, ::testing::ValuesIn(kSizes));

// 1 MB: lrzsz in checksum-128 mode is slow (rx is the limit), so the large file goes once each way
// in the modes where it matters: 1K/CRC both ways and checksum into our receiver.
// Not here: 1 MB in checksum-128 to plain rx. rx flushes its tty input right after each ACK, and a
// block that crosses the flush is lost until a timeout; over 8192 blocks on a loaded 2-core machine
// (load 4) runs took 108 s and 390 s (ACK timeout 10 s), 130 s and 94 s (2 s), with no pause after ACKs, and
// a 5 ms pause after each ACK costs 41 s by itself. 1K/CRC to rx -c covers the large file instead.
TEST(LrzszInteropLarge, OneMegabyteBothWays)
{
  sendTo({"/usr/bin/rx", "-c"}, true, Mode::k1K, kLarge, true);
  receiveFrom({"/usr/bin/sx", "-k"}, true, Mode::kCrc, kLarge);
  receiveFrom({"/usr/bin/sx"}, true, Mode::kChecksum, kLarge);
}

class PythonInterop : public ::testing::TestWithParam<size_t>
{
};

TEST_P(PythonInterop, OurSenderToPythonCrc)
{
  sendTo({"/usr/bin/python3", kPython, "recv", "crc"}, false, Mode::k1K, GetParam(), true);
}

TEST_P(PythonInterop, OurSenderToPythonChecksum)
{
  sendTo({"/usr/bin/python3", kPython, "recv", "checksum"}, false, Mode::kCrc, GetParam(), false);
}

TEST_P(PythonInterop, PythonOneKToOurCrcReceiver)
{
  receiveFrom({"/usr/bin/python3", kPython, "send", "1k"}, false, Mode::kCrc, GetParam());
}

TEST_P(PythonInterop, PythonToOurChecksumReceiver)
{
  receiveFrom({"/usr/bin/python3", kPython, "send", "checksum"}, false, Mode::kChecksum, GetParam());
}

// python3-xmodem 0.4.5 cannot receive an empty file (it wants a packet before EOT): sizes from 1.
INSTANTIATE_TEST_SUITE_P(Sizes, PythonInterop, ::testing::Values(1, 127, 128, 129, 1024, 1025, kLarge));

namespace
{
/// Counts the bytes a session writes, so a test can wait for "n NAKs sent" on a condition.
class CountingTransport : public ForwardingTransport
{
 public:
  explicit CountingTransport(Transport& inner) : ForwardingTransport(inner) {}
  using ForwardingTransport::write;
  void write(const uint8_t* data, size_t size, Milliseconds timeout = kWaitForever) override
  {
    inner_.write(data, size, timeout);
    std::lock_guard<std::mutex> lock(mutex_);
    written_ += size;
    changed_.notify_all();
  }
  bool waitForWritten(size_t count, Milliseconds timeout)
  {
    std::unique_lock<std::mutex> lock(mutex_);
    return changed_.wait_for(lock, timeout, [&] { return written_ >= count; });
  }

 private:
  std::mutex mutex_;
  std::condition_variable changed_;
  size_t written_ = 0;
};
}  // namespace

// The cell case (dnc_node -> sim_haas_serial xmodem): a control waiting to receive NAKs on a fixed
// schedule, so a dozen NAKs are queued when the host starts to send: in the pty while no host has
// the device open (dnc_node opens the port per transfer; the open discards them), or in the host's
// open port (~keep_open). dnc_node opens its port per transfer and keeps what is queued
// (InputOnOpen::kKeep). The sender takes a NAK as the start and must not take a queued or
// in-flight NAK as a NAK of block 1: every block goes once and the control gets exactly the file.
void sendAfterQueuedNaks(bool port_open_while_queued)
{
  PtyMaster pty;
  CountingTransport control_side(pty);
  Config control_config;
  control_config.nak_interval = Milliseconds(50);  // a Haas: ~1 s; the sender's turnaround is 10 ms
  control_config.start_timeout = Milliseconds(30000);
  Receiver control(control_side, Mode::kChecksum, control_config);
  SerialSettings settings;
  settings.device = pty.slavePath();
  settings.baud = 115200;
  std::unique_ptr<SerialPort> port;
  if (port_open_while_queued)
    port = std::make_unique<SerialPort>(settings);
  Bytes received;
  std::string control_error;
  std::thread control_thread(
      [&]
      {
        try
        {
          received = control.receive();
        }
        catch (const std::exception& e)
        {
          control_error = e.what();
        }
      });
  // Wait until 12 NAKs are queued on the host's side.
  ASSERT_TRUE(control_side.waitForWritten(12, Milliseconds(20000)));
  if (!port)
    port = std::make_unique<SerialPort>(settings, InputOnOpen::kKeep);

  const Bytes payload = randomBytes(3 * kBlockSize + 17, 12);
  Config config;
  config.stale_nak_settle = Milliseconds(1000);  // as dnc_node: min(char_timeout, 1 s)
  Sender sender(*port, Mode::kChecksum, config);
  const Stats stats = sender.send(payload);
  control_thread.join();
  EXPECT_EQ(control_error, "");
  ASSERT_GE(received.size(), payload.size());
  EXPECT_TRUE(std::equal(payload.begin(), payload.end(), received.begin()));
  EXPECT_EQ(stats.blocks, 4u);
  EXPECT_EQ(stats.retries, 0u) << "a queued NAK was taken for a NAK of a block";
  EXPECT_EQ(control.stats().duplicates, 0u) << "a block went twice";
}

TEST(HaasCell, SendAfterNaksQueuedWhileThePortWasClosed)
{
  sendAfterQueuedNaks(false);
}

TEST(HaasCell, SendAfterNaksQueuedInTheOpenPort)
{
  sendAfterQueuedNaks(true);
}

// A receiver that sent its start requests before the sender opened the port (started first, as a
// user starts the receiver and then the sender): the first queued request is the start, the rest
// are dropped, and block 1 follows without the receiver asking again. The receiver here is a
// script on the pty: it writes nothing but its three early NAKs and one ACK per packet it read.
TEST(XmodemStart, RequestsQueuedBeforeThePortWasOpenedStartTheSendOnce)
{
  PtyMaster receiver;
  receiver.write(Bytes{kNak, kNak, kNak});
  {
    // The pty hands bytes over through a kernel worker: wait until they are queued on the slave.
    const int probe = ::open(receiver.slavePath().c_str(), O_RDONLY | O_NOCTTY | O_NONBLOCK);
    ASSERT_GE(probe, 0);
    pollfd ready{probe, POLLIN, 0};
    ASSERT_EQ(::poll(&ready, 1, 10000), 1);
    ::close(probe);
  }
  SerialSettings settings;
  settings.device = receiver.slavePath();
  settings.baud = 115200;
  SerialPort port(settings, InputOnOpen::kKeep);
  Config config;
  config.start_wait = Milliseconds(5000);
  const Bytes payload = randomBytes(2 * kBlockSize + 5, 21);
  Sender sender(port, Mode::kChecksum, config);
  auto sent = std::async(std::launch::async, [&] { return sender.send(payload); });

  for (uint8_t block = 1; block <= 3; ++block)
  {
    Bytes packet(packetSize(kBlockSize, CheckType::kChecksum));
    ASSERT_EQ(receiver.readExactly(packet.data(), packet.size(), Milliseconds(10000)), packet.size())
        << "block " << int(block) << " did not come: the queued start request was lost";
    const Packet decoded = decodePacket(packet.data(), packet.size(), CheckType::kChecksum);
    ASSERT_EQ(decoded.status, PacketStatus::kOk);
    EXPECT_EQ(decoded.block, block) << "block 1 went once per queued NAK";
    receiver.writeByte(kAck);
  }
  EXPECT_EQ(receiver.readByte(Milliseconds(10000)), kEot);
  receiver.writeByte(kAck);
  const Stats stats = sent.get();
  EXPECT_EQ(stats.blocks, 3u);
  EXPECT_EQ(stats.retries, 0u);
  EXPECT_EQ(receiver.readByte(Milliseconds(100)), -1) << "the sender wrote more than three packets and EOT";
}
