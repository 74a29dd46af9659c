#pragma once
/// `wheelhil schema scenario|platform|campaign|outputs|firmware-config`: prints a JSON Schema
/// (draft 2020-12) of that kind of file, for editors' YAML language servers (docs/schemas.md).
///
/// The schema is made from the loaders themselves: the shipped files of that kind are loaded
/// with a bus::yaml::FieldRecorder on, and every mapping the loader checked becomes an object
/// with exactly the keys it allows (additionalProperties false), every value it read a number,
/// integer, boolean or string with the range it checked, every list an array. So a key the
/// loader accepts is in the schema, and the other way round. A section no shipped file has is
/// open (any value): the schema never refuses what the loader takes. Units come from the keys'
/// suffixes (_m, _s, _deg, ...), as wheelhil names them. Thread-compatible.

#include <CLI/CLI.hpp>

#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

namespace wheelhil::emulator {

/// The kinds `wheelhil schema` knows.
const std::vector<std::string>& SchemaKinds();

/// The schema of `kind` from loading `examples` (files of that kind). Throws
/// std::invalid_argument for an unknown kind or an example that does not load.
nlohmann::json FileSchema(const std::string& kind, const std::vector<std::string>& examples);

/// The shipped files of `kind` (the source tree next to the build directory, else the
/// installed data).
std::vector<std::string> ShippedExamples(const std::string& kind);

class SchemaCommand {
 public:
  explicit SchemaCommand(CLI::App& app);
  std::optional<int> Run();

 private:
  CLI::App* schema_ = nullptr;
  std::string kind_;
  std::string out_dir_;
};

}  // namespace wheelhil::emulator
