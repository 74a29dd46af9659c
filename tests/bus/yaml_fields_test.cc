// The located YAML field reader (bus/yaml_fields.h): positions, field names, value checks, and
// that no yaml-cpp exception gets out of a guarded read.

#include "bus/yaml_fields.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <stdexcept>
#include <string>

#include <fmt/format.h>

namespace wheelhil::bus::yaml {
namespace {

using ::testing::AllOf;
using ::testing::HasSubstr;
using ::testing::StartsWith;
using ::testing::ThrowsMessage;

// Runs `fn`, which must throw std::invalid_argument; returns its message.
template <typename Fn>
std::string MessageOf(Fn&& fn) {
  try {
    fn();
  } catch (const std::invalid_argument& e) {
    return e.what();
  }
  ADD_FAILURE() << "no std::invalid_argument";
  return "";
}

const char* kDoc =
    "name: robot\n"        // 1
    "rate_hz: 100\n"       // 2
    "bad: abc\n"           // 3
    "imu:\n"               // 4
    "  id: 0x174\n"        // 5
    "  enabled: yes\n"     // 6
    "  axis: [0, 0, 1]\n"  // 7
    "empty: ~\n"           // 8
    "inf: .inf\n";         // 9

class FieldReaderTest : public ::testing::Test {
 protected:
  FieldReader r{"robot.yaml"};
  YAML::Node root = r.Parse(kDoc);
};

TEST_F(FieldReaderTest, WhereIsOneBasedLineAndColumn) {
  EXPECT_EQ(r.Where(root["rate_hz"]), "robot.yaml:2:10");
  EXPECT_EQ(r.Where(root["imu"]["id"]), "robot.yaml:5:7");
  EXPECT_EQ(r.Where(YAML::Node()), "robot.yaml:0:0");
  EXPECT_EQ(r.Where(FieldReader::Get(root, "nothere")), "robot.yaml:0:0");
  EXPECT_EQ(r.Where(YAML::Mark::null_mark()), "robot.yaml:0:0");
}

TEST_F(FieldReaderTest, FailFormatsFileLineColumnFieldProblem) {
  EXPECT_EQ(MessageOf([&] { r.Fail(root["imu"]["id"], "imu.id", "taken"); }),
            "robot.yaml:5:7: imu.id: taken");
  EXPECT_EQ(MessageOf([&] { r.FailKey(root["imu"], "id", "imu.id", "taken"); }),
            "robot.yaml:5:7: imu.id: taken");
  // A missing key has no position: the message points at its parent.
  EXPECT_EQ(MessageOf([&] { r.FailKey(root["imu"], "rate", "imu.rate", "needed"); }),
            "robot.yaml:5:3: imu.rate: needed");
}

TEST_F(FieldReaderTest, JoinBuildsDottedPaths) {
  EXPECT_EQ(FieldReader::Join("", "a"), "a");
  EXPECT_EQ(FieldReader::Join("a.b[2]", "c"), "a.b[2].c");
}

TEST_F(FieldReaderTest, GetNeverReturnsANodeThatThrows) {
  const YAML::Node missing = FieldReader::Get(root, "nothere");
  EXPECT_FALSE(missing.IsDefined());
  EXPECT_FALSE(missing.IsSequence());  // yaml-cpp's own zombie node would throw InvalidNode here
  EXPECT_EQ(missing.size(), 0u);
  EXPECT_FALSE(FieldReader::Get(root["name"], "x").IsDefined());  // parent not a mapping
  EXPECT_FALSE(FieldReader::Get(missing, "x").IsDefined());
  EXPECT_EQ(FieldReader::Get(root, "name").Scalar(), "robot");
}

TEST_F(FieldReaderTest, PresentMeansDefinedAndNotNull) {
  EXPECT_TRUE(FieldReader::Present(root["name"]));
  EXPECT_FALSE(FieldReader::Present(root["empty"]));
  EXPECT_FALSE(FieldReader::Present(FieldReader::Get(root, "nothere")));
}

TEST_F(FieldReaderTest, CheckKeysNamesTheUnknownKeyAndTheAllowedOnes) {
  EXPECT_NO_THROW(r.CheckKeys(root["imu"], "imu", {"id", "enabled", "axis"}));
  EXPECT_EQ(MessageOf([&] {
              r.CheckKeys(root["imu"], "imu", {"id", "axis"});
            }),
            "robot.yaml:6:3: imu.enabled: unknown key (allowed: axis, id)");
  EXPECT_EQ(MessageOf([&] { r.CheckKeys(root["name"], "name", {}); }),
            "robot.yaml:1:7: name: must be a mapping");
  EXPECT_EQ(MessageOf([&] { r.CheckKeys(root, "", {"name"}); }),
            "robot.yaml:2:1: rate_hz: unknown key (allowed: name)");
  EXPECT_THAT(MessageOf([&] { r.CheckKeys(r.Parse("[a]: 1\n"), "", {"a"}); }),
              HasSubstr("(document): a key must be a plain name"));
}

TEST_F(FieldReaderTest, NumbersAreFiniteAndInRange) {
  EXPECT_DOUBLE_EQ(r.ToNumber(root["rate_hz"], "rate_hz"), 100.0);
  EXPECT_DOUBLE_EQ(r.ToNumber(root["rate_hz"], "rate_hz", 1, 1000), 100.0);
  EXPECT_EQ(MessageOf([&] { r.ToNumber(root["rate_hz"], "rate_hz", 1, 50); }),
            "robot.yaml:2:10: rate_hz: (100) must be in [1, 50]");
  EXPECT_EQ(MessageOf([&] { r.ToNumber(root["bad"], "bad"); }),
            "robot.yaml:3:6: bad: 'abc' is not a number");
  EXPECT_EQ(MessageOf([&] { r.ToNumber(root["imu"], "imu"); }),
            "robot.yaml:5:3: imu: must be a number");
  EXPECT_EQ(MessageOf([&] { r.ToNumber(root["inf"], "inf"); }),
            "robot.yaml:9:6: inf: must be finite");
}

TEST_F(FieldReaderTest, IntegersReadHexadecimal) {
  EXPECT_EQ(r.ToInteger(root["imu"]["id"], "imu.id", 1, 0x7FF), 0x174);
  EXPECT_EQ(MessageOf([&] { r.ToInteger(root["imu"]["id"], "imu.id", 1, 0xFF); }),
            "robot.yaml:5:7: imu.id: (372) must be in [1, 255]");
  EXPECT_EQ(MessageOf([&] { r.ToInteger(r.Parse("x: 1.5")["x"], "x", 0, 9); }),
            "robot.yaml:1:4: x: '1.5' is not an integer");
}

TEST_F(FieldReaderTest, BoolsAndStrings) {
  EXPECT_TRUE(r.ToBool(root["imu"]["enabled"], "imu.enabled"));
  EXPECT_EQ(MessageOf([&] { r.ToBool(root["name"], "name"); }),
            "robot.yaml:1:7: name: must be true or false");
  EXPECT_EQ(r.ToString(root["name"], "name"), "robot");
  EXPECT_EQ(MessageOf([&] { r.ToString(root["imu"]["axis"], "imu.axis"); }),
            "robot.yaml:7:9: imu.axis: must be a string");
}

TEST_F(FieldReaderTest, KeyedReadsTakeDefaultsOrNameTheMissingField) {
  const YAML::Node imu = root["imu"];
  EXPECT_DOUBLE_EQ(r.Number(root, "rate_hz", "", 0, 1e3), 100.0);
  EXPECT_DOUBLE_EQ(r.Number(imu, "gain", "imu", 0, 1, 0.5), 0.5);
  EXPECT_DOUBLE_EQ(r.Number(root, "empty", "", 0, 1, 0.25), 0.25);  // null: absent
  EXPECT_EQ(MessageOf([&] { r.Number(imu, "gain", "imu", 0, 1); }),
            "robot.yaml:5:3: imu.gain: is required");
  EXPECT_EQ(r.Integer(imu, "id", "imu", 0, 0x7FF), 0x174);
  EXPECT_EQ(r.Integer(imu, "count", "imu", 0, 9, 3), 3);
  EXPECT_TRUE(r.Bool(imu, "enabled", "imu"));
  EXPECT_FALSE(r.Bool(imu, "other", "imu", false));
  EXPECT_EQ(r.String(root, "name", ""), "robot");
  EXPECT_EQ(r.String(root, "nick", "", "none"), "none");
  EXPECT_EQ(MessageOf([&] { r.String(root, "nick", ""); }), "robot.yaml:1:1: nick: is required");
  // A keyed read of a parent that is not a mapping: the key is missing.
  EXPECT_EQ(MessageOf([&] { r.Number(root["name"], "x", "name", 0, 1); }),
            "robot.yaml:1:7: name.x: is required");
}

TEST(FieldReader, ParseReportsSyntaxErrorsWithTheirPosition) {
  const FieldReader r("bad.yaml");
  EXPECT_THAT(MessageOf([&] { r.Parse("a: [1, 2\nb: 3\n"); }),
              AllOf(StartsWith("bad.yaml:"), HasSubstr(": (document): YAML syntax error: ")));
  EXPECT_TRUE(r.Parse("").IsNull());
}

TEST(FieldReader, ParseRefusesTextThatIsNotUtf8AtItsPosition) {
  const FieldReader r("bad.yaml");
  // 0x8F alone (the campaign fuzzer's find: it reached a JSON fingerprint and threw there).
  EXPECT_THAT(MessageOf([&] { r.Parse("name: ok\npath: ab\x8F\n"); }),
              HasSubstr("bad.yaml:2:9: (document): not UTF-8 text (byte 0x8F at offset 17)"));
  for (const char* bad : {"\xC0\xAF", "\xED\xA0\x80", "\xF4\x90\x80\x80", "\xE2\x82", "\xFF"}) {
    EXPECT_THAT(MessageOf([&] { r.Parse(std::string("a: ") + bad); }), HasSubstr("not UTF-8"))
        << bad;
  }
  // Valid UTF-8 but not YAML: a NUL in a scalar (the campaign fuzzer's second find: yaml-cpp
  // turned it into a byte that is not UTF-8), other C0/C1 controls, DEL.
  EXPECT_THAT(MessageOf([&] { r.Parse(std::string("a: x\0y\n", 7)); }),
              HasSubstr("bad.yaml:1:5: (document): not YAML text: control character U+0000"));
  for (const char* bad : {"\x01", "\x7F", "\xC2\x9B"}) {
    EXPECT_THAT(MessageOf([&] { r.Parse(std::string("a: ") + bad); }),
                HasSubstr("control character"))
        << bad;
  }
  EXPECT_EQ(r.Parse("a:\tb\r\n")["a"].as<std::string>(), "b");
  // Valid: 2-, 3- and 4-byte forms.
  EXPECT_EQ(r.Parse("a: \xC3\xA9 \xE2\x82\xAC \xF0\x9F\x98\x80")["a"].as<std::string>(),
            "\xC3\xA9 \xE2\x82\xAC \xF0\x9F\x98\x80");
}

TEST(FieldReader, ReadFileNamesAFileThatCannotBeRead) {
  EXPECT_THAT([] { FieldReader("/nonexistent/x.yaml").ReadFile(); },
              ThrowsMessage<std::invalid_argument>(
                  HasSubstr("/nonexistent/x.yaml:0:0: (file): cannot be read")));
}

TEST(FieldReader, ReadFileRefusesWhatIsNotASmallRegularFile) {
  EXPECT_EQ(MessageOf([] { FieldReader("/dev/zero").ReadFile(); }),
            "/dev/zero:0:0: (file): is not a regular file (a device or a pipe?)");
  EXPECT_EQ(MessageOf([] { FieldReader("/tmp").ReadFile(); }),
            "/tmp:0:0: (file): is a directory, not a YAML file");
  const std::string big = ::testing::TempDir() + "/yaml_fields_big.yaml";
  {
    std::ofstream out(big, std::ios::binary);
    const std::string line(1023, '#');
    for (std::size_t i = 0; i <= FieldReader::kMaxFileBytes / 1024; ++i) out << line << '\n';
  }
  EXPECT_EQ(MessageOf([&] { FieldReader(big).ReadFile(); }),
            big + ":0:0: (file): is larger than 16 MiB; a wheelhil input file is a few KiB");
  std::filesystem::remove(big);
}

TEST(FieldReader, ParseRefusesDuplicateKeysAtTheRepetition) {
  const FieldReader r("d.yaml");
  EXPECT_EQ(MessageOf([&] { r.Parse("a: 1\nb: 2\na: 3\n"); }),
            "d.yaml:3:1: a: duplicate key (first at line 1)");
  EXPECT_EQ(MessageOf([&] { r.Parse("s:\n  - {x: 1, y: 2}\n  - {x: 1, x: 2}\n"); }),
            "d.yaml:3:12: s[1].x: duplicate key (first at line 3)");
  // The same key in different mappings is not a repetition.
  EXPECT_NO_THROW(r.Parse("a: {x: 1}\nb: {x: 1}\n"));
}

TEST(FieldReader, ParseBoundsNestingAndAliasExpansion) {
  const FieldReader r("n.yaml");
  std::string deep = "x: " + std::string(FieldReader::kMaxDepth + 1, '[') +
                     std::string(FieldReader::kMaxDepth + 1, ']') + "\n";
  EXPECT_THAT(MessageOf([&] { r.Parse(deep); }), HasSubstr("]: nested too deeply"));
  deep = "x: " + std::string(FieldReader::kMaxDepth - 1, '[') +
         std::string(FieldReader::kMaxDepth - 1, ']') + "\n";
  EXPECT_NO_THROW(r.Parse(deep));
  // Ten lists of ten aliases of the one before: 10^7 nodes from 9 lines.
  std::string bomb = "a0: &a0 [x, x, x, x, x, x, x, x, x, x]\n";
  for (int i = 1; i < 7; ++i) {
    bomb += fmt::format("a{0}: &a{0} [", i);
    for (int k = 0; k < 10; ++k) bomb += fmt::format("{}*a{}", k ? ", " : "", i - 1);
    bomb += "]\n";
  }
  EXPECT_THAT(MessageOf([&] { r.Parse(bomb); }),
              HasSubstr("the document expands to more than 1000000 nodes (aliases?)"));
}

TEST(FieldReader, CheckCountNamesTheCountAndTheLimit) {
  const FieldReader r("c.yaml");
  const YAML::Node root = r.Parse("l: [1, 2, 3]\n");
  EXPECT_NO_THROW(r.CheckCount(root["l"], "l", 3));
  EXPECT_EQ(MessageOf([&] { r.CheckCount(root["l"], "l", 2); }),
            "c.yaml:1:4: l: 3 entries; at most 2 are supported");
}

TEST(FieldReader, GuardTurnsYamlCppExceptionsIntoLocatedInputErrors) {
  const FieldReader r("g.yaml");
  const YAML::Node root = r.Parse("a: 1\nsection:\n  list: [1, x]\n");
  // InvalidNode has no position: reported at the section CheckKeys saw last.
  EXPECT_EQ(MessageOf([&] {
              r.Guard([&] {
                r.CheckKeys(root["section"], "section", {"list"});
                const YAML::Node missing = root["section"]["track"];  // yaml-cpp zombie node
                return missing.IsSequence();
              });
            }),
            "g.yaml:3:3: section: invalid node; first invalid key: \"track\"");
  // BadConversion carries the node's own position.
  EXPECT_EQ(MessageOf([&] { r.Guard([&] { return root["section"]["list"][1].as<double>(); }); }),
            "g.yaml:3:13: section: bad conversion");
  // Before any CheckKeys the whole document is the context.
  const FieldReader fresh("f.yaml");
  EXPECT_EQ(MessageOf([&] { fresh.Guard([&] { return root["zz"].Mark(); }); }),
            "f.yaml:0:0: (document): invalid node; first invalid key: \"zz\"");
  // Results and std::invalid_argument pass through unchanged.
  EXPECT_EQ(r.Guard([] { return 42; }), 42);
  EXPECT_THAT([&] { r.Guard([&] { r.Fail(root["a"], "a", "no"); }); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("g.yaml:1:4: a: no")));
}

}  // namespace
}  // namespace wheelhil::bus::yaml
