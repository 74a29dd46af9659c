#!/usr/bin/env python3
"""Reads an ASC or BLF log with python-can's ASCReader / BLFReader (an independent reader) and
prints one line per message for tests/bus/vector_logs_test.cc:

    <timestamp_us> <channel> <id hex> <ext 0/1> <rtr 0/1> <fd 0/1> <brs 0/1> <esi 0/1> <err 0/1> <tx 0/1> <dlc> <data hex or ->

ASC timestamps are relative to the file's start (the reader's default), BLF ones absolute (run
it with TZ=UTC: python-can reads BLF's start as local time). Usage: vector_python_can_read.py
asc|blf LOGFILE. Exit code 77 (reason on stderr) without python-can.
"""
import sys

try:
    import can
except ImportError as e:
    print(f"python-can not importable: {e}", file=sys.stderr)
    sys.exit(77)

reader = can.ASCReader(sys.argv[2]) if sys.argv[1] == "asc" else can.BLFReader(sys.argv[2])
for msg in reader:
    data = msg.data.hex().upper() if msg.data else "-"
    print(round(msg.timestamp * 1e6), msg.channel, f"{msg.arbitration_id:X}", int(msg.is_extended_id),
          int(msg.is_remote_frame), int(msg.is_fd), int(msg.bitrate_switch),
          int(msg.error_state_indicator), int(msg.is_error_frame), int(not msg.is_rx), msg.dlc, data)
