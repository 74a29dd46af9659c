#!/usr/bin/env python3
"""Reads a candump -L log with python-can's CanutilsLogReader (an independent reader) and prints
one line per message for tests/bus/candump_log_test.cc:

    <timestamp_us> <channel> <id hex> <ext 0/1> <rtr 0/1> <fd 0/1> <brs 0/1> <esi 0/1> <err 0/1> <dlc> <data hex or ->

Usage: candump_python_can_read.py LOGFILE. Exit code 77 (reason on stderr) without python-can.
"""
import sys

try:
    import can
except ImportError as e:
    print(f"python-can not importable: {e}", file=sys.stderr)
    sys.exit(77)

for msg in can.CanutilsLogReader(sys.argv[1]):
    data = msg.data.hex().upper() if msg.data else "-"
    print(round(msg.timestamp * 1e6), msg.channel, f"{msg.arbitration_id:X}", int(msg.is_extended_id),
          int(msg.is_remote_frame), int(msg.is_fd), int(msg.bitrate_switch),
          int(msg.error_state_indicator), int(msg.is_error_frame), msg.dlc, data)
