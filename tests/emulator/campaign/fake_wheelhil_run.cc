// TEST DOUBLE - never shipped. Stands in for `wheelhil run SCENARIO --out DIR --seed N` in the
// campaign tests: reads a few values from the scenario, derives a deterministic "error" from
// them and the seed, and writes DIR/report.json shaped like the real one (scenario, seed,
// verdict, expectations with values, metrics per stream, wall-clock fields kept apart).
// Scenario keys read: terrain.friction, faults[0].probability, sensors.gyro_bias_rad_s,
// fake.sleep_s (wall-clock delay, so a test can kill a campaign mid-run), fake.limit_m
// (expectation bound), fake.exit_without_report (simulates a crashing runner).
// $FAKE_WHEELHIL_RUN_LOG: append the run dir to this file after report.json is complete.

#include <yaml-cpp/yaml.h>
#include <nlohmann/json.hpp>

#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>
#include <thread>

#include <fcntl.h>
#include <unistd.h>

namespace {

double Get(const YAML::Node& n, double fallback) {
  return n && n.IsScalar() ? n.as<double>() : fallback;
}

std::uint64_t Mix(std::uint64_t x) {
  x += 0x9e3779b97f4a7c15ULL;
  x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ULL;
  x = (x ^ (x >> 27)) * 0x94d049bb133111ebULL;
  return x ^ (x >> 31);
}

}  // namespace

int main(int argc, char** argv) {
  std::string scenario, out;
  std::uint64_t seed = 1;
  if (argc < 3 || std::string(argv[1]) != "run") {
    std::fprintf(stderr, "usage: fake_wheelhil_run run SCENARIO --out DIR --seed N\n");
    return 2;
  }
  scenario = argv[2];
  for (int i = 3; i + 1 < argc; i += 2) {
    const std::string k = argv[i];
    if (k == "--out")
      out = argv[i + 1];
    else if (k == "--seed")
      seed = std::strtoull(argv[i + 1], nullptr, 10);
    else if (k == "--can" || k == "--cpu" || k == "--physics-thread")
      continue;
    else {
      std::fprintf(stderr, "fake_wheelhil_run: unknown option %s\n", k.c_str());
      return 2;
    }
  }
  if (out.empty()) return 2;
  YAML::Node s;
  try {
    s = YAML::LoadFile(scenario);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "fake_wheelhil_run: %s\n", e.what());
    return 2;
  }
  const double friction = Get(s["terrain"]["friction"], 0.5);
  const double probability = s["faults"] && s["faults"].IsSequence() && s["faults"].size() > 0
                                 ? Get(s["faults"][0]["probability"], 0.0)
                                 : 0.0;
  const double bias = Get(s["sensors"]["gyro_bias_rad_s"], 0.0);
  const double sleep_s = Get(s["fake"]["sleep_s"], 0.0);
  const double limit_m = Get(s["fake"]["limit_m"], 0.1);
  if (s["fake"]["exit_without_report"] && s["fake"]["exit_without_report"].as<bool>()) {
    std::fprintf(stderr, "fake_wheelhil_run: simulated crash\n");
    return 3;
  }
  std::this_thread::sleep_for(std::chrono::duration<double>(sleep_s));

  const double noise = static_cast<double>(Mix(seed) >> 11) * 0x1.0p-53;  // [0, 1)
  const double error_m = 0.01 + 0.2 * probability / friction + 10 * std::fabs(bias) + 0.005 * noise;
  const double heading_rad = 0.002 + 0.5 * std::fabs(bias) + 0.001 * noise;
  const bool ok = error_m < limit_m;
  nlohmann::json report = {
      {"scenario", s["name"] ? s["name"].as<std::string>() : "fake"},
      {"seed", seed},
      {"verdict", ok ? "pass" : "fail"},
      {"expectations",
       {{{"metric", "pose.final_position_error_m"},
         {"op", "<"},
         {"value", limit_m},
         {"actual", error_m},
         {"passed", ok}}}},
      {"metrics",
       {{"pose", {{"final_position_error_m", error_m}, {"final_heading_error_rad", heading_rad}}},
        {"bus", {{"frames_lost", static_cast<int>(std::lround(probability * 1000))}}}}},
      {"wall_clock", {{"started_utc", "2026-01-01T00:00:00Z"}, {"duration_s", sleep_s}}}};
  std::filesystem::create_directories(out);
  const std::string tmp = out + "/report.json.tmp";
  std::ofstream(tmp) << report.dump(2) << "\n";
  std::filesystem::rename(tmp, out + "/report.json");
  // FAKE_WHEELHIL_RUN_LOG: one line per completed run (O_APPEND, so lines never interleave).
  if (const char* log = std::getenv("FAKE_WHEELHIL_RUN_LOG")) {
    const int fd = ::open(log, O_WRONLY | O_CREAT | O_APPEND, 0644);
    const std::string line = out + "\n";
    if (fd >= 0) {
      (void)!::write(fd, line.data(), line.size());
      ::close(fd);
    }
  }
  return ok ? 0 : 1;
}
