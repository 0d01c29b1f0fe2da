// The hybrid share (docs/share_node.md, "Hybrid share"): a file server's folder (the NAS) beside
// the machines' own storage, both at once. Programs dropped onto the NAS are pushed to every
// machine once complete (DropFolder); programs the machines write on their own shares are
// collected onto the NAS, each version kept in the archive (Collection). At the end of the day the
// NAS's programs are withdrawn (removed and archived) by share_node's ~withdraw_at, as any share's.
//
// Both run on polls of ProgramStore listings, so a local folder and an SMB share behave alike (an
// SMB share has no change notification a client can rely on). A file is complete when two listings
// at least `settle` apart show it with the same size and time: a copy onto the NAS still running
// is not pushed half-written. The clock is passed in, so the rules are tested without waiting.
#pragma once

#include <chrono>
#include <functional>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "cnc_bridge/programs/archive.h"
#include "cnc_bridge/programs/fan_out.h"
#include "cnc_bridge/programs/program_name.h"
#include "cnc_bridge/programs/program_store.h"

namespace cnc_bridge::share
{
using HubClock = std::chrono::steady_clock;

/// \brief Which files of a folder are complete and new since they were last handled.
class SettledFiles
{
 public:
  explicit SettledFiles(std::chrono::milliseconds settle) : settle_(settle) {}

  /// \brief Takes one listing made at \p now. \returns the files complete now whose size and time
  /// differ from when they were last handled (handled() or, for the first time, never).
  std::vector<programs::ProgramEntry> update(const std::vector<programs::ProgramEntry>& listing,
                                             HubClock::time_point now);
  /// \brief Marks \p entry handled: it is not returned again until it changes.
  void handled(const programs::ProgramEntry& entry);

 private:
  struct Seen
  {
    programs::ProgramEntry entry;
    HubClock::time_point since;  ///< when this size and time were first seen
  };
  std::chrono::milliseconds settle_;
  std::map<std::string, Seen> seen_;
  std::map<std::string, programs::ProgramEntry> handled_;
};

/// \brief A machine of the hub: its name (for results), its own store, and the NAS folder its
/// programs are collected into (none: not collected).
struct HubMachine
{
  std::string name;
  std::shared_ptr<programs::ProgramStore> store;
  std::shared_ptr<programs::ProgramStore> collected_into;
};

/// \brief What became of one program: its name and each machine's result.
struct HubResult
{
  std::string program;
  std::vector<programs::TargetResult> machines;
};

/// \brief What the hub allows through: program files only (by the name pattern), none in the
/// protected range unless allowed (checked on the name and on the O number in the text).
struct HubRules
{
  programs::NamePattern pattern;
  programs::ProtectedRange protected_range{"O08000-O09999", false, "~allow_protected_programs"};
  std::chrono::milliseconds settle{2000};
};

/// \brief Pushes programs dropped onto the NAS to every machine.
///
/// A machine whose copy is already byte for byte the same is not written again (so a restart or
/// an unchanged file costs reads, not writes); a machine that fails is that machine's result and
/// the file is tried again at its next change (the results say so, and the NAS keeps the file).
class DropFolder
{
 public:
  using Report = std::function<void(const HubResult&)>;
  DropFolder(std::shared_ptr<programs::ProgramStore> nas, std::vector<HubMachine> machines, HubRules rules,
             Report report);

  /// \brief One poll: lists the NAS, pushes each newly complete program. \returns what was pushed.
  /// \throws what listing the NAS throws (its link is down: nothing is pushed, nothing forgotten).
  std::vector<HubResult> poll(HubClock::time_point now);

 private:
  HubResult push(const programs::ProgramEntry& entry);
  std::shared_ptr<programs::ProgramStore> nas_;
  std::vector<HubMachine> machines_;
  HubRules rules_;
  Report report_;
  SettledFiles settled_;
};

/// \brief Copies the programs each machine writes on its own share onto the NAS, into the
/// machine's own folder there (two machines may each have an O01000; the drop folder's listing does
/// not reach into subfolders, so nothing collected is pushed back), and keeps each new version in
/// the archive (direction "collected").
class Collection
{
 public:
  using Report = std::function<void(const std::string& machine, const HubResult&)>;
  Collection(std::vector<HubMachine> machines, HubRules rules, programs::ProgramArchive& archive,
             programs::VersionSource source, Report report);

  /// \brief One poll of every machine. A machine that cannot be listed is reported and skipped;
  /// the others are collected. \returns what was collected (or failed to be).
  std::vector<HubResult> poll(HubClock::time_point now);

 private:
  void collectFrom(const HubMachine& machine, SettledFiles& settled, HubClock::time_point now,
                   std::vector<HubResult>& results);
  std::vector<HubMachine> machines_;
  HubRules rules_;
  programs::ProgramArchive& archive_;
  programs::VersionSource source_;
  Report report_;
  std::map<std::string, SettledFiles> settled_;  ///< per machine
};

/// \brief "O01234.nc: vf2 ok, vf3 FAILED (connection refused)": a result in one line.
std::string describe(const HubResult& result);
}  // namespace cnc_bridge::share
