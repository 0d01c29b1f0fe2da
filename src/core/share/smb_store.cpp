// SmbProgramStore on libsmbclient's context API (one SMBCCTX per store, its calls serialised).
// The steps of an atomic write and their repair are described in smb_store.h.
#include "cnc_bridge/share/smb_store.h"

#include <libsmbclient.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <fstream>

#include "cnc_bridge/common/log.h"
#include "cnc_bridge/share/share_settings.h"

namespace cnc_bridge::share
{
using programs::NotFoundError;
using programs::ProgramEntry;

namespace
{
// Large requests let libsmbclient keep several SMB2 reads/writes in flight, as smbclient does.
constexpr size_t kChunk = size_t{1024} * 1024;

std::string trimmed(const std::string& text)
{
  const auto first = text.find_first_not_of(" \t\r");
  if (first == std::string::npos)
    return "";
  return text.substr(first, text.find_last_not_of(" \t\r") - first + 1);
}

std::string octalMode(mode_t mode)
{
  char text[8];
  std::snprintf(text, sizeof(text), "%04o", static_cast<unsigned>(mode & 07777));
  return text;
}

/// libsmbclient asks for credentials per server and share; every share gets the store's.
void authenticate(SMBCCTX* context, const char* /*server*/, const char* /*share*/, char* workgroup, int workgroup_size,
                  char* user, int user_size, char* password, int password_size)
{
  const auto* store = static_cast<SmbProgramStore*>(smbc_getOptionUserData(context));
  const SmbCredentials& c = store->credentials();
  auto copy = [](const std::string& value, char* out, int size)
  {
    if (size > 0)
    {
      std::strncpy(out, value.c_str(), static_cast<size_t>(size) - 1);
      out[size - 1] = '\0';
    }
  };
  if (!c.domain.empty())
    copy(c.domain, workgroup, workgroup_size);
  copy(c.guest ? "guest" : c.username, user, user_size);
  copy(c.guest ? "" : c.password, password, password_size);
}

/// libsmbclient keeps process-wide state (its talloc stack frames) that two threads must not use at
/// once, even through separate contexts, and Debian's build does not export smbc_thread_posix():
/// every call of every store takes this one lock.
std::recursive_mutex& libraryMutex()
{
  static std::recursive_mutex mutex;
  return mutex;
}

/// libsmbclient's own check of a cached connection, taken from the first context made (under the
/// library lock).
smbc_check_server_fn& libraryCheck()
{
  static smbc_check_server_fn check = nullptr;
  return check;
}

/// libsmbclient checks a cached connection before every call that needs the server: if nothing
/// has been heard from it (its own ECHO) within the timeout, it sends an ECHO and reconnects if
/// that fails. An answer to a real request proves the connection as well as an echo does, so a
/// store whose server answered within the timeout is not asked again: a short-lived store (one
/// cnc_dnc transfer) saves a round trip. A failed call clears the store's answer, so a connection
/// that went bad always gets libsmbclient's check.
int checkServer(SMBCCTX* context, SMBCSRV* server)
{
  const auto* store = static_cast<const SmbProgramStore*>(smbc_getOptionUserData(context));
  if (store->answeredRecently())
    return 0;
  return libraryCheck()(context, server);
}
}  // namespace

SmbUrl SmbUrl::parse(const std::string& given)
{
  refusePassword(given, "the SMB address");
  const std::string url = shownAddress(given);  // in messages (a password was refused above)
  const std::string scheme = "smb://";
  const std::string form = " (expected smb://[user@]host[:port]/share[/folder])";
  if (url.compare(0, scheme.size(), scheme) != 0)
    throw ConfigError("'" + url + "' is not an SMB address" + form);
  std::string rest = given.substr(scheme.size());
  SmbUrl result;
  const auto slash = rest.find('/');
  std::string authority = rest.substr(0, slash);
  std::string path = slash == std::string::npos ? "" : rest.substr(slash + 1);
  const auto at = authority.rfind('@');
  if (at != std::string::npos)
  {
    result.user = authority.substr(0, at);
    authority = authority.substr(at + 1);
    if (result.user.empty())
      throw ConfigError("'" + url + "': no user name before '@'" + form);
  }
  const auto colon = authority.rfind(':');
  result.host = authority.substr(0, colon);
  if (colon != std::string::npos)
  {
    const std::string port = authority.substr(colon + 1);
    char* end = nullptr;
    const unsigned long value = std::strtoul(port.c_str(), &end, 10);
    if (port.empty() || *end != '\0' || value == 0 || value > 65535)
      throw ConfigError("'" + url + "': port '" + port + "' is not 1-65535" + form);
    result.port = static_cast<unsigned>(value);
  }
  if (result.host.empty())
    throw ConfigError("'" + url + "' names no host" + form);
  while (!path.empty() && path.back() == '/')
    path.pop_back();
  const auto share_end = path.find('/');
  result.share = path.substr(0, share_end);
  result.folder = share_end == std::string::npos ? "" : path.substr(share_end + 1);
  if (result.share.empty())
    throw ConfigError("'" + url + "' names no share" + form);
  if (!result.folder.empty())
    programs::checkName(result.folder);
  return result;
}

std::string SmbUrl::describe() const
{
  return "smb://" + host + ":" + std::to_string(port) + "/" + share + (folder.empty() ? "" : "/" + folder);
}

std::string SmbUrl::pathOf(const std::string& name) const
{
  return describe() + (name.empty() ? "" : "/" + name);
}

SmbCredentials SmbCredentials::fromFile(const std::string& path)
{
  struct stat info;
  if (::stat(path.c_str(), &info) != 0)
    throw ConfigError("credentials file " + path + ": " + std::strerror(errno));
  if ((info.st_mode & 077) != 0)
  {
    throw ConfigError("credentials file " + path + " has mode " + octalMode(info.st_mode) +
                      ": it may be read or changed by others than its owner; refused (chmod 600 " + path + ")");
  }
  std::ifstream in(path);
  if (!in)
    throw ConfigError("credentials file " + path + " cannot be read");
  SmbCredentials credentials;
  credentials.guest = false;
  std::string line;
  int number = 0;
  while (std::getline(in, line))
  {
    ++number;
    const std::string text = trimmed(line);
    if (text.empty() || text[0] == '#' || text[0] == ';')
      continue;
    const auto equals = text.find('=');
    if (equals == std::string::npos)
      throw ConfigError("credentials file " + path + " line " + std::to_string(number) + ": expected 'key = value'");
    const std::string key = trimmed(text.substr(0, equals));
    const std::string value = trimmed(text.substr(equals + 1));
    if (key == "username")
      credentials.username = value;
    else if (key == "password")
      credentials.password = value;
    else if (key == "domain")
      credentials.domain = value;
    else
      throw ConfigError("credentials file " + path + " line " + std::to_string(number) + ": unknown key '" + key +
                        "' (username, password, domain)");
  }
  return credentials;
}

SmbProgramStore::SmbProgramStore(const std::string& url, SmbCredentials credentials, std::chrono::milliseconds timeout)
    : url_(SmbUrl::parse(url)), credentials_(std::move(credentials)), timeout_(timeout)
{
  if (!url_.user.empty())
  {
    credentials_.username = url_.user;
    credentials_.guest = false;
  }
  if (!credentials_.guest && credentials_.username.empty())
    throw ConfigError("no user name for " + url_.describe() + ": give one in the credentials file or the address");
}

SmbProgramStore::~SmbProgramStore()
{
  std::lock_guard<std::recursive_mutex> lock(libraryMutex());
  dropContext();
}

void SmbProgramStore::dropContext()
{
  if (context_ != nullptr)
  {
    smbc_free_context(context_, 1);  // 1: close its connections even with files open
    context_ = nullptr;
  }
}

SMBCCTX* SmbProgramStore::context()
{
  if (context_ != nullptr)
    return context_;
  SMBCCTX* context = smbc_new_context();
  if (context == nullptr)
    throw Error("libsmbclient: cannot create a context: " + std::string(std::strerror(errno)));
  smbc_setOptionUserData(context, this);
  smbc_setFunctionAuthDataWithContext(context, &authenticate);
  if (libraryCheck() == nullptr)
    libraryCheck() = smbc_getFunctionCheckServer(context);
  smbc_setFunctionCheckServer(context, &checkServer);
  smbc_setTimeout(context, static_cast<int>(timeout_.count()));
  smbc_setPort(context, static_cast<uint16_t>(url_.port));
  // A wrong password must fail as such, not fall back to an anonymous login.
  smbc_setOptionNoAutoAnonymousLogin(context, credentials_.guest ? 0 : 1);
  smbc_setOptionUseKerberos(context, 0);
  smbc_setDebug(context, 0);
  if (smbc_init_context(context) == nullptr)
  {
    const int error = errno;
    smbc_free_context(context, 1);
    throw Error("libsmbclient: cannot initialise a context: " + std::string(std::strerror(error)));
  }
  context_ = context;
  reached_ = false;
  answered_at_ = {};
  if (!repairs_.empty())
  {
    checkFolder();  // a repair needs the folder; if it cannot be reached, say why
    repairLocked();
    if (context_ == nullptr)
      throw LinkError("cannot open " + url_.describe() +
                      ": the link failed again while repairing an interrupted write");
  }
  return context_;
}

void SmbProgramStore::checkFolder()
{
  SMBCCTX* ctx = context_;
  struct stat info;
  if (smbc_getFunctionStat(ctx)(ctx, url_.pathOf("").c_str(), &info) != 0)
  {
    const int error = errno;
    dropContext();
    throw LinkError("cannot open " + url_.describe() + ": " + connectionFailure(error));
  }
  if (!S_ISDIR(info.st_mode))
  {
    dropContext();
    throw LinkError("cannot open " + url_.describe() + ": '" + url_.folder + "' is not a folder");
  }
  answered();
}

std::string SmbProgramStore::connectionFailure(int error) const
{
  switch (error)
  {
    case EACCES:
    case EPERM:
      return credentials_.guest ? "access denied to a guest: the share needs a user (give a credentials file)"
                                : "access denied for user '" + credentials_.username +
                                      "': wrong user name or password, or the user may not use this share";
    case ENOENT:
    case ENODEV:
    case ENOTDIR:
      return url_.folder.empty() ? "no share '" + url_.share + "' on " + url_.host
                                 : "no share '" + url_.share + "' or no folder '" + url_.folder + "' in it";
    case ECONNREFUSED:
      return "connection refused: no SMB server answers on " + url_.host + ":" + std::to_string(url_.port);
    case ETIMEDOUT:
      return "no answer within " + std::to_string(static_cast<double>(timeout_.count()) / 1000.0).substr(0, 4) + " s";
    default:
      return std::strerror(error);
  }
}

void SmbProgramStore::answered()
{
  reached_ = true;
  answered_at_ = std::chrono::steady_clock::now();
}

bool SmbProgramStore::answeredRecently() const
{
  return answered_at_ != std::chrono::steady_clock::time_point{} &&
         std::chrono::steady_clock::now() - answered_at_ < timeout_;
}

void SmbProgramStore::fail(const std::string& action, const std::string& name, int error)
{
  answered_at_ = {};  // whatever failed, the next call lets libsmbclient check the connection
  // Nothing has reached the folder on this connection yet: the server, the login, the share or the
  // folder may be what failed, not the program.
  if (!reached_ && context_ != nullptr)
  {
    const bool program_or_folder =
        error == ENOENT || error == ENOTDIR || error == ENODEV || error == EACCES || error == EPERM;
    if (program_or_folder)
      checkFolder();  // tells them apart: throws unless the folder is there and may be used
    else
    {
      dropContext();
      throw LinkError("cannot open " + url_.describe() + ": " + connectionFailure(error));
    }
  }
  if (error == ENOENT)
    throw NotFoundError("no program '" + name + "' in " + url_.describe());
  std::string reason = std::strerror(error);
  if (error == ETIMEDOUT)
    reason = "no answer within " + std::to_string(timeout_.count()) + " ms";
  if (error == EACCES || error == EPERM)
    throw Error(action + " " + name + " on " + url_.describe() + ": access denied");
  if (error == EEXIST)
    throw Error(action + " " + name + " on " + url_.describe() + ": " + reason);
  // Anything else: assume the connection is gone; the next call connects anew.
  dropContext();
  throw LinkError(action + " " + name + " on " + url_.describe() + " failed: " + reason);
}

ProgramEntry SmbProgramStore::statLocked(const std::string& name)
{
  programs::checkName(name);
  SMBCCTX* ctx = context();
  struct stat info;
  if (smbc_getFunctionStat(ctx)(ctx, url_.pathOf(name).c_str(), &info) != 0)
    fail("stat of", name, errno);
  answered();
  ProgramEntry entry;
  entry.name = name;
  entry.size = static_cast<uint64_t>(info.st_size);
  entry.mtime = info.st_mtime;
  return entry;
}

bool SmbProgramStore::existsLocked(const std::string& name)
{
  try
  {
    statLocked(name);
    return true;
  }
  catch (const NotFoundError&)
  {
    return false;
  }
}

void SmbProgramStore::renameLocked(const std::string& from, const std::string& to)
{
  SMBCCTX* ctx = context();
  if (smbc_getFunctionRename(ctx)(ctx, url_.pathOf(from).c_str(), ctx, url_.pathOf(to).c_str()) != 0)
    fail("rename of", from + " to " + to, errno);
  answered();
}

bool SmbProgramStore::moveAsideLocked(const std::string& name, const std::string& aside)
{
  SMBCCTX* ctx = context();
  if (smbc_getFunctionRename(ctx)(ctx, url_.pathOf(name).c_str(), ctx, url_.pathOf(aside).c_str()) == 0)
  {
    answered();
    return true;
  }
  const int error = errno;
  if (error == ENOENT && reached_)
    return false;  // no earlier version
  fail("rename of", name + " to " + aside, error);
}

void SmbProgramStore::unlinkLocked(const std::string& name)
{
  SMBCCTX* ctx = context();
  if (smbc_getFunctionUnlink(ctx)(ctx, url_.pathOf(name).c_str()) != 0)
    fail("removal of", name, errno);
  answered();
}

void SmbProgramStore::repairLocked()
{
  auto pending = std::move(repairs_);
  repairs_.clear();
  for (auto& repair : pending)
  {
    try
    {
      if (!repair.previous.empty() && existsLocked(repair.previous))
      {
        if (existsLocked(repair.name))
          unlinkLocked(repair.previous);
        else
          renameLocked(repair.previous, repair.name);  // the write never replaced it: back in place
      }
      if (!repair.temporary.empty() && existsLocked(repair.temporary))
        unlinkLocked(repair.temporary);
      CNC_LOG_INFO("removed what an interrupted write of " << repair.name << " left on " << url_.describe());
    }
    catch (const Error& e)
    {
      repairs_.push_back(repair);
      CNC_LOG_WARN("cannot yet repair the interrupted write of " << repair.name << ": " << e.what());
      if (context_ == nullptr)
        return;  // the link is gone again
    }
  }
}

void SmbProgramStore::check()
{
  list();
}

std::vector<ProgramEntry> SmbProgramStore::list()
{
  std::lock_guard<std::recursive_mutex> lock(libraryMutex());
  SMBCCTX* ctx = context();
  SMBCFILE* dir = smbc_getFunctionOpendir(ctx)(ctx, url_.pathOf("").c_str());
  if (dir == nullptr)
    fail("listing of", url_.folder.empty() ? "/" : url_.folder, errno);
  answered();
  std::vector<ProgramEntry> entries;
  errno = 0;
  struct stat info;
  while (const libsmb_file_info* file = smbc_getFunctionReaddirPlus2(ctx)(ctx, dir, &info))
  {
    const std::string name = file->name;
    if (S_ISDIR(info.st_mode) || (file->attrs & 0x10) != 0 || programs::isTemporaryName(name))
      continue;
    ProgramEntry entry;
    entry.name = name;
    entry.size = file->size;
    entry.mtime = file->mtime_ts.tv_sec;
    entries.push_back(entry);
  }
  const int error = errno;
  smbc_getFunctionClosedir(ctx)(ctx, dir);
  if (error != 0 && error != ENOENT)
    fail("listing of", url_.folder.empty() ? "/" : url_.folder, error);
  std::sort(entries.begin(), entries.end(), [](const auto& a, const auto& b) { return a.name < b.name; });
  return entries;
}

SMBCFILE* SmbProgramStore::openLocked(const std::string& name, int flags)
{
  SMBCCTX* ctx = context();
  SMBCFILE* file = smbc_getFunctionOpen(ctx)(ctx, url_.pathOf(name).c_str(), flags, 0644);
  if (file == nullptr)
    fail((flags & O_CREAT) != 0 ? "creating" : "opening", name, errno);
  answered();
  return file;
}

ProgramEntry SmbProgramStore::stat(const std::string& name)
{
  std::lock_guard<std::recursive_mutex> lock(libraryMutex());
  return statLocked(name);
}

std::string SmbProgramStore::read(const std::string& name, const programs::StoreProgress& progress,
                                  const std::atomic<bool>* cancel)
{
  std::string data;
  readTo(
      name, [&data](const char* chunk, size_t size) { data.append(chunk, size); }, progress, cancel);
  return data;
}

void SmbProgramStore::readTo(const std::string& name, const programs::StoreSink& sink,
                             const programs::StoreProgress& progress, const std::atomic<bool>* cancel)
{
  std::lock_guard<std::recursive_mutex> lock(libraryMutex());
  SMBCFILE* file = openLocked(name, O_RDONLY);
  SMBCCTX* ctx = context_;
  try
  {
    // The size as the file was opened, as smbclient's get reads it: reads of exactly what is left,
    // so that no request is spent to find the end (libsmbclient repeats a short read).
    struct stat info;
    if (smbc_getFunctionFstat(ctx)(ctx, file, &info) != 0)
      fail("stat of", name, errno);
    const auto total = static_cast<uint64_t>(info.st_size);
    std::string chunk(static_cast<size_t>(std::min<uint64_t>(kChunk, total)), '\0');
    uint64_t done = 0;
    while (done < total)
    {
      programs::throwIfCancelled(cancel, "reading " + name);
      const size_t want = static_cast<size_t>(std::min<uint64_t>(chunk.size(), total - done));
      const ssize_t n = smbc_getFunctionRead(ctx)(ctx, file, chunk.data(), want);
      if (n < 0)
        fail("reading", name, errno);
      if (n == 0)
        break;  // shortened since it was opened
      sink(chunk.data(), static_cast<size_t>(n));
      done += static_cast<uint64_t>(n);
      if (progress)
        progress(done, total);
    }
    if (done == 0 && progress)
      progress(0, 0);
  }
  catch (...)
  {
    if (context_ != nullptr)
      smbc_getFunctionClose(ctx)(ctx, file);
    throw;
  }
  if (smbc_getFunctionClose(ctx)(ctx, file) == 0)
    answered();
}

std::string SmbProgramStore::readHead(const std::string& name, size_t bytes)
{
  std::lock_guard<std::recursive_mutex> lock(libraryMutex());
  programs::checkName(name);
  SMBCFILE* file = openLocked(name, O_RDONLY);
  SMBCCTX* ctx = context_;
  std::string head(bytes, '\0');
  size_t got = 0;
  while (got < bytes)
  {
    const ssize_t n = smbc_getFunctionRead(ctx)(ctx, file, head.data() + got, bytes - got);
    if (n < 0)
    {
      const int error = errno;
      smbc_getFunctionClose(ctx)(ctx, file);
      fail("reading", name, error);
    }
    if (n == 0)
      break;
    got += static_cast<size_t>(n);
  }
  smbc_getFunctionClose(ctx)(ctx, file);
  head.resize(got);
  return head;
}

void SmbProgramStore::writeFrom(const std::string& name, uint64_t size, const programs::StoreSource& source,
                                const programs::StoreProgress& progress, const std::atomic<bool>* cancel)
{
  std::lock_guard<std::recursive_mutex> lock(libraryMutex());
  programs::checkName(name);
  char host[64] = "host";
  ::gethostname(host, sizeof(host) - 1);
  const std::string tag = std::string(host) + "-" + std::to_string(::getpid()) + "-" + std::to_string(++counter_);
  Repair repair{name, programs::temporaryName(name, tag), programs::temporaryName(name, tag + ".previous")};
  SMBCCTX* ctx = context();

  // 1. Upload under the temporary name.
  try
  {
    SMBCFILE* file = openLocked(repair.temporary, O_WRONLY | O_CREAT | O_EXCL);
    try
    {
      programs::writeChunks(
          name, size, source, kChunk, url_.describe(),
          [&](std::string_view chunk)
          {
            for (size_t sent = 0; sent < chunk.size();)
            {
              const ssize_t written = smbc_getFunctionWrite(ctx)(ctx, file, chunk.data() + sent, chunk.size() - sent);
              if (written <= 0)
                fail("writing", repair.temporary, written < 0 ? errno : EIO);
              sent += static_cast<size_t>(written);
            }
          },
          progress, cancel);
    }
    catch (...)
    {
      if (context_ != nullptr)
        smbc_getFunctionClose(ctx)(ctx, file);
      throw;
    }
    if (smbc_getFunctionClose(ctx)(ctx, file) != 0)
      fail("closing", repair.temporary, errno);
    answered();
  }
  catch (...)
  {
    repair.previous.clear();
    repairs_.push_back(repair);
    if (context_ != nullptr)
      repairLocked();  // the link still works: remove the temporary file now
    throw;
  }

  // 2. Move the old version aside, 3. the new one in, 4. delete the old one.
  bool replaced = false;
  try
  {
    replaced = moveAsideLocked(name, repair.previous);
    renameLocked(repair.temporary, name);
  }
  catch (...)
  {
    repairs_.push_back(repair);
    if (context_ != nullptr)
      repairLocked();  // puts the old version back and removes the new one
    throw;
  }
  if (replaced)
  {
    try
    {
      unlinkLocked(repair.previous);
    }
    catch (const Error& e)
    {
      repair.temporary.clear();
      repairs_.push_back(repair);
      CNC_LOG_WARN(name << " written to " << url_.describe() << ", but its previous version stays as "
                        << repair.previous << " until the next connection: " << e.what());
    }
  }
}

void SmbProgramStore::rename(const std::string& from, const std::string& to)
{
  std::lock_guard<std::recursive_mutex> lock(libraryMutex());
  programs::checkName(from);
  programs::checkName(to);
  if (!existsLocked(from))
    throw NotFoundError("no program '" + from + "' in " + url_.describe());
  // As write(): never ask libsmbclient to replace (it deletes the target before the rename).
  if (existsLocked(to))
    unlinkLocked(to);
  renameLocked(from, to);
}

void SmbProgramStore::remove(const std::string& name)
{
  std::lock_guard<std::recursive_mutex> lock(libraryMutex());
  programs::checkName(name);
  unlinkLocked(name);
}

std::unique_ptr<programs::ProgramStore> openStore(const std::string& address, const std::string& credentials_file,
                                                  std::chrono::milliseconds timeout)
{
  if (address.compare(0, 6, "smb://") == 0)
  {
    SmbCredentials credentials;
    if (!credentials_file.empty())
      credentials = SmbCredentials::fromFile(credentials_file);
    return std::make_unique<SmbProgramStore>(address, credentials, timeout);
  }
  if (address.find("://") != std::string::npos)
  {
    refusePassword(address, "the address");
    throw ConfigError("'" + address + "' is neither an smb:// address nor a local folder");
  }
  if (!credentials_file.empty())
    throw ConfigError("a credentials file is for smb:// addresses, not for the local directory " + address);
  return std::make_unique<programs::LocalProgramStore>(address);
}
}  // namespace cnc_bridge::share
