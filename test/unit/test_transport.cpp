// Transports against real peers: a pty pair (the test acts as the device on the master side, the
// SerialPort opens the slave), loopback TCP, and the scripted fake. Nothing here sleeps to wait
// for an event: every wait is a blocking read with a timeout or a condition variable.
#include <gtest/gtest.h>

#include <dlfcn.h>
#include <fcntl.h>
#include <poll.h>
#include <pty.h>
#include <sys/ioctl.h>
#include <sys/stat.h>
#include <termios.h>
#include <unistd.h>

#include <algorithm>
#include <ctime>
#include <filesystem>

#include <future>
#include <map>
#include <memory>
#include <mutex>
#include <thread>
#include <vector>

#include "cnc_bridge/common/error.h"
#include "cnc_bridge/transport/backoff.h"
#include "cnc_bridge/transport/forwarding_transport.h"
#include "cnc_bridge/transport/reconnecting_link.h"
#include "cnc_bridge/transport/serial_port.h"
#include "cnc_bridge/transport/tcp.h"
#include "testing/fake_transport.h"
#include "testing/paced_transport.h"
#include "testing/pty.h"

using namespace cnc_bridge;
using std::chrono::steady_clock;

namespace
{
// What the process last asked the driver for, per file descriptor (see tcsetattr below).
std::mutex requested_mutex;
std::map<int, termios> requested_termios;
}  // namespace

// Every tcsetattr() of this test passes here on its way to the C library's, so a test can see the
// termios a port asked for, including what a pty does not keep: its driver forces 8 data bits and
// no parity (drivers/tty/pty.c), so those two cannot be read back from a pty.
extern "C" int tcsetattr(int fd, int actions, const struct termios* tio) noexcept
{
  using Real = int (*)(int, int, const struct termios*);
  static const Real real = reinterpret_cast<Real>(::dlsym(RTLD_NEXT, "tcsetattr"));
  {
    std::lock_guard<std::mutex> lock(requested_mutex);
    requested_termios[fd] = *tio;
  }
  return real(fd, actions, tio);
}

namespace
{
termios requestedTermios(int fd)
{
  std::lock_guard<std::mutex> lock(requested_mutex);
  return requested_termios.at(fd);
}

termios driverTermios(int fd)
{
  termios tio{};
  EXPECT_EQ(::tcgetattr(fd, &tio), 0);
  return tio;
}

/// A pty pair held by the test itself (no PtyMaster), for what PtyMaster does not offer: the
/// master in packet mode, where the kernel reports the slave's output being stopped and started.
struct RawPty
{
  RawPty()
  {
    char name[64];
    if (::openpty(&master, &slave, name, nullptr, nullptr) != 0)
      throw std::runtime_error("openpty failed");
    slave_path = name;
  }
  ~RawPty()
  {
    ::close(master);
    ::close(slave);
  }
  /// Waits (at most \p limit, a bound against a hang) for a packet-mode status byte with \p flag.
  bool waitForStatus(int flag, std::chrono::seconds limit)
  {
    const auto end = steady_clock::now() + limit;
    while (steady_clock::now() < end)
    {
      pollfd fd{master, POLLIN | POLLPRI, 0};
      if (::poll(&fd, 1, 1000) <= 0)
        continue;
      uint8_t packet[256];
      const ssize_t n = ::read(master, packet, sizeof(packet));
      if (n > 0 && packet[0] != TIOCPKT_DATA && (packet[0] & flag))
        return true;
    }
    return false;
  }
  /// Data bytes that arrive (packet mode: each read starts with a status byte, 0 for data).
  std::string readData(size_t count, std::chrono::seconds limit)
  {
    std::string data;
    const auto end = steady_clock::now() + limit;
    while (data.size() < count && steady_clock::now() < end)
    {
      pollfd fd{master, POLLIN, 0};
      if (::poll(&fd, 1, 1000) <= 0)
        continue;
      char packet[256];
      const ssize_t n = ::read(master, packet, sizeof(packet));
      if (n > 1 && packet[0] == TIOCPKT_DATA)
        data.append(packet + 1, n - 1);
    }
    return data;
  }

  int master = -1;
  int slave = -1;
  std::string slave_path;
};

SerialSettings ptySettings(const PtyMaster& pty)
{
  SerialSettings settings;
  settings.device = pty.slavePath();
  settings.baud = 115200;
  return settings;
}

std::string readString(Transport& t, size_t n, Milliseconds per_byte = Milliseconds(2000))
{
  std::string out(n, '\0');
  const size_t got = t.readExactly(reinterpret_cast<uint8_t*>(&out[0]), n, per_byte);
  out.resize(got);
  return out;
}
}  // namespace

TEST(SerialPort, ExchangesBytesBothWaysOverAPty)
{
  PtyMaster device;
  SerialPort port(ptySettings(device));
  port.write(std::string("G00 X1\n"));
  EXPECT_EQ(readString(device, 7), "G00 X1\n");
  device.write(std::string("\x06\x15", 2));
  EXPECT_EQ(port.readByte(Milliseconds(1000)), 0x06);
  EXPECT_EQ(port.readByte(Milliseconds(1000)), 0x15);
}

TEST(SerialPort, RawModeKeepsEveryByteValue)
{
  PtyMaster device;
  SerialPort port(ptySettings(device));
  std::vector<uint8_t> all(256);
  for (int i = 0; i < 256; ++i)
    all[i] = static_cast<uint8_t>(i);
  device.write(all);
  std::vector<uint8_t> got(256);
  ASSERT_EQ(port.readExactly(got.data(), got.size(), Milliseconds(2000)), 256u);
  EXPECT_EQ(got, all);  // no CR/LF translation, no XON/XOFF eaten, no echo
  port.write(all);
  std::vector<uint8_t> back(256);
  ASSERT_EQ(device.readExactly(back.data(), back.size(), Milliseconds(2000)), 256u);
  EXPECT_EQ(back, all);
}

// A byte the device sent while nobody had the port open (an XModem receiver's start request) is
// kept for the program that opens the port when it asks (InputOnOpen::kKeep), dropped otherwise.
TEST(SerialPort, InputQueuedBeforeTheOpenIsKeptOnlyWhenAsked)
{
  for (const InputOnOpen on_open : {InputOnOpen::kKeep, InputOnOpen::kDiscard})
  {
    PtyMaster device;
    device.write(std::string("\x15"));  // NAK, before the port is opened
    {
      // The pty hands bytes over through a kernel worker: wait until the NAK is readable on the
      // slave, so that the open below finds it queued (a second descriptor that reads nothing).
      const int probe = ::open(device.slavePath().c_str(), O_RDONLY | O_NOCTTY | O_NONBLOCK);
      ASSERT_GE(probe, 0);
      pollfd ready{probe, POLLIN, 0};
      ASSERT_EQ(::poll(&ready, 1, 10000), 1) << "the NAK never reached the slave";
      ::close(probe);
    }
    SerialPort port(ptySettings(device), on_open);
    if (on_open == InputOnOpen::kKeep)
      EXPECT_EQ(port.readByte(Milliseconds(2000)), 0x15) << "the queued NAK was lost on open";
    else
      EXPECT_EQ(port.readByte(Milliseconds(200)), -1) << "a byte from before the open was read";
  }
}

TEST(SerialPort, ReadTimesOutWithNothingToRead)
{
  PtyMaster device;
  SerialPort port(ptySettings(device));
  const auto start = steady_clock::now();
  uint8_t byte;
  EXPECT_EQ(port.read(&byte, 1, Milliseconds(50)), 0u);
  EXPECT_GE(steady_clock::now() - start, Milliseconds(50));
}

// A read of 1 ms waits 1 ms; it is not a poll that returns at once (a loop of such reads, as a
// simulated control idling between programs makes, would spin a core).
TEST(SerialPort, AShortTimeoutIsWaitedInFull)
{
  PtyMaster device;
  SerialPort port(ptySettings(device));
  uint8_t byte;
  for (Transport* link : std::initializer_list<Transport*>{&port, &device})
  {
    const auto start = steady_clock::now();
    for (int i = 0; i < 100; ++i)
    {
      ASSERT_EQ(link->read(&byte, 1, Milliseconds(1)), 0u);
    }
    EXPECT_GE(steady_clock::now() - start, Milliseconds(100)) << link->describe();
  }
}

TEST(SerialPort, PartialReadsReturnWhatIsThere)
{
  PtyMaster device;
  SerialPort port(ptySettings(device));
  device.write(std::string("abc"));
  uint8_t buffer[64];
  size_t total = 0;
  while (total < 3)
  {
    const size_t n = port.read(buffer + total, sizeof(buffer) - total, Milliseconds(1000));
    ASSERT_GT(n, 0u);
    total += n;
  }
  EXPECT_EQ(std::string(reinterpret_cast<char*>(buffer), total), "abc");
}

TEST(SerialPort, AcceptsEveryLineSettingTheControlsUse)
{
  PtyMaster device;
  for (const unsigned baud : {1200u, 9600u, 19200u, 38400u, 57600u, 115200u, 230400u})
  {
    for (const Parity parity : {Parity::kNone, Parity::kEven, Parity::kOdd})
    {
      SerialSettings settings = ptySettings(device);
      settings.baud = baud;
      settings.data_bits = parity == Parity::kNone ? 8 : 7;
      settings.parity = parity;
      settings.stop_bits = baud == 9600 ? 2 : 1;
      settings.flow_control = baud == 57600 ? FlowControl::kXonXoff : FlowControl::kNone;
      EXPECT_NO_THROW(SerialPort port(settings)) << settings.describe();
    }
  }
}

struct LineCase
{
  unsigned baud;
  speed_t speed;
  Parity parity;
  FlowControl flow;
};

class SerialLineSettings : public ::testing::TestWithParam<LineCase>
{
};

// Each setting as the port asks the driver for it, and read back from the driver where a pty keeps
// it (speed, stop bits, odd parity's sense, flow control, raw mode; not data bits or parity on/off).
TEST_P(SerialLineSettings, ReachTheDriver)
{
  const LineCase line = GetParam();
  PtyMaster device;
  SerialSettings settings = ptySettings(device);
  settings.baud = line.baud;
  settings.data_bits = 7;
  settings.parity = line.parity;
  settings.stop_bits = 2;
  settings.flow_control = line.flow;
  SerialPort port(settings);
  const termios asked = requestedTermios(port.nativeHandle());
  const termios kept = driverTermios(port.nativeHandle());
  const bool odd = line.parity == Parity::kOdd, rtscts = line.flow == FlowControl::kRtsCts,
             xonxoff = line.flow == FlowControl::kXonXoff;

  EXPECT_EQ(asked.c_cflag & CSIZE, static_cast<tcflag_t>(CS7));
  EXPECT_TRUE(asked.c_cflag & PARENB);
  EXPECT_TRUE(asked.c_iflag & INPCK);
  for (const termios& tio : {asked, kept})
  {
    const char* which = &tio == &asked ? "asked" : "kept by the driver";
    SCOPED_TRACE(which);
    EXPECT_EQ(::cfgetispeed(&tio), line.speed);
    EXPECT_EQ(::cfgetospeed(&tio), line.speed);
    EXPECT_EQ(static_cast<bool>(tio.c_cflag & PARODD), odd);
    EXPECT_TRUE(tio.c_cflag & CSTOPB);
    EXPECT_EQ(static_cast<bool>(tio.c_cflag & CRTSCTS), rtscts);
    EXPECT_EQ(static_cast<bool>(tio.c_iflag & IXON), xonxoff);
    EXPECT_EQ(static_cast<bool>(tio.c_iflag & IXOFF), xonxoff);
    EXPECT_FALSE(tio.c_iflag & IXANY);  // only DC1 restarts output
    EXPECT_TRUE(tio.c_cflag & CREAD);
    EXPECT_TRUE(tio.c_cflag & CLOCAL);  // no modem lines on a 3-wire cable
    // Raw: no line editing, echo, signals, CR/LF translation or stripping, no output processing.
    EXPECT_EQ(tio.c_lflag & (ICANON | ECHO | ECHONL | ISIG | IEXTEN), 0u);
    EXPECT_EQ(tio.c_iflag & (ICRNL | INLCR | IGNCR | ISTRIP | IGNBRK | BRKINT | PARMRK), 0u);
    EXPECT_EQ(tio.c_oflag & OPOST, 0u);
    EXPECT_EQ(tio.c_cc[VMIN], 1);
    EXPECT_EQ(tio.c_cc[VTIME], 0);
  }
}

INSTANTIATE_TEST_SUITE_P(SerialPort, SerialLineSettings,
                         ::testing::Values(LineCase{230400, B230400, Parity::kEven, FlowControl::kRtsCts},
                                           LineCase{230400, B230400, Parity::kOdd, FlowControl::kXonXoff},
                                           LineCase{460800, B460800, Parity::kEven, FlowControl::kXonXoff},
                                           LineCase{460800, B460800, Parity::kOdd, FlowControl::kRtsCts},
                                           LineCase{460800, B460800, Parity::kOdd, FlowControl::kNone}));

TEST(SerialPort, EightBitsNoParityOneStopBitReachTheDriver)
{
  PtyMaster device;
  SerialPort port(ptySettings(device));
  const termios asked = requestedTermios(port.nativeHandle());
  EXPECT_EQ(asked.c_cflag & CSIZE, static_cast<tcflag_t>(CS8));
  EXPECT_EQ(asked.c_cflag & (PARENB | PARODD | CSTOPB | CRTSCTS), 0u);
  EXPECT_EQ(asked.c_iflag & (INPCK | IXON | IXOFF), 0u);
  EXPECT_EQ(::cfgetospeed(&asked), static_cast<speed_t>(B115200));
}

TEST(SerialPort, KernelXonXoffHoldsOutputUntilXon)
{
  RawPty device;
  int on = 1;
  ASSERT_EQ(::ioctl(device.master, TIOCPKT, &on), 0);
  SerialSettings settings;
  settings.device = device.slave_path;
  settings.baud = 9600;
  settings.flow_control = FlowControl::kXonXoff;
  SerialPort port(settings);

  ASSERT_EQ(::write(device.master, "\x13", 1), 1);  // the machine sends XOFF (DC3)
  ASSERT_TRUE(device.waitForStatus(TIOCPKT_STOP, std::chrono::seconds(10))) << "the kernel never stopped output";
  // Held: the driver takes nothing, so the write times out (its timeout is the only wait here).
  EXPECT_THROW(port.write(std::string("held"), Milliseconds(100)), TimeoutError);
  EXPECT_EQ(port.pendingOutput(), 0u);

  ASSERT_EQ(::write(device.master, "\x11", 1), 1);  // XON (DC1)
  ASSERT_TRUE(device.waitForStatus(TIOCPKT_START, std::chrono::seconds(10))) << "the kernel never restarted output";
  port.write(std::string("go"), Milliseconds(1000));
  EXPECT_EQ(device.readData(2, std::chrono::seconds(10)), "go");
}

TEST(SerialPort, DeviceEndClosingIsALinkErrorNotAHangOrAnEmptyRead)
{
  auto device = std::make_unique<PtyMaster>();
  SerialPort port(ptySettings(*device));
  device.reset();  // the simulator (the machine's end of the cable) goes away
  auto reader = std::async(std::launch::async,
                           [&]
                           {
                             uint8_t byte;
                             // Far longer than the test may take: returning at all means it did
                             // not wait for the timeout.
                             return port.read(&byte, 1, Milliseconds(3600 * 1000));
                           });
  if (reader.wait_for(std::chrono::seconds(30)) != std::future_status::ready)
  {
    port.interrupt();
    FAIL() << "the read went on after the device end closed";
  }
  try
  {
    const size_t n = reader.get();
    FAIL() << "the read returned " << n << " bytes instead of a link error";
  }
  catch (const LinkError& e)
  {
    EXPECT_NE(std::string(e.what()).find(port.settings().device), std::string::npos) << e.what();
  }
}

TEST(SerialPort, CharacterRateCountsStartDataParityAndStopBits)
{
  SerialSettings settings;
  settings.baud = 115200;
  EXPECT_DOUBLE_EQ(settings.charactersPerSecond(), 11520.0);  // 8N1: 10 bits a character
  settings.baud = 9600;
  settings.data_bits = 7;
  settings.parity = Parity::kEven;
  settings.stop_bits = 2;
  EXPECT_DOUBLE_EQ(settings.charactersPerSecond(), 872.7272727272727);  // 7E2: 11 bits
}

TEST(SerialPort, RejectsInvalidSettingsWithTheirName)
{
  SerialSettings settings;
  settings.device = "/dev/null";
  settings.data_bits = 9;
  try
  {
    SerialPort port(settings);
    FAIL() << "9 data bits accepted";
  }
  catch (const ConfigError& e)
  {
    EXPECT_NE(std::string(e.what()).find("data bits"), std::string::npos);
  }
  EXPECT_THROW(parseParity("mark"), ConfigError);
  EXPECT_THROW(parseFlowControl("dtr"), ConfigError);
  EXPECT_EQ(parseParity("even"), Parity::kEven);
}

TEST(SerialPort, MissingDeviceIsALinkErrorNamingIt)
{
  SerialSettings settings;
  settings.device = "/dev/does-not-exist";
  try
  {
    SerialPort port(settings);
    FAIL();
  }
  catch (const LinkError& e)
  {
    EXPECT_NE(std::string(e.what()).find("/dev/does-not-exist@9600 8N1"), std::string::npos) << e.what();
  }
}

TEST(SerialPort, APathThatNowNamesAnotherDeviceIsALinkError)
{
  // A simulator killed and restarted on a new pty (or a USB adapter re-plugged): the link path
  // moves to the new device while the old port is still open.
  const std::string link = ::testing::TempDir() + "serial_replaced_" + std::to_string(::getpid());
  auto first = std::make_unique<PtyMaster>(link);
  SerialPort port(ptySettings(*first));
  EXPECT_FALSE(port.deviceReplaced());
  first->write(reinterpret_cast<const uint8_t*>("ok"), 2, Milliseconds(1000));
  EXPECT_EQ(readString(port, 2), "ok");

  PtyMaster second(link);  // takes the link over
  EXPECT_TRUE(port.deviceReplaced());
  // The next read that comes after the check interval (half a second) says so.
  uint8_t byte;
  try
  {
    port.read(&byte, 1, Milliseconds(600));
    port.read(&byte, 1, Milliseconds(0));
    FAIL() << "no error for a replaced device";
  }
  catch (const LinkError& e)
  {
    EXPECT_NE(std::string(e.what()).find("another device"), std::string::npos) << e.what();
  }
  // Opened anew, the port is on the new device.
  SerialPort reopened(ptySettings(second));
  EXPECT_FALSE(reopened.deviceReplaced());
}

TEST(SerialPort, ALinkLeftByAnEndedSimulatorIsNotFollowedToAnotherProgramsPty)
{
  // A simulator killed without removing its link: the kernel hands the pty's number to the next
  // program, whose pty is then newer than the link that names it. Made here by dating the link back
  // (rather than by waiting for the kernel to reuse a number, which other programs can take first).
  const std::string link = ::testing::TempDir() + "serial_stale_" + std::to_string(::getpid());
  PtyMaster someone_elses;
  ::unlink(link.c_str());
  ASSERT_EQ(::symlink(someone_elses.slavePath().c_str(), link.c_str()), 0);
  const timespec an_hour_ago[2] = {{::time(nullptr) - 3600, 0}, {::time(nullptr) - 3600, 0}};
  ASSERT_EQ(::utimensat(AT_FDCWD, link.c_str(), an_hour_ago, AT_SYMLINK_NOFOLLOW), 0);
  SerialSettings settings;
  settings.device = link;
  try
  {
    SerialPort port(settings);
    FAIL() << "opened another program's pty through a stale link";
  }
  catch (const LinkError& e)
  {
    EXPECT_NE(std::string(e.what()).find("older than the pty"), std::string::npos) << e.what();
  }
  // A link made after its pty (a live simulator's) opens.
  PtyMaster live(link);
  EXPECT_NO_THROW(SerialPort{ptySettings(live)});
  ::unlink(link.c_str());
}

TEST(PtyMaster, MakesTheFolderOfItsLinkAndRemovesTheLinkWhenDone)
{
  const std::string folder = ::testing::TempDir() + "pty_folder_" + std::to_string(::getpid());
  const std::string link = folder + "/cell/laser_bus.pty";
  {
    PtyMaster pty(link);
    SerialPort port(ptySettings(pty));
    pty.write(reinterpret_cast<const uint8_t*>("up"), 2, Milliseconds(1000));
    EXPECT_EQ(readString(port, 2), "up");
  }
  struct stat gone;
  EXPECT_NE(::lstat(link.c_str(), &gone), 0);
  std::filesystem::remove_all(folder);
}

TEST(SerialPort, InterruptCancelsABlockedReadFromAnotherThread)
{
  PtyMaster device;
  SerialPort port(ptySettings(device));
  auto reader = std::async(std::launch::async,
                           [&]
                           {
                             uint8_t byte;
                             port.read(&byte, 1, Milliseconds(30000));
                           });
  // The interrupt may land before or during the read: both must end it with CancelledError.
  port.interrupt();
  ASSERT_EQ(reader.wait_for(std::chrono::seconds(5)), std::future_status::ready);
  EXPECT_THROW(reader.get(), CancelledError);
  // The port stays usable afterwards.
  device.write(std::string("x"));
  EXPECT_EQ(port.readByte(Milliseconds(1000)), 'x');
}

TEST(Tcp, ConnectsAcceptsAndExchanges)
{
  TcpServer server(0, "127.0.0.1");
  ASSERT_GT(server.port(), 0);
  auto accepted = std::async(std::launch::async, [&] { return server.accept(Milliseconds(5000)); });
  auto client = TcpConnection::connect("127.0.0.1", server.port(), Milliseconds(2000));
  auto peer = accepted.get();
  ASSERT_TRUE(peer);
  client->write(std::string("?Q500\r\n"));
  EXPECT_EQ(readString(*peer, 7), "?Q500\r\n");
  peer->write(std::string(">PROGRAM, O00110, IDLE, PARTS, 4523\r\n"));
  EXPECT_EQ(readString(*client, 37), ">PROGRAM, O00110, IDLE, PARTS, 4523\r\n");
}

TEST(Tcp, PeerThatDisappearsIsALinkError)
{
  TcpServer server(0, "127.0.0.1");
  auto accepted = std::async(std::launch::async, [&] { return server.accept(Milliseconds(5000)); });
  auto client = TcpConnection::connect("127.0.0.1", server.port(), Milliseconds(2000));
  auto peer = accepted.get();
  ASSERT_TRUE(peer);
  peer.reset();  // the machine is switched off
  uint8_t byte;
  try
  {
    client->read(&byte, 1, Milliseconds(5000));
    FAIL() << "read returned after the peer closed";
  }
  catch (const LinkError& e)
  {
    EXPECT_NE(std::string(e.what()).find("127.0.0.1:" + std::to_string(server.port())), std::string::npos) << e.what();
  }
}

TEST(Tcp, ConnectionRefusedIsALinkErrorWithHostAndPort)
{
  uint16_t port;
  {
    TcpServer probe(0, "127.0.0.1");
    port = probe.port();
  }
  EXPECT_THROW(TcpConnection::connect("127.0.0.1", port, Milliseconds(2000)), LinkError);
}

TEST(Tcp, AcceptTimesOutAndCanBeInterrupted)
{
  TcpServer server(0, "127.0.0.1");
  EXPECT_EQ(server.accept(Milliseconds(20)), nullptr);
  auto waiting = std::async(std::launch::async, [&] { return server.accept(Milliseconds(30000)); });
  server.interrupt();
  ASSERT_EQ(waiting.wait_for(std::chrono::seconds(5)), std::future_status::ready);
  EXPECT_THROW(waiting.get(), CancelledError);
}

TEST(Tcp, ReadTimeoutThenDataStillArrives)
{
  TcpServer server(0, "127.0.0.1");
  auto accepted = std::async(std::launch::async, [&] { return server.accept(Milliseconds(5000)); });
  auto client = TcpConnection::connect("localhost", server.port(), Milliseconds(2000));
  auto peer = accepted.get();
  uint8_t byte;
  EXPECT_EQ(client->read(&byte, 1, Milliseconds(20)), 0u);
  peer->write(std::string("!"));
  EXPECT_EQ(client->readByte(Milliseconds(2000)), '!');
}

TEST(Tcp, ReadReturnsTheBytesThatArrivedWithoutWaitingForMore)
{
  TcpServer server(0, "127.0.0.1");
  auto accepted = std::async(std::launch::async, [&] { return server.accept(Milliseconds(5000)); });
  auto client = TcpConnection::connect("127.0.0.1", server.port(), Milliseconds(2000));
  auto peer = accepted.get();
  ASSERT_TRUE(peer);
  peer->write(std::string("abc"));
  uint8_t buffer[64];
  // An hour's timeout, far beyond the test's budget: the read must return with what has come.
  auto reader =
      std::async(std::launch::async, [&] { return client->read(buffer, sizeof(buffer), Milliseconds(3600 * 1000)); });
  if (reader.wait_for(std::chrono::seconds(30)) != std::future_status::ready)
  {
    client->interrupt();
    FAIL() << "the read waited for the whole buffer";
  }
  const size_t n = reader.get();
  ASSERT_GT(n, 0u);
  ASSERT_LE(n, 3u);  // fewer than the 64 asked for
  std::string got(reinterpret_cast<char*>(buffer), n);
  got += readString(*client, 3 - n);  // the rest, should the segment have been split
  EXPECT_EQ(got, "abc");
}

TEST(FakeTransport, ScriptedRepliesPartialReadsAndDisconnect)
{
  FakeTransport fake;
  fake.onWrite(
      [](FakeTransport& self, const std::vector<uint8_t>& bytes)
      {
        if (bytes == std::vector<uint8_t>{'?'})
          self.feed(std::string("ok\n"));
      });
  fake.setMaxReadChunk(1);
  fake.write(std::string("?"));
  uint8_t buffer[8];
  EXPECT_EQ(fake.read(buffer, sizeof(buffer), Milliseconds(100)), 1u);
  EXPECT_EQ(buffer[0], 'o');
  EXPECT_EQ(fake.read(buffer, sizeof(buffer), Milliseconds(100)), 1u);
  EXPECT_EQ(fake.read(buffer, sizeof(buffer), Milliseconds(100)), 1u);
  EXPECT_EQ(fake.read(buffer, sizeof(buffer), Milliseconds(1)), 0u);
  fake.disconnect();
  EXPECT_THROW(fake.read(buffer, sizeof(buffer), Milliseconds(100)), LinkError);
}

TEST(Transport, PurgeDropsUntilTheLineIsQuiet)
{
  FakeTransport fake;
  fake.feed(std::string("noise noise"));
  EXPECT_EQ(fake.purge(Milliseconds(5)), 11u);
  EXPECT_EQ(fake.readByte(Milliseconds(1)), -1);
}

TEST(Backoff, GrowsGeometricallyUpToTheCapAndResets)
{
  Backoff backoff(Milliseconds(100), Milliseconds(1000), 2.0);
  EXPECT_EQ(backoff.next(), Milliseconds(100));
  EXPECT_EQ(backoff.next(), Milliseconds(200));
  EXPECT_EQ(backoff.next(), Milliseconds(400));
  EXPECT_EQ(backoff.next(), Milliseconds(800));
  EXPECT_EQ(backoff.next(), Milliseconds(1000));
  EXPECT_EQ(backoff.next(), Milliseconds(1000));
  EXPECT_EQ(backoff.failures(), 6u);
  backoff.reset();
  EXPECT_EQ(backoff.next(), Milliseconds(100));
}

TEST(Reconnector, RetriesUntilTheLinkComesUpAndReportsStates)
{
  std::mutex mutex;
  std::condition_variable cv;
  std::vector<LinkState> states;
  int attempts = 0;
  bool session_ran = false;
  StopSignal session_end;
  Reconnector::Callbacks callbacks;
  callbacks.connect = [&]
  {
    std::lock_guard<std::mutex> lock(mutex);
    if (++attempts < 3)
      throw LinkError("machine switched off");
  };
  callbacks.session = [&]
  {
    {
      std::lock_guard<std::mutex> lock(mutex);
      session_ran = true;
    }
    cv.notify_all();
    session_end.waitFor(Milliseconds(30000));
  };
  callbacks.on_state = [&](LinkState s, const std::string&)
  {
    std::lock_guard<std::mutex> lock(mutex);
    states.push_back(s);
  };
  std::atomic<bool> stopping{false};
  callbacks.disconnect = [&]
  {
    if (stopping)
      session_end.stop();
  };
  Reconnector reconnector("test link", callbacks, Backoff(Milliseconds(1), Milliseconds(2)));
  reconnector.start();
  {
    std::unique_lock<std::mutex> lock(mutex);
    ASSERT_TRUE(cv.wait_for(lock, std::chrono::seconds(5), [&] { return session_ran; }));
    EXPECT_EQ(attempts, 3);
    ASSERT_GE(states.size(), 5u);
    EXPECT_EQ(states[0], LinkState::kConnecting);
    EXPECT_EQ(states[1], LinkState::kDown);
    EXPECT_EQ(states.back(), LinkState::kUp);
  }
  stopping = true;
  reconnector.stop();
  EXPECT_EQ(reconnector.failures(), 2u);
}

namespace
{
/// Links handed out by an opener, so a test can play the peer of each one.
struct Links
{
  std::mutex mutex;
  std::condition_variable opened;
  std::vector<FakeTransport*> all;
  int refusals = 0;  // the first opens that fail, as a machine switched off

  ReconnectingLink::Opener opener()
  {
    return [this]() -> std::unique_ptr<Transport>
    {
      std::lock_guard<std::mutex> lock(mutex);
      if (refusals > 0)
      {
        --refusals;
        throw LinkError("connection refused");
      }
      auto link = std::make_unique<FakeTransport>("link " + std::to_string(all.size()));
      all.push_back(link.get());
      opened.notify_all();
      return link;
    };
  }
  FakeTransport* waitForLink(size_t index)
  {
    std::unique_lock<std::mutex> lock(mutex);
    return opened.wait_for(lock, std::chrono::seconds(5), [&] { return all.size() > index; }) ? all[index] : nullptr;
  }
};

/// The states a link reported, and a wait for one.
struct StateLog
{
  std::mutex mutex;
  std::condition_variable changed;
  std::vector<LinkState> states;

  ReconnectingLink::StateHandler handler()
  {
    return [this](LinkState state, const std::string&)
    {
      {
        std::lock_guard<std::mutex> lock(mutex);
        states.push_back(state);
      }
      changed.notify_all();
    };
  }
  /// Waits until \p state was reported \p times times in all.
  bool waitFor(LinkState state, long times = 1)
  {
    std::unique_lock<std::mutex> lock(mutex);
    return changed.wait_for(lock, std::chrono::seconds(5),
                            [&] { return std::count(states.begin(), states.end(), state) >= times; });
  }
};

/// A session that echoes what it reads until its link fails or is interrupted.
void echo(Transport& link)
{
  uint8_t buffer[64];
  for (;;)
  {
    const size_t n = link.read(buffer, sizeof buffer, Milliseconds(30000));
    link.write(buffer, n);
  }
}
}  // namespace

TEST(ReconnectingLink, OpensRunsTheSessionAndReopensAfterAFailure)
{
  Links links;
  links.refusals = 2;
  StateLog log;
  ReconnectingLink link("machine", links.opener(), Backoff(Milliseconds(1), Milliseconds(2)));
  link.start(echo, log.handler());
  FakeTransport* first = links.waitForLink(0);
  ASSERT_NE(first, nullptr);
  first->feed("ping");
  ASSERT_TRUE(first->waitForWritten(4, Milliseconds(5000)));
  ASSERT_TRUE(log.waitFor(LinkState::kUp));
  EXPECT_TRUE(link.isUp());
  EXPECT_EQ(link.failures(), 2u);  // the two refused opens
  first->disconnect();             // the peer goes away: the session fails, the link is reopened
  FakeTransport* second = links.waitForLink(1);
  ASSERT_NE(second, nullptr);
  second->feed("again");
  ASSERT_TRUE(second->waitForWritten(5, Milliseconds(5000)));
  ASSERT_TRUE(log.waitFor(LinkState::kUp, 2));
  EXPECT_EQ(link.failures(), 3u);
  EXPECT_EQ(link.reconnects(), 2u);  // up after the refusals, and again after the drop
  {
    std::lock_guard<std::mutex> lock(log.mutex);
    EXPECT_EQ(log.states.front(), LinkState::kConnecting);
    EXPECT_EQ(std::count(log.states.begin(), log.states.end(), LinkState::kDown), 3);  // 2 refusals, 1 drop
  }
  link.stop();
}

TEST(ReconnectingLink, OtherThreadsWriteOnlyThroughAnOpenLink)
{
  Links links;
  links.refusals = 1000000;  // never comes up
  StateLog down_log;
  ReconnectingLink down("machine", links.opener(), Backoff(Milliseconds(1), Milliseconds(2)));
  down.start(echo, down_log.handler());
  ASSERT_TRUE(down_log.waitFor(LinkState::kDown));
  EXPECT_FALSE(down.withLink([](Transport&) { ADD_FAILURE() << "used a link that is not open"; }));
  down.stop();

  Links up_links;
  StateLog up_log;
  ReconnectingLink up("machine", up_links.opener());
  up.start(echo, up_log.handler());
  ASSERT_TRUE(up_log.waitFor(LinkState::kUp));
  FakeTransport* fake = up_links.waitForLink(0);
  ASSERT_NE(fake, nullptr);
  const std::string command = "M1@";
  EXPECT_TRUE(up.withLink([&](Transport& l) { l.write(reinterpret_cast<const uint8_t*>(command.data()), 3); }));
  ASSERT_TRUE(fake->waitForWritten(3, Milliseconds(5000)));
  EXPECT_EQ(fake->written(), std::vector<uint8_t>(command.begin(), command.end()));
  up.stop();
}

TEST(ReconnectingLink, StopEndsABlockedSessionAndNoHandlerRunsAfterIt)
{
  Links links;
  std::atomic<int> calls_after_stop{0};
  std::atomic<bool> stopped{false};
  StateLog log;
  auto record = log.handler();
  ReconnectingLink link("machine", links.opener());
  link.start(echo,
             [&](LinkState state, const std::string& why)
             {
               if (stopped)
                 ++calls_after_stop;
               record(state, why);
             });
  ASSERT_TRUE(log.waitFor(LinkState::kUp));  // the session now waits in a 30 s read
  link.stop();                               // must not wait it out
  stopped = true;
  EXPECT_EQ(calls_after_stop, 0);
  EXPECT_FALSE(link.isUp());
  link.stop();  // idempotent
}

namespace
{
/// Records when each write reached the link.
class WriteClock : public ForwardingTransport
{
 public:
  using ForwardingTransport::ForwardingTransport;
  using ForwardingTransport::write;
  void write(const uint8_t* data, size_t size, Milliseconds timeout = kWaitForever) override
  {
    writes.emplace_back(steady_clock::now(), size);
    inner_.write(data, size, timeout);
  }
  std::vector<std::pair<steady_clock::time_point, size_t>> writes;
};

/// Writes 10 characters through a line of 1000 characters/s (slices of 2 characters) and checks
/// that the slice after \p sent_before characters left no sooner than \p sent_before ms (or, when
/// \p released_when_sent, no sooner than the end of its own characters). Lower bounds only: a
/// loaded machine can only make a slice later.
void expectPaced(PacedTransport::Release release, bool released_when_sent)
{
  FakeTransport fake;
  WriteClock clock(fake);
  PacedTransport line(clock, 1000.0, release);
  const auto start = steady_clock::now();
  line.write(std::vector<uint8_t>(10, 0x55));
  ASSERT_EQ(clock.writes.size(), 5u);
  size_t sent = 0;
  for (const auto& w : clock.writes)
  {
    const size_t line_time_ms = released_when_sent ? sent + w.second : sent;
    EXPECT_GE(w.first - start, std::chrono::milliseconds(line_time_ms)) << "after " << sent << " characters";
    sent += w.second;
  }
  EXPECT_EQ(fake.written(), std::vector<uint8_t>(10, 0x55));
}
}  // namespace

TEST(PacedTransport, EachSliceLeavesWhenTheLineIsFreeForIt)
{
  expectPaced(PacedTransport::Release::kWhenLineIsFree, false);
}

TEST(PacedTransport, WhenSentNoByteReachesTheLinkBeforeTheLineWouldHaveFinishedIt)
{
  // For stop-and-wait timing (the slave bus simulator and benchmark): a slice released when the
  // line starts it would let the last slice of a message arrive up to one slice early.
  expectPaced(PacedTransport::Release::kWhenSent, true);
}
