// SmbProgramStore against a real Samba server (smbd started by the test, samba_server.h): transfers
// both ways byte for byte, authentication and its errors, a server that vanishes mid-upload, a
// control polling the share during uploads, protected programs, listings with O numbers.
#include <gtest/gtest.h>
#include <pwd.h>

#include <atomic>
#include <condition_variable>
#include <cstdlib>
#include <filesystem>
#include <functional>
#include <mutex>
#include <random>
#include <thread>

#include "cnc_bridge/share/smb_store.h"
#include "samba_server.h"
#include "smb_request_log.h"
#include "temp_dir.h"

using namespace cnc_bridge;
using namespace cnc_bridge::programs;
using namespace cnc_bridge::share;
using cnc_bridge::test::readFile;
using cnc_bridge::test::TempDir;

namespace
{
std::string randomBytes(size_t size, unsigned seed)
{
  std::mt19937 random(seed);
  std::string data(size, '\0');
  for (char& c : data)
    c = static_cast<char>(random() & 0xff);
  return data;
}

/// The names in a folder on the server's disk (what a control mounting the share would see).
std::vector<std::string> filesOnDisk(const std::string& folder)
{
  std::vector<std::string> names;
  for (const auto& item : std::filesystem::directory_iterator(folder))
    names.push_back(item.path().filename().string());
  std::sort(names.begin(), names.end());
  return names;
}

class SmbStoreTest : public ::testing::Test
{
 protected:
  static void SetUpTestSuite()
  {
    dir_ = new TempDir("cnc_smb_test");
    server_ = new test::SambaServer(dir_->path);
    server_->start();
  }
  static void TearDownTestSuite()
  {
    delete server_;
    delete dir_;
  }
  void SetUp() override
  {
    if (!server_->running())
      server_->start();
    for (const char* share : {"guest", "secure"})
    {
      for (const auto& item : std::filesystem::directory_iterator(server_->folder(share)))
        std::filesystem::remove_all(item.path());
    }
  }
  SmbProgramStore guest() { return SmbProgramStore(server_->url("guest"), SmbCredentials{}); }

  static TempDir* dir_;
  static test::SambaServer* server_;
};
TempDir* SmbStoreTest::dir_ = nullptr;
test::SambaServer* SmbStoreTest::server_ = nullptr;
}  // namespace

TEST_F(SmbStoreTest, GuestTransfersBothWaysByteForByte)
{
  SmbProgramStore store(server_->url("guest"), SmbCredentials{});
  for (const size_t size : {size_t(1024), size_t(5) * 1024 * 1024})
  {
    const std::string up = randomBytes(size, static_cast<unsigned>(size));
    uint64_t last_progress = 0;
    store.write("O01000.nc", up, [&](uint64_t done, uint64_t total) { last_progress = done; });
    EXPECT_EQ(last_progress, size);
    EXPECT_EQ(readFile(server_->folder("guest") + "/O01000.nc"), up) << size << " bytes up";
    const std::string down = randomBytes(size, static_cast<unsigned>(size) + 1);
    test::writeFile(server_->folder("guest") + "/O01001.nc", down);
    EXPECT_EQ(store.read("O01001.nc"), down) << size << " bytes down";
    EXPECT_EQ(store.stat("O01001.nc").size, size);
  }
  EXPECT_EQ(filesOnDisk(server_->folder("guest")), (std::vector<std::string>{"O01000.nc", "O01001.nc"}));
}

TEST_F(SmbStoreTest, UserShareWithCredentialsFile)
{
  TempDir local;
  SmbProgramStore store(server_->url("secure"), SmbCredentials::fromFile(server_->credentials("good.auth")));
  const std::string program = "%\nO01234 (SECURE)\nG0 X1.\nM30\n%\n";
  const std::string path = local.write("O01234.nc", program);
  EXPECT_EQ(putProgram(store, path, "", ProtectedRange("O08000-O09999", false, "--allow-protected"), NamePattern()),
            program.size());
  EXPECT_EQ(readFile(server_->folder("secure") + "/O01234.nc"), program);
  EXPECT_EQ(getProgram(store, "O01234.nc", local.file("back.nc")), program.size());
  EXPECT_EQ(readFile(local.file("back.nc")), program);
  struct stat info;
  ASSERT_EQ(::stat(local.file("back.nc").c_str(), &info), 0);
  EXPECT_EQ(info.st_mode & 0137, 0u);  // a download is written kProgramFileMode (0640) or narrower
}

TEST_F(SmbStoreTest, ALinkOutOfTheSharedFolderIsNotRead)
{
  // smbd itself keeps a client inside the share ("wide links = no", its default): the store
  // cannot list or fetch a file a link in the shared folder points to.
  TempDir outside("cnc_outside"), local;
  const std::string secret = outside.write("secret", "SECRET\n");
  ::chmod(secret.c_str(), 0600);
  ASSERT_EQ(::symlink(secret.c_str(), (server_->folder("guest") + "/O01234.nc").c_str()), 0);
  SmbProgramStore store = guest();
  for (const ProgramEntry& entry : store.list())
    EXPECT_NE(entry.name, "O01234.nc");
  EXPECT_THROW(getProgram(store, "O01234.nc", local.file("O01234.nc")), Error);
  EXPECT_FALSE(std::filesystem::exists(local.file("O01234.nc")));
  EXPECT_EQ(readFile(secret), "SECRET\n");
}

TEST_F(SmbStoreTest, WrongPasswordSaysSoAndWritesNothing)
{
  SmbProgramStore store(server_->url("secure"),
                        SmbCredentials::fromFile(server_->credentials("bad.auth", "not-the-password")));
  try
  {
    store.write("O01234.nc", "O01234\n");
    FAIL() << "a wrong password was accepted";
  }
  catch (const LinkError& e)
  {
    EXPECT_NE(std::string(e.what()).find("wrong user name or password"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("/secure"), std::string::npos) << e.what();
  }
  EXPECT_TRUE(filesOnDisk(server_->folder("secure")).empty());
}

TEST_F(SmbStoreTest, GuestOnAUserShareIsRefused)
{
  SmbProgramStore store(server_->url("secure"), SmbCredentials{});
  try
  {
    store.list();
    FAIL() << "a guest listed a user's share";
  }
  catch (const LinkError& e)
  {
    EXPECT_NE(std::string(e.what()).find("access denied"), std::string::npos) << e.what();
  }
}

TEST_F(SmbStoreTest, MissingShareIsNamed)
{
  SmbProgramStore store(server_->url("nosuchshare"), SmbCredentials{});
  try
  {
    store.list();
    FAIL() << "a missing share was listed";
  }
  catch (const LinkError& e)
  {
    EXPECT_NE(std::string(e.what()).find("no share 'nosuchshare'"), std::string::npos) << e.what();
  }
  SmbProgramStore store2(server_->url("guest/nofolder"), SmbCredentials{});
  EXPECT_THROW(store2.list(), LinkError);
}

// A store connects with its first call, whatever it is: a failure of that call names what failed
// (login, share, folder), not the program it was about, and leaves nothing on the share.
TEST_F(SmbStoreTest, TheFirstCallOfAStoreNamesWhatFailedAtTheShare)
{
  std::filesystem::create_directories(server_->folder("guest") + "/programs");
  test::writeFile(server_->folder("guest") + "/afile", "not a folder");
  const std::string bad_password = server_->credentials("wrong.auth", "not-the-password");
  struct Case
  {
    std::string url;
    std::string credentials;  // empty: guest
    std::string says;
  };
  const std::vector<Case> cases = {
      {server_->url("nosuchshare"), "", "no share 'nosuchshare'"},
      {server_->url("guest/nofolder"), "", "no folder 'nofolder'"},
      {server_->url("guest/afile"), "", "'afile' is not a folder"},
      {server_->url("secure"), "", "access denied to a guest"},
      {server_->url("secure"), bad_password, "wrong user name or password"},
  };
  using Call = std::function<void(SmbProgramStore&)>;
  const std::vector<std::pair<std::string, Call>> calls = {
      {"list", [](SmbProgramStore& s) { s.list(); }},
      {"read", [](SmbProgramStore& s) { s.read("O01000.nc"); }},
      {"readHead", [](SmbProgramStore& s) { s.readHead("O01000.nc", 100); }},
      {"stat", [](SmbProgramStore& s) { s.stat("O01000.nc"); }},
      {"write", [](SmbProgramStore& s) { s.write("O01000.nc", "%\nO01000\n%\n"); }},
      {"rename", [](SmbProgramStore& s) { s.rename("O01000.nc", "O01001.nc"); }},
      {"remove", [](SmbProgramStore& s) { s.remove("O01000.nc"); }},
  };
  for (const auto& c : cases)
  {
    for (const auto& [call_name, call] : calls)
    {
      SmbProgramStore store(c.url, c.credentials.empty() ? SmbCredentials{} : SmbCredentials::fromFile(c.credentials));
      try
      {
        call(store);
        ADD_FAILURE() << call_name << " on " << c.url << " succeeded";
      }
      catch (const LinkError& e)
      {
        EXPECT_NE(std::string(e.what()).find(c.says), std::string::npos) << call_name << ": " << e.what();
      }
      catch (const std::exception& e)
      {
        ADD_FAILURE() << call_name << " on " << c.url << ": not a link error: " << e.what();
      }
    }
  }
  EXPECT_EQ(filesOnDisk(server_->folder("guest")), (std::vector<std::string>{"afile", "programs"}));
  EXPECT_TRUE(filesOnDisk(server_->folder("secure")).empty());
  // On a share that works, the first call's missing program is just that.
  SmbProgramStore store(server_->url("guest/programs"), SmbCredentials{});
  EXPECT_THROW(store.read("O01000.nc"), NotFoundError);
  EXPECT_THROW(SmbProgramStore(server_->url("guest/programs"), SmbCredentials{}).stat("O01000.nc"), NotFoundError);
  EXPECT_THROW(SmbProgramStore(server_->url("guest/programs"), SmbCredentials{}).remove("O01000.nc"), NotFoundError);
}

TEST_F(SmbStoreTest, MissingFileIsNotFound)
{
  SmbProgramStore store = guest();
  EXPECT_THROW(store.read("O04444.nc"), NotFoundError);
  EXPECT_THROW(store.remove("O04444.nc"), NotFoundError);
  // The store still works after a missing file (the link was not dropped).
  store.write("O04445.nc", "x");
  EXPECT_EQ(store.read("O04445.nc"), "x");
}

TEST_F(SmbStoreTest, CredentialsFileReadableByOthersIsRefused)
{
  const std::string path = server_->credentials("open.auth");
  ::chmod(path.c_str(), 0644);
  try
  {
    SmbCredentials::fromFile(path);
    FAIL() << "a credentials file readable by others was accepted";
  }
  catch (const ConfigError& e)
  {
    EXPECT_NE(std::string(e.what()).find(path), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("0644"), std::string::npos) << e.what();
  }
  ::chmod(path.c_str(), 0640);
  EXPECT_THROW(SmbCredentials::fromFile(path), ConfigError);
  ::chmod(path.c_str(), 0600);
  EXPECT_EQ(SmbCredentials::fromFile(path).username, server_->user);
}

TEST_F(SmbStoreTest, ServerStoppedMidUploadKeepsThePreviousVersion)
{
  SmbProgramStore store = guest();
  const std::string old_version = "%\nO02000 (OLD)\nM30\n%\n";
  store.write("O02000.nc", old_version);
  const std::string new_version = randomBytes(5 * 1024 * 1024, 7);
  try
  {
    store.write("O02000.nc", new_version,
                [&](uint64_t done, uint64_t total)
                {
                  if (done < total && server_->running())
                    server_->stop(SIGKILL);
                });
    FAIL() << "the upload succeeded with the server gone";
  }
  catch (const LinkError& e)
  {
    EXPECT_NE(std::string(e.what()).find("O02000.nc"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find(server_->url("guest").substr(6)), std::string::npos) << e.what();
  }
  EXPECT_EQ(readFile(server_->folder("guest") + "/O02000.nc"), old_version);
  // The server comes back: the next call reconnects, removes the temporary file the killed server
  // kept, and works.
  server_->start();
  const auto listing = store.list();
  ASSERT_EQ(listing.size(), 1u);
  EXPECT_EQ(listing[0].name, "O02000.nc");
  EXPECT_EQ(filesOnDisk(server_->folder("guest")), std::vector<std::string>{"O02000.nc"});
  EXPECT_EQ(store.read("O02000.nc"), old_version);
  store.write("O02000.nc", new_version);
  EXPECT_EQ(readFile(server_->folder("guest") + "/O02000.nc"), new_version);
}

TEST_F(SmbStoreTest, ServerDownIsALinkErrorNamingTheAddress)
{
  server_->stop();
  SmbProgramStore store = guest();
  try
  {
    store.list();
    FAIL() << "listed a share with no server";
  }
  catch (const LinkError& e)
  {
    EXPECT_NE(std::string(e.what()).find("127.0.0.1:" + std::to_string(server_->port)), std::string::npos) << e.what();
  }
}

// The control is Samba's own smbclient, in processes of its own, fetching the program again and
// again while new versions are uploaded. After every 1 MB chunk the upload waits for the control to
// finish one more fetch, so fetches certainly fall in the middle of uploads.
TEST_F(SmbStoreTest, AWatcherPollingTheShareNeverReadsAPartialProgram)
{
  constexpr int kVersions = 4;
  std::vector<std::string> versions;
  for (int v = 0; v < kVersions; ++v)
    versions.push_back(std::string(3 * 1024 * 1024, static_cast<char>('a' + v)));
  SmbProgramStore writer = guest();
  writer.write("O03000.nc", versions[0]);
  const std::string fetched = dir_->file("fetched.nc");
  const std::string fetch = "smbclient //127.0.0.1/guest -p " + std::to_string(server_->port) +
                            " -N -c 'get O03000.nc " + fetched + "' >" + dir_->file("smbclient.log") + " 2>&1";
  std::mutex mutex;
  std::condition_variable fetched_one;
  bool done = false;
  int fetches = 0, complete = 0, partial = 0, failed = 0;
  std::thread control(
      [&]
      {
        for (;;)
        {
          {
            std::lock_guard<std::mutex> lock(mutex);
            if (done)
              return;
          }
          std::filesystem::remove(fetched);
          const bool ok = std::system(fetch.c_str()) == 0;
          const std::string seen = readFile(fetched);
          std::lock_guard<std::mutex> lock(mutex);
          ++fetches;
          if (!ok)
            ++failed;  // not found, or a sharing violation during the renames: no program, not a partial one
          else if (std::find(versions.begin(), versions.end(), seen) != versions.end())
            ++complete;
          else
            ++partial;
          fetched_one.notify_all();
        }
      });
  for (int v = 1; v < kVersions; ++v)
  {
    writer.write("O03000.nc", versions[v],
                 [&](uint64_t, uint64_t)
                 {
                   std::unique_lock<std::mutex> lock(mutex);
                   const int seen = fetches;
                   fetched_one.wait(lock, [&] { return fetches > seen; });
                 });
  }
  {
    std::lock_guard<std::mutex> lock(mutex);
    done = true;
  }
  control.join();
  EXPECT_GE(fetches, 3 * (kVersions - 1));
  EXPECT_GT(complete, 0);
  EXPECT_EQ(partial, 0) << fetches << " fetches, " << complete << " complete, " << failed << " failed";
  EXPECT_EQ(readFile(server_->folder("guest") + "/O03000.nc"), versions.back());
  EXPECT_EQ(filesOnDisk(server_->folder("guest")), std::vector<std::string>{"O03000.nc"});
}

TEST_F(SmbStoreTest, ProtectedProgramIsRefusedBeforeAByteIsWritten)
{
  TempDir local;
  SmbProgramStore store = guest();
  const ProtectedRange range("O08000-O09999", false, "--allow-protected");
  const std::string by_name = local.write("O09000.nc", "%\nO01000 (NAME SAYS 9000)\nM30\n%\n");
  const std::string by_text = local.write("probe.nc", "%\nO08100 (WIPS)\nM30\n%\n");
  for (const std::string& path : {by_name, by_text})
  {
    try
    {
      putProgram(store, path, "", range, NamePattern());
      FAIL() << path << " was sent";
    }
    catch (const DisabledError& e)
    {
      EXPECT_NE(std::string(e.what()).find("O08000-O09999"), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find("--allow-protected"), std::string::npos) << e.what();
    }
  }
  EXPECT_TRUE(filesOnDisk(server_->folder("guest")).empty());
  putProgram(store, by_text, "", ProtectedRange("O08000-O09999", true, "--allow-protected"), NamePattern());
  EXPECT_EQ(filesOnDisk(server_->folder("guest")), std::vector<std::string>{"probe.nc"});
}

TEST_F(SmbStoreTest, ListingShowsNumbersAndFirstComments)
{
  test::writeFile(server_->folder("guest") + "/O01234.nc", "%\nO01234 (FACE MILL 3 IN)\nG0 X0\n%\n");
  test::writeFile(server_->folder("guest") + "/O00042.nc", "%\nO42\n(SECOND LINE COMMENT)\n%\n");
  test::writeFile(server_->folder("guest") + "/notes.txt", "no number here");
  std::filesystem::create_directories(server_->folder("guest") + "/requests");
  SmbProgramStore store = guest();
  const auto listing = listPrograms(store, NamePattern("O%05d.nc"));
  ASSERT_EQ(listing.size(), 3u);
  EXPECT_EQ(listing[0].entry.name, "O00042.nc");
  EXPECT_EQ(listing[0].name_number, 42u);
  EXPECT_EQ(listing[0].header.number, 42u);
  EXPECT_EQ(listing[0].header.comment, "SECOND LINE COMMENT");
  EXPECT_EQ(listing[1].entry.name, "O01234.nc");
  EXPECT_EQ(listing[1].header.number, 1234u);
  EXPECT_EQ(listing[1].header.comment, "FACE MILL 3 IN");
  EXPECT_GT(listing[1].entry.mtime, 0);
  EXPECT_EQ(listing[2].entry.name, "notes.txt");
  EXPECT_FALSE(listing[2].name_number.has_value());
}

TEST_F(SmbStoreTest, RenameAndRemove)
{
  SmbProgramStore store = guest();
  store.write("O05000.nc", "five");
  store.write("O05001.nc", "old");
  store.rename("O05000.nc", "O05001.nc");
  EXPECT_EQ(filesOnDisk(server_->folder("guest")), std::vector<std::string>{"O05001.nc"});
  EXPECT_EQ(store.read("O05001.nc"), "five");
  store.remove("O05001.nc");
  EXPECT_TRUE(store.list().empty());
}

// config/share/served_share.smb.conf as an administrator installs it (path and user replaced): the
// PC publishes into the served folder as cnc_dnc and share_node do (a local store), and a control
// logging in with the user's password lists and reads the program, and saves one back.
// An upload reads the local file as it sends it; a file cut short meanwhile (a program saved over
// it) fails the upload naming the file, and the share keeps the previous version, with no
// temporary file.
TEST_F(SmbStoreTest, AnUploadOfAFileCutShortWhileItIsSentKeepsThePreviousVersion)
{
  SmbProgramStore store = guest();
  const std::string old_version = "%\nO06000 (OLD)\nM30\n%\n";
  store.write("O06000.nc", old_version);
  const std::string local = dir_->file("O06000.nc");
  test::writeFile(local, "%\nO06000 (NEW)\n" + randomBytes(5 * 1024 * 1024, 9));
  try
  {
    putProgram(store, local, "", ProtectedRange("O08000-O09999", false, "--allow-protected"), NamePattern(),
               [&local](uint64_t done, uint64_t)
               {
                 if (done <= 1024 * 1024)
                   std::filesystem::resize_file(local, 1536 * 1024);
               });
    FAIL() << "a file cut short was sent";
  }
  catch (const Error& e)
  {
    EXPECT_NE(std::string(e.what()).find(local + " got shorter while it was sent"), std::string::npos) << e.what();
  }
  EXPECT_EQ(readFile(server_->folder("guest") + "/O06000.nc"), old_version);
  EXPECT_EQ(filesOnDisk(server_->folder("guest")), std::vector<std::string>{"O06000.nc"});
}

// What a transfer costs on the wire, counted by a proxy between the store and smbd. On a connected
// store a replacing upload is its atomic replace and nothing more: the temporary file (create,
// write, close), the old version moved aside and the new one renamed in (create, set info, close
// each), the old one deleted (create, close).
TEST_F(SmbStoreTest, AReplacingUploadSendsItsAtomicReplaceAndNothingMore)
{
  test::SmbRequestLog wire(server_->port);
  SmbProgramStore store(wire.url("guest"), SmbCredentials{});
  store.write("O05000.nc", "%\nO05000 (FIRST)\nM30\n%\n");
  wire.clear();
  const std::string second = "%\nO05000 (SECOND)\nM30\n%\n";
  store.write("O05000.nc", second);
  EXPECT_EQ(wire.commands(), (std::vector<std::string>{"CREATE", "WRITE", "CLOSE", "CREATE", "SET_INFO", "CLOSE",
                                                       "CREATE", "SET_INFO", "CLOSE", "CREATE", "CLOSE"}));
  EXPECT_EQ(readFile(server_->folder("guest") + "/O05000.nc"), second);
}

// libsmbclient sends an ECHO before it reuses a connection it has not heard from within the
// timeout; the store counts the answers to its own requests, so a fresh store (one cnc_dnc
// transfer) spends none: one connection, no ECHO, for an upload and for a stat and a download.
TEST_F(SmbStoreTest, AFreshStoreSpendsNoEchoOnAConnectionThatJustAnswered)
{
  test::SmbRequestLog wire(server_->port);
  const std::string program = randomBytes(100 * 1024, 11);
  SmbProgramStore(wire.url("guest"), SmbCredentials{}).write("O05001.nc", program);
  SmbProgramStore reader(wire.url("guest"), SmbCredentials{});
  EXPECT_EQ(reader.stat("O05001.nc").size, program.size());
  EXPECT_EQ(reader.read("O05001.nc"), program);
  const auto sent = wire.commands();
  EXPECT_EQ(std::count(sent.begin(), sent.end(), "NEGOTIATE"), 2) << "one connection per store";
  EXPECT_EQ(std::count(sent.begin(), sent.end(), "ECHO"), 0);
}

// The store's answers count for as long as libsmbclient trusts its own ECHO (the timeout). A store
// idle for longer lets libsmbclient check the connection, which finds the server restarted and
// reconnects: the call works.
TEST_F(SmbStoreTest, AStoreIdleLongerThanItsTimeoutReconnectsToARestartedServer)
{
  test::SmbRequestLog wire(server_->port);
  SmbProgramStore store(wire.url("guest"), SmbCredentials{}, std::chrono::milliseconds(1000));
  const std::string program = "%\nO05002 (KEPT)\nM30\n%\n";
  store.write("O05002.nc", program);
  server_->stop();
  server_->start();
  std::this_thread::sleep_for(std::chrono::milliseconds(1100));  // the idle time under test: past the timeout
  wire.clear();
  EXPECT_EQ(store.read("O05002.nc"), program);
  const auto sent = wire.commands();
  EXPECT_EQ(std::count(sent.begin(), sent.end(), "NEGOTIATE"), 1) << "reconnected once";
}

TEST(ServedShare, SnippetServesThePublishedPrograms)
{
  TempDir dir("cnc_served_share");
  const std::string served = dir.file("served");
  std::filesystem::create_directories(served);
  std::string snippet = readFile(SERVED_SHARE_CONF);
  ASSERT_FALSE(snippet.empty()) << SERVED_SHARE_CONF;
  const passwd* me = ::getpwuid(::geteuid());
  auto replace = [&](const std::string& from, const std::string& to)
  {
    for (auto at = snippet.find(from); at != std::string::npos; at = snippet.find(from, at + to.size()))
      snippet.replace(at, from.size(), to);
  };
  replace("/srv/cnc_programs", served);
  replace("users = cnc", std::string("users = ") + me->pw_name);
  replace("user = cnc", std::string("user = ") + me->pw_name);
  test::SambaServer server(dir.path, snippet);
  EXPECT_EQ(std::system(("testparm -s " + server.config() + " >/dev/null 2>&1").c_str()), 0);
  server.start();

  LocalProgramStore pc(served);
  const std::string program = "%\nO06000 (SERVED)\nM30\n%\n";
  pc.write("O06000.nc", program);
  SmbProgramStore control(server.url("cnc_programs"), SmbCredentials::fromFile(server.credentials("control.auth")));
  const auto listing = control.list();
  ASSERT_EQ(listing.size(), 1u);
  EXPECT_EQ(listing[0].name, "O06000.nc");
  EXPECT_EQ(control.read("O06000.nc"), program);
  control.write("O06001.nc", "%\nO06001 (SAVED AT THE CONTROL)\n%\n");
  EXPECT_EQ(pc.read("O06001.nc"), "%\nO06001 (SAVED AT THE CONTROL)\n%\n");
  EXPECT_THROW(SmbProgramStore(server.url("cnc_programs"), SmbCredentials{}).list(), LinkError);  // no guests
}

TEST(SmbUrl, Parses)
{
  const SmbUrl url = SmbUrl::parse("smb://cnc@10.0.0.5:4450/memory/user/programs/");
  EXPECT_EQ(url.user, "cnc");
  EXPECT_EQ(url.host, "10.0.0.5");
  EXPECT_EQ(url.port, 4450u);
  EXPECT_EQ(url.share, "memory");
  EXPECT_EQ(url.folder, "user/programs");
  EXPECT_EQ(SmbUrl::parse("smb://haas/share").port, 445u);
  try
  {
    SmbUrl::parse("smb://u:s3cret-pw@host/share");
    ADD_FAILURE() << "a password in the address was taken";
  }
  catch (const ConfigError& e)
  {
    EXPECT_NE(std::string(e.what()).find("holds user information with a password"), std::string::npos) << e.what();
    EXPECT_EQ(std::string(e.what()).find("s3cret-pw"), std::string::npos) << e.what();
  }
  EXPECT_THROW(SmbUrl::parse("smb://host"), ConfigError);
  EXPECT_THROW(SmbUrl::parse("smb://host:0/s"), ConfigError);
  EXPECT_THROW(SmbUrl::parse("smb://host/s/../etc"), ConfigError);
  EXPECT_THROW(SmbUrl::parse("ftp://host/s"), ConfigError);
}
