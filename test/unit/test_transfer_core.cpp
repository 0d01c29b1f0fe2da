// The transfer core dnc_node and share_node share (include/cnc_bridge/programs/transfer_core.h):
// one transfer at a time in the slot, one set of counters for both nodes' diagnostics, and one
// rule set for the files a transfer touches and the archive they are kept in.
#include <gtest/gtest.h>
#include <sys/stat.h>
#include <unistd.h>

#include <string>

#include "cnc_bridge/common/error.h"
#include "cnc_bridge/programs/transfer_core.h"
#include "temp_dir.h"

using namespace cnc_bridge;
using namespace cnc_bridge::programs;
using cnc_bridge::test::TempDir;

TEST(TransferSlot, OneTransferAtATimeAndTheCancelDoesNotCarryOver)
{
  TransferSlot slot;
  EXPECT_FALSE(slot.busy());
  slot.cancelFlag() = true;  // a cancel of an earlier transfer
  ASSERT_TRUE(slot.tryReserve("a send of O01234.nc"));
  EXPECT_TRUE(slot.busy());
  EXPECT_FALSE(slot.cancelFlag());
  std::string running;
  EXPECT_FALSE(slot.tryReserve("a receive of O04321.nc", &running));
  EXPECT_EQ(running, "a send of O01234.nc");
  EXPECT_EQ(slot.running(), "a send of O01234.nc");
  slot.release();
  EXPECT_FALSE(slot.busy());
  EXPECT_TRUE(slot.tryReserve("a receive of O04321.nc"));
  EXPECT_EQ(slot.running(), "a receive of O04321.nc");
}

// share_node counts a refusal after the start (a protected program) as refused, a failure (with
// its error kept for the diagnostics' summary) as failed; the store's checks share last_error.
TEST(TransferCounters, EveryEndAndTheChecks)
{
  TransferCounters counters;
  counters.started();
  counters.finished(TransferEnd::kRefused, 0, 0, 0, "refused: O09010 is protected");
  counters.started();
  counters.finished(TransferEnd::kFailed, 0, 0, 100, "the share does not answer");
  counters.started();
  counters.finished(TransferEnd::kCompleted, 0, 0, 300, "sent O01234.nc");
  counters.refused();  // busy
  TransferTotals totals = counters.totals();
  EXPECT_EQ(totals.transfers, 3u);
  EXPECT_EQ(totals.refused, 2u);
  EXPECT_EQ(totals.failed, 1u);
  EXPECT_EQ(totals.completed, 1u);
  EXPECT_EQ(totals.cancelled, 0u);
  EXPECT_EQ(totals.bytes, 400u);
  EXPECT_EQ(totals.last_error, "the share does not answer");
  EXPECT_EQ(totals.last_result, "sent O01234.nc");

  EXPECT_FALSE(counters.countCheck(0.25, ""));
  EXPECT_TRUE(counters.countCheck(0.5, "cannot list the share"));
  EXPECT_FALSE(counters.countCheck(0.5, "cannot list the share"));  // the same error: no new log line
  totals = counters.totals();
  EXPECT_EQ(totals.checks, 3u);
  EXPECT_EQ(totals.check_failures, 2u);
  EXPECT_DOUBLE_EQ(totals.round_trip, 0.5);
  EXPECT_EQ(totals.last_error, "cannot list the share");
}

// The archive reads a regular file only, for every node: a link planted where a program was moved
// to is not followed into a file outside the program directory (dnc_node followed it before).
TEST(TransferFiles, TheArchiveFollowsNoLinkAndKeepsTheMode)
{
  TempDir dir("transfer_core");
  TempDir archive_dir("transfer_core_archive");
  ProgramDirectory programs(dir.path);
  const ProtectedRange protected_range("O08000-O09999", false, "~allow_protected_programs");
  const NamePattern names("O%05d.nc");
  ProgramArchive archive(archive_dir.path + "/kept", 5);
  const TransferFiles files(programs, protected_range, names, archive);

  const std::string outside = archive_dir.write("secret.txt", "not a program\n");
  const std::string link = dir.file("O01111.nc");
  ASSERT_EQ(::symlink(outside.c_str(), link.c_str()), 0);
  EXPECT_THROW(files.archive(link, {"dnc_node", "vf2", "received"}), Error);
  EXPECT_TRUE(archive.history("O01111.nc").empty());

  const std::string path = dir.write("O01234.nc", "%\nO01234\nM30\n%\n");
  ASSERT_EQ(::chmod(path.c_str(), 0600), 0);
  EXPECT_EQ(files.archive(path, {"dnc_node", "vf2", "sent"}), "kept O01234.nc as version 1 in " + archive.root());
  const auto kept = archive.history("O01234.nc");
  ASSERT_EQ(kept.size(), 1u);
  struct stat info;
  ASSERT_EQ(::stat(kept[0].path.c_str(), &info), 0);
  EXPECT_EQ(info.st_mode & 0777, 0600u);
}

TEST(TransferFiles, ResolvesInsideTheProgramDirectoryAndChecksTheProtectedRangeOnSend)
{
  TempDir dir("transfer_core_files");
  TempDir archive_dir("transfer_core_files_archive");
  ProgramDirectory programs(dir.path);
  const ProtectedRange protected_range("O08000-O09999", false, "~allow_protected_programs");
  const NamePattern names("O%05d.nc");
  ProgramArchive archive(archive_dir.path + "/kept", 5);
  const TransferFiles files(programs, protected_range, names, archive);

  dir.write("O09010.nc", "%\nO09010 (PROBE)\nM99\n%\n");
  EXPECT_EQ(files.resolve("O09010.nc", true), programs.resolveExisting("O09010.nc"));
  EXPECT_THROW(files.resolve("../O09010.nc", false), ConfigError);
  EXPECT_FALSE(files.check("O09010.nc", true).accepted());
  EXPECT_TRUE(files.check("O09010.nc", false).accepted());
  EXPECT_THROW(files.sendCheck("O01234.nc")("%\nO09010\nM99\n%\n"), DisabledError);
  EXPECT_NO_THROW(files.sendCheck("O01234.nc")("%\nO01234\nM30\n%\n"));
}
