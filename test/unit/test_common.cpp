// Atomic file writes, program-directory confinement, the serial port lock and the job hold.
#include <gtest/gtest.h>

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <future>
#include <iterator>
#include <optional>
#include <sstream>
#include <thread>

#include "cancel_probe.h"
#include "cnc_bridge/common/atomic_file.h"
#include "cnc_bridge/common/error.h"
#include "cnc_bridge/common/job_hold.h"
#include "cnc_bridge/common/port_lock.h"
#include "cnc_bridge/common/program_dir.h"
#include "temp_dir.h"

using namespace cnc_bridge;

namespace
{
class InScratchDir : public ::testing::Test
{
 protected:
  std::string read(const std::string& path)
  {
    std::ifstream in(path);
    std::stringstream s;
    s << in.rdbuf();
    return s.str();
  }
  void writeFile(const std::string& path, const std::string& text) { std::ofstream(path) << text; }
  int entries() const { return static_cast<int>(std::distance(std::filesystem::directory_iterator(dir_), {})); }

  const test::TempDir scratch_{"cnc_bridge_test"};
  const std::string dir_ = scratch_.path;
};
}  // namespace

using AtomicFile = InScratchDir;
using ProgramDir = InScratchDir;

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

// A requested name no control or file system takes is refused before it is used or repeated: a
// 64 KB name, a part over NAME_MAX, control characters, bytes that are not UTF-8. The refusal
// shows the name shortened and escaped, never whole.
TEST_F(ProgramDir, NamesNoFileSystemTakesAreRefusedAndShownShortened)
{
  ::mkdir((dir_ + "/programs").c_str(), 0755);
  writeFile(dir_ + "/programs/O1.nc", "%\n");
  const ProgramDirectory programs(dir_ + "/programs");
  const auto refusal = [&](const std::string& name)
  {
    try
    {
      programs.resolveForWrite(name);
    }
    catch (const ConfigError& e)
    {
      return std::string(e.what());
    }
    return std::string("accepted");
  };
  const std::string huge = refusal(std::string(65536, 'x'));
  EXPECT_NE(huge.find("is 65536 bytes long, more than 1024: refused"), std::string::npos) << huge;
  EXPECT_LT(huge.size(), 200u) << "the name is repeated whole";
  EXPECT_NE(refusal(std::string(256, 'y') + ".nc").find("longer than 255 bytes"), std::string::npos);
  EXPECT_NE(refusal("O1\n.nc").find("holds a control character"), std::string::npos);
  const std::string latin1 = refusal("\xff\xfe\x80O1.nc");
  EXPECT_NE(latin1.find("'\\xff\\xfe\\x80O1.nc' is not UTF-8 text: refused"), std::string::npos) << latin1;
  EXPECT_NE(refusal("\xc0\xaf.nc").find("not UTF-8"), std::string::npos) << "an overlong '/' passed";
  EXPECT_EQ(refusal("Ö1234 Pièce.nc"), "accepted");
  EXPECT_EQ(refusal(std::string(255, 'z')), "accepted");
  EXPECT_EQ(printableName(std::string(100, 'a')), std::string(80, 'a') + "...");
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

TEST(PortLock, NodesOnOneDeviceServerPortShareTheLockWhicheverProtocolTheyUse)
{
  // dnc_node on tcp://, haas_mdc_node on rfc2217:// to the same server port: one line, one lock.
  // A lock directory of the test's own, so no other program's lock on the same name interferes.
  const test::TempDir locks("cnc_bridge_lock_test");
  const std::string& dir = locks.path;
  PortLock dnc("tcp://10.0.0.7:4001", dir);
  PortLock mdc("rfc2217://10.0.0.7:4001", dir);
  PortLock other_port("rfc2217://10.0.0.7:4002", dir);
  ASSERT_TRUE(dnc.tryLock());
  EXPECT_TRUE(mdc.heldElsewhere());
  EXPECT_FALSE(mdc.tryLock());
  EXPECT_FALSE(other_port.heldElsewhere());
  EXPECT_EQ(lockName("tcp://10.0.0.7:4001"), "net-10.0.0.7:4001");
  // The lock file stays inside the lock directory: no '/' of the URL makes a path of it.
  EXPECT_EQ(dnc.lockFile(), dir + "/cnc_bridge-net-10.0.0.7:4001.lock");
}

TEST(PortLock, ATransferWaitingForTheLockGoesBeforeTheNextQuery)
{
  // A lock directory of the test's own, so no other program's lock on the same name interferes.
  const test::TempDir locks("cnc_bridge_lock_test");
  const std::string& dir = locks.path;
  PortLock poller("/dev/ttyS_test_cnc_bridge", dir);
  PortLock dnc("/dev/ttyS_test_cnc_bridge", dir);
  ASSERT_TRUE(poller.tryLockForQuery());  // a query in flight
  std::atomic<bool> got{false};
  std::thread transfer([&] { got = dnc.lockForTransfer(std::chrono::seconds(10)); });
  // Bounded wait for the transfer to announce itself (it polls every 20 ms).
  for (int i = 0; i < 500 && !poller.wantedElsewhere(); ++i)
    std::this_thread::sleep_for(std::chrono::milliseconds(10));  // poll: a flag of another thread
  ASSERT_TRUE(poller.wantedElsewhere());
  poller.unlock();  // the query is done
  // The next query must not take the line from the waiting transfer.
  EXPECT_FALSE(poller.tryLockForQuery());
  transfer.join();
  EXPECT_TRUE(got);
  EXPECT_TRUE(dnc.held());
  EXPECT_FALSE(poller.tryLockForQuery());
  dnc.unlock();
  EXPECT_TRUE(poller.tryLockForQuery());
  poller.unlock();
}

TEST(PortLock, QueriesAndTransfersNeverOverlapAndTransfersAreNotStarved)
{
  // A poller that queries back to back (holding the lock for 2 ms, releasing it for microseconds)
  // and a transfer that needs the line five times, each within 2 s. Without the transfer's
  // announced wait the poller would win nearly every race for the lock.
  // A lock directory of the test's own, so no other program's lock on the same name interferes.
  const test::TempDir locks("cnc_bridge_lock_test");
  const std::string& dir = locks.path;
  std::atomic<int> inside{0};
  std::atomic<bool> overlap{false}, done{false};
  std::atomic<int> queries{0};
  auto enter = [&]
  {
    if (++inside > 1)
      overlap = true;
  };
  std::thread poller(
      [&]
      {
        PortLock lock("/dev/ttyS_test_cnc_bridge", dir);
        while (!done)
        {
          if (!lock.tryLockForQuery())
          {
            std::this_thread::yield();
            continue;
          }
          enter();
          std::this_thread::sleep_for(std::chrono::milliseconds(2));  // stands for the query's round trip
          --inside;
          lock.unlock();
          ++queries;
        }
      });
  PortLock dnc("/dev/ttyS_test_cnc_bridge", dir);
  int transfers = 0;
  for (int i = 0; i < 5; ++i)
  {
    while (queries < 3 * (i + 1))  // the poller is busy before each transfer asks
      std::this_thread::yield();
    if (!dnc.lockForTransfer(std::chrono::seconds(2)))
      continue;
    ++transfers;
    enter();
    std::this_thread::sleep_for(std::chrono::milliseconds(5));  // stands for the transfer
    --inside;
    dnc.unlock();
  }
  done = true;
  poller.join();
  EXPECT_FALSE(overlap);
  EXPECT_EQ(transfers, 5);
}

TEST(PortLock, EachTransferBumpsTheGenerationQueriesDoNot)
{
  // A lock directory of the test's own, so no other program's lock on the same name interferes.
  const test::TempDir locks("cnc_bridge_lock_test");
  const std::string& dir = locks.path;
  PortLock poller("/dev/ttyS_test_cnc_bridge", dir);
  PortLock dnc("/dev/ttyS_test_cnc_bridge", dir);
  ASSERT_TRUE(poller.tryLockForQuery());
  const uint64_t before = poller.generation();
  poller.unlock();
  ASSERT_TRUE(poller.tryLockForQuery());
  EXPECT_EQ(poller.generation(), before);
  poller.unlock();
  ASSERT_TRUE(dnc.lockForTransfer(std::chrono::milliseconds(100)));
  dnc.unlock();
  ASSERT_TRUE(poller.tryLockForQuery());
  EXPECT_EQ(poller.generation(), before + 1);
  poller.unlock();
}

TEST(PortLock, ACancelledTransferStopsWaiting)
{
  // A lock directory of the test's own, so no other program's lock on the same name interferes.
  const test::TempDir locks("cnc_bridge_lock_test");
  const std::string& dir = locks.path;
  PortLock poller("/dev/ttyS_test_cnc_bridge", dir);
  PortLock dnc("/dev/ttyS_test_cnc_bridge", dir);
  ASSERT_TRUE(poller.tryLockForQuery());
  int asked = 0;
  EXPECT_FALSE(dnc.lockForTransfer(std::chrono::seconds(60), [&] { return ++asked >= 3; }));
  EXPECT_EQ(asked, 3);
  EXPECT_FALSE(poller.wantedElsewhere());  // the wait is withdrawn
}

// ------------------------------------------------------------------------- JobHold
using cnc_bridge::test::CancelProbe;
using cnc_bridge::test::kPatience;

TEST(JobHold, AResumeWithNothingHeldChangesNothingAndDoesNotEndALaterHold)
{
  JobHold hold;
  EXPECT_FALSE(hold.resume().has_value());
  EXPECT_EQ(hold.held(), "");
  hold.hold("program stop M00 at line 4");
  EXPECT_EQ(hold.held(), "program stop M00 at line 4");
  // Cancelled at its first question: had the early resume counted, the wait would return true.
  EXPECT_FALSE(hold.waitForResume([] { return true; }));
  EXPECT_EQ(hold.held(), "");
}

TEST(JobHold, AResumeBetweenHoldAndWaitLetsTheWaitReturnAtOnce)
{
  JobHold hold(std::chrono::hours(1));  // no poll could end the wait within the test
  hold.hold("optional stop M01 at line 9");
  const std::optional<std::string> ended = hold.resume();
  ASSERT_TRUE(ended.has_value());
  EXPECT_EQ(*ended, "optional stop M01 at line 9");
  EXPECT_EQ(hold.held(), "optional stop M01 at line 9");  // until the job's wait takes the resume
  EXPECT_TRUE(hold.waitForResume([] { return false; }));
  EXPECT_EQ(hold.held(), "");
  EXPECT_FALSE(hold.resume().has_value());
}

TEST(JobHold, AResumeEndsAWaitInProgressWithoutWaitingForAPoll)
{
  JobHold hold(std::chrono::hours(1));
  CancelProbe probe;
  hold.hold("program stop M00 at line 12");
  auto waiting = std::async(std::launch::async, [&] { return hold.waitForResume(probe.predicate()); });
  ASSERT_EQ(probe.asked.get_future().wait_for(kPatience), std::future_status::ready);
  EXPECT_EQ(hold.held(), "program stop M00 at line 12");
  EXPECT_EQ(hold.resume().value_or(""), "program stop M00 at line 12");
  ASSERT_EQ(waiting.wait_for(kPatience), std::future_status::ready);
  EXPECT_TRUE(waiting.get());
  EXPECT_EQ(hold.held(), "");
}

TEST(JobHold, ACancelWhileHeldEndsTheWaitAtTheNextPollAndTheHold)
{
  JobHold hold(std::chrono::milliseconds(5));
  CancelProbe probe;
  hold.hold("program stop M00 at line 3");
  auto waiting = std::async(std::launch::async, [&] { return hold.waitForResume(probe.predicate()); });
  ASSERT_EQ(probe.asked.get_future().wait_for(kPatience), std::future_status::ready);
  probe.cancel = true;  // no notification: the wait must find it by polling
  ASSERT_EQ(waiting.wait_for(kPatience), std::future_status::ready);
  EXPECT_FALSE(waiting.get());
  EXPECT_EQ(hold.held(), "");
  EXPECT_FALSE(hold.resume().has_value());  // nothing left to resume
}

TEST(JobHold, WakeMakesAHeldWaitAskAtOnce)
{
  JobHold hold(std::chrono::hours(1));
  CancelProbe probe;
  hold.hold("program stop M00 at line 3");
  auto waiting = std::async(std::launch::async, [&] { return hold.waitForResume(probe.predicate()); });
  ASSERT_EQ(probe.asked.get_future().wait_for(kPatience), std::future_status::ready);
  probe.cancel = true;
  hold.wake();
  ASSERT_EQ(waiting.wait_for(kPatience), std::future_status::ready);
  EXPECT_FALSE(waiting.get());
}

TEST(JobHold, ADwellWaitsItsWholeTime)
{
  JobHold hold;
  const auto start = std::chrono::steady_clock::now();
  EXPECT_TRUE(hold.waitFor(std::chrono::duration<double>(0.06), [] { return false; }));
  EXPECT_GE(std::chrono::steady_clock::now() - start, std::chrono::milliseconds(60));
  EXPECT_TRUE(hold.waitFor(std::chrono::duration<double>(0.0), [] { return true; }));  // nothing to wait
}

TEST(JobHold, ACancelDuringADwellEndsItEarly)
{
  JobHold hold(std::chrono::milliseconds(5));
  CancelProbe probe;
  auto waiting = std::async(std::launch::async, [&] { return hold.waitFor(std::chrono::hours(1), probe.predicate()); });
  ASSERT_EQ(probe.asked.get_future().wait_for(kPatience), std::future_status::ready);
  probe.cancel = true;
  ASSERT_EQ(waiting.wait_for(kPatience), std::future_status::ready);
  EXPECT_FALSE(waiting.get());
}

TEST(JobHold, AResumeDoesNotShortenADwell)
{
  JobHold hold(std::chrono::hours(1));
  CancelProbe probe;
  auto waiting = std::async(std::launch::async, [&] { return hold.waitFor(std::chrono::hours(1), probe.predicate()); });
  ASSERT_EQ(probe.asked.get_future().wait_for(kPatience), std::future_status::ready);
  EXPECT_FALSE(hold.resume().has_value());  // a dwell is no hold
  probe.cancel = true;                      // ends the test's dwell
  hold.wake();
  ASSERT_EQ(waiting.wait_for(kPatience), std::future_status::ready);
  EXPECT_FALSE(waiting.get());  // cancelled, not elapsed
}

// ------------------------------------------------------------------------- PortLock files
// A symbolic link planted at the lock's path is never followed: the file it points to keeps its
// contents (the lock used to truncate it and write the generation into it) and the lock is refused
// with a message that says what is there.
TEST(PortLock, ALinkPlantedAtTheLockPathIsRefusedAndItsTargetUnchanged)
{
  // A lock directory of the test's own, so no other program's lock on the same name interferes.
  const test::TempDir locks("cnc_bridge_lock_test");
  const std::string& dir = locks.path;
  const std::string victim = dir + "/victim.conf";
  {
    std::ofstream out(victim);
    out << "precious contents\n";
  }
  PortLock probe("/dev/ttyS_test_cnc_bridge", dir);
  ASSERT_EQ(::symlink(victim.c_str(), probe.lockFile().c_str()), 0);
  PortLock dnc("/dev/ttyS_test_cnc_bridge", dir);
  try
  {
    dnc.lockForTransfer(std::chrono::milliseconds(100));
    FAIL() << "the lock followed a planted link";
  }
  catch (const LinkError& e)
  {
    const std::string what = e.what();
    EXPECT_NE(what.find(dnc.lockFile()), std::string::npos) << what;
    EXPECT_NE(what.find("symbolic link"), std::string::npos) << what;
  }
  std::ifstream in(victim);
  const std::string contents((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  EXPECT_EQ(contents, "precious contents\n");

  // A FIFO (or anything but a regular file) there is refused too, without blocking.
  ::unlink(dnc.lockFile().c_str());
  ASSERT_EQ(::mkfifo(dnc.lockFile().c_str(), 0600), 0);
  try
  {
    PortLock("/dev/ttyS_test_cnc_bridge", dir).tryLock();
    FAIL();
  }
  catch (const LinkError& e)
  {
    EXPECT_NE(std::string(e.what()).find("is a FIFO, not a regular file"), std::string::npos) << e.what();
  }
}

TEST(PortLock, LockFilesAreCreatedOwnerWritableOnly)
{
  // A lock directory of the test's own, so no other program's lock on the same name interferes.
  const test::TempDir locks("cnc_bridge_lock_test");
  const std::string& dir = locks.path;
  PortLock lock("/dev/ttyS_test_cnc_bridge", dir);
  ASSERT_TRUE(lock.tryLock());
  struct stat info;
  ASSERT_EQ(::lstat(lock.lockFile().c_str(), &info), 0);
  EXPECT_TRUE(S_ISREG(info.st_mode));
  EXPECT_EQ(info.st_mode & 0777 & ~0640, 0u);  // at most rw-r-----
}

// The default lock directory is /run/lock/cnc_bridge, not the world-writable /tmp: created if
// missing, a directory of this user (or root) that no other user may write to.
TEST(PortLock, TheDefaultLockDirectoryIsUnderRunLock)
{
  EXPECT_STREQ(kDefaultLockDir, "/run/lock/cnc_bridge");
  PortLock lock("/dev/ttyS_test_cnc_bridge");
  struct stat run_lock;
  if (::stat("/run/lock", &run_lock) != 0)
  {
    // No /run/lock on this system: the per-user fallback in /tmp is used.
    EXPECT_EQ(lock.lockFile().rfind("/tmp/cnc_bridge-" + std::to_string(::geteuid()) + "/", 0), 0u) << lock.lockFile();
    return;
  }
  EXPECT_EQ(lock.lockFile().rfind("/run/lock/cnc_bridge/cnc_bridge-", 0), 0u) << lock.lockFile();
  struct stat info;
  ASSERT_EQ(::lstat(kDefaultLockDir, &info), 0);
  EXPECT_TRUE(S_ISDIR(info.st_mode));
  EXPECT_TRUE(info.st_uid == ::geteuid() || info.st_uid == 0);
  EXPECT_EQ(info.st_mode & S_IWOTH, 0u);
  EXPECT_EQ(lockDirectory("/somewhere/else"), "/somewhere/else");  // a directory given is used as given
}
