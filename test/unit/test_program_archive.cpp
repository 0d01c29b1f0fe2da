// The program archive: versions kept once per distinct content, the keep limit, metadata, diffs;
// modes, and links planted in the archive not followed.
#include <gtest/gtest.h>
#include <sys/stat.h>
#include <unistd.h>

#include <filesystem>

#include "cnc_bridge/common/error.h"
#include "cnc_bridge/programs/archive.h"
#include "temp_dir.h"

using namespace cnc_bridge;
using namespace cnc_bridge::programs;

TEST(ProgramArchive, DistinctContentIsKeptOnceAndOldVersionsGo)
{
  test::TempDir dir;
  ProgramArchive archive(dir.file("archive"), 3);
  const VersionSource sent{"share_node", "haas_vf2", "sent"};
  const auto first = archive.add("O01234.nc", "%\nO01234\nG0 X1.\n%\n", sent);
  ASSERT_TRUE(first.has_value());
  EXPECT_EQ(first->number, 1u);
  const auto second =
      archive.add("O01234.nc", "%\nO01234\nG0 X2.\n%\n", VersionSource{"dnc_node", "haas_vf2", "received"});
  ASSERT_TRUE(second.has_value());
  EXPECT_EQ(second->number, 2u);
  EXPECT_FALSE(archive.add("O01234.nc", "%\nO01234\nG0 X1.\n%\n", sent).has_value());  // same as version 1
  auto history = archive.history("O01234.nc");
  ASSERT_EQ(history.size(), 2u);
  EXPECT_EQ(history[1].source.node, "dnc_node");
  EXPECT_EQ(history[1].source.direction, "received");
  EXPECT_EQ(history[0].crc32, crc32Hex("%\nO01234\nG0 X1.\n%\n"));
  EXPECT_EQ(test::readFile(history[1].path), "%\nO01234\nG0 X2.\n%\n");
  EXPECT_GT(history[0].time, 0);
  for (int x = 3; x <= 5; ++x)
    archive.add("O01234.nc", "G0 X" + std::to_string(x) + ".\n", sent);
  history = archive.history("O01234.nc");
  ASSERT_EQ(history.size(), 3u);  // keep = 3: versions 3, 4, 5
  EXPECT_EQ(history.front().number, 3u);
  EXPECT_EQ(history.back().number, 5u);
  EXPECT_THROW(archive.version("O01234.nc", 1), ConfigError);
  EXPECT_TRUE(archive.history("O09999.nc").empty());
  EXPECT_THROW(archive.add("../x", "y", sent), ConfigError);
}

TEST(ProgramArchive, UnifiedDiff)
{
  // CRC-32 check value of "123456789" (the catalogue's standard check).
  EXPECT_EQ(crc32Hex("123456789"), "cbf43926");
  test::TempDir dir;
  ProgramArchive archive(dir.file("archive"));
  const VersionSource sent{"cnc_dnc", "", "sent"};
  const auto a = archive.add("O00007.nc", "%\nO00007\nG0 X1.\nM30\n%\n", sent);
  const auto b = archive.add("O00007.nc", "%\nO00007\nG0 X1.5\nM30\n%\n", sent);
  const std::string diff = ProgramArchive::diff(a->path, "O00007.nc v1", b->path, "O00007.nc v2");
  EXPECT_NE(diff.find("--- O00007.nc v1"), std::string::npos) << diff;
  EXPECT_NE(diff.find("+++ O00007.nc v2"), std::string::npos) << diff;
  EXPECT_NE(diff.find("\n-G0 X1.\n+G0 X1.5\n"), std::string::npos) << diff;
  EXPECT_EQ(ProgramArchive::diff(a->path, "a", a->path, "b"), "");
  EXPECT_THROW(ProgramArchive::diff(dir.file("none"), "a", a->path, "b"), Error);
}

TEST(ProgramArchive, ALinkPlantedInTheArchiveIsNotFollowed)
{
  test::TempDir dir("cnc_archive"), outside("cnc_outside");
  const std::string victim = outside.write("v0001.nc", "NOT YOURS\n");
  ProgramArchive archive(dir.file("archive"));
  const VersionSource sent{"share_node", "vf2", "sent"};
  // A program's folder planted as a link to a folder outside: nothing is written there.
  ASSERT_EQ(::symlink(outside.path.c_str(), dir.file("archive/O01234.nc").c_str()), 0);
  EXPECT_THROW(archive.add("O01234.nc", "%\nO01234\n%\n", sent), Error);
  EXPECT_TRUE(archive.history("O01234.nc").empty());
  EXPECT_EQ(test::readFile(victim), "NOT YOURS\n");
  EXPECT_FALSE(std::filesystem::exists(outside.file("v0001.meta")));

  // A version's file planted as a link: replaced by the version, the file it named unchanged.
  std::filesystem::create_directories(dir.file("archive/O05555.nc"));
  ASSERT_EQ(::symlink(victim.c_str(), dir.file("archive/O05555.nc/v0001.nc").c_str()), 0);
  ASSERT_TRUE(archive.add("O05555.nc", "%\nO05555\n%\n", sent).has_value());
  EXPECT_EQ(test::readFile(dir.file("archive/O05555.nc/v0001.nc")), "%\nO05555\n%\n");
  EXPECT_EQ(test::readFile(victim), "NOT YOURS\n");

  // A version whose metadata names a file elsewhere is not shown.
  test::writeFile(dir.file("archive/O05555.nc/v0002.meta"), "time = 1\nsize = 10\nfile = ../../x/v0001.nc\n");
  EXPECT_EQ(archive.history("O05555.nc").size(), 1u);
}

TEST(ProgramArchive, VersionsAreWrittenOwnerAndGroupOnly)
{
  test::TempDir dir("cnc_archive");
  const mode_t umask_before = ::umask(0);
  ProgramArchive archive(dir.file("archive"));
  const auto open = archive.add("O01234.nc", "a", {"cnc_dnc", "", "sent"});
  const auto narrow = archive.add("O01234.nc", "b", {"cnc_dnc", "", "sent"}, 0600);
  ::umask(umask_before);
  struct stat info;
  ASSERT_EQ(::stat(open->path.c_str(), &info), 0);
  EXPECT_EQ(info.st_mode & 07777, 0640u);
  ASSERT_EQ(::stat(narrow->path.c_str(), &info), 0);
  EXPECT_EQ(info.st_mode & 07777, 0600u);
  ASSERT_EQ(::stat(dir.file("archive").c_str(), &info), 0);
  EXPECT_EQ(info.st_mode & 07777, 0750u);
  ASSERT_EQ(::stat(dir.file("archive/O01234.nc").c_str(), &info), 0);
  EXPECT_EQ(info.st_mode & 07777, 0750u);
}
