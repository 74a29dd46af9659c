#include "emulator/bench/bench_workloads.h"

#include <linux/can.h>
#include <pthread.h>
#include <sched.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <memory>
#include <optional>
#include <thread>
#include <vector>

#include <fmt/format.h>

#include "bus/socketcan_transport.h"
#include "bus/ucan_broker.h"
#include "emulator/bench/bench_report.h"
#include "emulator/bench/fan_out_readers.h"
#include "emulator/bench/paper002_device_set.h"
#include "emulator/peers/mecanum_peer.h"
#ifdef WHEELHIL_HAVE_MUJOCO
#include "emulator/peers/mujoco_mecanum.h"
#endif
#include "emulator/physics/physics_world.h"
#include "emulator/platforms/platform.h"
#include "emulator/realtime/realtime_pacer.h"

namespace wheelhil::emulator::bench {
namespace {

using Clock = std::chrono::steady_clock;

double SecondsSince(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}

// ---------------------------------------------------------------- physics

double MeasureWorld(const std::string& source_dir, const std::string& platform, bool mesh,
                    int count, double wall_s) {
  const platforms::Platform p =
      platforms::LoadPlatformFile(source_dir + "/scenarios/platforms/" + platform + ".yaml");
  physics::PhysicsWorld world;
  if (mesh) {
    world.terrain().AddMesh(source_dir + "/meshes/uneven_tiles.obj", MeshOptions{});
  } else {
    world.terrain().AddPlane(Eigen::Vector3d::UnitZ(), Eigen::Vector3d::Zero(), Friction{0.8, 0.7});
  }
  for (int i = 0; i < count; ++i) {
    auto& v = world.AddVehicle(p.vehicle, -1.5 + 0.75 * (i % 4), -1.5 + 0.75 * (i / 4), 0.0);
    platforms::CommandTwist(v, p, platforms::BodyTwist{0.05, 0.0, 0.05});
  }
  world.StepFor(0.2);  // settle
  constexpr int kChunkSteps = 100;
  std::vector<double> rtf;
  const Clock::time_point t0 = Clock::now();
  while (SecondsSince(t0) < wall_s || rtf.size() < 3) {
    const Clock::time_point c0 = Clock::now();
    for (int i = 0; i < kChunkSteps; ++i) world.Step();
    rtf.push_back(kChunkSteps * world.step_s() / SecondsSince(c0));
  }
  return Median(rtf);
}

// ---------------------------------------------------------------- bus

struct FanOutResult {
  double frames_per_s = 0;
  std::uint64_t lost = 0;
  std::string problem;
};

/// One writer, `readers` readers, flow-controlled by `window` frames in flight.
FanOutResult MeasureFanOut(const char* iface, int readers, double wall_s, std::uint64_t window) {
  FanOutResult result;
  const int tx = OpenRawCan(iface);
  std::vector<int> rx;
  for (int i = 0; i < readers; ++i) rx.push_back(OpenRawCan(iface));
  if (tx < 0 || std::count(rx.begin(), rx.end(), -1) > 0) {
    result.problem = fmt::format("cannot open {}: {}", iface, std::strerror(errno));
    if (tx >= 0) ::close(tx);
    for (int fd : rx) {
      if (fd >= 0) ::close(fd);
    }
    return result;
  }
  FanOutReaders reader_threads(rx);
  can_frame f{};
  f.can_id = 0x123;
  f.can_dlc = 8;
  std::uint64_t sent = 0;
  const Clock::time_point t0 = Clock::now();
  // A reader that stalls for 2 s past the measuring time no longer holds the writer back.
  const Clock::time_point give_up =
      t0 + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(wall_s + 2.0));
  while (SecondsSince(t0) < wall_s) {
    for (int burst = 0; burst < 256; ++burst) {
      reader_threads.WaitForWindow(sent, window, give_up);
      std::memcpy(f.data, &sent, sizeof(sent));
      if (::write(tx, &f, sizeof(f)) != sizeof(f)) {
        if (errno == ENOBUFS || errno == EAGAIN) {
          std::this_thread::sleep_for(std::chrono::microseconds(20));
          continue;
        }
        result.problem = fmt::format("write on {}: {}", iface, std::strerror(errno));
        break;
      }
      ++sent;
    }
    if (!result.problem.empty()) break;
  }
  // Wait for the readers to catch up (bounded: frames the bus dropped never arrive).
  reader_threads.WaitForAll(sent, 2.0);
  const double elapsed = SecondsSince(t0);
  reader_threads.Stop();
  ::close(tx);
  for (int fd : rx) ::close(fd);
  const std::uint64_t delivered = reader_threads.Slowest();
  result.lost = sent - delivered;
  result.frames_per_s = static_cast<double>(delivered) / elapsed;
  return result;
}

// ---------------------------------------------------------------- real time

class TransportSink final : public realtime::FrameSink {
 public:
  explicit TransportSink(bus::SocketCanTransport& t) : t_(t) {}
  std::error_code Send(const bus::CanFrame& frame) noexcept override { return t_.Send(frame); }

 private:
  bus::SocketCanTransport& t_;
};

/// Steal time of all CPUs so far (the "steal" column of /proc/stat's "cpu" line: time the
/// hypervisor ran something else while this machine's virtual CPUs had work), ms; -1 when
/// unreadable.
double StealMs() {
  std::FILE* f = std::fopen("/proc/stat", "r");
  if (!f) return -1;
  unsigned long long v[8] = {};
  const int n = std::fscanf(f, "cpu %llu %llu %llu %llu %llu %llu %llu %llu", &v[0], &v[1], &v[2],
                            &v[3], &v[4], &v[5], &v[6], &v[7]);
  std::fclose(f);
  const long hz = ::sysconf(_SC_CLK_TCK);
  if (n != 8 || hz <= 0) return -1;
  return static_cast<double>(v[7]) * 1000.0 / static_cast<double>(hz);
}

std::string JoinNotes(const std::vector<std::string>& notes) {
  std::string s;
  for (const auto& n : notes) s += (s.empty() ? "" : "; ") + n;
  return s;
}

}  // namespace

nlohmann::json RunPhysicsWorkload(const std::string& source_dir, double wall_s_per_case) {
  nlohmann::json report = nlohmann::json::object();
  for (const auto& platform : BenchPlatforms()) {
    for (const bool mesh : {false, true}) {
      const std::string key = fmt::format("physics.{}.{}_rtf", platform, mesh ? "mesh" : "flat");
      try {
        SetPath(report, key, MeasureWorld(source_dir, platform, mesh, 1, wall_s_per_case));
      } catch (const std::exception& e) {
        SetPath(report, key, Unavailable(e.what()));
      }
    }
  }
  for (int n : {1, 4, 16}) {
    const std::string key = fmt::format("physics.platforms_{}.rtf", n);
    try {
      SetPath(report, key, MeasureWorld(source_dir, "mecanum4_omni3", false, n, wall_s_per_case));
    } catch (const std::exception& e) {
      SetPath(report, key, Unavailable(e.what()));
    }
  }
  return report;
}

nlohmann::json RunPeersWorkload(const std::string& source_dir, int repeats) {
  nlohmann::json report = nlohmann::json::object();
  const char* kW = "peers.mecanum_wheelhil_steps_per_s";
  const char* kM = "peers.mecanum_mujoco_steps_per_s";
  const char* kRatio = "peers.mecanum_wheelhil_vs_mujoco";
  try {
    const platforms::Platform platform =
        platforms::LoadPlatformFile(source_dir + "/scenarios/platforms/mecanum4_mujoco_peer.yaml");
#ifndef WHEELHIL_HAVE_MUJOCO
    (void)repeats;
    SetPath(report, kW, peers::MeasureWheelhil(platform, peers::PeerMotions()[0], 0.8).steps_per_s);
    throw std::runtime_error("libmujoco-dev was not installed when wheelhil was built");
#else
    // Interleaved: each motion alternates the engines, so a change in the machine's load
    // touches both; the figures are medians over motions and repeats.
    std::vector<double> w, m;
    for (int r = 0; r < repeats; ++r) {
      for (const peers::PeerMotion& motion : peers::PeerMotions()) {
        w.push_back(peers::MeasureWheelhil(platform, motion, 0.8).steps_per_s);
        m.push_back(peers::MeasureMujoco(motion, peers::MujocoPeerOptions{}).steps_per_s);
      }
    }
    auto median = [](std::vector<double> v) {
      std::sort(v.begin(), v.end());
      const std::size_t n = v.size();
      return n % 2 == 1 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
    };
    SetPath(report, kW, median(w));
    SetPath(report, kM, median(m));
    SetPath(report, kRatio, median(w) / median(m));
#endif
  } catch (const std::exception& e) {
    if (!GetPath(report, kW)) SetPath(report, kW, Unavailable(e.what()));
    SetPath(report, kM, Unavailable(e.what()));
    SetPath(report, kRatio, Unavailable(e.what()));
  }
  return report;
}

nlohmann::json RunBusWorkload(const std::string& kind, double wall_s_per_case) {
  nlohmann::json report = nlohmann::json::object();
  const std::string k1 = fmt::format("bus.{}_frames_per_s", kind);
  const std::string k4 = fmt::format("bus.{}_fanout4_frames_per_s", kind);
  std::unique_ptr<bus::UcanBroker> broker;
  std::string iface;
  try {
    if (kind == "ucan") {
      const char* dir = std::getenv("WHEELHIL_UCAN_DIR");
      if (!dir || !std::getenv("LD_PRELOAD")) {
        throw std::runtime_error(
            "libwheelhil_ucan.so is not preloaded (run through wheelhil bench)");
      }
      bus::UcanBrokerOptions o;
      o.runtime_dir = dir;
      o.remove_runtime_dir = true;
      broker = std::make_unique<bus::UcanBroker>(o);
      broker->AddBus("ucan0");
      iface = "ucan0";
    } else {
      if (!std::filesystem::exists("/sys/class/net/vcan0")) {
        throw std::runtime_error(
            "no kernel vcan0 on this machine (measure it inside the test kernel: wheelhil bench "
            "--uml, or `modprobe vcan; ip link add vcan0 type vcan; ip link set vcan0 up`)");
      }
      iface = "vcan0";
    }
  } catch (const std::exception& e) {
    SetPath(report, k1, Unavailable(e.what()));
    SetPath(report, k4, Unavailable(e.what()));
    return report;
  }
  // vcan drops what does not fit a reader's socket buffer (about 300 frames by default); the
  // ucan broker queues up to 8192 per reader.
  const std::uint64_t window = kind == "ucan" ? 2048 : 128;
  for (const auto& [readers, key] : {std::pair{1, k1}, std::pair{4, k4}}) {
    const FanOutResult r = MeasureFanOut(iface.c_str(), readers, wall_s_per_case, window);
    if (!r.problem.empty()) {
      SetPath(report, key, Unavailable(r.problem));
    } else {
      SetPath(report, key, r.frames_per_s);
      if (r.lost) SetPath(report, key + "_lost_frames", r.lost);
    }
  }
  return report;
}

nlohmann::json RunRealtimeWorkload(const RealtimeWorkloadOptions& options) {
  using namespace realtime;
  nlohmann::json report = nlohmann::json::object();
  const std::string& px = options.prefix;
  const bool main_run = px == "realtime.";
  auto fail = [&](const std::string& reason) {
    for (const char* k : {"p50_us", "p99_us", "max_us", "missed_deadlines"}) {
      SetPath(report, px + k, Unavailable(reason));
    }
    if (main_run) {
      for (const char* k :
           {"frames", "duration_s", "arrival_p99_us", "spin_us", "bare_timer_p99_us",
            "bare_timer_max_us", "bare_spin_p99_us", "bare_spin_max_us"}) {
        SetPath(report, px + k, Unavailable(reason));
      }
      SetPath(report, "realtime.scheduling", Unavailable(reason));
    }
    return report;
  };
  const char* dir = std::getenv("WHEELHIL_UCAN_DIR");
  if (!dir || !std::getenv("LD_PRELOAD")) {
    return fail("libwheelhil_ucan.so is not preloaded (run through wheelhil bench)");
  }
  // mlockall(MCL_FUTURE) makes every thread stack resident: 512 KiB stacks instead of the
  // default 8 MiB keep the locked footprint small (glibc: also the default of std::thread).
  pthread_attr_t stack_attr;
  if (::pthread_attr_init(&stack_attr) == 0) {
    ::pthread_attr_setstacksize(&stack_attr, 512 * 1024);
    ::pthread_setattr_default_np(&stack_attr);
    ::pthread_attr_destroy(&stack_attr);
  }
  try {
    Paper002DeviceSetOptions dso;
    dso.source_dir = options.source_dir;
    Paper002DeviceSet devices(dso);
    const std::int64_t cycles = static_cast<std::int64_t>(options.duration_s * 1e9 /
                                                          static_cast<double>(devices.cycle_ns()));

    // The broker's, producer's and reader's threads inherit the policy of the thread that
    // creates them: under SCHED_FIFO the whole pipeline runs one step below the pacer, so a
    // busy machine cannot stall the bus behind the pacer's frames.
    RealtimeStatus pipeline;
    if (options.sched_fifo) {
      RealtimeOptions po;
      po.lock_memory = false;
      po.fifo_priority = std::max(1, options.fifo_priority - 1);
      pipeline = ApplyRealtimeSettings(po);
    }
    const int cores = static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
    const int pacer_cpu = options.cpu == -2 ? (pipeline.sched_fifo ? cores - 1 : -1) : options.cpu;
    const int pipeline_cpu = options.pipeline_cpu == -2 ? pacer_cpu : options.pipeline_cpu;
    // Threads inherit the CPU mask of the thread that starts them: with pipeline_cpu the
    // broker, producer, writer and reader start pinned, the pacer and the load threads with this
    // thread's original mask (restored below).
    cpu_set_t original_mask;
    const bool have_mask =
        ::pthread_getaffinity_np(::pthread_self(), sizeof(original_mask), &original_mask) == 0;
    bool pipeline_pinned = false;
    std::string pipeline_pin_refused;  // why a requested --bus-cpu was not applied
    if (pipeline_cpu >= 0) {
      int err = !have_mask ? EINVAL : pipeline_cpu >= CPU_SETSIZE ? EINVAL : 0;
      if (err == 0) {
        cpu_set_t set;
        CPU_ZERO(&set);
        CPU_SET(pipeline_cpu, &set);
        err = ::pthread_setaffinity_np(::pthread_self(), sizeof(set), &set);
      }
      pipeline_pinned = err == 0;
      if (!pipeline_pinned) {
        pipeline_pin_refused = fmt::format("; bus pipeline NOT pinned to CPU {}: {}", pipeline_cpu,
                                           std::strerror(err));
      }
    }
    bus::UcanBrokerOptions bo;
    bo.runtime_dir = dir;
    bo.remove_runtime_dir = true;
    bus::UcanBroker broker(bo);
    broker.AddBus("ucan0");
    bus::CanTransportOptions to;
    to.send_retry_limit = 0;
    bus::SocketCanTransport tx = bus::SocketCanTransport::Open("ucan0", to);
    bus::SocketCanTransport rx = bus::SocketCanTransport::Open("ucan0");

    // Everything the threads record is allocated here, before the stream starts.
    const std::size_t expected = static_cast<std::size_t>(cycles) * 8 + 64;
    SpscRing<PacedFrame> input(4096);
    SpscRing<SendRecord> records(8192);
    std::vector<SendRecord> log;
    log.reserve(expected);
    std::vector<std::int64_t> arrivals_ns;
    arrivals_ns.reserve(expected);
    std::atomic<bool> producer_done{false}, pacer_done{false}, stop{false}, reader_stop{false};
    std::atomic<bool> load_stop{false};

    // Producer: device models in virtual time, ahead of the pacer by at most the ring.
    std::vector<PacedFrame> batch;
    batch.reserve(64);
    std::thread producer([&] {
      for (std::int64_t c = 0; c < cycles && !stop.load(); ++c) {
        batch.clear();
        devices.NextCycle(batch);
        for (const PacedFrame& f : batch) {
          while (!input.TryPush(f)) {
            if (stop.load()) return;
            std::this_thread::sleep_for(std::chrono::milliseconds(1));
          }
        }
      }
      producer_done.store(true, std::memory_order_release);
    });
    // Prefill before the clock starts.
    while (input.SizeApprox() < input.capacity() / 2 && !producer_done.load()) {
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
    // Writer: the only place send records are stored (no I/O on the pacer's thread).
    std::thread writer([&] {
      SendRecord r;
      while (true) {
        if (records.TryPop(r)) {
          if (log.size() < log.capacity()) log.push_back(r);
        } else if (pacer_done.load(std::memory_order_acquire)) {
          if (!records.TryPop(r)) break;
          if (log.size() < log.capacity()) log.push_back(r);
        } else {
          std::this_thread::sleep_for(std::chrono::milliseconds(1));
        }
      }
    });
    // Reader: a node on the bus noting when each frame arrives.
    std::thread reader([&] {
      bus::ReceivedFrame f;
      while (!reader_stop.load()) {
        const std::error_code ec = rx.Receive(f, 100);
        if (!ec) {
          if (arrivals_ns.size() < arrivals_ns.capacity()) arrivals_ns.push_back(MonotonicNowNs());
        } else if (ec != std::errc::timed_out && ec != std::errc::bad_message) {
          break;
        }
      }
    });
    if (pipeline_pinned) {
      ::pthread_setaffinity_np(::pthread_self(), sizeof(original_mask), &original_mask);
    }
    std::vector<std::thread> load;
    for (int i = 0; i < options.load_threads; ++i) {
      load.emplace_back([&] {
        sched_param normal{};
        ::pthread_setschedparam(::pthread_self(), SCHED_OTHER, &normal);  // never starve others
        volatile std::uint64_t x = 0;
        while (!load_stop.load(std::memory_order_relaxed)) x = x + 1;
      });
    }

    TransportSink sink(tx);
    const std::int64_t spin_ns = std::llround(std::max(0.0, options.spin_us) * 1e3);
    const int bare_count = main_run ? static_cast<int>(options.bare_timer_s * 1000.0) : 0;
    std::vector<std::int64_t> bare_timer_ns, bare_spin_ns;
    std::int64_t start_ns = 0;
    double steal_before_ms = -1, steal_after_ms = -1;
    RealtimeStatus rt;
    PacerStats stats;
    std::thread pacer([&] {
      RealtimeOptions ro;
      ro.sched_fifo = options.sched_fifo;
      ro.lock_memory = options.sched_fifo;
      ro.fifo_priority = options.fifo_priority;
      ro.cpu = pacer_cpu;
      rt = ApplyRealtimeSettings(ro);
      // What the timer alone does on this thread, with the same settings, in the same run.
      bare_timer_ns = MeasureWakeErrorsNs(1'000'000, bare_count, 0);
      if (spin_ns > 0) bare_spin_ns = MeasureWakeErrorsNs(1'000'000, bare_count, spin_ns);
      start_ns = MonotonicNowNs() + 20'000'000;
      FramePacer p(input, records, sink, spin_ns);
      steal_before_ms = StealMs();
      stats = p.Run(start_ns, producer_done, stop);
      steal_after_ms = StealMs();
      pacer_done.store(true, std::memory_order_release);
    });
    pacer.join();
    producer.join();
    writer.join();
    load_stop = true;
    for (auto& t : load) t.join();
    // Let the reader collect the tail.
    const std::int64_t drain_until = MonotonicNowNs() + 500'000'000;
    while (arrivals_ns.size() < log.size() && MonotonicNowNs() < drain_until) {
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
    reader_stop = true;
    reader.join();

    std::vector<double> error_us, wake_us, send_us;
    error_us.reserve(log.size());
    wake_us.reserve(log.size());
    send_us.reserve(log.size());
    std::uint64_t missed = 0;
    int first_error = 0;
    for (const SendRecord& r : log) {
      if (r.error != 0 && first_error == 0) first_error = r.error;
      const double e = static_cast<double>(r.sent_ns - r.nominal_ns) * 1e-3;
      error_us.push_back(e);
      wake_us.push_back(static_cast<double>(r.woke_ns - r.nominal_ns) * 1e-3);
      send_us.push_back(static_cast<double>(r.sent_ns - r.woke_ns) * 1e-3);
      if (e > options.miss_threshold_us || r.error != 0) ++missed;
    }
    if (error_us.empty()) return fail("no frame was sent");
    SetPath(report, px + "p50_us", Percentile(error_us, 50));
    SetPath(report, px + "p99_us", Percentile(error_us, 99));
    SetPath(report, px + "max_us", Percentile(error_us, 100));
    SetPath(report, px + "missed_deadlines", missed);
    SetPath(report, px + "wake_p99_us", Percentile(wake_us, 99));
    SetPath(report, px + "wake_max_us", Percentile(wake_us, 100));
    SetPath(report, px + "send_p99_us", Percentile(send_us, 99));
    SetPath(report, px + "send_max_us", Percentile(send_us, 100));
    if (steal_before_ms >= 0 && steal_after_ms >= 0) {
      SetPath(report, px + "steal_ms", steal_after_ms - steal_before_ms);
    }
    if (main_run) {
      std::vector<double> arrival_us;
      const std::size_t n = std::min(arrivals_ns.size(), log.size());
      for (std::size_t i = 0; i < n; ++i) {
        arrival_us.push_back(static_cast<double>(arrivals_ns[i] - start_ns - log[i].nominal_ns) *
                             1e-3);
      }
      SetPath(report, "realtime.frames", log.size());
      SetPath(report, "realtime.duration_s",
              static_cast<double>(cycles) * devices.cycle_ns() * 1e-9);
      SetPath(report, "realtime.arrival_p99_us",
              arrival_us.empty() ? nlohmann::json(Unavailable("the reader received nothing"))
                                 : nlohmann::json(Percentile(arrival_us, 99)));
      SetPath(report, "realtime.frames_received", arrivals_ns.size());
      SetPath(report, "realtime.send_errors", stats.send_errors);
      if (first_error) SetPath(report, "realtime.first_send_error", std::strerror(first_error));
      SetPath(report, "realtime.underruns", stats.underruns);
      SetPath(report, "realtime.records_dropped", stats.records_dropped);
      SetPath(report, "realtime.device_problems", devices.problems());
      SetPath(report, "realtime.miss_threshold_us", options.miss_threshold_us);
      SetPath(report, "realtime.spin_us", spin_ns * 1e-3);
      auto bare = [&](const std::string& name, const std::vector<std::int64_t>& ns) {
        std::vector<double> us;
        for (const std::int64_t e : ns) us.push_back(static_cast<double>(e) * 1e-3);
        const std::string why = bare_count == 0 ? "no bare-timer loop in this run"
                                                : "spin margin 0: the pacer only sleeps";
        for (const auto& [k, p] :
             {std::pair{"p50_us", 50.0}, std::pair{"p99_us", 99.0}, std::pair{"max_us", 100.0}}) {
          SetPath(
              report, fmt::format("realtime.{}_{}", name, k),
              us.empty() ? nlohmann::json(Unavailable(why)) : nlohmann::json(Percentile(us, p)));
        }
      };
      bare("bare_timer", bare_timer_ns);
      bare("bare_spin", bare_spin_ns);
      std::string sched = fmt::format(
          "{}, {}, timer slack {} ns, {}{}",
          rt.sched_fifo ? fmt::format("SCHED_FIFO {}", options.fifo_priority)
                        : std::string("SCHED_OTHER"),
          rt.memory_locked ? "memory locked" : "memory not locked", rt.timer_slack_ns,
          spin_ns > 0 ? fmt::format("hybrid wait (sleep, then spin the last {} us)", spin_ns / 1000)
                      : std::string("clock_nanosleep only"),
          rt.pinned_cpu >= 0 ? fmt::format(", pinned to CPU {}", rt.pinned_cpu) : "");
      if (pipeline.sched_fifo) {
        sched += fmt::format("; bus broker, producer and reader SCHED_FIFO {}",
                             std::max(1, options.fifo_priority - 1));
      }
      if (pipeline_pinned) {
        sched += fmt::format("; broker, producer, writer, reader pinned to CPU {}", pipeline_cpu);
      }
      sched += pipeline_pin_refused;
      if (!rt.notes.empty()) sched += " (" + JoinNotes(rt.notes) + ")";
      if (!options.sched_fifo) sched += " (--no-rt)";
      SetPath(report, "realtime.scheduling", sched);
    } else {
      SetPath(report, px + "threads", options.load_threads);
    }
  } catch (const std::exception& e) {
    return fail(e.what());
  }
  return report;
}

}  // namespace wheelhil::emulator::bench
