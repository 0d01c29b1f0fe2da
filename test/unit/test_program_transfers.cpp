// ProgramTransfers (what share_node's ~send_program, ~receive_program and ~transfer do) between
// local folders: both directions byte for byte, each kept in the archive; a protected program, a
// missing one and a second transfer while one runs refused and counted so; a cancelled send
// leaves the previous version; the checks' counts. Links out of the share, directories and FIFOs
// where a program belongs refused; the modes of copies and kept versions.
#include <gtest/gtest.h>
#include <sys/stat.h>
#include <unistd.h>

#include <filesystem>
#include <string>
#include <utility>
#include <vector>

#include "cnc_bridge/programs/program_transfers.h"
#include "temp_dir.h"

using namespace cnc_bridge;
using namespace cnc_bridge::programs;
using cnc_bridge::test::readFile;
using cnc_bridge::test::TempDir;

namespace
{
class ProgramTransfersTest : public ::testing::Test
{
 protected:
  /// \p name inside the test's folder, created.
  static std::string folder(const TempDir& dir, const std::string& name)
  {
    std::filesystem::create_directories(dir.file(name));
    return dir.file(name);
  }

  TempDir dir_{"cnc_program_transfers"};
  LocalProgramStore share_{folder(dir_, "share")};
  ProgramDirectory programs_{folder(dir_, "programs")};
  ProgramArchive archive_{dir_.file("archive")};
  ProgramTransfers transfers_{
      share_,        programs_, ProtectedRange("O08000-O09999", false, "~allow_protected_programs"),
      NamePattern(), archive_,  {"share_node", "vf2", ""}};
};

std::string bigProgram()
{
  std::string text = "%\nO01234 (BIG)\n";
  for (int i = 0; text.size() < 300000; ++i)
    text += "N" + std::to_string(i) + " G1 X1.\n";
  return text + "M30\n%\n";
}
}  // namespace

TEST_F(ProgramTransfersTest, BothWaysByteForByteEachKept)
{
  const std::string program = bigProgram();
  dir_.write("programs/O01234.nc", program);
  TransferOutcome sent = transfers_.run(ProgramTransfers::Direction::kSend, "O01234.nc");
  ASSERT_TRUE(sent.success) << sent.message;
  EXPECT_EQ(sent.bytes, program.size());
  EXPECT_EQ(sent.message,
            "sent O01234.nc to " + dir_.file("share") + "/O01234.nc (" + std::to_string(program.size()) + " bytes)");
  EXPECT_EQ(readFile(dir_.file("share/O01234.nc")), program);

  dir_.write("share/O01234.nc", program + "(CHANGED AT THE CONTROL)\n");
  bool started = false;
  TransferOutcome received =
      transfers_.run(ProgramTransfers::Direction::kReceive, "O01234.nc", nullptr, [&] { started = true; });
  ASSERT_TRUE(received.success) << received.message;
  EXPECT_TRUE(started);
  EXPECT_EQ(readFile(dir_.file("programs/O01234.nc")), program + "(CHANGED AT THE CONTROL)\n");
  const auto versions = archive_.history("O01234.nc");
  ASSERT_EQ(versions.size(), 2u);
  EXPECT_EQ(versions[0].source.direction, "sent");
  EXPECT_EQ(versions[1].source.direction, "received");
  EXPECT_EQ(versions[1].source.machine, "vf2");
  const TransferCounts counts = transfers_.counts();
  EXPECT_EQ(counts.transfers, 2u);
  EXPECT_EQ(counts.completed, 2u);
  EXPECT_EQ(counts.bytes, 2 * program.size() + 25);
}

TEST_F(ProgramTransfersTest, RefusalsAndFailuresAreCountedApart)
{
  dir_.write("programs/O08001.nc", "%\nO08001 (PROBE)\nM99\n%\n");
  TransferOutcome outcome = transfers_.run(ProgramTransfers::Direction::kSend, "O08001.nc");
  EXPECT_TRUE(outcome.refused);
  EXPECT_NE(outcome.message.find("protected range O08000-O09999"), std::string::npos) << outcome.message;
  EXPECT_FALSE(std::filesystem::exists(dir_.file("share/O08001.nc")));
  outcome = transfers_.run(ProgramTransfers::Direction::kSend, "O04444.nc");
  EXPECT_TRUE(outcome.refused) << outcome.message;
  outcome = transfers_.run(ProgramTransfers::Direction::kReceive, "O04444.nc");  // not on the share
  EXPECT_FALSE(outcome.success);
  EXPECT_FALSE(outcome.refused);
  EXPECT_FALSE(outcome.link_lost);
  const TransferCounts counts = transfers_.counts();
  EXPECT_EQ(counts.transfers, 3u);
  EXPECT_EQ(counts.refused, 2u);
  EXPECT_EQ(counts.failed, 1u);
  EXPECT_EQ(counts.last_error, outcome.message);
}

TEST_F(ProgramTransfersTest, OneAtATimeAndACancelledSendLeavesThePreviousVersion)
{
  dir_.write("programs/O01234.nc", bigProgram());
  dir_.write("share/O01234.nc", "previous");
  TransferOutcome second;
  bool asked = false;
  const TransferOutcome first = transfers_.run(ProgramTransfers::Direction::kSend, "O01234.nc",
                                               [&](uint64_t, uint64_t)
                                               {
                                                 if (asked)
                                                   return;
                                                 asked = true;
                                                 EXPECT_TRUE(transfers_.busy());
                                                 second =
                                                     transfers_.run(ProgramTransfers::Direction::kSend, "O01234.nc");
                                                 transfers_.cancel();
                                               });
  EXPECT_TRUE(second.refused);
  EXPECT_NE(second.message.find("another transfer is running"), std::string::npos) << second.message;
  EXPECT_FALSE(first.success);
  EXPECT_TRUE(transfers_.cancelled());
  EXPECT_EQ(readFile(dir_.file("share/O01234.nc")), "previous");
  EXPECT_FALSE(transfers_.busy());
  const TransferCounts counts = transfers_.counts();
  EXPECT_EQ(counts.transfers, 1u);  // the refused one never started
  EXPECT_EQ(counts.refused, 1u);
  EXPECT_EQ(counts.failed, 1u);
}

TEST_F(ProgramTransfersTest, ChecksCountedAndANewErrorSaidOnce)
{
  EXPECT_FALSE(transfers_.countCheck(0.01, ""));
  EXPECT_TRUE(transfers_.countCheck(0.5, "connection refused"));
  EXPECT_FALSE(transfers_.countCheck(0.5, "connection refused"));
  const TransferCounts counts = transfers_.counts();
  EXPECT_EQ(counts.checks, 3u);
  EXPECT_EQ(counts.check_failures, 2u);
  EXPECT_DOUBLE_EQ(counts.round_trip, 0.5);
}

namespace
{
/// A file outside every folder of the test, readable by its owner only (a root-only file).
struct OutsideFile
{
  OutsideFile() : path(dir.write("secret", "root:SECRET:0:0\n")) { ::chmod(path.c_str(), 0600); }
  TempDir dir{"cnc_outside"};
  std::string path;
};

unsigned modeOf(const std::string& path)
{
  struct stat info;
  return ::lstat(path.c_str(), &info) == 0 ? (info.st_mode & 07777) : 0;
}
}  // namespace

TEST_F(ProgramTransfersTest, ALinkOutOfTheShareIsNotListedReadCopiedOrArchived)
{
  const OutsideFile secret;
  ASSERT_EQ(::symlink(secret.path.c_str(), dir_.file("share/O01234.nc").c_str()), 0);
  dir_.write("share/O00001.nc", "%\nO00001\n%\n");
  const auto listing = listPrograms(share_, NamePattern());  // the listing itself does not fail
  ASSERT_EQ(listing.size(), 1u);
  EXPECT_EQ(listing[0].entry.name, "O00001.nc");

  const TransferOutcome outcome = transfers_.run(ProgramTransfers::Direction::kReceive, "O01234.nc");
  EXPECT_FALSE(outcome.success);
  EXPECT_TRUE(outcome.refused);
  EXPECT_NE(outcome.message.find("is a symbolic link, not a program file"), std::string::npos) << outcome.message;
  EXPECT_FALSE(std::filesystem::exists(dir_.file("programs/O01234.nc")));
  EXPECT_TRUE(archive_.history("O01234.nc").empty());
  EXPECT_EQ(readFile(secret.path), "root:SECRET:0:0\n");
  EXPECT_EQ(modeOf(secret.path), 0600u);
}

TEST_F(ProgramTransfersTest, ADirectoryOrFifoWhereAProgramBelongsIsRefusedByName)
{
  std::filesystem::create_directories(dir_.file("share/O02222.nc"));
  ASSERT_EQ(::mkfifo(dir_.file("share/O03333.nc").c_str(), 0600), 0);
  ASSERT_EQ(::mkfifo(dir_.file("programs/O03333.nc").c_str(), 0600), 0);
  std::filesystem::create_directories(dir_.file("programs/O02222.nc"));
  EXPECT_TRUE(share_.list().empty());

  const std::vector<std::pair<ProgramTransfers::Direction, std::string>> refusals = {
      {ProgramTransfers::Direction::kReceive, "O02222.nc"},  // a directory on the share and here
      {ProgramTransfers::Direction::kReceive, "O03333.nc"},  // a FIFO on the share (and here)
      {ProgramTransfers::Direction::kSend, "O02222.nc"},
      {ProgramTransfers::Direction::kSend, "O03333.nc"}};
  for (const auto& [direction, file] : refusals)
  {
    const TransferOutcome outcome = transfers_.run(direction, file);
    EXPECT_TRUE(outcome.refused) << file << ": " << outcome.message;
    const std::string kind = file == "O02222.nc" ? "a directory" : "a FIFO";
    EXPECT_NE(outcome.message.find(kind + ", not a program file"), std::string::npos) << outcome.message;
  }
  EXPECT_TRUE(std::filesystem::is_directory(dir_.file("share/O02222.nc")));
  EXPECT_TRUE(std::filesystem::is_fifo(dir_.file("programs/O03333.nc")));
  EXPECT_TRUE(archive_.history("O02222.nc").empty());
  EXPECT_TRUE(archive_.history("O03333.nc").empty());
}

TEST_F(ProgramTransfersTest, CopiesAndVersionsAreNoMoreReadableThanTheProgram)
{
  const mode_t umask_before = ::umask(022);
  dir_.write("share/O01111.nc", "%\nO01111 (OPEN)\n%\n");
  ::chmod(dir_.file("share/O01111.nc").c_str(), 0644);
  dir_.write("share/O02222.nc", "%\nO02222 (OWNER ONLY)\n%\n");
  ::chmod(dir_.file("share/O02222.nc").c_str(), 0600);
  for (const std::string file : {"O01111.nc", "O02222.nc"})
  {
    const TransferOutcome outcome = transfers_.run(ProgramTransfers::Direction::kReceive, file);
    ASSERT_TRUE(outcome.success) << outcome.message;
  }
  dir_.write("programs/O03333.nc", "%\nO03333\n%\n");
  ::chmod(dir_.file("programs/O03333.nc").c_str(), 0644);
  ASSERT_TRUE(transfers_.run(ProgramTransfers::Direction::kSend, "O03333.nc").success);
  ::umask(umask_before);

  EXPECT_EQ(modeOf(dir_.file("programs/O01111.nc")), 0640u);  // kProgramFileMode, not 0644
  EXPECT_EQ(modeOf(dir_.file("programs/O02222.nc")), 0600u);  // the program's own, narrower
  EXPECT_EQ(modeOf(dir_.file("share/O03333.nc")), 0640u);
  EXPECT_EQ(modeOf(archive_.history("O01111.nc").at(0).path), 0640u);
  EXPECT_EQ(modeOf(archive_.history("O02222.nc").at(0).path), 0600u);
  EXPECT_EQ(modeOf(archive_.history("O03333.nc").at(0).path), 0640u);
  EXPECT_EQ(modeOf(dir_.file("archive/O01111.nc")) & 0007, 0u);  // the program's folder: nothing for others
}
