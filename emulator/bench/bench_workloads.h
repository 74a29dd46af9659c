#pragma once
/// The measured workloads of `wheelhil bench`. Each returns a partial report (nested JSON
/// objects, keys of emulator/bench/bench_report.h) and is meant to run in its own child process
/// (`wheelhil bench --worker NAME`), so that its peak RSS is its own. A figure that cannot be
/// measured is set to "unavailable: <reason>", never to a made-up number. Not thread-safe: each
/// workload owns the process while it runs.

#include <string>

#include <nlohmann/json.hpp>

namespace wheelhil::emulator::bench {

/// Physics alone at 1 kHz: each platform on the flat floor and on meshes/uneven_tiles.obj, and
/// 1, 4, 16 mecanum4_omni3 platforms in one world on the flat floor. Sets physics.*: median of
/// per-chunk simulated seconds per wall second. wall_s_per_case: measuring time per case.
nlohmann::json RunPhysicsWorkload(const std::string& source_dir, double wall_s_per_case);

/// The Mecanum cross-engine platform (emulator/peers, 10 discrete rollers per wheel, 1 ms) in
/// wheelhil's physics and in MuJoCo, interleaved motion by motion, `repeats` rounds of the four
/// motions. Sets peers.mecanum_wheelhil_steps_per_s, peers.mecanum_mujoco_steps_per_s (medians)
/// and peers.mecanum_wheelhil_vs_mujoco (their ratio); MuJoCo's figures are unavailable in a
/// build without libmujoco-dev.
nlohmann::json RunPeersWorkload(const std::string& source_dir, int repeats);

/// Frames per second 1 writer -> 1 reader and 1 -> 4 readers of 8-byte classic frames through
/// the plain SocketCAN API on `iface` (flow-controlled: at most a window of frames in flight to
/// the slowest reader; frames the bus dropped are reported, not counted as delivered).
/// kind "ucan": starts a private broker on $WHEELHIL_UCAN_DIR (this process must have
/// libwheelhil_ucan.so preloaded) and uses ucan0; "vcan": the kernel's vcan0.
/// Sets bus.<kind>_frames_per_s and bus.<kind>_fanout4_frames_per_s.
nlohmann::json RunBusWorkload(const std::string& kind, double wall_s_per_case);

struct RealtimeWorkloadOptions {
  std::string source_dir;
  double duration_s = 10.0;  ///< Paced stream length.
  bool sched_fifo = true;    ///< Ask for SCHED_FIFO (and mlockall).
  int fifo_priority = 80;
  /// Pin the pacer; -1 = no pinning; -2 = the last online CPU when SCHED_FIFO was granted, else
  /// none (a SCHED_OTHER pacer pinned to one CPU with the pipeline competes with everything else
  /// there: measured 4x the missed deadlines of an unpinned one).
  int cpu = -1;
  /// Pin the ucan broker, producer, writer and reader threads (they inherit it from the thread
  /// that starts them); -1 = no pinning; -2 = the pacer's CPU.
  int pipeline_cpu = -1;
  /// Margin of the pacer's hybrid wait (clock_nanosleep to deadline - spin, then spin), µs;
  /// 0 = clock_nanosleep only.
  double spin_us = 50.0;
  /// Length of each bare-timer loop (1 kHz, on the pacer's thread, before the stream), s;
  /// 0 = none.
  double bare_timer_s = 1.0;
  int load_threads = 0;               ///< Busy threads competing for the CPUs during the run.
  double miss_threshold_us = 1000.0;  ///< A frame later than this missed its deadline.
  std::string prefix = "realtime.";   ///< Key prefix: "realtime." or "realtime.loaded_".
};
/// The paper-002 device set (emulator/bench/paper002_device_set.h) paced in real time onto
/// a private ucan bus (broker on $WHEELHIL_UCAN_DIR, libwheelhil_ucan.so preloaded), a reader
/// on the bus recording each frame's arrival. Sets <prefix>p50_us, p99_us, max_us (send time
/// minus nominal instant, after the send returned), missed_deadlines, and for the unloaded run
/// frames, duration_s, arrival_p99_us, scheduling, spin_us and the bare timer's wake-up error
/// (bare_timer_*: clock_nanosleep alone; bare_spin_*: the hybrid wait alone).
nlohmann::json RunRealtimeWorkload(const RealtimeWorkloadOptions& options);

}  // namespace wheelhil::emulator::bench
