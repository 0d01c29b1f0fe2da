// Withdrawing programs from a share (share_node's ~withdraw_program, ~withdraw_all and
// ~withdraw_at, docs/share_node.md): each program is kept in the archive first, then removed, so
// that it is never gone from both.
#pragma once

#include <cstddef>
#include <cstdint>
#include <functional>
#include <string>

#include "cnc_bridge/programs/archive.h"
#include "cnc_bridge/programs/program_store.h"

namespace cnc_bridge::programs
{
/// \brief What became of one program.
struct Withdrawal
{
  std::string program;
  bool success = false;
  std::string message;   ///< "withdrew O01234.nc from <store> (archive version 2)", or why not
  unsigned version = 0;  ///< the archive version that holds the program (success only)
};

/// \brief Keeps \p file of \p store in \p archive (direction "withdrawn" in \p source; a version
/// identical to one kept is not stored again and that version is named), then removes it from the
/// store. \throws NotFoundError, Error: what stopped it (the program is removed only once kept).
Withdrawal withdrawProgram(ProgramStore& store, ProgramArchive& archive, const std::string& file,
                           const VersionSource& source);

/// \brief What withdrawAllPrograms() did.
struct WithdrawalSummary
{
  bool success = false;  ///< every program listed was withdrawn (true when there was none)
  size_t withdrawn = 0;
  size_t listed = 0;
  std::string message;  ///< "withdrew 2 of 3 programs from <store> into <archive>; failed: ..."
};

/// \brief Withdraws every program the store lists, one after the other; a program that cannot be
/// withdrawn is reported and the others still are. \p each is called with every program's outcome
/// (a failure too); \p label (`~withdraw_at 18:00`) starts the log lines. Does not throw: a store
/// that cannot be listed makes a summary that says so.
WithdrawalSummary withdrawAllPrograms(ProgramStore& store, ProgramArchive& archive, const VersionSource& source,
                                      const std::string& label,
                                      const std::function<void(const Withdrawal&)>& each = nullptr);
}  // namespace cnc_bridge::programs
