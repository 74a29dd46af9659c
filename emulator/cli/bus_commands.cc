#include "emulator/cli/bus_commands.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <fmt/format.h>

#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <stdexcept>
#include <thread>

#include "bus/install_paths.h"
#include "bus/ucan_broker.h"
#include "bus/ucan_runtime_dir.h"

namespace wheelhil::emulator {
namespace {

bool NoBroker(std::error_code ec) {
  return ec == std::errc::connection_refused || ec == std::errc::no_such_file_or_directory;
}

/// Child side of the daemon: detached, stdio on /dev/null, serves until the last bus is down.
[[noreturn]] void RunDaemon(const std::string& dir) {
  const int null_fd = ::open("/dev/null", O_RDWR | O_CLOEXEC);
  if (null_fd >= 0) {
    ::dup2(null_fd, 0);
    ::dup2(null_fd, 1);
    ::dup2(null_fd, 2);
  }
  for (int fd = 3; fd < 1024; ++fd) {
    if (fd != null_fd) ::close(fd);
  }
  try {
    bus::UcanBrokerOptions options;
    options.runtime_dir = dir;
    options.exit_when_empty = true;
    bus::UcanBroker broker(options);
    broker.Wait();
  } catch (...) {
    // Another daemon won the race for the lock (or the directory is unusable): nothing to do.
  }
  ::_exit(0);
}

void EnsureDaemon(const std::string& dir) {
  std::vector<bus::UcanBusStats> stats;
  auto ec = bus::UcanListBuses(dir, &stats);
  if (!ec) return;
  if (!NoBroker(ec)) {
    throw std::runtime_error(fmt::format("ucan broker in {}: {}", dir, ec.message()));
  }
  if (auto dir_ec = bus::EnsureUcanRuntimeDir(dir)) {
    throw std::runtime_error(fmt::format(
        "ucan runtime directory {}: {} (it must be yours, mode 0700; set WHEELHIL_UCAN_DIR to "
        "use another)",
        dir, dir_ec.message()));
  }
  // Double fork: the daemon is nobody's child (no zombie under the program `exec` starts).
  const pid_t pid = ::fork();
  if (pid < 0) throw std::runtime_error(fmt::format("fork: {}", std::strerror(errno)));
  if (pid == 0) {
    ::setsid();
    if (::fork() == 0) RunDaemon(dir);
    ::_exit(0);
  }
  int status = 0;
  ::waitpid(pid, &status, 0);
  for (int attempt = 0; attempt < 500; ++attempt) {
    ec = bus::UcanListBuses(dir, &stats);
    if (!ec) return;
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  throw std::runtime_error(fmt::format("ucan broker in {} did not start: {}", dir, ec.message()));
}

int RunUp(const std::string& name) {
  const std::string dir = bus::ResolveUcanRuntimeDir();
  try {
    const int index = EnsureUcanBus(dir, name);
    fmt::print("{} up (ifindex {}, runtime dir {})\n", name, index, dir);
    return 0;
  } catch (const std::exception& e) {
    fmt::print(stderr, "wheelhil bus up: {}\n", e.what());
    return 1;
  }
}

int RunDown(const std::string& name) {
  const std::string dir = bus::ResolveUcanRuntimeDir();
  const auto ec = bus::UcanRemoveBus(dir, name);
  if (ec) {
    fmt::print(stderr, "wheelhil bus down {}: {}\n", name,
               NoBroker(ec)                      ? fmt::format("no ucan broker in {}", dir)
               : ec == std::errc::no_such_device ? std::string("no such bus")
                                                 : ec.message());
    return 1;
  }
  fmt::print("{} down\n", name);
  return 0;
}

int RunList() {
  const std::string dir = bus::ResolveUcanRuntimeDir();
  std::vector<bus::UcanBusStats> stats;
  const auto ec = bus::UcanListBuses(dir, &stats);
  if (ec && !NoBroker(ec)) {
    fmt::print(stderr, "wheelhil bus list: {}\n", ec.message());
    return 1;
  }
  fmt::print("{:<16}{:>8}{:>9}{:>14}{:>10}{:>8}\n", "NAME", "IFINDEX", "CLIENTS", "FRAMES", "DROPS",
             "BAD");
  for (const auto& s : stats) {
    fmt::print("{:<16}{:>8}{:>9}{:>14}{:>10}{:>8}\n", s.name, s.ifindex, s.clients, s.frames,
               s.drops, s.bad_messages);
  }
  return 0;
}

// `runtime_dir` empty: the user's buses (bus/ucan_runtime_dir.h), started on demand; else a bus
// that already runs there, such as a run's private bus, which exec only attaches to.
int RunExec(const std::vector<std::string>& buses, const std::string& runtime_dir,
            const std::vector<std::string>& command) {
  if (command.empty()) {
    fmt::print(stderr, "wheelhil exec: no program given (wheelhil exec -- PROGRAM ARGS...)\n");
    return 2;
  }
  const std::string dir = runtime_dir.empty() ? bus::ResolveUcanRuntimeDir() : runtime_dir;
  if (!runtime_dir.empty()) {
    if (!buses.empty()) {
      fmt::print(stderr, "wheelhil exec: --runtime-dir attaches to buses that run there; it "
                         "cannot start one (--bus)\n");
      return 2;
    }
    std::vector<bus::UcanBusStats> stats;
    if (const auto ec = bus::UcanListBuses(dir, &stats)) {
      fmt::print(stderr, "wheelhil exec: no userspace bus runs in {}: {} (has its run ended?)\n",
                 dir, NoBroker(ec) ? std::string("no broker there") : ec.message());
      return 1;
    }
  }
  try {
    for (const auto& name : buses) EnsureUcanBus(dir, name);
  } catch (const std::exception& e) {
    fmt::print(stderr, "wheelhil exec: {}\n", e.what());
    return 1;
  }
  const std::string lib = UcanPreloadLibraryPath();
  struct stat st {};
  if (::stat(lib.c_str(), &st) != 0) {
    fmt::print(stderr, "wheelhil exec: {} not found (build target wheelhil_ucan)\n", lib);
    return 1;
  }
  for (const auto& [key, value] : UcanChildEnvironment(dir)) {
    ::setenv(key.c_str(), value.c_str(), 1);
  }
  std::vector<char*> argv;
  for (const auto& a : command) argv.push_back(const_cast<char*>(a.c_str()));
  argv.push_back(nullptr);
  std::fflush(stdout);
  ::execvp(argv[0], argv.data());
  fmt::print(stderr, "wheelhil exec: {}: {}\n", command[0], std::strerror(errno));
  return errno == ENOENT ? 127 : 126;
}

}  // namespace

int EnsureUcanBus(const std::string& runtime_dir, const std::string& name) {
  if (!bus::IsValidUcanBusName(name)) {
    throw std::runtime_error(
        fmt::format("bad bus name '{}': 1..15 characters, no '/', ':' or spaces", name));
  }
  EnsureDaemon(runtime_dir);
  int index = 0;
  auto ec = bus::UcanAddBus(runtime_dir, name, &index);
  if (ec && NoBroker(ec)) {  // the daemon just exited (its last bus went down): once more
    EnsureDaemon(runtime_dir);
    ec = bus::UcanAddBus(runtime_dir, name, &index);
  }
  if (ec) throw std::runtime_error(fmt::format("adding bus {}: {}", name, ec.message()));
  return index;
}

std::vector<std::pair<std::string, std::string>> UcanChildEnvironment(
    const std::string& runtime_dir) {
  return bus::UcanChildEnvironment(UcanPreloadLibraryPath(), runtime_dir);
}

std::string UcanPreloadLibraryPath() {
  if (const char* lib = std::getenv("WHEELHIL_UCAN_LIB"); lib != nullptr && lib[0] != '\0') {
    return lib;
  }
  return bus::FindPreloadLibrary(bus::RunningExecutableDir(), "libwheelhil_ucan.so");
}

BusCommands::BusCommands(CLI::App& app) {
  bus_ = app.add_subcommand("bus", "Userspace CAN buses (ucan): up, down, list");
  bus_->require_subcommand(1);
  up_ = bus_->add_subcommand("up", "Start the bus (and the broker daemon if none runs)");
  up_->add_option("name", up_name_, "Bus name, e.g. ucan0")->required();
  down_ = bus_->add_subcommand("down", "Remove the bus (the daemon exits with its last bus)");
  down_->add_option("name", down_name_, "Bus name")->required();
  list_ = bus_->add_subcommand("list", "Buses with clients, frames, drops");
  exec_ = app.add_subcommand(
      "exec", "Run a SocketCAN program on the userspace buses: exec [--bus NAME] -- PROGRAM ARGS");
  // Registered for --help; the command line is split by RunExecIfRequested() before CLI11
  // sees it, so the program's own options and `--` reach it untouched.
  exec_->add_option("--bus", exec_buses_, "Bring this bus up first (repeatable)");
  exec_->add_option("--runtime-dir", exec_runtime_dir_,
                    "Attach to the buses running in this directory (a run's private bus: "
                    "`wheelhil run` prints it) instead of your own");
  exec_->allow_extras();
}

std::optional<int> BusCommands::Run() {
  if (up_->parsed()) return RunUp(up_name_);
  if (down_->parsed()) return RunDown(down_name_);
  if (list_->parsed()) return RunList();
  if (exec_->parsed()) return RunExec(exec_buses_, exec_runtime_dir_, exec_->remaining());
  return std::nullopt;
}

std::optional<int> BusCommands::RunExecIfRequested(int argc, char** argv) {
  if (argc < 2 || std::strcmp(argv[1], "exec") != 0) return std::nullopt;
  std::vector<std::string> buses;
  std::string runtime_dir;
  int i = 2;
  for (; i < argc; ++i) {
    const std::string arg = argv[i];
    if (arg == "--") {
      ++i;
      break;
    }
    if (arg == "--bus" && i + 1 < argc) {
      buses.push_back(argv[++i]);
    } else if (arg.rfind("--bus=", 0) == 0) {
      buses.push_back(arg.substr(6));
    } else if (arg == "--runtime-dir" && i + 1 < argc) {
      runtime_dir = argv[++i];
    } else if (arg.rfind("--runtime-dir=", 0) == 0) {
      runtime_dir = arg.substr(14);
    } else if (arg == "-h" || arg == "--help") {
      return std::nullopt;  // CLI11 prints the help
    } else if (!arg.empty() && arg[0] == '-') {
      fmt::print(stderr,
                 "wheelhil exec: unknown option {} (exec [--bus NAME | --runtime-dir DIR] -- "
                 "PROGRAM ARGS)\n",
                 arg);
      return 2;
    } else {
      break;
    }
  }
  return RunExec(buses, runtime_dir, std::vector<std::string>(argv + i, argv + argc));
}

}  // namespace wheelhil::emulator
