#pragma once
/// run.mcap: a scored run as one MCAP file (https://mcap.dev, the default storage of rosbag2)
/// that Foxglove opens, written from what the run recorded (its bus log as can.log holds it,
/// its truth recorder, the firmware's decoded streams, its events). JSON messages; the poses
/// and logs in Foxglove's well-known schemas, the rest in schemas of ours (docs/logs.md):
///   /can                        wheelhil.CanFrame       every frame of the bus log
///   /truth/pose                 foxglove.PoseInFrame    each truth row (frame "world")
///   /truth/velocity             wheelhil.BodyVelocity   each truth row (body frame)
///   /truth/wheels               wheelhil.WheelStates    every wheel at each truth row: spin
///                               rate, slip speed, load, motor torque, contact, slipping
///   /estimate/<stream>/pose     foxglove.PoseInFrame    the firmware's pose streams
///   /estimate/<stream>/velocity wheelhil.BodyVelocity   its velocity streams
///   /slip                       wheelhil.SlipInterval   the ground-truth slip intervals
///   /events                     foxglove.Log            every event, one a message
/// Every message's log and publish time is on can.log's clock (ns since the run's start).
/// Unchunked, no summary: a reader streams it. Throws std::runtime_error naming the file when it
/// cannot be written. Thread-compatible.

#include <cstdint>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "bus/candump_log.h"
#include "emulator/scoring/estimate_decoder.h"
#include "emulator/scoring/run_artefacts.h"
#include "emulator/scoring/truth_recorder.h"

namespace wheelhil::emulator::scoring {

/// What a run recorded, as WriteRunArtefacts gets it, with its bus log.
struct RunRecord {
  const std::vector<bus::CandumpRecord>& bus_log;
  std::int64_t motion0_ns;  ///< the motion start on the bus log's clock
  const TruthRecorder& truth;
  const EstimateDecoder& estimates;
  const std::vector<nlohmann::json>& events;
};

void WriteRunMcap(const std::string& path, const RunRecord& run, const ReplayRobot& robot);

}  // namespace wheelhil::emulator::scoring
