// BoardSession: ethernut_node's connection to its board without ROS, against the simulated board
// (board.h) over TCP: opened through the link factory, the protocol loop's client offered once it
// is initialised, a reset that closes the connection and reconnects, and the board's standalone
// mode, after which the session reconnects only when another mode is asked for.
#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <condition_variable>
#include <functional>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "cnc_bridge/ethernut/board_session.h"
#include "cnc_bridge/transport/tcp.h"
#include "sim/ethernut/board.h"

using namespace cnc_bridge;
using namespace cnc_bridge::ethernut;

namespace
{
constexpr std::chrono::milliseconds kWait(10000);  // a wait that must end ends long before this

class EthernutSession : public ::testing::Test
{
 protected:
  EthernutSession() : board(boardOptions()), server(0, "127.0.0.1")
  {
    // The board serves one connection after the other, as sim_ethernut does.
    board_thread = std::thread(
        [this]
        {
          try
          {
            while (!stop.stopped())
            {
              if (auto peer = server.accept(std::chrono::milliseconds(50)))
              {
                board.serve(*peer, stop);
                std::lock_guard<std::mutex> lock(mutex);
                ++connections_served;
                changed.notify_all();
              }
            }
          }
          catch (const CancelledError&)
          {
            // interrupted at the end of the test
          }
        });
  }
  ~EthernutSession() override
  {
    session.reset();
    stop.stop();
    server.interrupt();
    board_thread.join();
  }
  static BoardOptions boardOptions()
  {
    BoardOptions options;
    options.report_period = std::chrono::milliseconds(0);
    return options;
  }
  SessionSettings settings() const
  {
    SessionSettings s;
    s.link = LinkSettings::tcp("127.0.0.1", server.port(), std::chrono::milliseconds(3000));
    return s;
  }
  void start()
  {
    session = std::make_unique<BoardSession>(settings(), nullptr);
    session->start(
        [this](LinkState state, const std::string& why)
        {
          std::lock_guard<std::mutex> lock(mutex);
          links.push_back(std::string(toString(state)) + (why.empty() ? "" : ": " + why));
          changed.notify_all();
        });
  }
  /// Waits until \p condition holds: woken by link changes, and looking again every few ms for
  /// the client's state, which no event here announces.
  bool waitFor(const std::function<bool()>& condition)
  {
    const auto deadline = std::chrono::steady_clock::now() + kWait;
    std::unique_lock<std::mutex> lock(mutex);
    while (!condition())
    {
      if (std::chrono::steady_clock::now() >= deadline)
      {
        return false;
      }
      changed.wait_for(lock, std::chrono::milliseconds(5));
    }
    return true;
  }
  std::shared_ptr<Client> running()
  {
    std::string why;
    std::shared_ptr<Client> client;
    waitFor(
        [&]
        {
          client = session->client(why);
          return client && client->mode() == BoardMode::kFile;
        });
    return client;
  }

  Board board;
  TcpServer server;
  StopSignal stop;
  std::thread board_thread;
  std::unique_ptr<BoardSession> session;
  std::mutex mutex;  // links, connections_served
  std::condition_variable changed;
  std::vector<std::string> links;
  int connections_served = 0;
};
}  // namespace

TEST_F(EthernutSession, TheClientIsOfferedOnceTheConnectionIsInitialised)
{
  session = std::make_unique<BoardSession>(settings(), nullptr);
  std::string why;
  EXPECT_EQ(session->client(why), nullptr);
  EXPECT_EQ(why, "not connected to the ethernut board at 127.0.0.1:" + std::to_string(server.port()));
  EXPECT_EQ(session->hardwareId(), "127.0.0.1:" + std::to_string(server.port()));
  start();
  const std::shared_ptr<Client> client = running();
  ASSERT_NE(client, nullptr);
  EXPECT_EQ(session->latest(), client);
}

TEST_F(EthernutSession, AResetClosesTheConnectionAndTheSessionReconnects)
{
  start();
  const std::shared_ptr<Client> first = running();
  ASSERT_NE(first, nullptr);
  first->reset();
  session->closeAfterReset(*first);
  ASSERT_TRUE(waitFor([&] { return connections_served >= 1; }));
  const std::shared_ptr<Client> second = running();
  ASSERT_NE(second, nullptr);
  EXPECT_NE(second, first);
  EXPECT_EQ(session->reconnects(), 1u);
  std::lock_guard<std::mutex> lock(mutex);
  bool said_reset = false;
  for (const std::string& link : links)
  {
    said_reset = said_reset || link.find("reset: the connection was closed as ~reset does") != std::string::npos;
  }
  EXPECT_TRUE(said_reset);
}

// The board drops the link on purpose in standalone mode: the session waits for another mode
// instead of reconnecting (which would take the board out of it).
TEST_F(EthernutSession, StandaloneModeHoldsTheReconnectionUntilAnotherModeIsSelected)
{
  start();
  const std::shared_ptr<Client> first = running();
  ASSERT_NE(first, nullptr);
  EXPECT_EQ(session->selectMode(BoardMode::kStandalone), std::nullopt);  // connected: the client switches
  first->setMode(BoardMode::kStandalone);
  // The link reports the session's end once the session knows the board is standalone.
  ASSERT_TRUE(waitFor([&] { return std::find(links.begin(), links.end(), "down: session ended") != links.end(); }));
  EXPECT_EQ(first->state(), SessionState::kStandalone);
  EXPECT_EQ(session->selectMode(BoardMode::kStandalone).value_or(""), "already in standalone mode");
  EXPECT_EQ(session->latest(), first);  // no new connection
  {
    std::lock_guard<std::mutex> lock(mutex);
    EXPECT_EQ(connections_served, 1);
  }
  EXPECT_EQ(session->selectMode(BoardMode::kFile).value_or(""), "reconnecting in file mode");
  const std::shared_ptr<Client> second = running();
  ASSERT_NE(second, nullptr);
  EXPECT_NE(second, first);
}
