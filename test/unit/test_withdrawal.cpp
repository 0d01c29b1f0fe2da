// Withdrawing programs from a store (share_node's ~withdraw_program, ~withdraw_all, ~withdraw_at)
// on a local folder: kept in the archive before removal, the version named when identical content
// was kept already, a missing program named, and withdrawing every program going on past one that
// cannot be removed (which stays, and is kept).
#include <gtest/gtest.h>

#include <filesystem>
#include <string>
#include <vector>

#include "cnc_bridge/common/error.h"
#include "cnc_bridge/programs/withdrawal.h"
#include "temp_dir.h"

using namespace cnc_bridge;
using namespace cnc_bridge::programs;
using cnc_bridge::test::readFile;
using cnc_bridge::test::TempDir;

namespace
{
/// A local folder whose removal of one name fails (a file the control holds open).
class StickyStore : public LocalProgramStore
{
 public:
  StickyStore(const std::string& root, std::string sticky) : LocalProgramStore(root), sticky_(std::move(sticky)) {}
  void remove(const std::string& name) override
  {
    if (name == sticky_)
      throw Error("removal of " + name + ": the file is in use");
    LocalProgramStore::remove(name);
  }

 private:
  std::string sticky_;
};

class WithdrawalTest : public ::testing::Test
{
 protected:
  void SetUp() override { std::filesystem::create_directories(dir_.file("share")); }
  std::string share(const std::string& name) const { return dir_.file("share/" + name); }

  TempDir dir_{"cnc_withdrawal"};
  ProgramArchive archive_{dir_.file("archive")};
  const VersionSource source_{"share_node", "vf2", "withdrawn"};
};
}  // namespace

TEST_F(WithdrawalTest, KeptInTheArchiveThenRemoved)
{
  LocalProgramStore store(dir_.file("share"));
  dir_.write("share/O01000.nc", "%\nO01000 (OP1)\nM30\n%\n");
  const Withdrawal done = withdrawProgram(store, archive_, "O01000.nc", source_);
  EXPECT_TRUE(done.success);
  EXPECT_EQ(done.version, 1u);
  EXPECT_EQ(done.message, "withdrew O01000.nc from " + dir_.file("share") + " (archive version 1)");
  EXPECT_FALSE(std::filesystem::exists(share("O01000.nc")));
  EXPECT_EQ(readFile(dir_.file("archive/O01000.nc/v0001.nc")), "%\nO01000 (OP1)\nM30\n%\n");
  EXPECT_NE(readFile(dir_.file("archive/O01000.nc/v0001.meta")).find("withdrawn"), std::string::npos);

  // The same content again: not stored twice, and the version that holds it is named.
  dir_.write("share/O01000.nc", "%\nO01000 (OP1)\nM30\n%\n");
  EXPECT_EQ(withdrawProgram(store, archive_, "O01000.nc", source_).version, 1u);
  EXPECT_EQ(archive_.history("O01000.nc").size(), 1u);
}

TEST_F(WithdrawalTest, AMissingProgramIsNamedAndNothingIsKept)
{
  LocalProgramStore store(dir_.file("share"));
  EXPECT_THROW(withdrawProgram(store, archive_, "O04444.nc", source_), NotFoundError);
  EXPECT_TRUE(archive_.history("O04444.nc").empty());
}

TEST_F(WithdrawalTest, EveryProgramEachReportedAndOneThatFailsDoesNotStopTheOthers)
{
  StickyStore store(dir_.file("share"), "O01001.nc");
  for (const char* name : {"O01000.nc", "O01001.nc", "O01002.nc"})
    dir_.write(std::string("share/") + name, std::string("%\n(") + name + ")\nM30\n%\n");
  std::vector<Withdrawal> reported;
  const WithdrawalSummary summary = withdrawAllPrograms(store, archive_, source_, "~withdraw_all",
                                                        [&](const Withdrawal& w) { reported.push_back(w); });
  EXPECT_FALSE(summary.success);
  EXPECT_EQ(summary.withdrawn, 2u);
  EXPECT_EQ(summary.listed, 3u);
  EXPECT_NE(summary.message.find("withdrew 2 of 3 programs"), std::string::npos) << summary.message;
  EXPECT_NE(summary.message.find("failed: O01001.nc (removal of O01001.nc: the file is in use)"), std::string::npos)
      << summary.message;
  ASSERT_EQ(reported.size(), 3u);
  EXPECT_TRUE(reported[0].success);
  EXPECT_FALSE(reported[1].success);
  EXPECT_EQ(reported[1].program, "O01001.nc");
  EXPECT_TRUE(reported[2].success);
  EXPECT_FALSE(std::filesystem::exists(share("O01000.nc")));
  EXPECT_TRUE(std::filesystem::exists(share("O01001.nc")));  // stays on the share...
  EXPECT_EQ(archive_.history("O01001.nc").size(), 1u);       // ...and is kept all the same
  EXPECT_FALSE(std::filesystem::exists(share("O01002.nc")));
}

TEST_F(WithdrawalTest, AnEmptyShareIsNoFailureAndAnUnreadableOneIsReported)
{
  LocalProgramStore store(dir_.file("share"));
  WithdrawalSummary summary = withdrawAllPrograms(store, archive_, source_, "~withdraw_at 18:00");
  EXPECT_TRUE(summary.success);
  EXPECT_NE(summary.message.find("withdrew 0 of 0 programs"), std::string::npos) << summary.message;

  std::filesystem::remove_all(dir_.file("share"));
  summary = withdrawAllPrograms(store, archive_, source_, "~withdraw_at 18:00");
  EXPECT_FALSE(summary.success);
  EXPECT_EQ(summary.message.rfind("withdrawal of every program not done: ", 0), 0u) << summary.message;
}
