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

void WriteRunArtefacts(const std::string& out_dir, const nlohmann::json& report,
                       const TruthRecorder& truth, const EstimateDecoder& estimates,
                       const std::vector<nlohmann::json>& events);

}  // namespace wheelhil::emulator::scoring
