#include "emulator/cli/completion_command.h"

#include <fmt/format.h>

#include <string_view>
#include <vector>

namespace wheelhil::emulator {

namespace {

// One node of the command tree as the script sees it.
struct CommandWords {
  std::string path;                  // "" for the program, else "bus up"
  std::vector<std::string> subcommands;
  std::vector<std::string> options;  // every spelling: --out, -h
  std::vector<std::pair<std::string, std::string>> value_lists;  // option -> "a b c"
  std::vector<std::string> valued;   // options that take a value (a file, unless a list)
  bool positionals = false;          // takes operands (files)
};

// "TEXT:{auto,on,off}" (CLI::IsMember's description in the type name) -> "auto on off"; empty
// when the option has no fixed set of values.
std::string ValueList(const CLI::Option& opt) {
  const std::string type = opt.get_type_name();
  const auto open = type.find('{');
  const auto close = type.find('}', open);
  if (open == std::string::npos || close == std::string::npos) return {};
  std::string words = type.substr(open + 1, close - open - 1);
  for (char& c : words) {
    if (c == ',') c = ' ';
  }
  return words;
}

// Named subcommands (CLI11 keeps option groups as unnamed ones).
std::vector<const CLI::App*> Subcommands(const CLI::App& app) {
  return app.get_subcommands([](const CLI::App* sub) { return !sub->get_name().empty(); });
}

void Collect(const CLI::App& app, const std::string& path, std::vector<CommandWords>& out) {
  CommandWords w;
  w.path = path;
  for (const CLI::App* sub : Subcommands(app)) w.subcommands.push_back(sub->get_name());
  for (const CLI::Option* opt : app.get_options()) {
    if (!opt->nonpositional()) {
      w.positionals = true;
      continue;
    }
    std::vector<std::string> names;
    for (const auto& l : opt->get_lnames()) names.push_back("--" + l);
    for (const auto& s : opt->get_snames()) names.push_back("-" + s);
    const bool takes_value = opt->get_type_size_max() > 0;
    const std::string values = ValueList(*opt);
    for (const auto& n : names) {
      w.options.push_back(n);
      if (!takes_value) continue;
      w.valued.push_back(n);
      if (!values.empty()) w.value_lists.emplace_back(n, values);
    }
  }
  if (app.get_allow_extras()) w.positionals = true;
  out.push_back(w);
  for (const CLI::App* sub : Subcommands(app)) {
    Collect(*sub, path.empty() ? sub->get_name() : path + " " + sub->get_name(), out);
  }
}

std::string Join(const std::vector<std::string>& words) {
  std::string s;
  for (const auto& w : words) s += (s.empty() ? "" : " ") + w;
  return s;
}

}  // namespace

std::string BashCompletionScript(const CLI::App& app, const std::string& program) {
  std::vector<CommandWords> tree;
  Collect(app, "", tree);
  std::string fn = "_" + program;
  for (char& c : fn) {
    if (c == '-') c = '_';
  }
  std::string s = fmt::format(
      "# bash completion for {0}, generated from its command-line definition by\n"
      "# `{0} completion bash`. Install: <prefix>/share/bash-completion/completions/{0}, or\n"
      "# source it from ~/.bashrc.\n"
      "{1}() {{\n"
      "  local cur=\"${{COMP_WORDS[COMP_CWORD]}}\" prev=\"${{COMP_WORDS[COMP_CWORD-1]}}\"\n"
      "  local cmd=\"\" w i\n"
      "  for ((i = 1; i < COMP_CWORD; ++i)); do\n"
      "    w=\"${{COMP_WORDS[i]}}\"\n"
      "    if [ \"$cmd\" = exec ] && [ \"$w\" = -- ]; then\n"
      "      # the program exec runs, then its own arguments\n"
      "      if [ $((i + 1)) -eq \"$COMP_CWORD\" ]; then\n"
      "        COMPREPLY=($(compgen -c -- \"$cur\"))\n"
      "      else\n"
      "        COMPREPLY=($(compgen -f -- \"$cur\"))\n"
      "      fi\n"
      "      return 0\n"
      "    fi\n"
      "    case \"$cmd:$w\" in\n",
      program, fn);
  for (const auto& node : tree) {
    for (const auto& sub : node.subcommands) {
      const std::string next = node.path.empty() ? sub : node.path + " " + sub;
      s += fmt::format("      \"{}:{}\") cmd=\"{}\" ;;\n", node.path, sub, next);
    }
  }
  s +=
      "    esac\n"
      "  done\n"
      "  local subs=\"\" opts=\"\" valued=\"\" files=0\n"
      "  case \"$cmd\" in\n";
  for (const auto& node : tree) {
    s += fmt::format("    \"{}\") subs=\"{}\"; opts=\"{}\"; valued=\"{}\"; files={} ;;\n", node.path,
                     Join(node.subcommands), Join(node.options), Join(node.valued),
                     node.positionals ? 1 : 0);
  }
  s +=
      "  esac\n"
      "  case \"$cmd:$prev\" in\n";
  for (const auto& node : tree) {
    for (const auto& [opt, values] : node.value_lists) {
      s += fmt::format("    \"{}:{}\") COMPREPLY=($(compgen -W \"{}\" -- \"$cur\")); return 0 ;;\n",
                       node.path, opt, values);
    }
  }
  s +=
      "  esac\n"
      "  if [[ \" $valued \" == *\" $prev \"* ]]; then\n"
      "    COMPREPLY=($(compgen -f -- \"$cur\"))\n"
      "    return 0\n"
      "  fi\n"
      "  if [[ \"$cur\" == -* ]]; then\n"
      "    COMPREPLY=($(compgen -W \"$opts\" -- \"$cur\"))\n"
      "    return 0\n"
      "  fi\n"
      "  COMPREPLY=($(compgen -W \"$subs\" -- \"$cur\"))\n"
      "  if [ \"$files\" = 1 ]; then COMPREPLY+=($(compgen -f -- \"$cur\")); fi\n"
      "  return 0\n"
      "}\n";
  s += fmt::format("complete -o filenames -F {} {}\n", fn, program);
  return s;
}

CompletionCommand::CompletionCommand(CLI::App& root) : root_(root) {
  completion_ = root.add_subcommand(
      "completion", "Print a shell completion script: wheelhil completion bash");
  completion_->add_option("shell", shell_, "The shell (bash)")
      ->check(CLI::IsMember({"bash"}));
}

std::optional<int> CompletionCommand::Run() {
  if (!completion_->parsed()) return std::nullopt;
  fmt::print("{}", BashCompletionScript(root_, "wheelhil"));
  return 0;
}

}  // namespace wheelhil::emulator
