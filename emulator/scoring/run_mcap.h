#pragma once
/// run.mcap: a scored run as one MCAP file (https://mcap.dev, the default storage of rosbag2)
/// that Foxglove opens, written from the run's artefacts in its folder (can.log, truth.csv,
/// estimate.csv, the estimate_<stream>.tum of its pose streams, events.jsonl). JSON messages;
/// the poses and logs in Foxglove's well-known schemas, the rest in schemas of ours
/// (docs/scenarios.md, "run.mcap"):
///   /can                      wheelhil.CanFrame         every frame of can.log
///   /truth/pose               foxglove.PoseInFrame      truth.csv (frame "world")
///   /truth/velocity           wheelhil.BodyVelocity     truth.csv (body frame)
///   /truth/wheels             wheelhil.WheelStates      every wheel at each truth row: spin
///                             rate, slip speed, load, motor torque, contact, slipping
///   /estimate/<stream>/pose   foxglove.PoseInFrame      estimate.csv, its pose streams
///   /estimate/<stream>/velocity wheelhil.BodyVelocity   estimate.csv, its velocity streams
///   /slip                     wheelhil.SlipInterval     the ground-truth slip intervals
///   /events                   foxglove.Log              events.jsonl, one line a message
/// Every message's log and publish time is on can.log's clock (ns since the run's start; the
/// motion_start event says where the motion's t = 0 falls on it). Unchunked, no summary: a
/// reader streams it. Throws std::runtime_error naming a file it cannot read or write.
/// Thread-compatible.

#include <string>

#include "emulator/scoring/run_artefacts.h"

namespace wheelhil::emulator::scoring {

/// `truth`: the run's recorder, for the wheels' states (its rows are truth.csv's).
void WriteRunMcap(const std::string& out_dir, const ReplayRobot& robot, const TruthRecorder& truth);

}  // namespace wheelhil::emulator::scoring
