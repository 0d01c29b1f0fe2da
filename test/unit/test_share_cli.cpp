// cnc_dnc send/receive --share and cnc_dnc list as a user runs them, against a real smbd
// (samba_server.h): exit 0 and progress lines for a complete transfer, one error line and exit 1
// for a wrong password, a missing share or file, a protected program (the share then holds
// nothing new), exit 2 for a bad command line; a password in the address refused and never printed.
#include <gtest/gtest.h>
#include <sys/stat.h>

#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <random>
#include <sstream>

#include "cnc_bridge/programs/archive.h"
#include "samba_server.h"
#include "temp_dir.h"

using namespace cnc_bridge::test;

namespace
{
struct ToolRun
{
  int status = -1;
  std::string out, err;
};

std::string quoted(const std::string& word)
{
  return "'" + word + "'";
}

std::vector<std::string> lines(const std::string& text)
{
  std::vector<std::string> out;
  std::istringstream in(text);
  for (std::string line; std::getline(in, line);)
    out.push_back(line);
  return out;
}

class ShareCliTest : public ::testing::Test
{
 protected:
  static void SetUpTestSuite()
  {
    // The sanitizer build's cnc_dnc: libsmbclient's allocations kept until exit are not leaks of ours.
    ::setenv("LSAN_OPTIONS", "suppressions=" LSAN_SUPPRESSIONS ":print_suppressions=0", 0);
    dir_ = new TempDir("cnc_share_cli");
    server_ = new SambaServer(dir_->path);
    server_->start();
  }
  static void TearDownTestSuite()
  {
    delete server_;
    delete dir_;
  }

  ToolRun cncDnc(const std::vector<std::string>& args)
  {
    std::string command = CNC_DNC;
    for (const auto& a : args)
      command += " " + quoted(a);
    command += " </dev/null >" + local_.file("out") + " 2>" + local_.file("err");
    ToolRun run;
    const int status = std::system(command.c_str());
    run.status = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
    run.out = readFile(local_.file("out"));
    run.err = readFile(local_.file("err"));
    return run;
  }

  void expectOneErrorLine(const ToolRun& run, const std::string& command, const std::string& reason)
  {
    EXPECT_EQ(run.status, 1) << run.err;
    const auto err = lines(run.err);
    ASSERT_EQ(err.size(), 1u) << run.err;
    EXPECT_EQ(err[0].rfind("cnc_dnc " + command + ": error: ", 0), 0u) << err[0];
    EXPECT_NE(err[0].find(reason), std::string::npos) << err[0];
    EXPECT_EQ(run.out, "");
  }

  TempDir local_{"cnc_share_cli_local"};
  static TempDir* dir_;
  static SambaServer* server_;
};
TempDir* ShareCliTest::dir_ = nullptr;
SambaServer* ShareCliTest::server_ = nullptr;
}  // namespace

TEST_F(ShareCliTest, SendReceiveAndListThroughTheShare)
{
  std::string program = "%\nO01234 (POCKET ROUGH)\n";
  std::mt19937 random(3);
  while (program.size() < 300000)
    program += "G01 X" + std::to_string(random() % 1000) + ". F100.\n";
  program += "M30\n%\n";
  const std::string source = local_.write("O01234.nc", program);
  const std::string credentials = server_->credentials("cli.auth");

  const ToolRun sent = cncDnc({"send", "--share", server_->url("secure"), "--credentials", credentials, source});
  ASSERT_EQ(sent.status, 0) << sent.err;
  EXPECT_EQ(readFile(server_->folder("secure") + "/O01234.nc"), program);
  ASSERT_EQ(lines(sent.out).size(), 1u) << sent.out;
  EXPECT_EQ(sent.out.rfind("sent " + source + " to " + server_->url("secure") + "/O01234.nc: 300", 0), 0u) << sent.out;
  // stderr is a file: plain progress lines, the last at 100 %.
  const auto progress = lines(sent.err);
  ASSERT_FALSE(progress.empty());
  EXPECT_NE(progress.back().find("100%"), std::string::npos) << sent.err;
  EXPECT_EQ(sent.err.find('\r'), std::string::npos);

  const ToolRun received = cncDnc({"receive", "--share", server_->url("secure"), "--credentials", credentials,
                                   "O01234.nc", local_.file("back.nc")});
  ASSERT_EQ(received.status, 0) << received.err;
  EXPECT_EQ(readFile(local_.file("back.nc")), program);
  struct stat info;
  ASSERT_EQ(::stat(local_.file("back.nc").c_str(), &info), 0);
  EXPECT_EQ(info.st_mode & 0007, 0u);  // nothing for others (0640 or narrower)

  writeFile(server_->folder("secure") + "/O00077.nc", "%\nO77 (DEBURR)\n%\n");
  const ToolRun listed = cncDnc({"list", "--share", server_->url("secure"), "--credentials", credentials});
  ASSERT_EQ(listed.status, 0) << listed.err;
  const auto rows = lines(listed.out);
  ASSERT_EQ(rows.size(), 2u) << listed.out;
  EXPECT_EQ(rows[0].rfind("O00077.nc\tO00077\t17\t", 0), 0u) << rows[0];
  EXPECT_NE(rows[0].find("\tDEBURR"), std::string::npos) << rows[0];
  EXPECT_EQ(rows[1].rfind("O01234.nc\tO01234\t" + std::to_string(program.size()) + "\t", 0), 0u) << rows[1];
  EXPECT_NE(rows[1].find("\tPOCKET ROUGH"), std::string::npos) << rows[1];
}

TEST_F(ShareCliTest, FailuresExitOneWithOneClearLine)
{
  const std::string source = local_.write("O01000.nc", "%\nO01000\nM30\n%\n");
  const std::string wrong = server_->credentials("wrong.auth", "nope");
  expectOneErrorLine(cncDnc({"send", "--share", server_->url("secure"), "--credentials", wrong, source}), "send",
                     "wrong user name or password");
  expectOneErrorLine(cncDnc({"send", "--share", server_->url("nosuch"), source}), "send", "no share 'nosuch'");
  expectOneErrorLine(cncDnc({"receive", "--share", server_->url("guest"), "O04321.nc", local_.file("x.nc")}), "receive",
                     "no program 'O04321.nc'");
  EXPECT_FALSE(exists(local_.file("x.nc")));
  const std::string open_file = server_->credentials("open.auth");
  ::chmod(open_file.c_str(), 0644);
  expectOneErrorLine(cncDnc({"list", "--share", server_->url("secure"), "--credentials", open_file}), "list",
                     "mode 0644");
  expectOneErrorLine(cncDnc({"send", "--share", "smb://127.0.0.1:1/guest", "--timeout", "2", source}), "send",
                     "127.0.0.1:1");

  const std::string probe = local_.write("O09100.nc", "%\nO09100 (PROBE CAL)\nM99\n%\n");
  const ToolRun refused = cncDnc({"send", "--share", server_->url("guest"), probe});
  expectOneErrorLine(refused, "send", "protected range O08000-O09999");
  EXPECT_NE(refused.err.find("--allow-protected"), std::string::npos);
  EXPECT_TRUE(std::filesystem::is_empty(server_->folder("guest")));
  EXPECT_EQ(cncDnc({"send", "--share", server_->url("guest"), "--allow-protected", probe}).status, 0);
  EXPECT_TRUE(exists(server_->folder("guest") + "/O09100.nc"));
  std::filesystem::remove(server_->folder("guest") + "/O09100.nc");

  EXPECT_EQ(cncDnc({"send", "--share"}).status, 2);
  EXPECT_EQ(cncDnc({"receive", "--share", server_->url("guest"), "O1.nc"}).status, 2);
}

TEST_F(ShareCliTest, APasswordInTheShareAddressIsRefusedAndNeverPrinted)
{
  const std::string source = local_.write("O01001.nc", "%\nO01001\nM30\n%\n");
  const std::string url =
      "smb://" + server_->user + ":" + server_->password + "@127.0.0.1:" + std::to_string(server_->port) + "/secure";
  const auto files = [this]
  {
    std::vector<std::string> names;
    for (const auto& item : std::filesystem::directory_iterator(server_->folder("secure")))
      names.push_back(item.path().filename().string());
    std::sort(names.begin(), names.end());
    return names;
  };
  const std::vector<std::string> before = files();
  for (const std::vector<std::string>& args :
       {std::vector<std::string>{"send", "--share", url, source},
        std::vector<std::string>{"receive", "--share", url, "O01001.nc", local_.file("x.nc")},
        std::vector<std::string>{"list", "--share", url}})
  {
    const ToolRun run = cncDnc(args);
    expectOneErrorLine(run, args[0], "--share holds user information with a password");
    EXPECT_NE(run.err.find("credentials file"), std::string::npos) << run.err;
    EXPECT_EQ((run.out + run.err).find(server_->password), std::string::npos) << run.out << run.err;
  }
  EXPECT_EQ(files(), before);  // nothing reached the share
  EXPECT_FALSE(exists(local_.file("x.nc")));
}

// cnc_dnc history and diff read the archive the nodes keep beside their program directory.
TEST_F(ShareCliTest, HistoryAndDiffOfTheArchive)
{
  const std::string programs = local_.file("programs");
  std::filesystem::create_directories(programs);
  cnc_bridge::programs::ProgramArchive archive(programs + ".archive");
  archive.add("O01500.nc", "%\nO01500\nS1000 M03\n%\n", {"share_node", "lathe", "sent"});
  archive.add("O01500.nc", "%\nO01500\nS1200 M03\n%\n", {"dnc_node", "lathe", "received"});
  writeFile(programs + "/O01500.nc", "%\nO01500\nS1500 M03\n%\n");

  const ToolRun history = cncDnc({"history", "--program-dir", programs, "O01500.nc"});
  ASSERT_EQ(history.status, 0) << history.err;
  const auto rows = lines(history.out);
  ASSERT_EQ(rows.size(), 2u) << history.out;
  EXPECT_EQ(rows[0].rfind("1\t", 0), 0u) << rows[0];
  EXPECT_NE(rows[1].find("\tdnc_node\tlathe\treceived\t21\t"), std::string::npos) << rows[1];

  const ToolRun two = cncDnc({"diff", "--archive", programs + ".archive", "O01500.nc", "1", "2"});
  ASSERT_EQ(two.status, 0) << two.err;
  EXPECT_NE(two.out.find("-S1000 M03\n+S1200 M03\n"), std::string::npos) << two.out;
  const ToolRun current = cncDnc({"diff", "--program-dir", programs, "O01500.nc"});
  ASSERT_EQ(current.status, 0) << current.err;
  EXPECT_NE(current.out.find("--- O01500.nc v2"), std::string::npos) << current.out;
  EXPECT_NE(current.out.find("-S1200 M03\n+S1500 M03\n"), std::string::npos) << current.out;
  expectOneErrorLine(cncDnc({"diff", "--program-dir", programs, "O01500.nc", "9"}), "diff", "no version 9");
  EXPECT_EQ(cncDnc({"history", "O01500.nc"}).status, 1);
}

// One command publishes to several machines' shares; each is reported on its own line, and one
// that fails (here a share that does not exist) does not stop the others.
TEST_F(ShareCliTest, SendFansOutToSeveralSharesAndReportsEach)
{
  const std::string program = "%\nO02500 (FAN OUT)\nM30\n%\n";
  const std::string source = local_.write("O02500.nc", program);
  const std::string credentials = server_->credentials("fan.auth");
  const std::string local_share = local_.file("served");
  std::filesystem::create_directories(local_share);
  const ToolRun run = cncDnc({"send", "--credentials", credentials, "--share", server_->url("secure"), "--share",
                              server_->url("nosuch"), "--share", local_share + "/", source});
  EXPECT_EQ(run.status, 1) << run.err;
  const auto out = lines(run.out);
  ASSERT_EQ(out.size(), 1u) << run.out;  // the local folder: a credentials file is for smb:// only
  EXPECT_EQ(out[0].rfind("sent " + source + " to " + server_->url("secure") + "/O02500.nc", 0), 0u) << out[0];
  EXPECT_NE(run.err.find("cnc_dnc send: error: cannot open " + server_->url("nosuch")), std::string::npos) << run.err;
  EXPECT_EQ(readFile(server_->folder("secure") + "/O02500.nc"), program);

  const ToolRun guest_and_local = cncDnc(
      {"send", "--share", server_->url("guest"), "--share", local_share, "--share", server_->url("nosuch"), source});
  EXPECT_EQ(guest_and_local.status, 1);
  EXPECT_EQ(lines(guest_and_local.out).size(), 2u) << guest_and_local.out;
  EXPECT_EQ(readFile(server_->folder("guest") + "/O02500.nc"), program);
  EXPECT_EQ(readFile(local_share + "/O02500.nc"), program);
  std::filesystem::remove(server_->folder("guest") + "/O02500.nc");
}
