// The XModem tools as a user runs them: the `cnc_dnc send` and `cnc_dnc receive` executables against
// sim_haas_serial xmodem (both spawned as processes, the simulator on its own pty), and the
// simulator's fault injection (--faults, seeded) against this process's XModem over the pty.
// Checks exit statuses (0 only for an exact file, 1 with one `cnc_dnc ...: error: ...` line, 2 for
// a bad command line), plain progress lines when stderr is no terminal, the simulator's SEND key
// (SIGUSR1), and that no failed transfer leaves a partial file. No sleeps: every wait is a read of
// a process's output with a timeout, or the exit of a process whose own timeouts bound it.
#include <fcntl.h>
#include <gtest/gtest.h>
#include <poll.h>
#include <signal.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <dirent.h>
#include <algorithm>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <fstream>
#include <iostream>
#include <map>
#include <mutex>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "cnc_bridge/common/error.h"
#include "cnc_bridge/transport/serial_port.h"
#include "cnc_bridge/xmodem/file_transfer.h"
#include "peer_process.h"
#include "temp_dir.h"
#include "testing/pty.h"

using namespace cnc_bridge;
using namespace cnc_bridge::test;

namespace
{
std::vector<std::string> filesIn(const std::string& dir)
{
  std::vector<std::string> names;
  if (DIR* d = ::opendir(dir.c_str()))
  {
    while (dirent* e = ::readdir(d))
      if (std::string(e->d_name) != "." && std::string(e->d_name) != "..")
        names.push_back(e->d_name);
    ::closedir(d);
  }
  std::sort(names.begin(), names.end());
  return names;
}

std::vector<std::string> lines(const std::string& text)
{
  std::vector<std::string> out;
  std::istringstream in(text);
  for (std::string line; std::getline(in, line);)
    out.push_back(line);
  return out;
}

/// An NC program with O number \p number, about \p size bytes, LF line ends.
std::string program(unsigned number, size_t size)
{
  char head[64];
  std::snprintf(head, sizeof(head), "%%\nO%05u (CLI TEST)\n", number);
  std::string out = head;
  for (unsigned n = 10; out.size() < size; n += 10)
    out += "N" + std::to_string(n) + " G01 X" + std::to_string((n * 37) % 1000) + ".5 F200.\n";
  return out + "M30\n%\n";
}

/// Starts \p argv with stdout and stderr going to \p out_fd and \p err_fd (closed in the child after dup).
pid_t spawn(const std::vector<std::string>& argv, int out_fd, int err_fd)
{
  const pid_t pid = ::fork();
  if (pid == 0)
  {
    ::dup2(out_fd, 1);
    ::dup2(err_fd, 2);
    const int null = ::open("/dev/null", O_RDONLY);
    ::dup2(null, 0);
    cnc_bridge::test::execOrExit(argv);
  }
  return pid;
}

int exitStatus(pid_t pid)
{
  int status = 0;
  ::waitpid(pid, &status, 0);
  return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
}

/// A finished run of the cnc_dnc tool: exit status and what it printed (to files: no terminal).
struct ToolRun
{
  int status = -1;
  std::string out;
  std::string err;
};

/// cnc_dnc started in the background; finish() waits for it (its own --timeout bounds the wait).
class Tool
{
 public:
  Tool(const std::vector<std::string>& args, const std::string& dir) : out_(dir + "/tool.out"), err_(dir + "/tool.err")
  {
    std::vector<std::string> argv = {CNC_DNC};
    argv.insert(argv.end(), args.begin(), args.end());
    const int out = ::open(out_.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    const int err = ::open(err_.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    pid_ = spawn(argv, out, err);
    ::close(out);
    ::close(err);
  }
  ToolRun finish()
  {
    ToolRun run;
    run.status = exitStatus(pid_);
    pid_ = -1;
    run.out = readFile(out_);
    run.err = readFile(err_);
    return run;
  }
  ~Tool()
  {
    if (pid_ > 0)
    {
      ::kill(pid_, SIGKILL);
      ::waitpid(pid_, nullptr, 0);
    }
  }

 private:
  std::string out_, err_;
  pid_t pid_ = -1;
};

ToolRun cncDnc(const std::vector<std::string>& args, const std::string& dir)
{
  return Tool(args, dir).finish();
}

/// A failed run: exit status 1 and exactly one line on stderr, "cnc_dnc COMMAND: error: ...",
/// containing \p reason; nothing on stdout.
void expectOneErrorLine(const ToolRun& run, const std::string& command, const std::string& reason)
{
  EXPECT_EQ(run.status, 1) << run.err;
  const auto err = lines(run.err);
  ASSERT_EQ(err.size(), 1u) << run.err;
  EXPECT_EQ(err[0].rfind("cnc_dnc " + command + ": error: ", 0), 0u) << err[0];
  EXPECT_NE(err[0].find(reason), std::string::npos) << err[0];
  EXPECT_EQ(run.out, "");
}

/// sim_haas_serial xmodem on its own pty; its output is read line by line.
class Simulator
{
 public:
  Simulator(const std::string& dir, const std::vector<std::string>& options, const std::string& timeout_scale = "0.1")
  {
    int fds[2];
    if (::pipe(fds) != 0)
      throw std::runtime_error("pipe");
    std::vector<std::string> argv = {SIM_HAAS_SERIAL,  "xmodem", "--dir",           dir,
                                     "--nak-interval", "0.2",    "--timeout-scale", timeout_scale};
    argv.insert(argv.end(), options.begin(), options.end());
    pid_ = spawn(argv, fds[1], fds[1]);
    ::close(fds[1]);
    output_ = fds[0];
    const std::string first = waitFor("sim_haas_serial pty ", std::chrono::seconds(10));
    if (first.empty())
      throw std::runtime_error("sim_haas_serial did not start: " + seen_);
    port_ = first.substr(first.rfind(' ') + 1);
  }
  ~Simulator()
  {
    stop();
    ::close(output_);
  }
  /// Stops the simulator (SIGTERM) and waits for it. \returns its exit status.
  int stop()
  {
    if (pid_ <= 0)
      return -1;
    ::kill(pid_, SIGTERM);
    const int status = exitStatus(pid_);
    pid_ = -1;
    waitFor("\n", std::chrono::milliseconds(1000));  // reads what is left up to the end of its output
    return status;
  }
  const std::string& port() const { return port_; }
  pid_t pid() const { return pid_; }

  /// The next line of output containing \p text ("" if none came within \p timeout).
  std::string waitFor(const std::string& text, std::chrono::milliseconds timeout)
  {
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    for (;;)
    {
      for (size_t end; (end = pending_.find('\n')) != std::string::npos;)
      {
        const std::string line = pending_.substr(0, end);
        pending_.erase(0, end + 1);
        if (line.find(text) != std::string::npos)
          return line;
      }
      const auto left =
          std::chrono::duration_cast<std::chrono::milliseconds>(deadline - std::chrono::steady_clock::now());
      pollfd p{output_, POLLIN, 0};
      if (left.count() <= 0 || ::poll(&p, 1, static_cast<int>(left.count())) <= 0)
        return "";
      char buffer[4096];
      const ssize_t n = ::read(output_, buffer, sizeof(buffer));
      if (n <= 0)
        return "";
      pending_.append(buffer, n);
      seen_.append(buffer, n);
    }
  }
  /// Everything the simulator printed so far (for failure messages).
  const std::string& seen() const { return seen_; }

 private:
  pid_t pid_ = -1;
  int output_ = -1;
  std::string port_;
  std::string pending_;
  std::string seen_;
};

constexpr auto kSimulatorReply = std::chrono::seconds(20);
}  // namespace

// ---------------------------------------------------------------------------------------------
TEST(CncDncCli, SendStoresTheExactProgramOnTheSimulatedHaas)
{
  TempDir dir("test_xmodem_cli");
  const std::string memory = dir.path + "/haas";
  Simulator haas(memory, {});
  const std::string source = dir.path + "/O01234.nc";
  const std::string text = program(1234, 5000);
  writeFile(source, text);
  const ToolRun run =
      cncDnc({"send", "--port", haas.port(), "--mode", "checksum", "--timeout", "20", source}, dir.path);
  ASSERT_EQ(run.status, 0) << run.err;
  EXPECT_NE(haas.waitFor("received " + memory + "/O01234.nc", kSimulatorReply), "") << haas.seen();
  EXPECT_EQ(readFile(memory + "/O01234.nc"), text);
  // One result line on stdout; the Haas's CAN answer to EOT is reported as complete.
  const auto out = lines(run.out);
  ASSERT_EQ(out.size(), 1u) << run.out;
  EXPECT_EQ(out[0].rfind("sent " + source + ": ", 0), 0u) << out[0];
  EXPECT_NE(out[0].find("answered EOT with CAN"), std::string::npos) << out[0];
  // stderr is a file, not a terminal: plain progress lines, no carriage returns, the last one 100 %.
  EXPECT_EQ(run.err.find('\r'), std::string::npos);
  const auto err = lines(run.err);
  ASSERT_FALSE(err.empty());
  EXPECT_EQ(err.back().rfind("send " + source + " [", 0), 0u) << err.back();
  EXPECT_NE(err.back().find("100%"), std::string::npos) << err.back();
}

TEST(CncDncCli, ReceiveStoresTheSimulatorsProgramExactly)
{
  TempDir dir("test_xmodem_cli");
  const std::string source = dir.path + "/O00777.nc";
  const std::string text = program(777, 3000);
  writeFile(source, text);
  Simulator haas(dir.path + "/haas", {"--program", source});
  const std::string target = dir.path + "/received.nc";
  writeFile(target, "previous version\n");
  const ToolRun run =
      cncDnc({"receive", "--port", haas.port(), "--mode", "checksum", "--timeout", "20", target}, dir.path);
  ASSERT_EQ(run.status, 0) << run.err;
  EXPECT_EQ(readFile(target), text);
  const auto out = lines(run.out);
  ASSERT_EQ(out.size(), 1u) << run.out;
  EXPECT_EQ(out[0].rfind("received " + target + " (" + std::to_string(text.size()) + " bytes)", 0), 0u) << out[0];
  EXPECT_EQ(run.err.find('\r'), std::string::npos);
  ASSERT_FALSE(run.err.empty());
  EXPECT_EQ(lines(run.err).back().rfind("receive " + target + " ", 0), 0u) << run.err;
}

// Haas setting 25 and the two ways of summing an end of block: with the simulated control set to
// each pattern and each reading, cnc_dnc set the same moves the program exactly both ways; set
// to the other reading, a receive fails naming the reading the control uses.
TEST(CncDncCli, EveryEndOfBlockPatternAndChecksumReadingMovesTheProgramBothWays)
{
  TempDir dir("test_xmodem_cli");
  const std::string source = dir.path + "/O02500.nc";
  const std::string text = program(2500, 1500);
  writeFile(source, text);
  for (const char* reading : {"wire", "lf"})
  {
    for (const char* eob : {"lf", "cr", "crlf", "crcr", "lflf"})
    {
      SCOPED_TRACE(std::string(eob) + " " + reading);
      const std::string memory = dir.path + "/haas_" + eob + "_" + reading;
      Simulator haas(memory, {"--eob", eob, "--eob-checksum", reading, "--program", source});
      const std::vector<std::string> options = {"--port", haas.port(), "--mode", "checksum",       "--timeout",
                                                "20",     "--eob",     eob,      "--eob-checksum", reading};
      std::vector<std::string> send = {"send"};
      send.insert(send.end(), options.begin(), options.end());
      send.push_back(source);
      const ToolRun sent = cncDnc(send, dir.path);
      ASSERT_EQ(sent.status, 0) << sent.err;
      EXPECT_NE(haas.waitFor("received " + memory + "/O02500.nc", kSimulatorReply), "") << haas.seen();
      EXPECT_EQ(readFile(memory + "/O02500.nc"), text);

      std::vector<std::string> receive = {"receive"};
      receive.insert(receive.end(), options.begin(), options.end());
      receive.push_back(dir.path + "/back.nc");
      const ToolRun received = cncDnc(receive, dir.path);
      ASSERT_EQ(received.status, 0) << received.err;
      EXPECT_EQ(readFile(dir.path + "/back.nc"), text);
    }
  }
}

TEST(CncDncCli, AReceiveOnTheOtherChecksumReadingSaysWhichOneTheControlUses)
{
  TempDir dir("test_xmodem_cli");
  const std::string source = dir.path + "/O02501.nc";
  writeFile(source, program(2501, 1500));
  Simulator haas(dir.path + "/haas", {"--eob", "crlf", "--eob-checksum", "lf", "--program", source});
  const std::string target = dir.path + "/received.nc";
  const ToolRun run = cncDnc({"receive", "--port", haas.port(), "--mode", "checksum", "--timeout", "20", "--eob",
                              "crlf", "--retries", "3", target},
                             dir.path);
  expectOneErrorLine(run, "receive", "set --eob-checksum to lf");
  EXPECT_FALSE(exists(target));
}

// --send-on signal: the control sends only when its operator presses SEND (SIGUSR1). A host
// asking before that gets nothing and gives up with one clear line; after SIGUSR1 it gets the program.
TEST(CncDncCli, SimulatorSendsOnlyAfterSendIsPressed)
{
  TempDir dir("test_xmodem_cli");
  const std::string source = dir.path + "/O00042.nc";
  const std::string text = program(42, 2000);
  writeFile(source, text);
  Simulator haas(dir.path + "/haas", {"--program", source, "--send-on", "signal"});
  const std::string target = dir.path + "/received.nc";

  const ToolRun early =
      cncDnc({"receive", "--port", haas.port(), "--mode", "checksum", "--timeout", "1.5", target}, dir.path);
  expectOneErrorLine(early, "receive", "did not start");
  EXPECT_FALSE(exists(target));

  // --timeout 12: the host repeats its NAK every 2 s, and the control sends at the first NAK after SEND.
  Tool waiting({"receive", "--port", haas.port(), "--mode", "checksum", "--timeout", "12", target}, dir.path);
  ASSERT_EQ(::kill(haas.pid(), SIGUSR1), 0);
  EXPECT_NE(haas.waitFor("SEND pressed", kSimulatorReply), "") << haas.seen();
  const ToolRun run = waiting.finish();
  ASSERT_EQ(run.status, 0) << run.err;
  EXPECT_EQ(readFile(target), text);
  EXPECT_NE(haas.waitFor("sent " + source, kSimulatorReply), "") << haas.seen();
}

TEST(CncDncCli, FailuresExitOneWithOneErrorLineAndLeaveNoFile)
{
  TempDir dir("test_xmodem_cli");
  PtyMaster silent;  // a peer that never answers
  const std::string source = dir.path + "/O00001.nc";
  writeFile(source, program(1, 500));

  expectOneErrorLine(cncDnc({"send", "--port", silent.slavePath(), dir.path + "/missing.nc"}, dir.path), "send",
                     "missing.nc");
  expectOneErrorLine(cncDnc({"send", "--port", dir.path + "/no_such_tty", source}, dir.path), "send", "no_such_tty");
  expectOneErrorLine(cncDnc({"receive", "--port", dir.path + "/no_such_tty", dir.path + "/x.nc"}, dir.path), "receive",
                     "no_such_tty");
  expectOneErrorLine(cncDnc({"send", "--port", silent.slavePath(), "--timeout", "0.5", source}, dir.path), "send",
                     "did not start");

  const std::string target = dir.path + "/kept.nc";
  writeFile(target, "previous version\n");
  expectOneErrorLine(cncDnc({"receive", "--port", silent.slavePath(), "--timeout", "0.5", target}, dir.path), "receive",
                     "did not start");
  EXPECT_EQ(readFile(target), "previous version\n");
  expectOneErrorLine(
      cncDnc({"receive", "--port", silent.slavePath(), "--timeout", "0.5", dir.path + "/new.nc"}, dir.path), "receive",
      "did not start");
  EXPECT_FALSE(exists(dir.path + "/new.nc"));
  // Only the files this test wrote: no temporary file of a failed receive.
  EXPECT_EQ(filesIn(dir.path), (std::vector<std::string>{"O00001.nc", "kept.nc", "tool.err", "tool.out"}));
}

// Haas keeps probing/WIPS and OEM macros in O08000-O09999: send and drip refuse those numbers
// (by file name or by the program's O number) before the port is opened, unless --allow-protected.
TEST(CncDncCli, ProtectedProgramIsRefusedAndTheControlReceivesNothing)
{
  TempDir dir("test_xmodem_cli");
  const std::string memory = dir.path + "/haas";
  Simulator haas(memory, {});
  const std::string source = dir.path + "/probe.nc";
  const std::string text = program(9001, 2000);
  writeFile(source, text);
  const ToolRun refused =
      cncDnc({"send", "--port", haas.port(), "--mode", "checksum", "--timeout", "20", source}, dir.path);
  expectOneErrorLine(refused, "send", "in the protected range O08000-O09999");
  EXPECT_NE(refused.err.find("--allow-protected"), std::string::npos) << refused.err;
  EXPECT_FALSE(exists(memory + "/O09001.nc"));

  PtyMaster line;  // the drip-fed control: any byte cnc_dnc wrote would be waiting here
  writeFile(dir.path + "/O08500.nc", program(100, 500));
  expectOneErrorLine(cncDnc({"drip", "--port", line.slavePath(), "--no-pace", dir.path + "/O08500.nc"}, dir.path),
                     "drip", "O08500");
  uint8_t byte = 0;
  EXPECT_EQ(line.read(&byte, 1, Milliseconds(0)), 0u);

  const ToolRun allowed = cncDnc(
      {"send", "--port", haas.port(), "--mode", "checksum", "--timeout", "20", "--allow-protected", source}, dir.path);
  ASSERT_EQ(allowed.status, 0) << allowed.err;
  EXPECT_NE(haas.waitFor("received " + memory + "/O09001.nc", kSimulatorReply), "") << haas.seen();
  EXPECT_EQ(readFile(memory + "/O09001.nc"), text);
}

// The number is read where the control takes it: a comment block, blank lines or tape leader
// before O09010 do not hide it (they used to: only the first block was looked at). The simulated
// Haas stores nothing.
TEST(CncDncCli, AProtectedNumberAfterCommentsAndLeaderIsRefusedAndTheControlReceivesNothing)
{
  TempDir dir("test_xmodem_cli");
  const std::string memory = dir.path + "/haas";
  Simulator haas(memory, {});
  std::string hidden = program(9010, 1500);
  hidden.replace(0, 2, std::string("%\n(SETUP SHEET: VISE ON TABLE)\n\n\0\0  \n", 37));
  writeFile(dir.path + "/setup.nc", hidden);
  expectOneErrorLine(
      cncDnc({"send", "--port", haas.port(), "--mode", "checksum", "--timeout", "20", dir.path + "/setup.nc"},
             dir.path),
      "send", "is program O09010, in the protected range O08000-O09999");
  // A number the control would take but that cannot be read (nine digits) is refused as well.
  writeFile(dir.path + "/odd.nc", "%\nO123456789 (MACRO)\nM99\n%\n");
  expectOneErrorLine(
      cncDnc({"send", "--port", haas.port(), "--mode", "checksum", "--timeout", "20", dir.path + "/odd.nc"}, dir.path),
      "send", "cannot be read from its first block");
  EXPECT_TRUE(!exists(memory) || filesIn(memory).empty());
}

// receive --max-bytes: a control that sends more is cancelled, nothing is stored, and the error
// names the option.
TEST(CncDncCli, ReceiveCancelsAProgramLongerThanMaxBytesAndStoresNothing)
{
  TempDir dir("test_xmodem_cli");
  const std::string source = dir.path + "/O00778.nc";
  writeFile(source, program(778, 8000));
  Simulator haas(dir.path + "/haas", {"--program", source});
  const std::string target = dir.path + "/received.nc";
  const ToolRun run =
      cncDnc({"receive", "--port", haas.port(), "--mode", "checksum", "--timeout", "20", "--max-bytes", "2048", target},
             dir.path);
  EXPECT_EQ(run.status, 1) << run.err;
  ASSERT_FALSE(lines(run.err).empty());
  const std::string error = lines(run.err).back();  // after a progress line of the first block
  EXPECT_EQ(error.rfind("cnc_dnc receive: error: ", 0), 0u) << run.err;
  EXPECT_NE(error.find("longer than --max-bytes (2048 bytes)"), std::string::npos) << run.err;
  EXPECT_FALSE(exists(target));
  EXPECT_EQ(filesIn(dir.path), (std::vector<std::string>{"O00778.nc", "haas", "tool.err", "tool.out"}));
}

TEST(CncDncCli, BadCommandLineExitsTwo)
{
  TempDir dir("test_xmodem_cli");
  const std::vector<std::vector<std::string>> bad = {
      {},
      {"frobnicate"},
      {"send"},
      {"send", dir.path + "/a.nc"},  // no --port
      {"send", "--port", "/dev/null", "--mode", "zmodem", "a.nc"},
      {"send", "--port", "/dev/null", "--eob", "semicolon", "a.nc"},
      {"send", "--port", "/dev/null", "--baud", "fast", "a.nc"},
      {"receive", "--port", "/dev/null", "--mode", "1k", "a.nc"},
      {"receive", "--port", "/dev/null", "--timeout", "0", "a.nc"},
      {"receive", "--port", "/dev/null", "--file-eob", "x", "a.nc"},
  };
  for (const auto& args : bad)
  {
    const ToolRun run = cncDnc(args, dir.path);
    std::string line;
    for (const auto& a : args)
      line += a + " ";
    EXPECT_EQ(run.status, 2) << "cnc_dnc " << line << "\n" << run.err;
    EXPECT_FALSE(run.err.empty()) << "cnc_dnc " << line;
  }
  EXPECT_EQ(cncDnc({"--help"}, dir.path).status, 0);
  EXPECT_EQ(cncDnc({"send", "--help"}, dir.path).status, 0);
}

// ---------------------------------------------------------------------------------------------
// sim_haas_serial --faults (seeded; bytes it writes and reads are damaged): every transfer in
// either direction delivers the exact program or fails with a clear error, and no failed transfer
// leaves a file (or a temporary file) on either side. This process is the host, with timeouts
// short enough for a test (the simulator's are scaled by 0.05).
TEST(SimHaasSerialFaults, EveryTransferIsExactOrAClearErrorWithNoPartialFile)
{
  TempDir dir("test_xmodem_cli");
  const std::string memory = dir.path + "/haas";
  const std::string host = dir.path + "/host";
  ::mkdir(host.c_str(), 0755);
  const std::string offered = dir.path + "/O09000.nc";
  const std::string offered_text = program(9000, 2500);
  writeFile(offered, offered_text);
  Simulator haas(memory, {"--program", offered, "--faults", "flip=0.0015,drop=0.0015,lose=0.03,read=1,seed=11"},
                 "0.05");

  xmodem::Config config;
  config.nak_interval = Milliseconds(400);
  config.start_timeout = config.start_wait = Milliseconds(15000);  // the simulator may still be in a failed transfer
  config.block_timeout = config.ack_timeout = config.eot_timeout = Milliseconds(300);
  config.char_timeout = Milliseconds(50);
  config.purge_quiet = Milliseconds(40);
  config.stale_nak_settle = Milliseconds(150);
  SerialSettings settings;
  settings.device = haas.port();
  settings.baud = 115200;
  const xmodem::TextOptions text;

  constexpr unsigned kEachWay = 10;
  std::vector<bool> sent_ok(kEachWay, false);
  unsigned ok = 0, failed = 0, repaired = 0;
  for (unsigned i = 0; i < kEachWay; ++i)
  {
    const std::string source = host + "/O0" + std::to_string(1000 + i) + ".nc";
    writeFile(source, program(1000 + i, 1500 + 300 * i));
    const std::string target = host + "/received_" + std::to_string(i) + ".nc";
    for (const bool send : {true, false})
    {
      SerialPort port(settings);
      xmodem::Stats stats;
      try
      {
        if (send)
        {
          xmodem::sendFile(port, source, xmodem::Mode::kChecksum, config, text, nullptr, nullptr, &stats);
          sent_ok[i] = true;
        }
        else
        {
          xmodem::receiveFile(port, target, xmodem::Mode::kChecksum, config, text, nullptr, nullptr, &stats);
          EXPECT_EQ(readFile(target), offered_text) << "receive " << i;
        }
        ++ok;
      }
      catch (const Error& e)
      {
        ++failed;
        EXPECT_GT(std::string(e.what()).size(), 20u);
        if (!send)
        {
          EXPECT_FALSE(exists(target)) << "a failed receive left " << target << ": " << e.what();
        }
      }
      repaired += stats.retries;
    }
  }
  ASSERT_EQ(haas.stop(), 0) << haas.seen();
  // The control's memory: a program the host reported sent is there exactly; one that failed is
  // there exactly (the last answer was lost) or not at all; nothing else (no temporary file).
  std::vector<std::string> expected;
  for (unsigned i = 0; i < kEachWay; ++i)
  {
    const std::string name = "O0" + std::to_string(1000 + i) + ".nc";
    if (sent_ok[i] || exists(memory + "/" + name))
    {
      expected.push_back(name);
      EXPECT_EQ(readFile(memory + "/" + name), readFile(host + "/" + name)) << name;
    }
  }
  EXPECT_EQ(filesIn(memory), expected);
  EXPECT_GT(ok, kEachWay);                     // most transfers got through the damaged line
  EXPECT_GT(repaired + failed, kEachWay / 2);  // which really was damaged
  std::cout << "sim_haas_serial --faults: " << ok << " transfers exact, " << failed << " failed cleanly, " << repaired
            << " blocks resent or NAKed by this side\n"
            << haas.seen();
}

// ---------------------------------------------------------------------------------------------
// A user starts lrzsz `rx` first, then `cnc_dnc send`: rx's NAK reaches the port before cnc_dnc
// has opened it. That NAK is the start: block 1 must follow it without rx having to NAK again (rx
// repeats its request only after 10 s). The two programs talk through this process, which relays
// every byte between their ptys and records who sent what.
namespace
{
/// Relays bytes between two pty masters in both directions and keeps a record of each direction.
class Tap
{
 public:
  Tap(Transport& a, Transport& b)
      : a_(a),
        b_(b),
        a_to_b_([this] { pump(a_, b_, from_a_, nullptr); }),
        b_to_a_([this] { pump(b_, a_, from_b_, &lose_eot_from_b_); })
  {
  }
  ~Tap()
  {
    stop_ = true;
    a_to_b_.join();
    b_to_a_.join();
  }
  std::string fromA() const { return copy(from_a_); }
  std::string fromB() const { return copy(from_b_); }
  /// The next EOT side B sends is recorded but not passed on, as if the receiver had flushed it
  /// away (lrzsz rx flushes its input right after it ACKs a block).
  void loseNextEotFromB() { lose_eot_from_b_ = true; }
  /// Waits until side A has sent at least \p n bytes.
  bool waitForA(size_t n, Milliseconds timeout) const
  {
    std::unique_lock<std::mutex> lock(mutex_);
    return changed_.wait_for(lock, timeout, [&] { return from_a_.size() >= n; });
  }

 private:
  void pump(Transport& from, Transport& to, std::string& record, std::atomic<bool>* lose_eot)
  {
    uint8_t buffer[4096];
    while (!stop_)
    {
      size_t n = 0;
      try
      {
        n = from.read(buffer, sizeof(buffer), Milliseconds(50));
        // An EOT goes alone, once its sender has the ACK of the last block.
        const bool lost = lose_eot != nullptr && n == 1 && buffer[0] == 0x04 && lose_eot->exchange(false);
        if (n > 0 && !lost)
          to.write(buffer, n, Milliseconds(5000));
      }
      catch (const Error&)
      {
        return;
      }
      if (n > 0)
      {
        std::lock_guard<std::mutex> lock(mutex_);
        record.append(reinterpret_cast<const char*>(buffer), n);
        changed_.notify_all();
      }
    }
  }
  std::string copy(const std::string& s) const
  {
    std::lock_guard<std::mutex> lock(mutex_);
    return s;
  }

  Transport& a_;
  Transport& b_;
  mutable std::mutex mutex_;
  mutable std::condition_variable changed_;
  std::string from_a_, from_b_;
  std::atomic<bool> stop_{false};
  std::atomic<bool> lose_eot_from_b_{false};
  std::thread a_to_b_, b_to_a_;
};

/// Starts lrzsz \p program (`rx FILE` or `sx FILE`) in \p dir with its stdin and stdout on \p tty;
/// what it says (its verbose account of every block, timeout and error) goes to \p dir/\p program.log.
pid_t startLrzsz(const char* program, const std::string& tty, const std::string& dir, const std::string& file)
{
  const pid_t pid = ::fork();
  if (pid == 0)
  {
    const int fd = ::open(tty.c_str(), O_RDWR | O_NOCTTY);
    if (fd < 0 || ::chdir(dir.c_str()) != 0)
      ::_exit(126);
    ::dup2(fd, 0);
    ::dup2(fd, 1);
    const int log = ::open((std::string(program) + ".log").c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0600);
    ::dup2(log, 2);
    ::execl((std::string("/usr/bin/") + program).c_str(), program, "-vv", file.c_str(), static_cast<char*>(nullptr));
    ::_exit(127);
  }
  return pid;
}

pid_t startRx(const std::string& tty, const std::string& dir, const std::string& file)
{
  return startLrzsz("rx", tty, dir, file);
}

/// The control characters of an XModem exchange by name, a packet's contents as a count: what
/// each side said, readable in a failure message.
std::string exchange(const std::string& bytes)
{
  std::string out;
  for (size_t i = 0; i < bytes.size(); ++i)
  {
    const unsigned char c = static_cast<unsigned char>(bytes[i]);
    if (c == 0x01 && i + 131 < bytes.size())
    {
      out += "[block " + std::to_string(static_cast<unsigned char>(bytes[i + 1])) + "]";
      i += 131;
      continue;
    }
    static const std::map<unsigned char, const char*> names{
        {0x04, "EOT"}, {0x06, "ACK"}, {0x15, "NAK"}, {0x18, "CAN"}, {'C', "C"}};
    const auto name = names.find(c);
    out += name != names.end() ? std::string(name->second) : "0x" + std::to_string(c);
    out += ' ';
  }
  return out;
}

/// lrzsz `rx FILE` in \p dir on one pty, the tap between it and the pty `cnc_dnc send` opens.
class RxThroughTap
{
 public:
  RxThroughTap(const std::string& dir, const std::string& file)
      : dir_(dir), tap_(rx_side_, dnc_side_), rx_(startRx(rx_side_.slavePath(), dir, file))
  {
  }
  /// Side A is rx, side B cnc_dnc.
  Tap& tap() { return tap_; }
  const Tap& tap() const { return tap_; }
  /// The port cnc_dnc opens.
  const std::string& cncDncPort() const { return dnc_side_.slavePath(); }
  /// Waits for rx's start request (it has set its port up by then).
  bool started() const { return tap_.waitForA(1, Milliseconds(20000)); }
  /// `cnc_dnc send --mode checksum --binary --retries 1 FILE` to rx. One retry: rx answers a second
  /// EOT only when it did not get the first, and has left otherwise.
  ToolRun send(const std::string& file) const
  {
    return cncDnc(
        {"send", "--port", cncDncPort(), "--mode", "checksum", "--binary", "--timeout", "30", "--retries", "1", file},
        dir_);
  }
  /// rx's exit status, once it has ended.
  int rxStatus() const { return exitStatus(rx_); }
  /// What rx said (its verbose log) and what each side sent, for a failure message.
  std::string account() const
  {
    return "rx said: " + readFile(dir_ + "/rx.log") + "\nrx sent: " + exchange(tap_.fromA()) +
           "\ncnc_dnc sent: " + exchange(tap_.fromB());
  }

 private:
  std::string dir_;
  PtyMaster rx_side_, dnc_side_;
  Tap tap_;
  pid_t rx_;
};
}  // namespace

// The interop check that reported complete transfers as failed: cnc_dnc send to lrzsz rx, a
// 1025-byte program, again and again. Every send succeeds, and rx has the exact program each time.
TEST(CncDncCli, EverySendToRxOfAProgramSucceedsAndArrivesExact)
{
  TempDir dir("test_xmodem_cli");
  const std::string payload = program(1025, 1025);
  writeFile(dir.path + "/O01025.nc", payload);
  int unconfirmed = 0;
  for (int round = 0; round < 10; ++round)
  {
    SCOPED_TRACE("round " + std::to_string(round));
    const std::string received = "received" + std::to_string(round) + ".nc";
    const RxThroughTap link(dir.path, received);
    ASSERT_TRUE(link.started()) << "rx sent no start request";
    const ToolRun send = link.send(dir.path + "/O01025.nc");
    EXPECT_EQ(link.rxStatus(), 0) << link.account();
    EXPECT_EQ(send.status, 0) << send.err;
    unconfirmed += send.out.find("the end was not") != std::string::npos ? 1 : 0;
    const std::string got = readFile(dir.path + "/" + received);
    ASSERT_GE(got.size(), payload.size());
    EXPECT_EQ(got.substr(0, payload.size()), payload);
  }
  std::cout << unconfirmed << " of 10 sends had rx's acknowledgement of the end lost\n";
}

// rx flushes its input right after it ACKs the last block, and an EOT that crosses that flush is
// lost: rx waits on, NAKs, and after some 50 s gives up and deletes the file. cnc_dnc, allowed one
// retry, took the silence after its one EOT for a receiver that had left and reported success
// (CI saw rx fail this way once). Here the tap loses the EOT: cnc_dnc sends it again, and rx keeps
// the file.
TEST(CncDncCli, AnEotLostOnTheWayToRxIsSentAgainAndRxKeepsTheFile)
{
  TempDir dir("test_xmodem_cli");
  const std::string payload = program(1026, 3 * 128 + 7);
  writeFile(dir.path + "/O01026.nc", payload);
  RxThroughTap link(dir.path, "received.nc");
  link.tap().loseNextEotFromB();
  ASSERT_TRUE(link.started()) << "rx sent no start request";
  const ToolRun send = link.send(dir.path + "/O01026.nc");
  EXPECT_EQ(link.rxStatus(), 0) << link.account();
  EXPECT_EQ(send.status, 0) << send.err;
  const std::string from_dnc = link.tap().fromB();
  EXPECT_EQ(std::count(from_dnc.end() - 2, from_dnc.end(), '\x04'), 2) << "cnc_dnc did not send EOT again";
  const std::string got = readFile(dir.path + "/received.nc");
  ASSERT_GE(got.size(), payload.size()) << "rx did not keep the file";
  EXPECT_EQ(got.substr(0, payload.size()), payload);
}

TEST(CncDncCli, SendStartsOnTheNakRxSentBeforeThePortWasOpened)
{
  TempDir dir("test_xmodem_cli");
  const std::string payload = program(4321, 3 * 128 + 40);
  writeFile(dir.path + "/O04321.nc", payload);
  const RxThroughTap link(dir.path, "received.nc");
  ASSERT_TRUE(link.started()) << "rx sent no start request";
  ASSERT_EQ(link.tap().fromA(), "\x15") << "rx's first request is one NAK (checksum mode)";
  {
    // The NAK is now queued on cnc_dnc's side of the link, where nobody has the port open yet.
    const int probe = ::open(link.cncDncPort().c_str(), O_RDONLY | O_NOCTTY | O_NONBLOCK);
    ASSERT_GE(probe, 0);
    pollfd ready{probe, POLLIN, 0};
    ASSERT_EQ(::poll(&ready, 1, 10000), 1) << "the NAK never reached cnc_dnc's port";
    ::close(probe);
  }
  const ToolRun send = link.send(dir.path + "/O04321.nc");
  const int rx_status = link.rxStatus();
  // rx flushes its tty as it exits, so its ACK of EOT can be lost: the send still succeeds (every
  // block was acknowledged) and says the end went unconfirmed.
  EXPECT_EQ(send.status, 0) << send.err;
  EXPECT_EQ(rx_status, 0) << link.account();
  const std::string from_rx = link.tap().fromA(), from_dnc = link.tap().fromB();
  ASSERT_GE(from_dnc.size(), 132u);
  EXPECT_EQ(from_dnc[0], '\x01') << "cnc_dnc's first byte is not SOH";
  EXPECT_EQ(from_dnc[1], '\x01') << "cnc_dnc's first packet is not block 1";
  // After its one NAK rx sent only ACKs, one per block (and the ACK of EOT when it was not lost):
  // no second start request was needed, and no block was NAKed.
  const size_t blocks = (payload.size() + 127) / 128;
  const std::string expected = std::string("\x15") + std::string(blocks, '\x06');
  EXPECT_TRUE(from_rx == expected || from_rx == expected + '\x06') << "rx had to ask again, or NAKed a block";
  const std::string received = readFile(dir.path + "/received.nc");
  ASSERT_GE(received.size(), payload.size());
  EXPECT_EQ(received.substr(0, payload.size()), payload);
  EXPECT_EQ(received.find_first_not_of('\x1a', payload.size()), std::string::npos) << "more than SUB padding";
}

// The other direction: lrzsz `sx` sends a program to `cnc_dnc receive`, which asks with a NAK
// (checksum mode) and stores exactly what sx sent (its last block padded with SUB, which text
// mode removes). Every byte goes through the tap, so the test also sees what cnc_dnc answered: a
// block that came in late on a loaded machine may be NAKed and sent again, but every block is
// ACKed.
TEST(CncDncCli, ReceiveTakesTheExactProgramFromSx)
{
  TempDir dir("test_xmodem_cli");
  const std::string payload = program(4322, 5 * 128 + 17);
  writeFile(dir.path + "/O04322.nc", payload);
  PtyMaster sx_side, dnc_side;
  Tap tap(sx_side, dnc_side);
  const std::string target = dir.path + "/received.nc";
  Tool receive({"receive", "--port", dnc_side.slavePath(), "--mode", "checksum", "--timeout", "30", target}, dir.path);
  const pid_t sx = startLrzsz("sx", sx_side.slavePath(), dir.path, "O04322.nc");
  const ToolRun run = receive.finish();
  exitStatus(sx);  // reaped; what it delivered is checked below
  ASSERT_EQ(run.status, 0) << run.err;
  EXPECT_EQ(readFile(target), payload);
  const std::string from_dnc = tap.fromB();
  ASSERT_FALSE(from_dnc.empty());
  EXPECT_EQ(from_dnc[0], '\x15') << "cnc_dnc's start request is not a NAK";
  const size_t blocks = (payload.size() + 127) / 128;
  // The ACK of EOT may be the last byte before both programs close their ports, and the tap can
  // lose it then.
  EXPECT_GE(static_cast<size_t>(std::count(from_dnc.begin(), from_dnc.end(), '\x06')), blocks)
      << "a block was not ACKed";
  EXPECT_EQ(from_dnc.find_first_not_of("\x06\x15"), std::string::npos) << "cnc_dnc sent more than NAKs and ACKs";
}

// ---------------------------------------------------------------------------------------------
// Wire traces: `cnc_dnc replay` plays the far side of a trace. The Haas capture (a serial
// sniffer's dump of a Haas Classic sending O05555, test/data/xmodem/) played to `cnc_dnc receive`
// hands it the captured program; a trace `cnc_dnc send --wire-trace` recorded against the simulated
// Haas, played back, gets the same send from cnc_dnc again, and a different program is caught.
namespace
{
std::string onlyTraceIn(const std::string& dir)
{
  const auto names = filesIn(dir);
  return names.size() == 1 ? dir + "/" + names[0] : "";
}
}  // namespace

TEST(CncDncReplay, TheHaasCapturePlayedToReceiveHandsItTheCapturedProgram)
{
  TempDir dir("test_xmodem_cli");
  PtyMaster haas_side, dnc_side;
  Tap tap(haas_side, dnc_side);
  const std::string target = dir.path + "/received.nc";
  const std::string replay_dir = dir.path + "/replay";
  ::mkdir(replay_dir.c_str(), 0755);
  Tool replay(
      {"replay", "--port", haas_side.slavePath(), "--speed", "10", XMODEM_TEST_DATA "/haas_capture_cnc_to_pc.trace"},
      replay_dir);
  Tool receive({"receive", "--port", dnc_side.slavePath(), "--mode", "checksum", "--timeout", "30", target}, dir.path);
  const ToolRun received = receive.finish();
  const ToolRun replayed = replay.finish();
  ASSERT_EQ(received.status, 0) << received.err;
  EXPECT_EQ(readFile(target), readFile(XMODEM_TEST_DATA "/haas_O05555.nc"));
  EXPECT_EQ(replayed.status, 0) << replayed.out << replayed.err;
  // Two NAKs, eight block ACKs and the ACK of EOT: what the PC of OpenDNC's capture answered.
  EXPECT_NE(replayed.out.find("the program answered all 11 bytes as recorded"), std::string::npos) << replayed.out;
}

TEST(CncDncReplay, ASendRecordedAgainstTheSimulatedHaasReplaysToTheSameSendAndCatchesAnother)
{
  TempDir dir("test_xmodem_cli");
  const std::string traces = dir.path + "/traces";
  ::mkdir(traces.c_str(), 0755);
  const std::string payload = program(4400, 3 * 128 + 40);
  const std::string file = dir.path + "/O04400.nc";
  writeFile(file, payload);
  {
    Simulator haas(dir.path + "/haas", {});
    const ToolRun sent =
        cncDnc({"send", "--port", haas.port(), "--mode", "checksum", "--timeout", "20", "--wire-trace", traces, file},
               dir.path);
    ASSERT_EQ(sent.status, 0) << sent.err;
  }
  const std::string trace = onlyTraceIn(traces);
  ASSERT_FALSE(trace.empty()) << "trace files: " << filesIn(traces).size();
  auto replayAgainstSendOf = [&](const std::string& path, const std::string& name)
  {
    PtyMaster haas_side, dnc_side;
    Tap tap(haas_side, dnc_side);
    const std::string replay_dir = dir.path + "/" + name;
    ::mkdir(replay_dir.c_str(), 0755);
    Tool replay({"replay", "--port", haas_side.slavePath(), "--slack", "5", trace}, replay_dir);
    const ToolRun sent = cncDnc(
        {"send", "--port", dnc_side.slavePath(), "--mode", "checksum", "--timeout", "10", "--retries", "1", path},
        dir.path);
    return std::make_pair(sent, replay.finish());
  };
  const auto [again, replayed] = replayAgainstSendOf(file, "same");
  EXPECT_EQ(again.status, 0) << again.err;
  EXPECT_EQ(replayed.status, 0) << replayed.out << replayed.err;

  std::string changed = payload;
  changed[payload.size() / 2] = changed[payload.size() / 2] == '1' ? '2' : '1';
  writeFile(dir.path + "/O04401.nc", changed);
  const auto [other, caught] = replayAgainstSendOf(dir.path + "/O04401.nc", "other");
  EXPECT_EQ(caught.status, 1) << caught.out << caught.err;
  EXPECT_NE(caught.out.find("where the trace has"), std::string::npos) << caught.out;
}

TEST(CncDncReplay, WhatIsNoTraceIsABadCommandLineAndThePortReceivesNothing)
{
  TempDir dir("test_xmodem_cli");
  PtyMaster control;
  writeFile(dir.path + "/empty.trace", "# a trace with no entries\n");
  writeFile(dir.path + "/garbage.trace", std::string("\x01\xff not a trace\n"));
  const std::vector<std::pair<std::vector<std::string>, std::string>> bad = {
      {{dir.path}, "is not a file"},
      {{dir.path + "/empty.trace"}, "has no entries"},
      {{dir.path + "/garbage.trace"}, "line 1: bytes outside an entry"},
      {{"--speed", "nan", XMODEM_TEST_DATA "/haas_capture_cnc_to_pc.trace"}, "speed must be above 0"},
      {{"--slack", "-1", XMODEM_TEST_DATA "/haas_capture_cnc_to_pc.trace"}, "--slack must be from 0"},
  };
  for (const auto& [args, reason] : bad)
  {
    std::vector<std::string> command = {"replay", "--port", control.slavePath()};
    command.insert(command.end(), args.begin(), args.end());
    const ToolRun run = cncDnc(command, dir.path);
    EXPECT_EQ(run.status, 2) << args.back() << ": " << run.err;
    EXPECT_NE(run.err.find(reason), std::string::npos) << run.err;
  }
  uint8_t byte = 0;
  EXPECT_EQ(control.read(&byte, 1, Milliseconds(100)), 0u) << "the port received a byte";
}
