// The port doctor: open failures explained in words (missing device, permission, busy) as every
// SerialPort user reports them, a silent control, a port another program holds, and `cnc_dnc
// doctor --listen` judging 7E1 from 8N1 by the punch output of the simulated control at 9600 baud
// and reading a peer that waits in its protocol (the simulated Haas and lrzsz rx in XModem RECV,
// a control asking for a drip-feed) as a good line.
#include <arpa/inet.h>
#include <fcntl.h>
#include <grp.h>
#include <netinet/in.h>
#include <pty.h>
#include <signal.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>
#include <yaml-cpp/yaml.h>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

#include "cnc_bridge/common/error.h"
#include "cnc_bridge/transport/port_doctor.h"
#include "cnc_bridge/transport/serial_port.h"
#include "cnc_bridge/transport/tcp.h"
#include "temp_dir.h"

using namespace cnc_bridge;

namespace
{
/// A scratch folder of this file's tests, removed with everything in it when the test ends.
struct TempDir : test::TempDir
{
  TempDir() : test::TempDir("test_port_doctor") {}
};

/// A pty pair; the slave's path is what a program opens.
struct Pty
{
  int master = -1, slave = -1;
  std::string path;
  Pty()
  {
    char name[128];
    if (::openpty(&master, &slave, name, nullptr, nullptr) != 0)
      throw std::runtime_error("openpty");
    path = name;
  }
  ~Pty()
  {
    ::close(master);
    ::close(slave);
  }
};

/// What a command printed (stdout and stderr) and its exit status.
struct ToolRun
{
  int status = -1;
  std::string output;
};

ToolRun run(const std::string& command)
{
  ToolRun result;
  // Bounded: a tool that hangs fails its case (status 124) instead of holding the whole run.
  FILE* pipe = ::popen(("timeout -k 5 120 " + command + " 2>&1").c_str(), "r");
  char buffer[4096];
  size_t n;
  while ((n = std::fread(buffer, 1, sizeof(buffer), pipe)) > 0)
    result.output.append(buffer, n);
  const int status = ::pclose(pipe);
  result.status = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return result;
}

/// Waits until \p path exists (a simulator's link), up to \p timeout.
bool appears(const std::string& path, std::chrono::seconds timeout)
{
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  struct stat st;
  while (::lstat(path.c_str(), &st) != 0)
  {
    if (std::chrono::steady_clock::now() > deadline)
      return false;
    std::this_thread::sleep_for(std::chrono::milliseconds(20));  // polling a file's appearance
  }
  return true;
}

/// What opening \p device as user nobody (uid and gid 65534, no other groups) says.
std::string openAsNobody(const std::string& device)
{
  int fds[2];
  if (::pipe(fds) != 0)
    return "pipe failed";
  const pid_t child = ::fork();
  if (child == 0)
  {
    ::close(fds[0]);
    std::string message = "opened";
    if (::setgroups(0, nullptr) != 0 || ::setgid(65534) != 0 || ::setuid(65534) != 0)
      message = "cannot become nobody";
    else
    {
      try
      {
        SerialPort port(SerialSettings{device});
      }
      catch (const std::exception& e)
      {
        message = e.what();
      }
    }
    (void)!::write(fds[1], message.data(), message.size());
    ::_exit(0);
  }
  ::close(fds[1]);
  std::string message;
  char buffer[4096];
  ssize_t n;
  while ((n = ::read(fds[0], buffer, sizeof(buffer))) > 0)
    message.append(buffer, static_cast<size_t>(n));
  ::close(fds[0]);
  ::waitpid(child, nullptr, 0);
  return message;
}

const std::string kProgram = []
{
  std::string text = "%\nO01001 (DOCTOR)\n";
  for (int i = 0; i < 60; ++i)
    text += "N" + std::to_string(i) + " G01 X" + std::to_string(i) + ".25 Y-1.5 F200.\n";
  return text + "M30\n%\n";
}();

/// `cnc_dnc doctor --listen 3` on the simulated control punching kProgram at 9600 baud.
ToolRun listenToPunch(bool seven_e1)
{
  TempDir dir;
  const std::string program = dir.path + "/O01001.nc", link = dir.path + "/haas.pty";
  std::ofstream(program) << kProgram;
  const pid_t sim = ::fork();
  if (sim == 0)
  {
    const int null = ::open("/dev/null", O_WRONLY);
    ::dup2(null, 1);
    std::vector<const char*> argv = {SIM_HAAS_SERIAL, "punch",  "--file", program.c_str(), "--link",
                                     link.c_str(),    "--baud", "9600",   "--at-once",     "--no-dc-codes"};
    if (seven_e1)
      argv.push_back("--7e1");
    argv.push_back(nullptr);
    ::execv(argv[0], const_cast<char* const*>(argv.data()));
    ::_exit(127);
  }
  ToolRun result;
  if (appears(link, std::chrono::seconds(10)))
    result = run(std::string(CNC_DNC) + " doctor --port " + link + " --baud 9600 --listen 3");
  else
    result.output = "the simulator made no link";
  ::kill(sim, SIGTERM);
  ::waitpid(sim, nullptr, 0);
  return result;
}
/// Starts \p argv (stdin, stdout and stderr from \p io, /dev/null if empty); \returns its pid.
pid_t start(const std::vector<std::string>& argv, const std::string& io = "")
{
  const pid_t pid = ::fork();
  if (pid == 0)
  {
    const int in = ::open(io.empty() ? "/dev/null" : io.c_str(), O_RDWR | O_NOCTTY);
    const int null = ::open("/dev/null", O_WRONLY);
    ::dup2(in, 0);
    ::dup2(io.empty() ? null : in, 1);
    ::dup2(null, 2);
    for (int fd = 3; fd < 1024; ++fd)
      ::close(fd);  // not the test's own ptys: the program holds only what it is given
    std::vector<const char*> args;
    for (const auto& arg : argv)
      args.push_back(arg.c_str());
    args.push_back(nullptr);
    ::execvp(args[0], const_cast<char* const*>(args.data()));
    ::_exit(127);
  }
  return pid;
}

void stop(pid_t pid)
{
  ::kill(pid, SIGTERM);
  for (int i = 0; i < 1000; ++i)
  {
    if (::waitpid(pid, nullptr, WNOHANG) == pid)
      return;
    std::this_thread::sleep_for(std::chrono::milliseconds(10));  // poll: waitpid has no timeout
  }
  ADD_FAILURE() << "process " << pid << " did not stop within 10 s of SIGTERM: killed";
  ::kill(pid, SIGKILL);
  ::waitpid(pid, nullptr, 0);
}

/// `cnc_dnc doctor --listen SECONDS` on \p link once it exists (a peer's pty).
ToolRun doctorListening(const std::string& link, const std::string& seconds = "2")
{
  ToolRun result;
  if (appears(link, std::chrono::seconds(10)))
    result = run(std::string(CNC_DNC) + " doctor --port " + link + " --baud 9600 --listen " + seconds);
  else
    result.output = "the peer made no link " + link;
  return result;
}

void expectAGoodLine(const ToolRun& doctor, const std::string& peer)
{
  EXPECT_EQ(doctor.status, 0) << doctor.output;
  EXPECT_NE(doctor.output.find("peer: " + peer), std::string::npos) << doctor.output;
  EXPECT_NE(doctor.output.find("9600 baud looks right (the peer's characters arrive intact)"), std::string::npos)
      << doctor.output;
  EXPECT_EQ(doctor.output.find("likely not"), std::string::npos) << "a healthy line judged wrong: " << doctor.output;
}
}  // namespace

// ---------------------------------------------------------------------------------------------
TEST(PortDoctor, APeerWaitingInItsProtocolIsAGoodLineNotAWrongBaudRate)
{
  std::vector<uint8_t> naks(12, 0x15), crcs_7e1(8, 0xC3), dc1s(3, 0x11);  // 'C' at 7E1: its parity bit set
  const LineGuess nak = guessLineSettings(naks, 0, 9600);
  EXPECT_FALSE(nak.baud_suspect) << nak.line;
  EXPECT_NE(nak.peer.find("XModem receiver waiting for a program (it repeats NAK"), std::string::npos) << nak.peer;
  EXPECT_EQ(nak.parity, 'N');
  const LineGuess crc = guessLineSettings(crcs_7e1, 0, 9600);
  EXPECT_NE(crc.peer.find("it repeats 'C', CRC mode"), std::string::npos) << crc.peer;
  EXPECT_EQ(crc.data_bits, 7u);
  EXPECT_EQ(crc.parity, 'E');
  const LineGuess dc1 = guessLineSettings(dc1s, 0, 9600);
  EXPECT_NE(dc1.peer.find("asking for a drip-feed (DC1)"), std::string::npos) << dc1.peer;
  EXPECT_FALSE(dc1.baud_suspect);
  EXPECT_NE(guessLineSettings({0x11}, 0, 9600).peer.find("one DC1"), std::string::npos);
  // Not one kind of character, or with framing errors: not a peer, a baud rate to check.
  std::vector<uint8_t> mixed = {0x15, 0x15, 0x8f, 0x3a, 0x15, 0xe1};
  EXPECT_EQ(guessLineSettings(mixed, 0, 9600).peer, "");
  EXPECT_TRUE(guessLineSettings(mixed, 0, 9600).baud_suspect);
  EXPECT_EQ(guessLineSettings(naks, 6, 9600).peer, "");
  EXPECT_NE(guessLineSettings({0x15}, 0, 9600).peer.find("one NAK so far"), std::string::npos);
}

TEST(PortDoctor, ASimulatedHaasWaitingInRecvIsAGoodLine)
{
  TempDir dir;
  const std::string link = dir.path + "/haas.pty";
  const pid_t haas = start({SIM_HAAS_SERIAL, "xmodem", "--link", link, "--dir", dir.path, "--nak-interval", "0.2"});
  const ToolRun doctor = doctorListening(link);
  stop(haas);
  expectAGoodLine(doctor, "an XModem receiver waiting for a program (it repeats NAK, checksum mode)");
}

TEST(PortDoctor, LrzszRxWaitingIsAGoodLine)
{
  TempDir dir;
  const std::string ours = dir.path + "/ours.pty", theirs = dir.path + "/theirs.pty";
  const pid_t line = start({"socat", "pty,rawer,link=" + ours, "pty,rawer,link=" + theirs});
  ASSERT_TRUE(appears(theirs, std::chrono::seconds(10)));
  const pid_t rx = start({"rx", dir.path + "/received.nc"}, theirs);
  const ToolRun doctor = doctorListening(ours, "4");
  stop(rx);
  stop(line);
  EXPECT_EQ(doctor.status, 0) << doctor.output;
  EXPECT_NE(doctor.output.find("peer: an XModem receiver waiting for a program"), std::string::npos) << doctor.output;
  EXPECT_EQ(doctor.output.find("likely not"), std::string::npos) << doctor.output;
}

TEST(PortDoctor, ASimulatedControlAskingForADripFeedIsAGoodLine)
{
  TempDir dir;
  const std::string link = dir.path + "/fanuc.pty";
  const pid_t control = start({SIM_HAAS_SERIAL, "drip", "--link", link, "--dc1-at-start"});
  const ToolRun doctor = doctorListening(link);
  stop(control);
  expectAGoodLine(doctor, "a control asking for a drip-feed");
}

TEST(PortDoctor, NothingReceivedSaysToPressPunchWhileListeningNotToRunItselfAgain)
{
  Pty pty;
  const ToolRun doctor = run(std::string(CNC_DNC) + " doctor --port " + pty.path + " --listen 1");
  EXPECT_EQ(doctor.status, 1) << doctor.output;
  EXPECT_NE(doctor.output.find("press PUNCH/SEND on the control"), std::string::npos) << doctor.output;
  EXPECT_EQ(doctor.output.find("doctor --port DEV --listen"), std::string::npos)
      << "advice loops back: " << doctor.output;
}

TEST(PortDoctor, APortHeldByAnotherProgramExitsNonZeroNamingIt)
{
  Pty pty;
  const pid_t holder = start({"sleep", "600"}, pty.path);  // holds the port open, as a terminal program would
  ASSERT_GT(holder, 0);
  bool held = false;
  for (int i = 0; i < 500 && !held; ++i)
  {
    held = !processesHolding(pty.path, ::getpid()).empty();
    if (!held)
      std::this_thread::sleep_for(std::chrono::milliseconds(10));  // poll: /proc has no event to wait on
  }
  const ToolRun doctor = run(std::string(CNC_DNC) + " doctor --port " + pty.path);
  stop(holder);
  ASSERT_TRUE(held);
  EXPECT_EQ(doctor.status, 1) << doctor.output;
  EXPECT_NE(doctor.output.find("not free for a transfer"), std::string::npos) << doctor.output;
  EXPECT_NE(doctor.output.find(std::to_string(holder) + " (sleep): another program"), std::string::npos)
      << doctor.output;
  EXPECT_EQ(describeHolder("812 (dnc_node)").find("812 (dnc_node): a node of cnc_bridge"), 0u);
  EXPECT_NE(describeHolder("9 (sim_haas_serial)").find("a simulator of cnc_bridge"), std::string::npos);
  EXPECT_NE(describeHolder("10 (cnc_dnc)").find("cnc_bridge's cnc_dnc"), std::string::npos);
}

TEST(PortDoctor, MissingDeviceListsTheAdaptersById)
{
  TempDir dir;
  const std::string by_id = dir.path + "/by-id";
  ::mkdir(by_id.c_str(), 0755);
  const std::string missing = dir.path + "/ttyUSB9";
  const std::string none = explainOpenFailure(missing, ENOENT, by_id);
  EXPECT_NE(none.find(missing + " does not exist"), std::string::npos) << none;
  EXPECT_NE(none.find("no USB serial adapter is plugged in"), std::string::npos) << none;

  ASSERT_EQ(::symlink("/dev/null", (by_id + "/usb-FTDI_FT232R_USB_UART_A10K-if00-port0").c_str()), 0);
  const std::string some = explainOpenFailure(missing, ENOENT, by_id);
  EXPECT_NE(some.find(by_id + "/usb-FTDI_FT232R_USB_UART_A10K-if00-port0 -> /dev/null"), std::string::npos) << some;

  // The same words reach whoever opens the port: nodes and cnc_dnc report SerialPort's error.
  try
  {
    SerialPort port(SerialSettings{missing});
    FAIL() << "opened a missing device";
  }
  catch (const LinkError& e)
  {
    EXPECT_NE(std::string(e.what()).find(missing + " does not exist"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("/dev/serial/by-id"), std::string::npos) << e.what();
  }
}

TEST(PortDoctor, PermissionNamesOwnerGroupModeAndTheFix)
{
  ASSERT_EQ(::geteuid(), 0u) << "this test makes a device of root:dialout and opens it as nobody";
  Pty pty;
  const group* dialout = ::getgrnam("dialout");
  ASSERT_NE(dialout, nullptr);
  ASSERT_EQ(::chown(pty.path.c_str(), 0, dialout->gr_gid), 0);
  ASSERT_EQ(::chmod(pty.path.c_str(), 0660), 0);
  const std::string message = openAsNobody(pty.path);
  EXPECT_NE(message.find("permission denied: " + pty.path + " is owned by root:dialout with mode crw-rw----"),
            std::string::npos)
      << message;
  EXPECT_NE(message.find("nobody is neither its owner nor in group dialout"), std::string::npos) << message;
  EXPECT_NE(message.find("`sudo usermod -aG dialout nobody`, then log out and in again"), std::string::npos) << message;

  // A device only its owner may open: joining a group would not help, so that is not advised.
  ASSERT_EQ(::chmod(pty.path.c_str(), 0600), 0);
  const std::string owner_only = openAsNobody(pty.path);
  EXPECT_NE(owner_only.find("only root can open it"), std::string::npos) << owner_only;
  EXPECT_EQ(owner_only.find("usermod"), std::string::npos) << owner_only;
}

TEST(PortDoctor, BusyNamesTheProcessHoldingThePort)
{
  Pty pty;
  int ready[2];
  ASSERT_EQ(::pipe(ready), 0);
  const pid_t holder = ::fork();
  if (holder == 0)
  {
    const int fd = ::open(pty.path.c_str(), O_RDWR | O_NOCTTY);
    (void)!::write(ready[1], fd >= 0 ? "y" : "n", 1);
    ::pause();
    ::_exit(0);
  }
  char answer = 0;
  ASSERT_EQ(::read(ready[0], &answer, 1), 1);
  ASSERT_EQ(answer, 'y');
  const std::string message = explainOpenFailure(pty.path, EBUSY);
  ::kill(holder, SIGTERM);
  ::waitpid(holder, nullptr, 0);
  ::close(ready[0]);
  ::close(ready[1]);
  EXPECT_NE(message.find(pty.path + " is busy, held by"), std::string::npos) << message;
  EXPECT_NE(message.find(" " + std::to_string(holder) + " (test_port_docto"), std::string::npos) << message;
  EXPECT_EQ(message.find(" " + std::to_string(::getpid()) + " ("), std::string::npos) << "names itself: " << message;
}

TEST(PortDoctor, SilentControlGetsTheSettingsToCompare)
{
  Pty pty;  // nobody writes to the master
  const ToolRun doctor = run(std::string(CNC_DNC) + " doctor --port " + pty.path + " --listen 1");
  EXPECT_EQ(doctor.status, 1) << doctor.output;
  EXPECT_NE(doctor.output.find("port " + pty.path + ": opens"), std::string::npos) << doctor.output;
  EXPECT_NE(doctor.output.find("listen: nothing received in 1 s"), std::string::npos) << doctor.output;
  EXPECT_NE(doctor.output.find("Haas settings 11, 12, 37, 13"), std::string::npos) << doctor.output;
  EXPECT_NE(doctor.output.find("null-modem"), std::string::npos) << doctor.output;

  // A transfer to a control that never asks says the same, and sends no block: only the CANs
  // that tell the control the transfer is off.
  TempDir dir;
  const std::string program = dir.path + "/O01001.nc";
  std::ofstream(program) << kProgram;
  const ToolRun send = run(std::string(CNC_DNC) + " send --port " + pty.path + " --timeout 1 " + program);
  EXPECT_EQ(send.status, 1) << send.output;
  EXPECT_NE(send.output.find("did not start"), std::string::npos) << send.output;
  EXPECT_NE(send.output.find("cnc_dnc doctor --port DEV --listen 10"), std::string::npos) << send.output;
  char buffer[256];
  ::fcntl(pty.master, F_SETFL, O_NONBLOCK);
  const ssize_t sent = ::read(pty.master, buffer, sizeof(buffer));
  for (ssize_t i = 0; i < sent; ++i)
    EXPECT_EQ(buffer[i], 0x18) << "byte " << i << " of what the sender wrote to a control that never asked";
}

TEST(PortDoctor, RefusedConnectionNamesTheServerSettings)
{
  // A port nobody listens on: bound once to learn a free number, then closed.
  uint16_t port = 0;
  {
    const int probe = ::socket(AF_INET, SOCK_STREAM, 0);
    sockaddr_in address{};
    address.sin_family = AF_INET;
    address.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    ASSERT_EQ(::bind(probe, reinterpret_cast<sockaddr*>(&address), sizeof(address)), 0);
    socklen_t length = sizeof(address);
    ::getsockname(probe, reinterpret_cast<sockaddr*>(&address), &length);
    port = ntohs(address.sin_port);
    ::close(probe);
  }
  try
  {
    TcpConnection::connect("127.0.0.1", port, Milliseconds(2000));
    FAIL() << "connected to a port nobody listens on";
  }
  catch (const LinkError& e)
  {
    const std::string where = "127.0.0.1:" + std::to_string(port);
    EXPECT_NE(std::string(e.what()).find("nothing listens on " + where), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("Setting 143 for MDC, 263 for DPRNT"), std::string::npos) << e.what();
  }
  EXPECT_NE(explainConnectFailure("10.0.0.9:5051", 0).find("no answer from 10.0.0.9:5051: check the address"),
            std::string::npos);
}

TEST(PortDoctor, ReadsParityFromBitSeven)
{
  std::vector<uint8_t> eight_n1(kProgram.begin(), kProgram.end()), seven_e1, seven_o1;
  for (uint8_t c : eight_n1)
  {
    const bool odd_ones = __builtin_popcount(c) % 2;
    seven_e1.push_back(odd_ones ? (c | 0x80) : c);
    seven_o1.push_back(odd_ones ? c : (c | 0x80));
  }
  const LineGuess n = guessLineSettings(eight_n1, 0, 9600), e = guessLineSettings(seven_e1, 0, 9600),
                  o = guessLineSettings(seven_o1, 0, 9600);
  EXPECT_EQ(n.data_bits, 8u);
  EXPECT_EQ(n.parity, 'N');
  EXPECT_EQ(e.data_bits, 7u);
  EXPECT_EQ(e.parity, 'E');
  EXPECT_EQ(o.parity, 'O');
  EXPECT_FALSE(e.baud_suspect);
  EXPECT_EQ(e.profiles, (std::vector<std::string>{"haas_classic_rs232_7e1", "fanuc_0i_rs232"}));
  // 7N2 read at 8N1: the first stop bit is bit 7 of every byte.
  std::vector<uint8_t> seven_n2;
  for (uint8_t c : eight_n1)
    seven_n2.push_back(c | 0x80);
  const LineGuess m = guessLineSettings(seven_n2, 0, 9600);
  EXPECT_EQ(m.data_bits, 7u);
  EXPECT_NE(m.line.find("set 7 data bits, no parity, 2 stop bits"), std::string::npos) << m.line;
  EXPECT_EQ(m.profiles, (std::vector<std::string>{"fanuc_0i_rs232_7n2"}));

  // A baud rate that differs: characters that are not program text, and framing errors.
  std::vector<uint8_t> garbled;
  for (int i = 0; i < 300; ++i)
    garbled.push_back(static_cast<uint8_t>((i * 151 + 7) & 0xff));
  const LineGuess g = guessLineSettings(garbled, 40, 9600);
  EXPECT_TRUE(g.baud_suspect);
  EXPECT_EQ(g.data_bits, 0u);
  EXPECT_NE(g.line.find("baud rate is likely not 9600"), std::string::npos) << g.line;
  EXPECT_TRUE(guessLineSettings({}, 0, 9600).line == "nothing received");
}

TEST(PortDoctor, TellsSevenE1FromEightN1InTheSimulatedPunchAt9600)
{
  const ToolRun seven = listenToPunch(true);
  EXPECT_EQ(seven.status, 0) << seven.output;
  EXPECT_NE(seven.output.find("line: 7 data bits, even parity (7E1"), std::string::npos) << seven.output;
  EXPECT_NE(seven.output.find("9600 baud looks right"), std::string::npos) << seven.output;
  EXPECT_NE(seven.output.find("profile: haas_classic_rs232_7e1, fanuc_0i_rs232"), std::string::npos) << seven.output;

  const ToolRun eight = listenToPunch(false);
  EXPECT_EQ(eight.status, 0) << eight.output;
  EXPECT_NE(eight.output.find("line: 8 data bits, no parity (8N1)"), std::string::npos) << eight.output;
  EXPECT_NE(eight.output.find("profile: haas_classic_rs232 (at 115200 baud there)"), std::string::npos) << eight.output;
}

TEST(PortDoctor, ProfileTableMatchesConfigControls)
{
  for (const auto& profile : serialProfiles())
  {
    const YAML::Node file = YAML::LoadFile(std::string(CONTROLS_DIR) + "/" + profile.name + ".yaml");
    EXPECT_EQ(file["baud"].as<unsigned>(), profile.baud) << profile.name;
    EXPECT_EQ(file["data_bits"] ? file["data_bits"].as<unsigned>() : 8u, profile.data_bits) << profile.name;
    const std::string parity = file["parity"] ? file["parity"].as<std::string>() : "none";
    EXPECT_EQ(static_cast<char>(std::toupper(parity == "none" ? 'N' : parity[0])), profile.parity) << profile.name;
    EXPECT_EQ(file["stop_bits"] ? file["stop_bits"].as<unsigned>() : 1u, profile.stop_bits) << profile.name;
  }
}
