#pragma once
// Damaged copies of a YAML input file, and the check that a loader answers each with a located
// std::invalid_argument (bus/yaml_fields.h) or a result, never another exception: used by the
// tests of every loader (scenario, platform, campaign, firmware config).

#include <gtest/gtest.h>

#include <fstream>
#include <iterator>
#include <stdexcept>
#include <string>
#include <vector>

namespace wheelhil::yaml_mutation {

inline std::string ReadText(const std::string& path) {
  std::ifstream in(path);
  return std::string(std::istreambuf_iterator<char>(in), {});
}

/// Every copy of `text` with one line deleted, and every copy with one value (the text after a
/// "key: " up to the next ',' '}' ']' or the end of the line) replaced by a list, a mapping, a
/// null or a word.
inline std::vector<std::string> YamlMutations(const std::string& text) {
  std::vector<std::string> lines;
  std::size_t start = 0;
  while (start < text.size()) {
    const std::size_t end = text.find('\n', start);
    lines.push_back(text.substr(start, end == std::string::npos ? std::string::npos : end - start));
    if (end == std::string::npos) break;
    start = end + 1;
  }
  auto join = [&](std::size_t skip, const std::string* replacement) {
    std::string out;
    for (std::size_t i = 0; i < lines.size(); ++i) {
      if (i == skip && replacement == nullptr) continue;
      out += (i == skip ? *replacement : lines[i]) + "\n";
    }
    return out;
  };
  const std::vector<std::string> values = {"[1, 2]", "{a: 1}", "~", "word"};
  std::vector<std::string> out;
  for (std::size_t i = 0; i < lines.size(); ++i) {
    const std::string& line = lines[i];
    if (line.find_first_not_of(' ') == std::string::npos ||
        line[line.find_first_not_of(' ')] == '#') {
      continue;
    }
    out.push_back(join(i, nullptr));
    for (std::size_t at = line.find(": "); at != std::string::npos; at = line.find(": ", at + 2)) {
      const std::size_t from = at + 2;
      std::size_t to = line.find_first_of(",}]#", from);
      if (to == std::string::npos) to = line.size();
      if (to == from) continue;
      for (const auto& v : values) {
        const std::string changed = line.substr(0, from) + v + line.substr(to);
        out.push_back(join(i, &changed));
      }
    }
  }
  return out;
}

/// Runs `load` on each mutation of `text`: it must return, or throw std::invalid_argument whose
/// message starts with "<file>:<line>:<col>: ". Reports the first few offenders.
/// "<file>:<line>:<col>: <something>" (no std::regex: GCC 12 warns inside it under the
/// sanitizers).
inline bool Located(const std::string& what, const std::string& file) {
  if (what.rfind(file + ":", 0) != 0) return false;
  std::size_t i = file.size() + 1;
  for (int field = 0; field < 2; ++field) {
    const std::size_t start = i;
    while (i < what.size() && what[i] >= '0' && what[i] <= '9') ++i;
    if (i == start || i >= what.size() || what[i] != ':') return false;
    ++i;
  }
  return i + 1 < what.size() && what[i] == ' ';
}

template <typename Load>
void ExpectOnlyLocatedInputErrors(const std::string& text, const std::string& file, Load&& load) {
  int reported = 0;
  const std::vector<std::string> mutations = YamlMutations(text);
  for (const std::string& m : mutations) {
    if (reported >= 5) break;
    try {
      load(m);
    } catch (const std::invalid_argument& e) {
      if (!Located(e.what(), file)) {
        ADD_FAILURE() << "unlocated error: " << e.what() << "\n--- input:\n" << m;
        ++reported;
      }
    } catch (const std::exception& e) {
      ADD_FAILURE() << "not an input error: " << e.what() << "\n--- input:\n" << m;
      ++reported;
    } catch (...) {
      ADD_FAILURE() << "not an input error (not a std::exception)\n--- input:\n" << m;
      ++reported;
    }
  }
  EXPECT_GT(mutations.size(), 0u) << file;
}

}  // namespace wheelhil::yaml_mutation
