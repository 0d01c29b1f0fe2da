// Atomic file writes and program-directory confinement, on a real temporary directory.
#include <gtest/gtest.h>

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cstdlib>
#include <fstream>
#include <sstream>

#include "cnc_bridge/common/atomic_file.h"
#include "cnc_bridge/common/error.h"
#include "cnc_bridge/common/port_lock.h"
#include "cnc_bridge/common/program_dir.h"

using namespace cnc_bridge;

namespace
{
class TempDir : public ::testing::Test
{
 protected:
  void SetUp() override
  {
    char pattern[] = "/tmp/cnc_bridge_test_XXXXXX";
    ASSERT_NE(::mkdtemp(pattern), nullptr);
    dir_ = pattern;
  }
  void TearDown() override { std::system(("rm -rf " + dir_).c_str()); }

  std::string read(const std::string& path)
  {
    std::ifstream in(path);
    std::stringstream s;
    s << in.rdbuf();
    return s.str();
  }
  void writeFile(const std::string& path, const std::string& text) { std::ofstream(path) << text; }
  int entries()
  {
    int n = 0;
    const std::string cmd = "ls -A " + dir_ + " | wc -l";
    FILE* p = ::popen(cmd.c_str(), "r");
    if (p)
    {
      if (std::fscanf(p, "%d", &n) != 1)
        n = -1;
      ::pclose(p);
    }
    return n;
  }

  std::string dir_;
};
}  // namespace

using AtomicFile = TempDir;
using ProgramDir = TempDir;

TEST_F(AtomicFile, CommitReplacesTheDestinationWhole)
{
  const std::string path = dir_ + "/O05555.nc";
  writeFile(path, "old program");
  {
    AtomicFileWriter writer(path);
    writer.write("%\nO05555\n");
    EXPECT_EQ(read(path), "old program");  // unchanged until commit
    writer.write("M30\n%\n");
    writer.commit();
  }
  EXPECT_EQ(read(path), "%\nO05555\nM30\n%\n");
  EXPECT_EQ(entries(), 1);  // no temporary file left
}

TEST_F(AtomicFile, AbandonedWriteLeavesThePreviousFileAndNoTemporary)
{
  const std::string path = dir_ + "/O1.nc";
  writeFile(path, "previous");
  {
    AtomicFileWriter writer(path);
    writer.write("half a progr");
  }  // transfer failed: destructor discards
  EXPECT_EQ(read(path), "previous");
  EXPECT_EQ(entries(), 1);
  {
    AtomicFileWriter writer(dir_ + "/new.nc");
    writer.write("x");
    writer.discard();
  }
  EXPECT_EQ(entries(), 1);
}

TEST_F(AtomicFile, MissingDirectoryIsAConfigError)
{
  EXPECT_THROW(AtomicFileWriter(dir_ + "/no/such/dir/file.nc"), ConfigError);
}

TEST_F(ProgramDir, ResolvesNamesInsideAndRefusesEscapes)
{
  ::mkdir((dir_ + "/programs").c_str(), 0755);
  ::mkdir((dir_ + "/programs2").c_str(), 0755);
  writeFile(dir_ + "/programs/O1.nc", "%\n");
  writeFile(dir_ + "/secret.txt", "no");
  writeFile(dir_ + "/programs2/O2.nc", "%\n");
  ASSERT_EQ(::symlink((dir_ + "/secret.txt").c_str(), (dir_ + "/programs/link.nc").c_str()), 0);
  ASSERT_EQ(::symlink((dir_ + "/programs/O1.nc").c_str(), (dir_ + "/programs/inside.nc").c_str()), 0);
  const ProgramDirectory programs(dir_ + "/programs");

  EXPECT_EQ(programs.resolveExisting("O1.nc"), programs.root() + "/O1.nc");
  EXPECT_EQ(programs.resolveExisting(programs.root() + "/O1.nc"), programs.root() + "/O1.nc");
  EXPECT_EQ(programs.resolveExisting("inside.nc"), programs.root() + "/O1.nc");
  EXPECT_THROW(programs.resolveExisting("../secret.txt"), ConfigError);
  EXPECT_THROW(programs.resolveExisting(dir_ + "/secret.txt"), ConfigError);
  EXPECT_THROW(programs.resolveExisting("link.nc"), ConfigError);
  EXPECT_THROW(programs.resolveExisting("../programs2/O2.nc"), ConfigError);  // prefix, not parent
  EXPECT_THROW(programs.resolveExisting("missing.nc"), ConfigError);
  EXPECT_THROW(programs.resolveExisting(""), ConfigError);

  EXPECT_EQ(programs.resolveForWrite("new.nc"), programs.root() + "/new.nc");
  EXPECT_THROW(programs.resolveForWrite("../new.nc"), ConfigError);
  EXPECT_THROW(programs.resolveForWrite("/etc/passwd"), ConfigError);
  EXPECT_THROW(programs.resolveForWrite("link.nc"), ConfigError);
  EXPECT_THROW(programs.resolveForWrite("sub/new.nc"), ConfigError);  // no such subdirectory
  EXPECT_THROW(programs.resolveForWrite(".."), ConfigError);
  try
  {
    programs.resolveExisting("../secret.txt");
  }
  catch (const ConfigError& e)
  {
    EXPECT_NE(std::string(e.what()).find("outside the program directory"), std::string::npos);
  }
}

TEST_F(ProgramDir, RootMustExist)
{
  EXPECT_THROW(ProgramDirectory(dir_ + "/nope"), ConfigError);
}

TEST(PortLock, OneHolderAtATimeAcrossObjects)
{
  // Two objects stand for two processes: flock locks belong to the open file description.
  PortLock dnc("/dev/ttyS_test_cnc_bridge");
  PortLock mdc("/dev/ttyS_test_cnc_bridge");
  EXPECT_FALSE(mdc.heldElsewhere());
  ASSERT_TRUE(dnc.tryLock());
  EXPECT_TRUE(mdc.heldElsewhere());
  EXPECT_FALSE(mdc.tryLock());
  EXPECT_THROW(ScopedPortLock guard(mdc), LinkError);
  dnc.unlock();
  EXPECT_FALSE(mdc.heldElsewhere());
  {
    ScopedPortLock guard(mdc);
    EXPECT_TRUE(dnc.heldElsewhere());
  }
  EXPECT_FALSE(dnc.heldElsewhere());
}
