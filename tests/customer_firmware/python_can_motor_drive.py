#!/usr/bin/python3
"""A customer's firmware for a robot whose drives are not CANopen, written with Debian's
python3-can and nothing of wheelhil: it commands a two-channel motor controller described by
its DBC (scenarios/own_hardware/dual_motor_controller.dbc) and closes the loop on the wheel
positions the controller reports. It produces SYNC every period (the bus's cycle), sends
  0x310 MC_Command (5 bytes): left, right speed int16 LE in 0.1 rpm at the wheel, enable bit
drives DISTANCE metres straight on a trapezoid (SPEED, ACCEL) measured on the mean wheel travel,
then holds zero, and publishes its dead-reckoned pose in its own frames:
  0x3D0 (8 bytes): x, y   int32 little endian, 0.1 mm
  0x3D1 (8 bytes): theta  int32 little endian, microradians; cycle uint32
Usage: python_can_motor_drive.py --can IFACE [--distance M] [--speed M/S] [--accel M/S2]
                                 [--radius M] [--track M] [--cpr N] [--period-ms N]
"""
import argparse
import math
import signal
import struct
import time

import can


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--can", required=True)
    p.add_argument("--distance", type=float, default=1.0)
    p.add_argument("--speed", type=float, default=0.25)
    p.add_argument("--accel", type=float, default=0.5)
    p.add_argument("--radius", type=float, default=0.075)
    p.add_argument("--track", type=float, default=0.32)
    p.add_argument("--cpr", type=int, default=4096)
    p.add_argument("--period-ms", type=int, default=10)
    a = p.parse_args()
    stop = []
    signal.signal(signal.SIGTERM, lambda *_: stop.append(1))

    bus = can.Bus(interface="socketcan", channel=a.can)
    period = a.period_ms / 1000.0
    pos = None          # wheel positions [counts] from MC_Position
    start = None
    last = None
    x = y = theta = 0.0
    v = 0.0
    cycle = 0
    next_tick = time.monotonic() + period

    def send(arb_id, data):
        bus.send(can.Message(arbitration_id=arb_id, data=bytes(data), is_extended_id=False))

    while not stop:
        msg = bus.recv(timeout=max(0.0, next_tick - time.monotonic()))
        if msg is not None:
            if msg.arbitration_id == 0x312 and len(msg.data) == 8:
                pos = struct.unpack("<ii", msg.data)
            continue
        if time.monotonic() < next_tick:
            continue
        next_tick += period
        send(0x080, [])
        if pos is None:
            continue
        if start is None:
            start = last = pos
        k = 2.0 * math.pi * a.radius / a.cpr
        dl, dr = (pos[0] - last[0]) * k, (pos[1] - last[1]) * k
        ds, dth = 0.5 * (dl + dr), (dr - dl) / a.track
        x += ds * math.cos(theta + 0.5 * dth)
        y += ds * math.sin(theta + 0.5 * dth)
        theta += dth
        last = pos
        travelled = 0.5 * ((pos[0] - start[0]) + (pos[1] - start[1])) * k
        remaining = a.distance - travelled
        if remaining > 0.002:
            v = min(a.speed, math.sqrt(2.0 * a.accel * remaining), v + a.accel * period)
            v = max(v, 0.01)
        else:
            v = 0.0
        rpm10 = round(v / a.radius * 60.0 / (2.0 * math.pi) * 10.0)
        send(0x310, struct.pack("<hhB", rpm10, rpm10, 1))
        send(0x3D0, struct.pack("<ii", round(x * 1e4), round(y * 1e4)))
        send(0x3D1, struct.pack("<iI", round(theta * 1e6), cycle & 0xFFFFFFFF))
        cycle += 1
    bus.shutdown()


if __name__ == "__main__":
    main()
