#pragma once
// Shared fixtures of the campaign tests: a temp folder with a base scenario the fake runner
// understands and helpers to write campaign files.

#include <gtest/gtest.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>

namespace wheelhil::emulator::campaign::testing {

inline constexpr const char* kBaseScenario = R"(name: fake_base
terrain:
  friction: 0.5
faults:
  - kind: frame_loss
    probability: 0.0
sensors:
  gyro_bias_rad_s: 0.0
fake:
  sleep_s: 0.0
  limit_m: 0.1
)";

class TempDir {
 public:
  TempDir() {
    std::string tmpl =
        (std::filesystem::temp_directory_path() / "wheelhil_campaign_XXXXXX").string();
    path_ = ::mkdtemp(tmpl.data());
  }
  ~TempDir() {
    std::error_code ec;
    std::filesystem::remove_all(path_, ec);
  }
  const std::filesystem::path& path() const { return path_; }
  std::filesystem::path Write(const std::string& name, const std::string& text) const {
    const auto p = path_ / name;
    std::filesystem::create_directories(p.parent_path());
    std::ofstream(p) << text;
    return p;
  }

 private:
  std::filesystem::path path_;
};

}  // namespace wheelhil::emulator::campaign::testing
