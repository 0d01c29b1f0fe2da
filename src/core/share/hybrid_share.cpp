// The hybrid share: the drop folder and the collection (hybrid_share.h).
#include "cnc_bridge/share/hybrid_share.h"

#include <algorithm>

#include "cnc_bridge/common/error.h"

namespace cnc_bridge::share
{
namespace
{
bool sameFile(const programs::ProgramEntry& a, const programs::ProgramEntry& b)
{
  return a.size == b.size && a.mtime == b.mtime;
}

programs::TargetResult failed(const std::string& target, const std::string& message)
{
  return programs::TargetResult{target, false, message};
}

/// Refuses what the hub must not move: a file that is no program by the name pattern, a program
/// in the protected range. \returns the reason, or "" when it may go.
std::string refusal(const HubRules& rules, const std::string& name, const std::string& content)
{
  const auto number = rules.pattern.number(name);
  if (!number)
  {
    return "not a program name (pattern " + rules.pattern.text() + "): left where it is";
  }
  try
  {
    rules.protected_range.checkHeader(name, number, programs::readHeader(content));
  }
  catch (const DisabledError& e)
  {
    return e.what();
  }
  return "";
}
}  // namespace

std::vector<programs::ProgramEntry> SettledFiles::update(const std::vector<programs::ProgramEntry>& listing,
                                                         HubClock::time_point now)
{
  std::map<std::string, Seen> seen;
  std::vector<programs::ProgramEntry> complete;
  for (const auto& entry : listing)
  {
    const auto before = seen_.find(entry.name);
    const bool unchanged = before != seen_.end() && sameFile(before->second.entry, entry);
    const Seen now_seen{entry, unchanged ? before->second.since : now};
    seen.emplace(entry.name, now_seen);
    const auto done = handled_.find(entry.name);
    const bool new_version = done == handled_.end() || !sameFile(done->second, entry);
    // Two listings, the settle time apart, that agree: the writer has finished.
    if (unchanged && now - now_seen.since >= settle_ && new_version)
    {
      complete.push_back(entry);
    }
  }
  // A file gone is forgotten: dropped again, it is new again.
  for (auto it = handled_.begin(); it != handled_.end();)
  {
    it = seen.count(it->first) != 0 ? std::next(it) : handled_.erase(it);
  }
  seen_ = std::move(seen);
  return complete;
}

void SettledFiles::handled(const programs::ProgramEntry& entry)
{
  handled_[entry.name] = entry;
}

// ---------------------------------------------------------------------------------------------

DropFolder::DropFolder(std::shared_ptr<programs::ProgramStore> nas, std::vector<HubMachine> machines, HubRules rules,
                       Report report)
    : nas_(std::move(nas)),
      machines_(std::move(machines)),
      rules_(std::move(rules)),
      report_(std::move(report)),
      settled_(rules_.settle)
{
  if (machines_.empty())
  {
    throw ConfigError("a drop folder needs at least one machine to push to");
  }
}

std::vector<HubResult> DropFolder::poll(HubClock::time_point now)
{
  std::vector<HubResult> results;
  for (const auto& entry : settled_.update(nas_->list(), now))
  {
    results.push_back(push(entry));
    settled_.handled(entry);
    if (report_)
    {
      report_(results.back());
    }
  }
  return results;
}

HubResult DropFolder::push(const programs::ProgramEntry& entry)
{
  HubResult result{entry.name, {}};
  std::string content;
  try
  {
    content = nas_->read(entry.name);
  }
  catch (const Error& e)
  {
    result.machines.push_back(
        failed("(all)", std::string("cannot read it from ") + nas_->describe() + ": " + e.what()));
    return result;
  }
  const std::string refused = refusal(rules_, entry.name, content);
  if (!refused.empty())
  {
    result.machines.push_back(failed("(all)", refused));
    return result;
  }
  std::vector<std::string> names;
  for (const auto& machine : machines_)
  {
    names.push_back(machine.name);
  }
  result.machines = programs::fanOut(names,
                                     [&](const std::string& name)
                                     {
                                       const auto& machine =
                                           *std::find_if(machines_.begin(), machines_.end(),
                                                         [&](const HubMachine& m) { return m.name == name; });
                                       try
                                       {
                                         if (machine.store->read(entry.name) == content)
                                         {
                                           return std::string("already there, the same");
                                         }
                                       }
                                       catch (const programs::NotFoundError&)
                                       {
                                       }
                                       machine.store->write(entry.name, content);
                                       return "written (" + std::to_string(content.size()) + " bytes)";
                                     });
  return result;
}

// ---------------------------------------------------------------------------------------------

Collection::Collection(std::vector<HubMachine> machines, HubRules rules, programs::ProgramArchive& archive,
                       programs::VersionSource source, Report report)
    : machines_(std::move(machines)),
      rules_(std::move(rules)),
      archive_(archive),
      source_(std::move(source)),
      report_(std::move(report))
{
  for (const auto& machine : machines_)
  {
    if (!machine.collected_into)
    {
      throw ConfigError("machine " + machine.name + " has no NAS folder to collect its programs into");
    }
    settled_.emplace(machine.name, SettledFiles(rules_.settle));
  }
}

std::vector<HubResult> Collection::poll(HubClock::time_point now)
{
  std::vector<HubResult> results;
  for (const auto& machine : machines_)
  {
    collectFrom(machine, settled_.at(machine.name), now, results);
  }
  return results;
}

void Collection::collectFrom(const HubMachine& machine, SettledFiles& settled, HubClock::time_point now,
                             std::vector<HubResult>& results)
{
  std::vector<programs::ProgramEntry> complete;
  try
  {
    complete = settled.update(machine.store->list(), now);
  }
  catch (const Error& e)
  {
    results.push_back({"(listing)",
                       {failed(machine.name, std::string("cannot list ") + machine.store->describe() + ": " + e.what() +
                                                 " (collected at the next poll)")}});
    if (report_)
    {
      report_(machine.name, results.back());
    }
    return;
  }
  for (const auto& entry : complete)
  {
    HubResult result{entry.name, {}};
    try
    {
      if (!rules_.pattern.number(entry.name))
      {
        settled.handled(entry);  // not a program: not collected, not reported again
        continue;
      }
      const std::string content = machine.store->read(entry.name);
      machine.collected_into->write(entry.name, content);
      programs::VersionSource source = source_;
      source.machine = machine.name;
      const auto version = archive_.add(entry.name, content, source);
      result.machines.push_back(
          {machine.name, true,
           "collected into " + machine.collected_into->describe() +
               (version ? ", archive version " + std::to_string(version->number) : ", already in the archive")});
      settled.handled(entry);
    }
    catch (const Error& e)
    {
      // Not marked handled: tried again at the next poll.
      result.machines.push_back(failed(machine.name, e.what()));
    }
    results.push_back(result);
    if (report_)
    {
      report_(machine.name, result);
    }
  }
}

std::string describe(const HubResult& result)
{
  std::string text = result.program + ":";
  for (const auto& machine : result.machines)
  {
    text += " " + machine.target + (machine.success ? " ok" : " FAILED") + " (" + machine.message + ")";
    if (&machine != &result.machines.back())
    {
      text += ",";
    }
  }
  return text;
}
}  // namespace cnc_bridge::share
