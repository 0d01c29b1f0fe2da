// The hybrid share (cnc_bridge/share/hybrid_share.h): a program dropped onto the NAS reaches every
// machine once complete, each machine's result its own; one being written is not pushed; the
// protected range and names that are no program stay where they are; programs the machines write
// are collected onto the NAS, a folder per machine, each version kept in the archive. Local
// folders stand for the NAS and the machines, with one machine a real Samba share. The clock is
// passed in: no test waits for the settle time.
#include <gtest/gtest.h>
#include <sys/stat.h>

#include <filesystem>

#include "cnc_bridge/share/hybrid_share.h"
#include "cnc_bridge/share/share_settings.h"
#include "cnc_bridge/share/smb_store.h"
#include "samba_server.h"
#include "temp_dir.h"

using namespace cnc_bridge;
using namespace cnc_bridge::share;
using cnc_bridge::test::readFile;
using cnc_bridge::test::TempDir;
using programs::LocalProgramStore;
using programs::ProgramEntry;

namespace
{
const std::string kProgram = "%\nO01000 (BRACKET OP10)\nG0 G90 X0 Y0\nM30\n%\n";
const auto kT0 = HubClock::time_point() + std::chrono::hours(1);
const auto kSettle = std::chrono::seconds(2);

std::string makeFolder(const std::string& path)
{
  std::filesystem::create_directories(path);
  return path;
}

HubRules rules()
{
  HubRules r;
  r.settle = kSettle;
  return r;
}

/// The NAS and two machines, each a local folder.
struct Cell
{
  TempDir dir{"test_hybrid_share"};
  std::string nas_dir = makeFolder(dir.path + "/nas");
  std::string vf2_dir = makeFolder(dir.path + "/vf2");
  std::string vf3_dir = makeFolder(dir.path + "/vf3");
  std::shared_ptr<LocalProgramStore> nas = std::make_shared<LocalProgramStore>(nas_dir);
  std::vector<HubMachine> machines{{"vf2", std::make_shared<LocalProgramStore>(vf2_dir), nullptr},
                                   {"vf3", std::make_shared<LocalProgramStore>(vf3_dir), nullptr}};
  std::vector<HubResult> reported;
  DropFolder drop{nas, machines, rules(), [this](const HubResult& r) { reported.push_back(r); }};
};
}  // namespace

TEST(SettledFiles, AFileIsCompleteWhenTwoListingsTheSettleTimeApartAgree)
{
  SettledFiles files(kSettle);
  const ProgramEntry growing{"O01000.nc", 100, 50};
  EXPECT_TRUE(files.update({growing}, kT0).empty()) << "first seen";
  EXPECT_TRUE(files.update({growing}, kT0 + std::chrono::seconds(1)).empty()) << "not yet the settle time";
  const ProgramEntry grown{"O01000.nc", 200, 51};
  EXPECT_TRUE(files.update({grown}, kT0 + std::chrono::seconds(3)).empty()) << "it changed: the wait starts again";
  EXPECT_TRUE(files.update({grown}, kT0 + std::chrono::seconds(4)).empty());
  const auto complete = files.update({grown}, kT0 + std::chrono::seconds(5));
  ASSERT_EQ(complete.size(), 1u);
  files.handled(complete[0]);
  EXPECT_TRUE(files.update({grown}, kT0 + std::chrono::seconds(9)).empty()) << "handled: not again";
  // Gone, then dropped again the same: new again.
  EXPECT_TRUE(files.update({}, kT0 + std::chrono::seconds(10)).empty());
  EXPECT_TRUE(files.update({grown}, kT0 + std::chrono::seconds(11)).empty());
  EXPECT_EQ(files.update({grown}, kT0 + std::chrono::seconds(13)).size(), 1u);
}

TEST(DropFolder, AProgramDroppedOntoTheNasReachesEveryMachineOnceComplete)
{
  Cell cell;
  cell.nas->write("O01000.nc", kProgram);
  EXPECT_TRUE(cell.drop.poll(kT0).empty());
  EXPECT_FALSE(std::filesystem::exists(cell.vf2_dir + "/O01000.nc")) << "pushed before it was complete";
  const auto pushed = cell.drop.poll(kT0 + kSettle);
  ASSERT_EQ(pushed.size(), 1u);
  EXPECT_EQ(readFile(cell.vf2_dir + "/O01000.nc"), kProgram);
  EXPECT_EQ(readFile(cell.vf3_dir + "/O01000.nc"), kProgram);
  ASSERT_EQ(pushed[0].machines.size(), 2u);
  EXPECT_TRUE(programs::allSucceeded(pushed[0].machines)) << describe(pushed[0]);
  const std::string written = "written (" + std::to_string(kProgram.size()) + " bytes)";
  EXPECT_EQ(describe(pushed[0]), "O01000.nc: vf2 ok (" + written + "), vf3 ok (" + written + ")");
  ASSERT_EQ(cell.reported.size(), 1u);
  // The NAS keeps it (the day's end withdraws it); nothing is pushed again while it is unchanged.
  EXPECT_TRUE(std::filesystem::exists(cell.nas_dir + "/O01000.nc"));
  EXPECT_TRUE(cell.drop.poll(kT0 + 10 * kSettle).empty());
}

TEST(DropFolder, AMachineThatIsGoneIsItsOwnResultAndTheOthersGetTheProgram)
{
  Cell cell;
  std::filesystem::remove_all(cell.vf2_dir);  // the machine's share went away
  cell.nas->write("O01000.nc", kProgram);
  cell.drop.poll(kT0);
  const auto pushed = cell.drop.poll(kT0 + kSettle);
  ASSERT_EQ(pushed.size(), 1u);
  ASSERT_EQ(pushed[0].machines.size(), 2u);
  EXPECT_FALSE(pushed[0].machines[0].success);
  EXPECT_NE(pushed[0].machines[0].message.find("vf2"), std::string::npos) << pushed[0].machines[0].message;
  EXPECT_TRUE(pushed[0].machines[1].success);
  EXPECT_EQ(readFile(cell.vf3_dir + "/O01000.nc"), kProgram);
}

TEST(DropFolder, AMachineWithTheSameProgramIsNotWrittenAgain)
{
  Cell cell;
  cell.machines[0].store->write("O01000.nc", kProgram);
  struct stat before
  {
  };
  ASSERT_EQ(::stat((cell.vf2_dir + "/O01000.nc").c_str(), &before), 0);
  cell.nas->write("O01000.nc", kProgram);
  cell.drop.poll(kT0);
  const auto pushed = cell.drop.poll(kT0 + kSettle);
  ASSERT_EQ(pushed.size(), 1u);
  EXPECT_EQ(pushed[0].machines[0].message, "already there, the same");
  struct stat after
  {
  };
  ASSERT_EQ(::stat((cell.vf2_dir + "/O01000.nc").c_str(), &after), 0);
  EXPECT_EQ(before.st_ino, after.st_ino) << "rewritten (a write replaces the file by a rename)";
}

TEST(DropFolder, AProtectedProgramAndAFileThatIsNoProgramStayOnTheNas)
{
  Cell cell;
  cell.nas->write("O09010.nc", "%\nO09010 (PROBE MACRO)\nM99\n%\n");
  cell.nas->write("O01001.nc", "%\nO09011 (PROTECTED BY ITS TEXT)\nM99\n%\n");
  cell.nas->write("notes.txt", "fixture plate: 4 bolts\n");
  cell.drop.poll(kT0);
  const auto pushed = cell.drop.poll(kT0 + kSettle);
  ASSERT_EQ(pushed.size(), 3u);
  for (const auto& result : pushed)
  {
    ASSERT_EQ(result.machines.size(), 1u) << describe(result);
    EXPECT_FALSE(result.machines[0].success) << describe(result);
  }
  EXPECT_NE(describe(pushed[0]).find("~allow_protected_programs"), std::string::npos) << describe(pushed[0]);
  EXPECT_NE(describe(pushed[1]).find("~allow_protected_programs"), std::string::npos) << describe(pushed[1]);
  EXPECT_NE(describe(pushed[2]).find("not a program name"), std::string::npos) << describe(pushed[2]);
  EXPECT_TRUE(std::filesystem::is_empty(cell.vf2_dir)) << "a machine received a file";
  EXPECT_TRUE(std::filesystem::is_empty(cell.vf3_dir)) << "a machine received a file";
}

TEST(DropFolder, ANasThatCannotBeListedIsAnErrorAndNothingIsForgotten)
{
  Cell cell;
  cell.nas->write("O01000.nc", kProgram);
  cell.drop.poll(kT0);
  std::filesystem::rename(cell.nas_dir, cell.nas_dir + ".away");
  EXPECT_THROW(cell.drop.poll(kT0 + kSettle), Error);
  std::filesystem::rename(cell.nas_dir + ".away", cell.nas_dir);
  EXPECT_EQ(cell.drop.poll(kT0 + 2 * kSettle).size(), 1u) << "the file seen before the NAS went away";
  EXPECT_EQ(readFile(cell.vf3_dir + "/O01000.nc"), kProgram);
}

TEST(DropFolder, APushReachesAMachineOnARealSambaShare)
{
  TempDir dir("test_hybrid_share");
  test::SambaServer server(dir.path + "/smb");
  server.start();
  const std::string nas_dir = makeFolder(dir.path + "/nas");
  auto nas = std::make_shared<LocalProgramStore>(nas_dir);
  std::vector<HubMachine> machines{
      {"vf2", std::shared_ptr<programs::ProgramStore>(openStore(server.url("guest"))), nullptr}};
  DropFolder drop(nas, machines, rules(), nullptr);
  nas->write("O01000.nc", kProgram);
  drop.poll(kT0);
  const auto pushed = drop.poll(kT0 + kSettle);
  ASSERT_EQ(pushed.size(), 1u);
  EXPECT_TRUE(programs::allSucceeded(pushed[0].machines)) << describe(pushed[0]);
  EXPECT_EQ(readFile(server.folder("guest") + "/O01000.nc"), kProgram);
}

TEST(Collection, WhatAMachineWritesIsCollectedIntoItsNasFolderAndKeptInTheArchive)
{
  TempDir dir("test_hybrid_share");
  auto vf2 = std::make_shared<LocalProgramStore>(makeFolder(dir.path + "/vf2"));
  auto vf3 = std::make_shared<LocalProgramStore>(makeFolder(dir.path + "/vf3"));
  auto into_vf2 = std::make_shared<LocalProgramStore>(makeFolder(dir.path + "/nas/vf2"));
  auto into_vf3 = std::make_shared<LocalProgramStore>(makeFolder(dir.path + "/nas/vf3"));
  programs::ProgramArchive archive(dir.path + "/archive");
  std::vector<std::string> reported;
  Collection collection({{"vf2", vf2, into_vf2}, {"vf3", vf3, into_vf3}}, rules(), archive,
                        {"share_node", "", "collected"},
                        [&](const std::string& machine, const HubResult& r) { reported.push_back(machine); });
  // Both machines edited their own O01000 at the control.
  vf2->write("O01000.nc", kProgram);
  vf3->write("O01000.nc", "%\nO01000 (OTHER PART)\nM30\n%\n");
  vf3->write("O01000.bak", "not a program name\n");
  collection.poll(kT0);
  const auto collected = collection.poll(kT0 + kSettle);
  ASSERT_EQ(collected.size(), 2u);
  EXPECT_EQ(readFile(dir.path + "/nas/vf2/O01000.nc"), kProgram);
  EXPECT_EQ(readFile(dir.path + "/nas/vf3/O01000.nc"), "%\nO01000 (OTHER PART)\nM30\n%\n");
  EXPECT_FALSE(std::filesystem::exists(dir.path + "/nas/vf3/O01000.bak"));
  EXPECT_EQ((std::vector<std::string>{"vf2", "vf3"}), reported);
  const auto history = archive.history("O01000.nc");
  ASSERT_EQ(history.size(), 2u);
  EXPECT_EQ(history[0].source.machine, "vf2");
  EXPECT_EQ(history[0].source.direction, "collected");
  // The operator edits it again at the VF-2: a new version, collected and kept.
  vf2->write("O01000.nc", kProgram + "(EDITED)\n");
  collection.poll(kT0 + 3 * kSettle);
  EXPECT_EQ(collection.poll(kT0 + 4 * kSettle).size(), 1u);
  EXPECT_EQ(readFile(dir.path + "/nas/vf2/O01000.nc"), kProgram + "(EDITED)\n");
  EXPECT_EQ(archive.history("O01000.nc").size(), 3u);
}

TEST(Collection, AMachineThatCannotBeListedIsReportedAndTheOthersAreCollected)
{
  TempDir dir("test_hybrid_share");
  const std::string vf2_dir = makeFolder(dir.path + "/vf2");
  auto vf2 = std::make_shared<LocalProgramStore>(vf2_dir);
  auto vf3 = std::make_shared<LocalProgramStore>(makeFolder(dir.path + "/vf3"));
  programs::ProgramArchive archive(dir.path + "/archive");
  Collection collection({{"vf2", vf2, std::make_shared<LocalProgramStore>(makeFolder(dir.path + "/nas/vf2"))},
                         {"vf3", vf3, std::make_shared<LocalProgramStore>(makeFolder(dir.path + "/nas/vf3"))}},
                        rules(), archive, {"share_node", "", "collected"}, nullptr);
  vf3->write("O01000.nc", kProgram);
  std::filesystem::remove_all(vf2_dir);
  collection.poll(kT0);
  const auto collected = collection.poll(kT0 + kSettle);
  ASSERT_EQ(collected.size(), 2u);
  EXPECT_FALSE(collected[0].machines[0].success);
  EXPECT_NE(collected[0].machines[0].message.find("cannot list"), std::string::npos) << describe(collected[0]);
  EXPECT_TRUE(collected[1].machines[0].success) << describe(collected[1]);
  EXPECT_EQ(readFile(dir.path + "/nas/vf3/O01000.nc"), kProgram);
}

TEST(HubConfiguration, ADropFolderWithoutMachinesAndACollectionWithoutAFolderAreRefused)
{
  TempDir dir("test_hybrid_share");
  auto nas = std::make_shared<LocalProgramStore>(dir.path);
  EXPECT_THROW(DropFolder(nas, {}, rules(), nullptr), ConfigError);
  programs::ProgramArchive archive(dir.path + "/archive");
  EXPECT_THROW(Collection({{"vf2", nas, nullptr}}, rules(), archive, {}, nullptr), ConfigError);
}

TEST(HubConfiguration, AMachineNameThatIsNoFolderNameIsRefusedNamingTheParameter)
{
  for (const std::string name : std::vector<std::string>{"", ".", "..", "../etc", "vf2/x", "vf\n2"})
  {
    try
    {
      checkMachineName(name, "/nas/share_node/collect_from");
      ADD_FAILURE() << "took '" << name << "'";
    }
    catch (const ConfigError& e)
    {
      EXPECT_NE(std::string(e.what()).find("/nas/share_node/collect_from"), std::string::npos) << e.what();
    }
  }
  EXPECT_NO_THROW(checkMachineName("haas_vf2", "~collect_from"));
}
