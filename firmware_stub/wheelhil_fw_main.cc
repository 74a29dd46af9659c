// `wheelhil-fw --can IFACE --config FILE.yaml`: the reference estimator firmware. It talks plain
// SocketCAN only (bus/socketcan_transport.h); nothing of emulator/ is linked in, so it runs
// unchanged on vcan0, can0 or a userspace bus under `wheelhil exec`.
//
// Exit codes: 0 clean stop (SIGINT/SIGTERM), 1 the interface cannot be opened (the transport's
// message is printed), 2 bad command line, config or DBC files (file:line: field: problem).

#include <fmt/format.h>
#include <time.h>
#include <unistd.h>
#include <CLI/CLI.hpp>

#include <atomic>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <csignal>
#include <filesystem>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>
#include <system_error>

#include "bus/candump_log.h"
#include "bus/install_paths.h"
#include "bus/socketcan_transport.h"
#include "firmware_stub/drive_protocol.h"
#include "firmware_stub/fw_app.h"
#include "firmware_stub/fw_config.h"
#include "firmware_stub/fw_protocol.h"

namespace {

std::atomic<bool> g_stop{false};
double g_clock_rate = 1.0;  // --clock-rate: host seconds the firmware counts per real second.

extern "C" void OnSignal(int) { g_stop.store(true); }

/// A real duration [ns] on the firmware's host clock (scaled by --clock-rate).
std::int64_t ScaledNs(std::int64_t real_ns) {
  return g_clock_rate == 1.0 ? real_ns
                             : static_cast<std::int64_t>(std::llround(real_ns * g_clock_rate));
}

std::int64_t NowNs() {
  return ScaledNs(std::chrono::duration_cast<std::chrono::nanoseconds>(
                      std::chrono::steady_clock::now().time_since_epoch())
                      .count());
}

std::int64_t RealtimeNs() {
  timespec ts{};
  ::clock_gettime(CLOCK_REALTIME, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}


}  // namespace

int main(int argc, char** argv) {
  using namespace wheelhil;
  CLI::App app{"wheelhil-fw - reference estimator firmware (CANopen master) over SocketCAN"};
  std::string iface;
  std::string config_path;
  std::string dbc_dir;
  std::string log_path;
  bool quiet = false;
  app.add_option("--can", iface, "CAN interface (vcan0, can0, ucan0, ...)")->required();
  app.add_option("--config", config_path, "Firmware config YAML")->required();
  app.add_option("--dbc-dir", dbc_dir,
                 "Directory with the protocol DBC files (default: config dbc_dir, "
                 "$WHEELHIL_DBC_DIR, the shipped files: <exe>/../../bus/dbc in a build tree, "
                 "<exe>/" + bus::InstalledDataDirFromBin() + "/dbc installed)");
  app.add_option("--log", log_path, "Write every frame received and sent (candump -L format)");
  app.add_flag("--quiet", quiet, "No start-up / summary messages on stderr");
  app.add_option("--clock-rate", g_clock_rate,
                 "Test aid: the firmware's host clock runs this many times faster than real "
                 "time (a slow emulator seen from the firmware; default 1)")
      ->check(CLI::Range(0.001, 1000.0))
      // CLI::Range lets NaN through (every comparison with it is false).
      ->check([](const std::string& v) {
        return std::isfinite(std::strtod(v.c_str(), nullptr)) ? std::string()
                                                              : "must be a finite number";
      });
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    const int code = app.exit(e);
    return code == 0 ? 0 : 2;
  }

  // Installed before the start-up work (config, DBC files, the interface): a SIGTERM that comes
  // while the firmware starts is a clean stop too, not the default action's death.
  struct sigaction sa {};
  sa.sa_handler = OnSignal;
  sigemptyset(&sa.sa_mask);
  sa.sa_flags = 0;  // No SA_RESTART: a signal ends the wait at once.
  sigaction(SIGINT, &sa, nullptr);
  sigaction(SIGTERM, &sa, nullptr);

  fw::FwConfig cfg;
  std::unique_ptr<fw::FwProtocol> protocol;
  std::unique_ptr<fw::DriveProtocol> drive_protocol;
  std::unique_ptr<fw::FwApp> fwapp;
  try {
    cfg = fw::LoadFwConfig(config_path);
    const std::string dir =
        fw::FwProtocol::FindDbcDir(dbc_dir.empty() ? cfg.dbc_dir : dbc_dir, bus::RunningExecutableDir());
    if (dir.empty()) {
      throw std::invalid_argument(
          "no DBC directory: set dbc_dir in the config, --dbc-dir or WHEELHIL_DBC_DIR "
          "(searched <exe>/../../bus/dbc and <exe>/" +
          bus::InstalledDataDirFromBin() + "/dbc)");
    }
    std::vector<int> ids;
    for (const auto& n : cfg.encoder_nodes()) ids.push_back(n.node_id);
    protocol = std::make_unique<fw::FwProtocol>(
        fw::FwProtocol::LoadDir(dir, ids, cfg.imu.enabled ? cfg.imu.yaw_frame_id : 0,
                                cfg.accel.enabled ? cfg.accel.frame_id : 0));
    if (cfg.drives.enabled) {
      std::vector<int> drive_ids;
      for (const auto& n : cfg.drives.nodes) drive_ids.push_back(n.node_id);
      drive_protocol =
          std::make_unique<fw::DriveProtocol>(fw::DriveProtocol::LoadDir(dir, drive_ids));
    }
    fwapp = std::make_unique<fw::FwApp>(cfg, *protocol, drive_protocol.get());
    if (!quiet) {
      fmt::print(stderr, "wheelhil-fw: estimator {}, SYNC {} every {} s, DBC {}\n",
                 fw::EstimatorName(cfg.estimator), cfg.sync.produce ? "produced" : "followed",
                 cfg.sync.period_s, dir);
      if (cfg.drives.enabled) {
        fmt::print(stderr, "wheelhil-fw: {} CiA 402 drives, {}\n", cfg.drives.nodes.size(),
                   cfg.path.enabled
                       ? fmt::format("following {} waypoints", cfg.path.waypoints.size())
                       : std::string("holding still (no path)"));
      }
      for (const auto& s : protocol->unbound_output_signals()) {
        fmt::print(stderr, "wheelhil-fw: note: output signal {} is not filled (sent as 0)\n", s);
      }
    }
  } catch (const std::invalid_argument& e) {
    fmt::print(stderr, "wheelhil-fw: {}\n", e.what());
    return 2;
  }

  std::optional<bus::SocketCanTransport> can;
  try {
    bus::CanTransportOptions options;
    can.emplace(bus::SocketCanTransport::Open(iface, options));
  } catch (const std::exception& e) {
    fmt::print(stderr, "wheelhil-fw: {}\n", e.what());
    return 1;
  }
  std::unique_ptr<bus::CandumpWriter> log;
  if (!log_path.empty()) {
    try {
      log = std::make_unique<bus::CandumpWriter>(log_path,
                                                 bus::CandumpWriter::FlushPolicy::kEveryLine);
    } catch (const std::invalid_argument& e) {
      fmt::print(stderr, "wheelhil-fw: {}\n", e.what());
      return 2;
    }
  }

  const std::int64_t t0 = NowNs();
  std::vector<bus::CanFrame> out;
  std::uint64_t send_errors = 0;
  auto flush = [&](std::int64_t t) {
    for (const auto& f : out) {
      if (can->Send(f)) {
        ++send_errors;
      } else if (log) {
        (void)log->Write(t - t0, iface, f);
      }
    }
    out.clear();
  };
  fwapp->Start(t0, out);
  flush(t0);
  bool sync_silent = false;
  while (!g_stop.load()) {
    const std::int64_t now = NowNs();
    const std::int64_t next = fwapp->NextEventNs();
    const std::int64_t wait_ns =
        next <= now ? 0
                    : std::min<std::int64_t>(
                          static_cast<std::int64_t>(static_cast<double>(next - now) / g_clock_rate),
                          50'000'000);
    bus::ReceivedFrame rx;
    const std::error_code ec = can->Receive(rx, static_cast<int>((wait_ns + 999'999) / 1'000'000));
    const std::int64_t t = NowNs();
    if (!ec) {
      // Judged by when it arrived (the kernel's receive stamp), not when this loop read it.
      const std::int64_t now_real = RealtimeNs();
      const std::int64_t arrival =
          rx.kernel_timestamp
              ? fw::ArrivalOnMonotonicNs(now_real - ScaledNs(now_real - rx.timestamp_ns), now_real,
                                         t, ScaledNs(1'000'000'000))
              : t;
      if (log) (void)log->Write(arrival - t0, iface, rx.frame);
      fwapp->OnFrameArrived(rx.frame, arrival, out);
    } else if (ec != std::errc::timed_out && ec != std::errc::resource_unavailable_try_again &&
               ec != std::errc::bad_message && ec != std::errc::interrupted) {
      fmt::print(stderr, "wheelhil-fw: receive on {}: {}\n", iface, ec.message());
      if (ec == std::errc::network_down || ec == std::errc::no_such_device) break;
    }
    fwapp->Poll(t, out);
    flush(t);
    if (fwapp->sync_silent() != sync_silent) {
      // Not a node fault: the whole bus (or its SYNC producer) is quiet.
      sync_silent = fwapp->sync_silent();
      if (sync_silent) {
        fmt::print(stderr,
                   "wheelhil-fw: no SYNC on {} for {} s: bus dead or SYNC producer gone; CANopen "
                   "timers run on the host clock until SYNC returns\n",
                   iface, static_cast<double>(fwapp->SyncSilenceNs()) * 1e-9);
      } else {
        fmt::print(stderr, "wheelhil-fw: SYNC back on {}; CANopen timers on bus time again\n",
                   iface);
      }
    }
  }
  if (!quiet) {
    const auto& s = fwapp->stats();
    fmt::print(stderr,
               "wheelhil-fw: stopped: {} frames in ({} bad, {} unknown ids), {} out ({} send "
               "errors), {} cycles, {} steps, {} skipped, {} SYNC silences, faults 0x{:X}\n",
               s.frames_in, s.bad_frames, s.unknown_frames, s.frames_out, send_errors, s.cycles,
               s.steps, s.skipped_steps, s.sync_silences, fwapp->last_faults());
  }
  return 0;
}
