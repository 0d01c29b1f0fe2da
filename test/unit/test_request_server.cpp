// RequestServer (share_node's program requests) on local folders: a request file is read, removed
// and served by the transfer it asks for; a program that is not there, a protected one and a file
// without a request are answered with the reason and nothing is transferred; DPRNT lines; a
// requests folder that does not exist yet is looked for again at the next call.
#include <gtest/gtest.h>

#include <sys/stat.h>

#include <atomic>
#include <filesystem>
#include <string>
#include <utility>
#include <vector>

#include "cnc_bridge/common/error.h"
#include "cnc_bridge/programs/request_server.h"
#include "temp_dir.h"

using namespace cnc_bridge;
using namespace cnc_bridge::programs;
using cnc_bridge::test::TempDir;

namespace
{
class RequestServerTest : public ::testing::Test
{
 protected:
  void SetUp() override
  {
    std::filesystem::create_directories(dir_.file("programs"));
    dir_.write("programs/O01234.nc", "%\nO01234\nM30\n%\n");
    dir_.write("programs/O08001.nc", "%\nO08001 (PROBE)\nM99\n%\n");
    server_.setRequestFolder("requests", [this] { return std::make_unique<LocalProgramStore>(dir_.file("requests")); });
  }

  RequestTransfer transfer(RequestDecision::Action action, const std::string& program)
  {
    transfers_.emplace_back(action, program);
    return {true, "moved " + program};
  }

  TempDir dir_{"cnc_request_server"};
  std::vector<std::pair<RequestDecision::Action, std::string>> transfers_;
  std::vector<RequestOutcome> reported_;
  RequestServer server_{RequestWords(),
                        NamePattern("O%05d.nc"),
                        ProtectedRange("O08000-O09999", false, "~allow_protected_programs"),
                        dir_.file("programs"),
                        [this](RequestDecision::Action action, const std::string& program)
                        { return transfer(action, program); },
                        [this](const RequestOutcome& outcome) { reported_.push_back(outcome); }};
};
}  // namespace

TEST_F(RequestServerTest, ARequestFileIsServedAndRemoved)
{
  std::filesystem::create_directories(dir_.file("requests"));
  dir_.write("requests/r1.nc", "%\nO00001 (LOAD O1234)\nM30\n%\n");
  dir_.write("requests/r2.nc", "%\nO00002 (save o4321)\nM30\n%\n");
  server_.serveRequestFiles();
  ASSERT_EQ(transfers_.size(), 2u);
  EXPECT_EQ(transfers_[0], std::make_pair(RequestDecision::Action::kSend, std::string("O01234.nc")));
  EXPECT_EQ(transfers_[1], std::make_pair(RequestDecision::Action::kReceive, std::string("O04321.nc")));
  ASSERT_EQ(reported_.size(), 2u);
  EXPECT_EQ(reported_[0].source, "share requests/r1.nc");
  EXPECT_EQ(reported_[0].word, "LOAD");
  EXPECT_EQ(reported_[0].number, 1234u);
  EXPECT_EQ(reported_[0].program, "O01234.nc");
  EXPECT_TRUE(reported_[0].success);
  EXPECT_EQ(reported_[0].outcome, "moved O01234.nc");
  EXPECT_EQ(reported_[1].word, "SAVE");
  EXPECT_TRUE(std::filesystem::is_empty(dir_.file("requests")));
}

TEST_F(RequestServerTest, RefusalsAreReportedWithTheReasonAndNothingIsTransferred)
{
  std::filesystem::create_directories(dir_.file("requests"));
  dir_.write("requests/a.nc", "%\nO00001 (SEND O4444)\nM30\n%\n");
  dir_.write("requests/b.nc", "%\nO00001 (LOAD O8001)\nM30\n%\n");
  dir_.write("requests/c.nc", "%\nO00001 (HELLO)\nM30\n%\n");
  server_.serveRequestFiles();
  EXPECT_TRUE(transfers_.empty());
  ASSERT_EQ(reported_.size(), 3u);
  for (const RequestOutcome& outcome : reported_)
    EXPECT_FALSE(outcome.success) << outcome.source;
  EXPECT_NE(reported_[0].outcome.find("no O04444.nc in " + dir_.file("programs")), std::string::npos)
      << reported_[0].outcome;
  EXPECT_NE(reported_[1].outcome.find("O08000-O09999"), std::string::npos) << reported_[1].outcome;
  EXPECT_EQ(reported_[2].word, "");
  EXPECT_EQ(reported_[2].outcome, noRequestOutcome());
  EXPECT_TRUE(std::filesystem::is_empty(dir_.file("requests")));  // each served once
}

TEST_F(RequestServerTest, DprntLinesThatAreRequestsAreServedOthersIgnored)
{
  EXPECT_TRUE(server_.serveDprntLine("LOAD O1234"));
  EXPECT_FALSE(server_.serveDprntLine("PART 17 X1.0000"));
  ASSERT_EQ(transfers_.size(), 1u);
  EXPECT_EQ(transfers_[0].second, "O01234.nc");
  ASSERT_EQ(reported_.size(), 1u);
  EXPECT_EQ(reported_[0].source, "dprnt");
}

TEST_F(RequestServerTest, AFolderThatDoesNotExistYetIsLookedForAgain)
{
  server_.serveRequestFiles();  // no folder: nothing, no throw
  EXPECT_TRUE(reported_.empty());
  std::filesystem::create_directories(dir_.file("requests"));
  dir_.write("requests/r1.nc", "(LOAD O1234)\n");
  server_.serveRequestFiles();
  ASSERT_EQ(reported_.size(), 1u);
  EXPECT_TRUE(reported_[0].success);
}

namespace
{
/// A local folder that counts the bytes it hands out.
class CountingStore : public LocalProgramStore
{
 public:
  CountingStore(const std::string& root, uint64_t& bytes_read) : LocalProgramStore(root), bytes_read_(bytes_read) {}
  std::string read(const std::string& name, const StoreProgress& progress, const std::atomic<bool>* cancel) override
  {
    std::string data = LocalProgramStore::read(name, progress, cancel);
    bytes_read_ += data.size();
    return data;
  }
  std::string readHead(const std::string& name, size_t bytes) override
  {
    std::string head = LocalProgramStore::readHead(name, bytes);
    bytes_read_ += head.size();
    return head;
  }

 private:
  uint64_t& bytes_read_;
};
}  // namespace

// Only the head of a request file can hold the request: a large file is not read whole (a 400 MB
// file took 550 MB of memory), and a FIFO planted in the folder is refused without blocking.
TEST_F(RequestServerTest, OnlyTheHeadOfARequestFileIsReadAndAFifoIsRefused)
{
  std::filesystem::create_directories(dir_.file("requests"));
  std::string big = "%\nO00001 (LOAD O1234)\n";
  while (big.size() < 8 * 1024 * 1024)
    big += "(FILLER FILLER FILLER FILLER FILLER FILLER FILLER FILLER)\n";
  dir_.write("requests/big.nc", big);
  ASSERT_EQ(::mkfifo(dir_.file("requests/fifo.nc").c_str(), 0600), 0);
  uint64_t bytes_read = 0;
  server_.setRequestFolder(
      "requests", [this, &bytes_read] { return std::make_unique<CountingStore>(dir_.file("requests"), bytes_read); });
  server_.serveRequestFiles();  // returns: the FIFO is not opened for a blocking read
  ASSERT_EQ(transfers_.size(), 1u);
  EXPECT_EQ(transfers_[0], std::make_pair(RequestDecision::Action::kSend, std::string("O01234.nc")));
  EXPECT_LE(bytes_read, kRequestHeadBytes);
  EXPECT_FALSE(std::filesystem::exists(dir_.file("requests/big.nc")));
}
