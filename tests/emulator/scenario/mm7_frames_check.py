#!/usr/bin/python3
"""Checks the Bosch MM7.10 frames of a run of scenarios/own_hardware/robot_mm7_imu.yaml with
Debian's python3-canmatrix, independently of wheelhil's DBC codec: every frame decodes through
the DBC to the ground truth's body rates and specific force (within the sensor noise and the
signal's resolution), the three frames of one sample carry one counter that steps by 1 mod 16,
each CRC is CRC-8 SAE J1850 over the payload with the CRC byte zero, and the temperature signal
reads the configured 31 degC. Prints a summary; exits 1 naming what failed.
Usage: mm7_frames_check.py RUN_DIR DBC"""
import bisect
import csv
import json
import math
import sys

import canmatrix.formats


def crc8_j1850(data):
    crc = 0xFF
    for b in data:
        crc ^= b
        for _ in range(8):
            crc = ((crc << 1) ^ 0x1D) & 0xFF if crc & 0x80 else (crc << 1) & 0xFF
    return crc ^ 0xFF


def main():
    run_dir, dbc_path = sys.argv[1], sys.argv[2]
    db = canmatrix.formats.loadp_flat(dbc_path)
    frames_by_id = {f.arbitration_id.id: f for f in db.frames}
    motion0 = None
    with open(run_dir + "/events.jsonl") as f:
        for line in f:
            e = json.loads(line)
            if e["event"] == "motion_start":
                motion0 = e["bus_time_s"]
    truth_t, truth_w, truth_v = [], [], []
    with open(run_dir + "/truth.csv") as f:
        for row in csv.DictReader(f):
            truth_t.append(float(row["t_s"]))
            truth_w.append(float(row["omega_rad_s"]))
            truth_v.append(float(row["vx_m_s"]))
    problems = []
    checked = {"rate": 0, "az": 0, "frames": 0}
    max_err = {"rate_deg_s": 0.0, "az_g": 0.0}
    counters = {}
    # The scenario's noise, 0.0002 rad/s/sqrt(Hz) and 0.002 m/s^2/sqrt(Hz) sampled at 100 Hz:
    # sigma = density * sqrt(rate) = 0.115 deg/s and 0.0020 g; 6 sigma plus a resolution step.
    rate_tol = 6 * math.degrees(0.0002 * math.sqrt(100)) + 0.005
    az_tol = 6 * 0.002 * math.sqrt(100) / 9.80665 + 0.000127465
    with open(run_dir + "/can.log") as f:
        for line in f:
            parts = line.split()
            t_bus = float(parts[0].strip("()"))
            can_id, data_hex = parts[2].split("#")
            fid = int(can_id, 16)
            if fid not in (0x174, 0x178, 0x17C):
                continue
            data = bytes.fromhex(data_hex)
            frame = frames_by_id[fid]
            values = {k: float(v.phys_value) for k, v in frame.decode(data).items()}
            checked["frames"] += 1
            if crc8_j1850(data[:7] + b"\x00") != data[7]:
                problems.append("%.6f %X: CRC %02X is not CRC-8 SAE J1850" % (t_bus, fid, data[7]))
            cnt = [v for k, v in values.items() if k.startswith("MSG_CNT")][0]
            # Due every 10 ms from the device's start; on the wire within a fraction of that.
            counters.setdefault(math.floor(t_bus * 100 + 1e-6), set()).add(int(cnt))
            if fid == 0x174 and abs(values["TEMP_RATE_Z"] - 31) > 0.5:
                problems.append("%.6f: TEMP_RATE_Z %g, not 31" % (t_bus, values["TEMP_RATE_Z"]))
            if motion0 is None or t_bus < motion0:
                continue
            t = t_bus - motion0
            i = bisect.bisect_left(truth_t, t)
            if i < 2 or i + 2 >= len(truth_t):
                continue
            # Steady: body rate and speed constant over +-20 ms (no transient to time-align).
            ws, vs = truth_w[i - 2:i + 3], truth_v[i - 2:i + 3]
            steady = max(ws) - min(ws) < 1e-3 and max(vs) - min(vs) < 1e-4
            if not steady:
                continue
            w = truth_w[i]
            if fid == 0x174:
                err = abs(values["YawRate"] - math.degrees(w))
                max_err["rate_deg_s"] = max(max_err["rate_deg_s"], err)
                checked["rate"] += 1
                if err > rate_tol:
                    problems.append("%.6f: YawRate %g deg/s, truth %g" % (t_bus, values["YawRate"],
                                                                           math.degrees(w)))
            if fid == 0x17C:
                err = abs(values["AZ"] - 1.0)
                max_err["az_g"] = max(max_err["az_g"], err)
                checked["az"] += 1
                if err > az_tol:
                    problems.append("%.6f: AZ %g g on a level floor" % (t_bus, values["AZ"]))
    groups = sorted(counters.items())
    for (t, c) in groups:
        if len(c) != 1:
            problems.append("sample %d: its frames carry counters %s" % (t, sorted(c)))
    seq = [min(c) for (_, c) in groups]
    for a, b in zip(seq, seq[1:]):
        if b != (a + 1) % 16:
            problems.append("counter steps %d -> %d" % (a, b))
            break
    if checked["rate"] < 100 or checked["az"] < 100:
        problems.append("too few steady samples checked: %s" % checked)
    print("mm7_frames_check: %d frames, %d samples; checked %s; max |error| %s (tolerance "
          "%.3f deg/s, %.4f g)" % (checked["frames"], len(groups), checked, max_err, rate_tol,
                                  az_tol))
    for p in problems[:20]:
        print("  " + p)
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
