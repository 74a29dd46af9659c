#!/usr/bin/env python3
"""Independent DBC check for tests/bus/dbc_test.cc: decodes payloads with canmatrix (Debian's
python3-canmatrix), a DBC parser and codec that shares no code with wheelhil.

stdin: one request a line, `<dbc path> <frame id hex> <payload hex>`.
stdout: for each request, one line `<signal>=<physical value>` per signal, then a line `--`.
Exit code 77 (with the reason on stderr) when canmatrix is not installed.
"""
import sys

try:
    import canmatrix
    import canmatrix.formats
except ImportError as e:  # the test skips with this reason
    print(f"canmatrix not importable: {e}", file=sys.stderr)
    sys.exit(77)

cache = {}
for line in sys.stdin:
    parts = line.split()
    if not parts:
        continue
    path, frame_id, payload = parts[0], int(parts[1], 16), parts[2] if len(parts) > 2 else ""
    if path not in cache:
        cache[path] = canmatrix.formats.loadp(path)[""]
    frame = cache[path].frame_by_id(canmatrix.ArbitrationId(frame_id))
    if frame is None:
        print(f"no frame 0x{frame_id:X} in {path}", file=sys.stderr)
        sys.exit(1)
    for name, value in frame.decode(bytearray.fromhex(payload)).items():
        print(f"{name}={float(value.phys_value)!r}")
    print("--")
