// Stop on SIGINT/SIGTERM: a thread waits for the signal, then stops and runs the callbacks.
#include "cnc_bridge/common/stop_handler.h"

#include <csignal>
#include <mutex>
#include <thread>
#include <vector>

namespace cnc_bridge
{
namespace
{
/// The registered callbacks, made on first use (no mutable global).
struct Callbacks
{
  std::mutex mutex;
  std::vector<std::function<void()>> list;
};

Callbacks& callbacks()
{
  static Callbacks instance;
  return instance;
}
}  // namespace

StopSignal& installStopHandler()
{
  static StopSignal stop;
  static std::once_flag once;
  std::call_once(once,
                 []
                 {
                   sigset_t set;
                   sigemptyset(&set);
                   sigaddset(&set, SIGINT);
                   sigaddset(&set, SIGTERM);
                   pthread_sigmask(SIG_BLOCK, &set, nullptr);
                   std::thread(
                       [set]
                       {
                         int signal_number = 0;
                         sigwait(&set, &signal_number);
                         stop.stop();
                         std::lock_guard<std::mutex> lock(callbacks().mutex);
                         for (auto& callback : callbacks().list)
                         {
                           callback();
                         }
                       })
                       .detach();
                 });
  return stop;
}

void onStop(std::function<void()> callback)
{
  std::lock_guard<std::mutex> lock(callbacks().mutex);
  callbacks().list.push_back(std::move(callback));
}
}  // namespace cnc_bridge
