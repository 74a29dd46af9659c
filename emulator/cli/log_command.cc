#include "emulator/cli/log_command.h"

#include <fmt/format.h>

#include <filesystem>
#include <stdexcept>

#include "bus/vector_logs.h"

namespace wheelhil::emulator {

LogCommand::LogCommand(CLI::App& app) {
  log_ = app.add_subcommand("log", "CAN logs: convert between candump, Vector ASC and BLF");
  log_->require_subcommand(1);
  convert_ = log_->add_subcommand(
      "convert", "Convert a CAN log (formats by name: .log candump -L, .asc, .blf)");
  convert_->add_option("in", in_, "The log to read")->required()->check(CLI::ExistingFile);
  convert_->add_option("out", out_, "The log to write (replaced if it exists)")->required();
}

std::optional<int> LogCommand::Run() {
  if (!log_->parsed() || !convert_->parsed()) return std::nullopt;
  const bus::CanLogFormat from = bus::CanLogFormatOf(in_);
  const bus::CanLogFormat to = bus::CanLogFormatOf(out_);
  std::error_code ec;
  if (std::filesystem::equivalent(in_, out_, ec)) {
    throw std::invalid_argument(fmt::format("{}: in and out are the same file", out_));
  }
  const auto records = bus::ReadCanLog(in_, from);
  bus::WriteCanLog(out_, to, records);
  fmt::print("{}: {} frames\n", out_, records.size());
  return 0;
}

}  // namespace wheelhil::emulator
