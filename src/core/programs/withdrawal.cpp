#include "cnc_bridge/programs/withdrawal.h"

#include <vector>

#include "cnc_bridge/common/log.h"

namespace cnc_bridge::programs
{
Withdrawal withdrawProgram(ProgramStore& store, ProgramArchive& archive, const std::string& file,
                           const VersionSource& source)
{
  Withdrawal result;
  result.program = file;
  const std::string content = store.read(file);
  // Kept first: a program is never gone from both the share and the archive.
  if (const auto kept = archive.add(file, content, source))
  {
    result.version = kept->number;
  }
  else
  {
    for (const ArchiveVersion& v : archive.history(file))
    {
      if (v.crc32 == crc32Hex(content) && v.size == content.size())
        result.version = v.number;
    }
  }
  store.remove(file);
  result.success = true;
  result.message =
      "withdrew " + file + " from " + store.describe() + " (archive version " + std::to_string(result.version) + ")";
  CNC_LOG_INFO(result.message);
  return result;
}

WithdrawalSummary withdrawAllPrograms(ProgramStore& store, ProgramArchive& archive, const VersionSource& source,
                                      const std::string& label, const std::function<void(const Withdrawal&)>& each)
{
  WithdrawalSummary summary;
  std::vector<ProgramEntry> files;
  try
  {
    files = store.list();
  }
  catch (const Error& e)
  {
    summary.message = std::string("withdrawal of every program not done: ") + e.what();
    CNC_LOG_ERROR(summary.message);
    return summary;
  }
  summary.listed = files.size();
  std::string failures;
  for (const ProgramEntry& file : files)
  {
    Withdrawal outcome;
    try
    {
      outcome = withdrawProgram(store, archive, file.name, source);
      ++summary.withdrawn;
    }
    catch (const Error& e)
    {
      outcome.program = file.name;
      outcome.message = e.what();
      failures += (failures.empty() ? "; failed: " : ", ") + file.name + " (" + e.what() + ")";
      CNC_LOG_ERROR("withdrawal of " << file.name << ": " << e.what());
    }
    if (each)
      each(outcome);
  }
  summary.success = summary.withdrawn == summary.listed;
  summary.message = "withdrew " + std::to_string(summary.withdrawn) + " of " + std::to_string(summary.listed) +
                    " programs from " + store.describe() + " into " + archive.root() + failures;
  CNC_LOG_INFO(label << ": " << summary.message);
  return summary;
}
}  // namespace cnc_bridge::programs
