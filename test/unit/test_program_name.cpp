// Program names and numbers, program heads, the protected range, the local program store (no link
// followed, only regular files read),
// getProgram()'s download written chunk by chunk and putProgram()'s upload read chunk by chunk.
#include <gtest/gtest.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <filesystem>
#include <string>
#include <vector>

#include <sys/stat.h>

#include "cnc_bridge/programs/program_name.h"
#include "cnc_bridge/programs/program_store.h"
#include "temp_dir.h"

using namespace cnc_bridge;
using namespace cnc_bridge::programs;

TEST(NamePattern, FormatsAndParses)
{
  const NamePattern haas("O%05d.nc");
  EXPECT_EQ(haas.format(1234), "O01234.nc");
  EXPECT_EQ(haas.number("O01234.nc"), 1234u);
  EXPECT_EQ(haas.number("o01234.NC"), 1234u);
  EXPECT_EQ(haas.number("O1234.nc"), 1234u);
  EXPECT_FALSE(haas.number("O01234.txt"));
  EXPECT_FALSE(haas.number("O.nc"));
  EXPECT_FALSE(haas.number("O123456789.nc"));
  EXPECT_FALSE(haas.number("XO01234.nc"));
  const NamePattern fanuc("%d");
  EXPECT_EQ(fanuc.format(7), "7");
  EXPECT_EQ(fanuc.number("0007"), 7u);
  EXPECT_EQ(NamePattern("P%%%04d.min").format(12), "P%0012.min");
  EXPECT_EQ(NamePattern("P%%%04d.min").number("P%0012.min"), 12u);
  // The last: a width that overflowed an int (found by fuzz_program_name).
  for (const char* bad : {"O.nc", "O%s.nc", "O%d%d", "O%09d", "a/%d", "%", "P%066666666666666666666666600d"})
    EXPECT_THROW(NamePattern{bad}, ConfigError) << bad;
}

TEST(ProgramHeader, NumberAndFirstComment)
{
  // The head of OpenDNC's Haas capture in test/data/xmodem (a program punched by a Haas VF-2).
  auto h = readHeader("%\nO05555(CS390_Test_NC)\n(Using G0 which travels along dogleg path.)\n");
  EXPECT_EQ(h.number, 5555u);
  EXPECT_EQ(h.comment, "CS390_Test_NC");
  h = readHeader("\r\n%\r\n:0100\r\nG0 X1 (MOVE)\r\n");
  EXPECT_EQ(h.number, 100u);
  EXPECT_EQ(h.comment, "MOVE");
  h = readHeader("G0 X1\nO1234 (LATE)\n");
  EXPECT_FALSE(h.number.has_value());  // only the first block carries the program number
  EXPECT_EQ(h.comment, "LATE");
  h = readHeader("%\nO12 (UNCLOSED");
  EXPECT_EQ(h.comment, "UNCLOSED");
  EXPECT_FALSE(readHeader("").number.has_value());
}

// The number is read where a control takes it: after '%', leader and blank blocks, and blocks
// that hold only comments (a comment block before O09010 used to send a protected program).
TEST(ProgramHeader, NumberIsReadWhereTheControlTakesIt)
{
  auto h = readHeader("%\n(WIPS CALIBRATION)\nO09010 (PROBE)\nM99\n%\n");
  EXPECT_EQ(h.number, 9010u);
  EXPECT_EQ(h.comment, "WIPS CALIBRATION");  // the first comment, as before
  EXPECT_EQ(readHeader("\n\n   \n\r\n\tO09010\nM99\n").number, 9010u);
  EXPECT_EQ(readHeader(std::string("\0\0\0  \x7f%\n\0\0O09010\n", 17)).number, 9010u);
  EXPECT_EQ(readHeader("%\n:9010\nM99\n").number, 9010u);
  EXPECT_EQ(readHeader("%\no9010\nm99\n").number, 9010u);
  EXPECT_EQ(readHeader("%\nO 9010\n").number, 9010u);
  EXPECT_EQ(readHeader("(A) (B)\n( C )\nO9010(D)").number, 9010u);
  EXPECT_EQ(readHeader("%\n(UNCLOSED\nO9010\n").number, 9010u);

  // Far beyond the 4 KB that used to be looked at.
  std::string comments = "%\n";
  while (comments.size() < 1024 * 1024)
    comments += "(PADDING PADDING PADDING PADDING)\n";
  h = readHeader(comments + "O09010\nM99\n%\n");
  EXPECT_EQ(h.number, 9010u);
  EXPECT_EQ(h.comment, "PADDING PADDING PADDING PADDING");

  // A number a control would take but this code cannot read.
  for (const char* unreadable : {"%\nO\nM99\n", "O(TITLE)\n", "%\nO123456789\n", ":\n", "%\nO"})
  {
    h = readHeader(unreadable);
    EXPECT_TRUE(h.number_unreadable) << unreadable;
    EXPECT_FALSE(h.number) << unreadable;
  }
  EXPECT_EQ(readHeader("%\nO123456789\n").first_block, "O123456789");
  // No number at all: the program's first block is program text (the control names it).
  h = readHeader("%\n(NO NUMBER)\nG0 X1\nO09010\n");
  EXPECT_FALSE(h.number);
  EXPECT_FALSE(h.number_unreadable);
}

TEST(ProgramHeader, ScannerTakesTheBytesInAnyPiecesAndStopsAtTheFirstBlock)
{
  const std::string program = "%\n(TITLE)\n\nO09010 (PROBE)\nG65 P9023\nM99\n%\n";
  for (size_t piece = 1; piece <= program.size(); ++piece)
  {
    HeaderScanner scanner;
    for (size_t at = 0; at < program.size() && !scanner.done(); at += piece)
      scanner.feed(program.substr(at, piece));
    scanner.finish();
    EXPECT_EQ(scanner.header().number, 9010u) << piece;
    EXPECT_EQ(scanner.header().comment, "TITLE") << piece;
  }
  HeaderScanner scanner;
  EXPECT_TRUE(scanner.feed("O01234 (T)\n"));  // the number and a comment: nothing more is needed
}

TEST(ProgramHeader, FileHeadsAreReadPastFourKilobytesAndOnlyFromRegularFiles)
{
  test::TempDir dir;
  std::string program;
  while (program.size() < 64 * 1024)
    program += "(LONG COMMENT BLOCK BEFORE THE NUMBER)\n";
  program += "O09010\nM99\n";
  test::writeFile(dir.file("O00001.nc"), program);
  EXPECT_EQ(readHeaderOfFile(dir.file("O00001.nc")).number, 9010u);
  const ProtectedRange range("O08000-O09999", false, "~allow_protected_programs");
  EXPECT_THROW(checkProtectedFile(range, NamePattern(), dir.file("O00001.nc")), DisabledError);

  ASSERT_EQ(::mkfifo(dir.file("fifo.nc").c_str(), 0600), 0);
  try
  {
    readHeaderOfFile(dir.file("fifo.nc"));  // would block in open() or read() if it were opened as a file
    FAIL();
  }
  catch (const ConfigError& e)
  {
    EXPECT_NE(std::string(e.what()).find("is a FIFO"), std::string::npos) << e.what();
  }
  try
  {
    readHeaderOfFile(dir.path);
    FAIL();
  }
  catch (const ConfigError& e)
  {
    EXPECT_NE(std::string(e.what()).find("is a directory"), std::string::npos) << e.what();
  }
}

TEST(ProtectedRange, AProgramWhoseNumberCannotBeReadIsRefusedUnlessAllowed)
{
  const ProtectedRange range("O08000-O09999", false, "~allow_protected_programs");
  const ProgramHeader unreadable = readHeader("%\nO123456789 (MACRO)\nM99\n");
  try
  {
    range.checkHeader("O00001.nc", 1, unreadable);
    FAIL();
  }
  catch (const DisabledError& e)
  {
    const std::string what = e.what();
    EXPECT_NE(what.find("O00001.nc"), std::string::npos) << what;
    EXPECT_NE(what.find("'O123456789 (MACRO)'"), std::string::npos) << what;
    EXPECT_NE(what.find("~allow_protected_programs"), std::string::npos) << what;
  }
  EXPECT_NO_THROW(ProtectedRange("O08000-O09999", true, "x").checkHeader("a", 1, unreadable));
  EXPECT_NO_THROW(ProtectedRange("none", false, "x").checkHeader("a", 1, unreadable));
  EXPECT_NO_THROW(range.checkHeader("a", 1, readHeader("G0 X1\n")));  // no number: the control names it
  EXPECT_THROW(range.checkHeader("a", 1, readHeader("(X)\nO9010\n")), DisabledError);
}

TEST(ProtectedRange, RefusesInsideUnlessAllowed)
{
  const ProtectedRange range("O08000-O09999", false, "~allow_protected_programs");
  EXPECT_TRUE(range.contains(8000));
  EXPECT_TRUE(range.contains(9999));
  EXPECT_FALSE(range.contains(7999));
  EXPECT_FALSE(range.contains(10000));
  EXPECT_NO_THROW(range.check("a", 1234, std::nullopt));
  try
  {
    range.check("O09010.nc", std::nullopt, 9010);
    FAIL();
  }
  catch (const DisabledError& e)
  {
    const std::string what = e.what();
    EXPECT_NE(what.find("O09010"), std::string::npos) << what;
    EXPECT_NE(what.find("O08000-O09999"), std::string::npos) << what;
    EXPECT_NE(what.find("~allow_protected_programs"), std::string::npos) << what;
  }
  EXPECT_NO_THROW(ProtectedRange("O08000-O09999", true, "x").check("a", 9000, 9000));
  EXPECT_NO_THROW(ProtectedRange("", false, "x").check("a", 9000, 9000));
  EXPECT_TRUE(ProtectedRange("100-200", false, "x").contains(150));
  for (const char* bad : {"O9-O8", "O8000", "x-y", "O8000-"})
    EXPECT_THROW(ProtectedRange(bad, false, "x"), ConfigError) << bad;
}

TEST(ProgramNames, CheckedAndTemporary)
{
  for (const char* bad : {"", "/etc/passwd", "../x", "a/../../x", "a//b", "a/./b", "a\nb"})
    EXPECT_THROW(checkName(bad), ConfigError) << bad;
  EXPECT_NO_THROW(checkName("requests/O1.nc"));
  EXPECT_TRUE(isTemporaryName(temporaryName("O01234.nc", "host-1-2")));
  EXPECT_TRUE(isTemporaryName(".O01234.nc.partial.Ab12Cd"));  // AtomicFileWriter's
  EXPECT_FALSE(isTemporaryName("O01234.nc"));
  EXPECT_EQ(temporaryName("sub/O1.nc", "t"), "sub/.O1.nc.t.partial");
}

TEST(LocalProgramStore, WritesAtomicallyAndLists)
{
  test::TempDir dir;
  LocalProgramStore store(dir.path);
  store.write("O00001.nc", "%\nO00001 (ONE)\n%\n");
  store.write("O00002.nc", "two");
  test::writeFile(dir.file(".O00003.nc.partial.XXXX"), "half");
  const auto listing = listPrograms(store, NamePattern());
  ASSERT_EQ(listing.size(), 2u);
  EXPECT_EQ(listing[0].header.comment, "ONE");
  EXPECT_EQ(listing[1].entry.size, 3u);
  std::atomic<bool> cancel{true};
  EXPECT_THROW(store.write("O00002.nc", std::string(200000, 'x'), nullptr, &cancel), CancelledError);
  EXPECT_EQ(store.read("O00002.nc"), "two");
  EXPECT_THROW(store.read("O00009.nc"), NotFoundError);
  store.rename("O00002.nc", "O00001.nc");
  EXPECT_EQ(store.read("O00001.nc"), "two");
  store.remove("O00001.nc");
  EXPECT_EQ(store.list().size(), 0u);
  EXPECT_THROW(store.write("../escape.nc", "x"), ConfigError);
}

TEST(LocalProgramStore, FollowsNoLinkAndReadsOnlyRegularFiles)
{
  test::TempDir dir("cnc_store"), outside("cnc_outside");
  const std::string secret = outside.write("secret", "SECRET\n");
  ::chmod(secret.c_str(), 0600);
  std::filesystem::create_directories(outside.file("folder"));
  LocalProgramStore store(dir.path);
  store.write("O00001.nc", "%\nO00001\n%\n");
  ASSERT_EQ(::symlink(secret.c_str(), dir.file("O01234.nc").c_str()), 0);            // a link out
  ASSERT_EQ(::symlink("O00001.nc", dir.file("O00002.nc").c_str()), 0);               // a link inside
  ASSERT_EQ(::symlink(outside.file("folder").c_str(), dir.file("sub").c_str()), 0);  // a folder out
  ASSERT_EQ(::mkfifo(dir.file("O00003.nc").c_str(), 0600), 0);

  const auto names = [&store]
  {
    std::vector<std::string> listed;
    for (const ProgramEntry& entry : store.list())
      listed.push_back(entry.name);
    return listed;
  };
  EXPECT_EQ(names(), std::vector<std::string>{"O00001.nc"});
  EXPECT_EQ(names(), std::vector<std::string>{"O00001.nc"});  // listed again: said once in the log
  for (const std::string name : {"O01234.nc", "O00002.nc"})
  {
    try
    {
      store.read(name);
      ADD_FAILURE() << name << " was read";
    }
    catch (const ConfigError& e)
    {
      EXPECT_NE(std::string(e.what()).find(dir.file(name) + " is a symbolic link, not a program file"),
                std::string::npos)
          << e.what();
    }
    EXPECT_THROW(store.readHead(name, 100), ConfigError);
    EXPECT_THROW(store.stat(name), ConfigError);
  }
  EXPECT_THROW(store.read("O00003.nc"), ConfigError);  // at once: a FIFO is not waited on
  EXPECT_THROW(store.read("sub/secret"), ConfigError);
  EXPECT_THROW(store.write("sub/O05555.nc", "into the folder outside"), ConfigError);
  EXPECT_TRUE(std::filesystem::is_empty(outside.file("folder")));

  store.write("O01234.nc", "%\nO01234\n%\n");  // replaces the link itself
  EXPECT_EQ(store.read("O01234.nc"), "%\nO01234\n%\n");
  store.remove("O00002.nc");  // the link, not the file it names
  EXPECT_EQ(store.read("O00001.nc"), "%\nO00001\n%\n");
  EXPECT_EQ(test::readFile(secret), "SECRET\n");
  struct stat info;
  ASSERT_EQ(::stat(secret.c_str(), &info), 0);
  EXPECT_EQ(info.st_mode & 07777, 0600u);
}

namespace
{
/// A store that hands a download over in chunks (as the SMB store does) and fails after \p chunks.
class ChunkedStore : public LocalProgramStore
{
 public:
  ChunkedStore(const std::string& root, int chunks) : LocalProgramStore(root), fail_after_(chunks) {}
  void readTo(const std::string& name, const StoreSink& sink, const StoreProgress& progress,
              const std::atomic<bool>* cancel) override
  {
    const std::string data = read(name, progress, cancel);
    const size_t chunk = 1024 * 1024;
    for (size_t at = 0, n = 0; at < data.size(); at += chunk, ++n)
    {
      if (static_cast<int>(n) == fail_after_)
        throw LinkError("the share vanished");
      sink(data.data() + at, std::min(chunk, data.size() - at));
    }
  }

 private:
  int fail_after_;
};
}  // namespace

TEST(GetProgram, WritesEachChunkAsItComesAndLeavesNothingWhenTheDownloadFails)
{
  test::TempDir dir;
  std::filesystem::create_directories(dir.file("share"));
  std::string program;
  for (int i = 0; program.size() < 3 * 1024 * 1024 + 5; ++i)
    program += "N" + std::to_string(i) + " G1 X1.\n";
  test::writeFile(dir.file("share/O00001.nc"), program);
  test::writeFile(dir.file("O00001.nc"), "old");

  ChunkedStore failing(dir.file("share"), 2);  // two chunks written, then the link goes
  EXPECT_THROW(getProgram(failing, "O00001.nc", dir.file("O00001.nc")), LinkError);
  EXPECT_EQ(test::readFile(dir.file("O00001.nc")), "old");  // the previous version stays...
  size_t files = 0;
  for ([[maybe_unused]] const auto& entry : std::filesystem::directory_iterator(dir.path))
    ++files;
  EXPECT_EQ(files, 2u);  // ...and no temporary file is left: share/ and O00001.nc

  ChunkedStore whole(dir.file("share"), -1);
  EXPECT_EQ(getProgram(whole, "O00001.nc", dir.file("O00001.nc")), program.size());
  EXPECT_EQ(test::readFile(dir.file("O00001.nc")), program);
}

// putProgram() reads the local file as it sends it: each chunk the store asks for is read then. A
// file cut short while it is sent (a program saved over it) fails the upload with the file's name,
// and the store keeps its previous version, with no temporary file.
TEST(PutProgram, ReadsTheFileAsItSendsItAndRefusesAFileCutShortMeanwhile)
{
  test::TempDir dir;
  std::filesystem::create_directories(dir.file("share"));
  std::string program = "%\nO00007 (LONG)\n";
  for (int i = 0; program.size() < 1024 * 1024; ++i)
    program += "N" + std::to_string(i) + " G1 X1.\n";
  program += "M30\n%\n";
  const std::string local = dir.file("O00007.nc");
  test::writeFile(local, program);
  LocalProgramStore store(dir.file("share"));
  store.write("O00007.nc", "old");

  std::vector<uint64_t> seen;
  EXPECT_EQ(putProgram(store, local, "", ProtectedRange("O08000-O09999", false, "--allow-protected"), NamePattern(),
                       [&seen](uint64_t done, uint64_t) { seen.push_back(done); }),
            program.size());
  EXPECT_EQ(store.read("O00007.nc"), program);
  EXPECT_GT(seen.size(), 10u) << "sent in chunks";

  store.write("O00007.nc", "old");
  try
  {
    putProgram(store, local, "", ProtectedRange("O08000-O09999", false, "--allow-protected"), NamePattern(),
               [&local](uint64_t done, uint64_t)
               {
                 if (done < 200000)
                   std::filesystem::resize_file(local, 100000);  // cut short after the first chunk
               });
    FAIL() << "a file cut short was sent";
  }
  catch (const Error& e)
  {
    EXPECT_NE(std::string(e.what()).find(local + " got shorter while it was sent"), std::string::npos) << e.what();
  }
  EXPECT_EQ(store.read("O00007.nc"), "old");
  std::vector<std::string> names;
  for (const auto& entry : std::filesystem::directory_iterator(dir.file("share")))
    names.push_back(entry.path().filename().string());
  EXPECT_EQ(names, std::vector<std::string>{"O00007.nc"});
}

namespace
{
/// A folder whose write first overwrites the local file being sent with a protected program of the
/// same size (another program saved over it after the check).
class SwappingStore : public LocalProgramStore
{
 public:
  SwappingStore(const std::string& root, std::string local, std::string swapped)
      : LocalProgramStore(root), local_(std::move(local)), swapped_(std::move(swapped))
  {
  }
  void writeFrom(const std::string& name, uint64_t size, const StoreSource& source, const StoreProgress& progress,
                 const std::atomic<bool>* cancel) override
  {
    test::writeFile(local_, swapped_);
    LocalProgramStore::writeFrom(name, size, source, progress, cancel);
  }

 private:
  std::string local_, swapped_;
};
}  // namespace

// The protected range is checked on the head of the file, and the head sent must be that head: a
// protected program saved over the file between the check and the upload is not sent.
TEST(PutProgram, SendsOnlyTheHeadItChecked)
{
  test::TempDir dir;
  std::filesystem::create_directories(dir.file("share"));
  const std::string local = dir.file("O00008.nc");
  test::writeFile(local, "%\nO00008 (FREE)\nM30\n%\n");
  SwappingStore store(dir.file("share"), local, "%\nO09008 (WIPS)\nM99\n%\n");
  try
  {
    putProgram(store, local, "", ProtectedRange("O08000-O09999", false, "--allow-protected"), NamePattern());
    FAIL() << "sent a program other than the one checked";
  }
  catch (const Error& e)
  {
    EXPECT_NE(std::string(e.what()).find(local + " changed while it was sent"), std::string::npos) << e.what();
  }
  EXPECT_TRUE(std::filesystem::is_empty(dir.file("share")));
}
