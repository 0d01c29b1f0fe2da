// What share_node decides for its services, checks and diagnostics (share_service.h), on local
// folders: the transfers it accepts, a check skipped while a transfer runs and its errors logged
// once, the link state changed only when it differs, removal only when enabled, and how
// listings, comparisons, a fan-out's result and the next withdrawal read.
#include <gtest/gtest.h>

#include <filesystem>
#include <string>
#include <vector>

#include "cnc_bridge/share/share_service.h"
#include "scoped_time_zone.h"
#include "temp_dir.h"

using namespace cnc_bridge;
using namespace cnc_bridge::programs;
using namespace cnc_bridge::share;
using cnc_bridge::test::TempDir;

TEST(TransferRequest, SendOrReceiveOverSmbOnly)
{
  EXPECT_EQ(transferRequest("send", "").direction, ProgramTransfers::Direction::kSend);
  EXPECT_EQ(transferRequest("send", "smb").direction, ProgramTransfers::Direction::kSend);
  EXPECT_EQ(transferRequest("receive", "").direction, ProgramTransfers::Direction::kReceive);
  EXPECT_EQ(transferRequest("receive", "smb").refusal, "");

  const TransferRequest push = transferRequest("push", "");
  EXPECT_FALSE(push.direction);
  EXPECT_EQ(push.refusal, "refused: direction must be 'send' or 'receive', not 'push'");
  const TransferRequest xmodem = transferRequest("send", "xmodem");
  EXPECT_FALSE(xmodem.direction);
  EXPECT_EQ(xmodem.refusal, "refused: share_node moves whole files over SMB (protocol '' or 'smb'), not 'xmodem'");
  // The direction is named first when both are wrong.
  EXPECT_EQ(transferRequest("SEND", "drip").refusal, "refused: direction must be 'send' or 'receive', not 'SEND'");
}

namespace
{
class ShareServiceTest : public ::testing::Test
{
 protected:
  static std::string folder(const TempDir& dir, const std::string& name)
  {
    std::filesystem::create_directories(dir.file(name));
    return dir.file(name);
  }

  TempDir dir_{"cnc_share_service"};
  LocalProgramStore share_{folder(dir_, "share")};
  ProgramDirectory programs_{folder(dir_, "programs")};
  ProgramArchive archive_{dir_.file("archive")};
  ProgramTransfers transfers_{share_,        programs_, ProtectedRange("none", false, "~allow_protected_programs"),
                              NamePattern(), archive_,  {"share_node", "vf2", ""}};
};
}  // namespace

TEST_F(ShareServiceTest, ACheckListsTheShareAndLogsEachNewErrorOnce)
{
  StoreCheck check = checkStore(share_, transfers_);
  EXPECT_TRUE(check.checked);
  EXPECT_EQ(check.error, "");
  EXPECT_FALSE(check.new_error);

  std::filesystem::remove_all(dir_.file("share"));
  check = checkStore(share_, transfers_);
  EXPECT_TRUE(check.checked);
  EXPECT_NE(check.error.find("cannot list " + dir_.file("share")), std::string::npos) << check.error;
  EXPECT_TRUE(check.new_error);
  check = checkStore(share_, transfers_);
  EXPECT_NE(check.error, "");
  EXPECT_FALSE(check.new_error);  // the same error again: no second log line

  const TransferCounts counts = transfers_.counts();
  EXPECT_EQ(counts.checks, 3u);
  EXPECT_EQ(counts.check_failures, 2u);
}

TEST_F(ShareServiceTest, NoCheckWhileATransferRuns)
{
  dir_.write("programs/O01234.nc", "%\nO01234 (PART)\nG0 X0.\nM30\n%\n");
  std::vector<StoreCheck> during;
  const TransferOutcome sent =
      transfers_.run(ProgramTransfers::Direction::kSend, "O01234.nc",
                     [&](uint64_t, uint64_t) { during.push_back(checkStore(share_, transfers_)); });
  ASSERT_TRUE(sent.success) << sent.message;
  ASSERT_FALSE(during.empty());
  for (const StoreCheck& check : during)
    EXPECT_FALSE(check.checked);
  EXPECT_EQ(transfers_.counts().checks, 0u);
  EXPECT_TRUE(checkStore(share_, transfers_).checked);
}

TEST(LinkChange, OnlyWhatDiffersFromTheShownState)
{
  EXPECT_FALSE(linkChange(LinkState::kUp, "sent O01234.nc", ""));  // the transfer's message stays
  for (const LinkState shown : {LinkState::kConnecting, LinkState::kDown})
  {
    const auto up = linkChange(shown, "cannot open", "");
    ASSERT_TRUE(up);
    EXPECT_EQ(up->state, LinkState::kUp);
    EXPECT_EQ(up->message, "share answers");
  }
  for (const LinkState shown : {LinkState::kConnecting, LinkState::kUp})
  {
    const auto down = linkChange(shown, "cannot open", "cannot open");
    ASSERT_TRUE(down);
    EXPECT_EQ(down->state, LinkState::kDown);
    EXPECT_EQ(down->message, "cannot open");
  }
  EXPECT_FALSE(linkChange(LinkState::kDown, "connection refused", "connection refused"));
  const auto other = linkChange(LinkState::kDown, "connection refused", "timed out");
  ASSERT_TRUE(other);
  EXPECT_EQ(other->state, LinkState::kDown);
  EXPECT_EQ(other->message, "timed out");
}

TEST_F(ShareServiceTest, RemovalOnlyWhenEnabled)
{
  dir_.write("share/O01234.nc", "%\nO01234\nM30\n%\n");
  Answer removed = removeProgram(share_, "O01234.nc", false);
  EXPECT_FALSE(removed.success);
  EXPECT_EQ(removed.message, "refused: removing programs from " + dir_.file("share") + " is off (set ~enable_remove)");
  EXPECT_TRUE(test::exists(dir_.file("share/O01234.nc")));

  removed = removeProgram(share_, "O01234.nc", true);
  EXPECT_TRUE(removed.success);
  EXPECT_EQ(removed.message, "removed O01234.nc from " + dir_.file("share"));
  EXPECT_FALSE(test::exists(dir_.file("share/O01234.nc")));

  removed = removeProgram(share_, "O01234.nc", true);
  EXPECT_FALSE(removed.success);
  EXPECT_EQ(removed.message, "no program 'O01234.nc' in " + dir_.file("share"));
}

TEST(ListedNumber, HeaderThenFileNameThenNone)
{
  ProgramListing listing;
  EXPECT_EQ(listedNumber(listing), -1);
  listing.name_number = 1234;
  EXPECT_EQ(listedNumber(listing), 1234);
  listing.header.number = 4321;  // the program's own O number wins over its file name
  EXPECT_EQ(listedNumber(listing), 4321);
  listing.name_number.reset();
  EXPECT_EQ(listedNumber(listing), 4321);
}

TEST(CurrentFile, TheBaseNameInTheProgramFolder)
{
  EXPECT_EQ(currentFile("/home/cnc/nc_programs", "O01234.nc"), "/home/cnc/nc_programs/O01234.nc");
  EXPECT_EQ(currentFile("/home/cnc/nc_programs", "cell/vf2/O01234.nc"), "/home/cnc/nc_programs/O01234.nc");
}

TEST(FanOutSummary, CountsAndNamesEachFailedMachine)
{
  EXPECT_EQ(fanOutSummary({}, "O01234.nc"), "no machines given: nothing published");
  EXPECT_EQ(fanOutSummary({{"/vf2", true, "sent"}, {"/st10", true, "sent"}}, "O01234.nc"),
            "2 of 2 machines got O01234.nc");
  EXPECT_EQ(
      fanOutSummary({{"/vf2", false, "no answer"}, {"/st10", true, "sent"}, {"/umc", false, "refused"}}, "O01234.nc"),
      "1 of 3 machines got O01234.nc; failed: /vf2 (no answer), /umc (refused)");
}

TEST(SendProgramServices, TheNodeThenTheShareNodeInTheNamespace)
{
  EXPECT_EQ(sendProgramServices("/cell/haas_vf2"),
            (std::vector<std::string>{"/cell/haas_vf2/send_program", "/cell/haas_vf2/share_node/send_program"}));
}

TEST(TransfersSummary, WarnsWhileTheLastTransferFailed)
{
  TransferCounts counts;
  TransfersSummary summary = transfersSummary(counts);
  EXPECT_FALSE(summary.warn);
  EXPECT_EQ(summary.text, "no transfer yet");

  counts.failed = 1;
  counts.last_error = counts.last_result = "no program 'O01234.nc'";
  summary = transfersSummary(counts);
  EXPECT_TRUE(summary.warn);
  EXPECT_EQ(summary.text, "last transfer failed: no program 'O01234.nc'");

  counts.last_result = "sent O01234.nc";  // a success since: the earlier failure is history
  summary = transfersSummary(counts);
  EXPECT_FALSE(summary.warn);
  EXPECT_EQ(summary.text, "sent O01234.nc");
}

TEST(LocalTimeText, TheLocalClockWithItsZone)
{
  const std::time_t at = 1795789200;  // 2026-11-27 14:20 UTC
  {
    const test::ScopedTimeZone utc("UTC0");
    EXPECT_EQ(localTimeText(at), "2026-11-27 14:20 UTC");
  }
  const test::ScopedTimeZone berlin("CET-1CEST,M3.5.0,M10.5.0/3");
  EXPECT_EQ(localTimeText(at), "2026-11-27 15:20 CET");
}
