#pragma once
/// Writes a scored run into its output folder: truth.csv, estimate.csv, truth.tum, estimate.tum
/// (stream "pose"), estimate_raw.tum ("pose_raw"), events.jsonl, report.json and report.html
/// (the report's table and the trajectory, residual, velocity and error-over-distance plots).
/// Throws std::runtime_error naming the file that cannot be written. Thread-compatible.

#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "emulator/scoring/estimate_decoder.h"
#include "emulator/scoring/truth_recorder.h"

namespace wheelhil::emulator::scoring {

/// The robot as the report's top-down replay draws it: its chassis box and its wheels, in the
/// body frame (x forward, y left, m). `slip_bit`: the wheel's bit in TruthRow::slipping_wheels
/// (-1: its slip is not scored).
struct ReplayRobot {
  double half_length_m = 0.2, half_width_m = 0.15;
  struct Wheel {
    std::string name;
    double x_m = 0, y_m = 0, radius_m = 0.05;
    int slip_bit = -1;
  };
  std::vector<Wheel> wheels;
  /// The bus's bit rate, for the bus-load timeline read back from can.log (0: no timeline).
  double bus_bitrate_bps = 0;
};

void WriteRunArtefacts(const std::string& out_dir, const nlohmann::json& report,
                       const TruthRecorder& truth, const EstimateDecoder& estimates,
                       const std::vector<nlohmann::json>& events, const ReplayRobot& robot = {});

}  // namespace wheelhil::emulator::scoring
