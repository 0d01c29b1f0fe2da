// Programs on an SMB share through Samba's own client library (libsmbclient): a Haas NGC's
// "Net Share" memory, a file server the controls mount, or any Windows/Samba share. Addressed as
// smb://[user@]host[:port]/share[/folder]; credentials come only from a file in smbclient's
// authentication-file format (`smbclient -A`, see smbclient(1)):
//
//     username = cnc
//     password = secret
//     domain   = WORKGROUP      (optional)
//
// which must be readable by its owner only. Without a file the share is opened as guest.
//
// Writes are atomic for the control: the program is uploaded as `.<name>.<tag>.partial` in the
// same folder and renamed when complete. SMB has a replacing rename, but libsmbclient's
// smbc_rename() replaces an existing name by deleting it first, which loses the old version if
// the second step fails; so the store moves the old version aside (`.<name>.<tag>.previous`),
// renames the new one in, and deletes the old one last. A control polling the folder sees the
// complete old program, then (for one round trip) no program, then the complete new one; never a
// partial one. A failure between the steps is repaired at once or, if the server vanished, at the
// next connection (old version back in place, temporary files removed).
#pragma once

#include <chrono>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "cnc_bridge/programs/program_store.h"

// libsmbclient's own declaration of its context type, repeated so that this header need not include it.
// NOLINTNEXTLINE(bugprone-reserved-identifier,cert-dcl37-c,cert-dcl51-cpp,modernize-use-using)
typedef struct _SMBCCTX SMBCCTX;
// NOLINTNEXTLINE(bugprone-reserved-identifier,cert-dcl37-c,cert-dcl51-cpp,modernize-use-using)
typedef struct _SMBCFILE SMBCFILE;

namespace cnc_bridge::share
{
/// \brief The parts of smb://[user@]host[:port]/share[/folder].
struct SmbUrl
{
  std::string user;  ///< from the URL; the credentials file's username wins if both are given
  std::string host;
  unsigned port = 445;
  std::string share;
  std::string folder;  ///< "" or "a/b", no leading or trailing '/'

  /// \throws ConfigError naming what is wrong and the expected form.
  static SmbUrl parse(const std::string& url);
  /// \brief smb://host:port/share/folder (no user), for messages.
  std::string describe() const;
  /// \brief The URL libsmbclient opens for \p name inside the folder ("" for the folder itself).
  std::string pathOf(const std::string& name) const;
};

/// \brief Credentials from an smbclient authentication file.
struct SmbCredentials
{
  std::string username, password, domain;
  bool guest = true;  ///< no file given

  /// \brief Reads \p path (`username =`, `password =`, `domain =`; '#' and ';' start comments).
  /// \throws ConfigError if it cannot be read, is readable or writable by group or others (naming
  /// the file and its mode), or names no username.
  static SmbCredentials fromFile(const std::string& path);
};

/// \brief A folder on an SMB share. Thread-safe: calls of all stores in the process are serialised
/// (libsmbclient's own state is process-wide), each store has its own libsmbclient context.
/// After a link failure the context is dropped and the next call connects anew.
class SmbProgramStore : public programs::ProgramStore
{
 public:
  /// \param timeout limit of every SMB request (connect, read, write, rename), libsmbclient's
  /// smbc_setTimeout().
  /// \throws ConfigError for a bad URL. Does not connect (the first call does).
  SmbProgramStore(const std::string& url, SmbCredentials credentials,
                  std::chrono::milliseconds timeout = std::chrono::seconds(10));
  ~SmbProgramStore() override;

  std::string describe() const override { return url_.describe(); }
  std::vector<programs::ProgramEntry> list() override;
  programs::ProgramEntry stat(const std::string& name) override;
  std::string read(const std::string& name, const programs::StoreProgress& progress = nullptr,
                   const std::atomic<bool>* cancel = nullptr) override;
  void readTo(const std::string& name, const programs::StoreSink& sink,
              const programs::StoreProgress& progress = nullptr, const std::atomic<bool>* cancel = nullptr) override;
  std::string readHead(const std::string& name, size_t bytes) override;
  void writeFrom(const std::string& name, uint64_t size, const programs::StoreSource& source,
                 const programs::StoreProgress& progress = nullptr, const std::atomic<bool>* cancel = nullptr) override;
  void rename(const std::string& from, const std::string& to) override;
  void remove(const std::string& name) override;

  /// \brief Connects if needed and lists the folder: what a link check calls. \throws as list().
  void check();

  /// The credentials, for libsmbclient's authentication callback.
  const SmbCredentials& credentials() const { return credentials_; }
  /// Whether the server answered a call on this connection within the timeout, for libsmbclient's
  /// check of a connection it reuses (it sends an ECHO unless this is true).
  bool answeredRecently() const;

 private:
  /// The context, created (and leftovers of an earlier failure repaired) if there is none.
  /// Connecting is left to the first call that needs the share, so that a transfer costs no
  /// requests beyond its own (a failure of that first call is explained by checkFolder()).
  SMBCCTX* context();
  void dropContext();
  /// The server answered a call: the folder is reached and the connection works.
  void answered();
  /// Stats the share folder: \throws LinkError saying whether the server, the login, the share or
  /// the folder failed. Marks the folder reached.
  void checkFolder();
  std::string connectionFailure(int error) const;
  /// Turns errno after a failed call into the matching exception and drops the context if the
  /// link is gone. Never returns.
  [[noreturn]] void fail(const std::string& action, const std::string& name, int error);
  programs::ProgramEntry statLocked(const std::string& name);
  /// Opens \p name in the folder (O_RDONLY, or O_WRONLY | O_CREAT | O_EXCL for an upload).
  SMBCFILE* openLocked(const std::string& name, int flags);
  /// Renames \p name to \p aside; false if there is no \p name.
  bool moveAsideLocked(const std::string& name, const std::string& aside);
  void renameLocked(const std::string& from, const std::string& to);
  void unlinkLocked(const std::string& name);
  bool existsLocked(const std::string& name);
  /// Repairs what an interrupted write left (see the file comment).
  void repairLocked();

  SmbUrl url_;
  SmbCredentials credentials_;
  std::chrono::milliseconds timeout_;
  SMBCCTX* context_ = nullptr;
  bool reached_ = false;  ///< a call on this context has reached the folder (login, share and folder work)
  std::chrono::steady_clock::time_point answered_at_{};  ///< the server's last answer; cleared by a failure
  struct Repair
  {
    std::string name, temporary, previous;
  };
  std::vector<Repair> repairs_;  ///< interrupted writes to finish at the next connection
  unsigned counter_ = 0;
};

/// \brief Opens a store by address: `smb://...` an SMB share (credentials from
/// \p credentials_file, guest if it is empty), anything else a local directory.
/// \throws ConfigError for a bad address or credentials file.
std::unique_ptr<programs::ProgramStore> openStore(const std::string& address, const std::string& credentials_file = "",
                                                  std::chrono::milliseconds timeout = std::chrono::seconds(10));
}  // namespace cnc_bridge::share
