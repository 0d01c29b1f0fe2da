// sim_mtconnect: a simulated machine that serves MTConnect, as a machine with an agent of its own
// (a Mazak, Okuma or DMG Mori with its adapter and agent, a Haas NGC's built-in agent). The machine
// is a scripted timeline (the script format of sim_haas_mdc, src/sim/mdc/sim_machine.h); the
// project's SHDR adapter core serves its state as one device; with --agent-port the reference
// agent (cppagent, scripts/build_cppagent.sh) is started on the Devices.xml and agent.cfg written
// for that device, and answers /probe, /current and /sample on that port. The agent is this
// simulator's child: it stops with it (also when the simulator is killed).
//
// usage: sim_mtconnect --script FILE --device NAME [--port N] [--host ADDR] [--files DIR]
//                      [--agent-port N] [--agent BINARY]
// First line: "sim_mtconnect tcp <host>:<port>" (the SHDR adapter), then, with --agent-port,
// "sim_mtconnect agent http://<host>:<agent port>".
#include <signal.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <boost/program_options.hpp>
#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <memory>

#include "cnc_bridge/common/error.h"
#include "cnc_bridge/mtconnect/shdr.h"
#include "cnc_bridge/mtconnect/shdr_adapter.h"
#include "sim/mdc/sim_machine.h"
#include "sim/mtconnect/sim_device.h"
#include "sim/sim_support.h"

namespace fs = std::filesystem;
using cnc_bridge::ConfigError;
using cnc_bridge::mdc::SimMachine;
namespace mtc = cnc_bridge::mtconnect;

namespace
{
// Where scripts/build_cppagent.sh installs the agent; $CNC_MTCONNECT_AGENT (as for the tests) or
// --agent points elsewhere.
const char* const kDefaultAgent = "/usr/local/lib/cnc_bridge/cppagent-1.8.0.3/agent";

struct Options
{
  std::string script, device, uuid, host = "127.0.0.1", files, agent;
  int port = 0, agent_port = 0;
  double rate = 10.0;
};

std::string agentBinary(const Options& options)
{
  if (!options.agent.empty())
    return options.agent;
  const char* from_env = std::getenv("CNC_MTCONNECT_AGENT");
  return from_env && *from_env ? from_env : kDefaultAgent;
}

void writeFile(const fs::path& path, const std::string& text)
{
  std::ofstream out(path, std::ios::trunc);
  out << text;
  if (!out.flush())
    throw ConfigError("--files: cannot write " + path.string());
}

// Devices.xml and agent.cfg for this one device, in \p dir. \returns the agent.cfg's path.
fs::path writeAgentFiles(const Options& options, uint16_t adapter_port)
{
  const fs::path dir = fs::absolute(options.files);
  std::error_code error;
  fs::create_directories(dir, error);
  if (error)
    throw ConfigError("--files: cannot create " + dir.string() + ": " + error.message());
  const std::vector<mtc::DeviceSpec> devices{{options.device, options.uuid.empty() ? options.device : options.uuid}};
  writeFile(dir / "Devices.xml", mtc::devicesXml(devices));
  const fs::path config = dir / "agent.cfg";
  writeFile(config, mtc::agentConfig(devices, (dir / "Devices.xml").string(), options.host, adapter_port,
                                     static_cast<uint16_t>(options.agent_port)));
  return config;
}

// Starts `agent run <config>` in the config's folder (where it writes its agent.log). The child
// gets SIGTERM when this process ends, however it ends.
pid_t startAgent(const std::string& agent, const fs::path& config)
{
  const std::string config_path = config.string(), folder = config.parent_path().string();
  const char* argv[] = {agent.c_str(), "run", config_path.c_str(), nullptr};
  const pid_t parent = ::getpid();
  const pid_t pid = ::fork();
  if (pid < 0)
    throw cnc_bridge::LinkError("cannot start the MTConnect agent: fork failed");
  if (pid == 0)
  {
    // Only async-signal-safe calls until exec. The stop handler blocked SIGINT and SIGTERM in this
    // process, and exec keeps the mask: unblock them for the agent.
    sigset_t none;
    ::sigemptyset(&none);
    ::sigprocmask(SIG_SETMASK, &none, nullptr);
    ::prctl(PR_SET_PDEATHSIG, SIGTERM);
    if (::getppid() != parent || ::chdir(folder.c_str()) != 0)
      ::_exit(127);
    ::execv(argv[0], const_cast<char* const*>(argv));
    ::_exit(127);
  }
  return pid;
}

// \returns the agent's exit status once it has ended, -1 while it runs.
int agentEnded(pid_t agent)
{
  int status = 0;
  if (::waitpid(agent, &status, WNOHANG) != agent)
    return -1;
  return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
}

void stopAgent(pid_t agent)
{
  ::kill(agent, SIGTERM);
  for (int i = 0; i < 30; ++i)
  {
    if (agentEnded(agent) >= 0)
      return;
    ::usleep(100000);  // the agent's own shutdown: up to 3 s, then it is killed
  }
  ::kill(agent, SIGKILL);
  ::waitpid(agent, nullptr, 0);
}

int run(const Options& options)
{
  auto& stop = cnc_bridge::sim::installStopHandler();
  std::ifstream in(options.script);
  if (!in)
    throw ConfigError("cannot open script " + options.script);
  SimMachine machine = SimMachine::fromScript(in, options.script);
  const std::string agent = agentBinary(options);
  if (options.agent_port > 0 && ::access(agent.c_str(), X_OK) != 0)
    throw ConfigError("the MTConnect agent (cppagent 1.8.0.3) is not at " + agent +
                      ": run scripts/setup.sh (it builds the agent with scripts/build_cppagent.sh), "
                      "or point --agent or CNC_MTCONNECT_AGENT at an agent");
  mtc::AdapterSettings settings;
  settings.address = options.host;
  settings.port = static_cast<uint16_t>(options.port);
  mtc::ShdrAdapter adapter(settings, {options.device});
  machine.start(SimMachine::Clock::now());
  cnc_bridge::sim::announce("sim_mtconnect", "tcp " + options.host + ":" + std::to_string(adapter.port()));
  pid_t child = -1;
  if (!options.files.empty())
  {
    const fs::path config = writeAgentFiles(options, adapter.port());
    if (options.agent_port > 0)
    {
      child = startAgent(agent, config);
      cnc_bridge::sim::announce("sim_mtconnect", "agent http://" + options.host + ":" +
                                                     std::to_string(options.agent_port) + " (" + config.string() + ")");
    }
  }
  const auto period =
      std::chrono::duration_cast<cnc_bridge::Milliseconds>(std::chrono::duration<double>(1.0 / options.rate));
  int status = 0;
  while (!stop.stopped())
  {
    adapter.publish(options.device, mtc::reportOf(machine.stateAt(SimMachine::Clock::now()), machine.inch()),
                    std::chrono::system_clock::now());
    if (child > 0)
    {
      const int ended = agentEnded(child);
      if (ended >= 0)
      {
        std::cerr << "sim_mtconnect: the MTConnect agent " << agent << " exited with status " << ended
                  << " (its agent.log is in " << fs::absolute(options.files).string() << ")" << std::endl;
        child = -1;
        status = 1;
        break;
      }
    }
    stop.waitFor(period);
  }
  if (child > 0)
    stopAgent(child);
  adapter.stop();
  return status;
}
}  // namespace

int main(int argc, char** argv)
{
  namespace po = boost::program_options;
  Options o;
  po::options_description options("sim_mtconnect options");
  options.add_options()("help,h", "this help")(
      "script", po::value(&o.script)->required(),
      "machine script (the format of sim_haas_mdc: src/sim/mdc/sim_machine.h)")(
      "device", po::value(&o.device)->required(), "the agent's device name (an XML name)")(
      "uuid", po::value(&o.uuid), "the device's uuid (default: its name)")(
      "host", po::value(&o.host)->default_value("127.0.0.1"), "address the SHDR adapter listens on")(
      "port", po::value(&o.port)->default_value(0), "the SHDR adapter's TCP port; 0 picks a free one")(
      "rate", po::value(&o.rate)->default_value(10.0), "machine states sent to the adapter per second")(
      "files", po::value(&o.files), "write the agent's Devices.xml and agent.cfg into this folder")(
      "agent-port", po::value(&o.agent_port)->default_value(0),
      "start the MTConnect agent on --files, serving HTTP on this port; 0: no agent")(
      "agent", po::value(&o.agent),
      "the agent's binary (default $CNC_MTCONNECT_AGENT, else cppagent 1.8.0.3 "
      "where scripts/build_cppagent.sh installs it)");
  po::variables_map vm;
  try
  {
    // Unregistered arguments are allowed: roslaunch appends __name:= and __log:= to every node.
    po::store(po::command_line_parser(argc, argv).options(options).allow_unregistered().run(), vm);
    if (vm.count("help"))
    {
      std::cout << options;
      return 0;
    }
    po::notify(vm);
    if (o.port < 0 || o.port > 65535 || o.agent_port < 0 || o.agent_port > 65535)
      throw po::error("--port and --agent-port: 0 to 65535");
    if (!(o.rate > 0 && o.rate <= 1000))
      throw po::error("--rate: more than 0, at most 1000 a second");
    if (o.agent_port > 0 && o.files.empty())
      throw po::error("--agent-port needs --files: the folder for the agent's Devices.xml and agent.cfg");
  }
  catch (const po::error& e)
  {
    std::cerr << "sim_mtconnect: " << e.what() << "\n" << options;
    return 2;
  }
  try
  {
    return run(o);
  }
  catch (const cnc_bridge::Error& e)
  {
    std::cerr << "sim_mtconnect: " << e.what() << std::endl;
    return 2;
  }
}
