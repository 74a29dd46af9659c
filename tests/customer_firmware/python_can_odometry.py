#!/usr/bin/python3
"""A differential-drive odometry firmware written as a customer would write it in Python, with
Debian's python3-can and nothing of wheelhil: can.Bus(interface="socketcan"), recv(timeout)
paced by time.monotonic(). It is the CANopen master of two CiA 406 encoders (boot-up,
SDO 0x1800:02 = 1, NMT start, SYNC every period) and publishes its pose in its own frames:
  0x3C0 (8 bytes): x, y   int32 little endian, 0.1 mm
  0x3C1 (8 bytes): theta  int32 little endian, microradians; cycle uint32
Usage: python_can_odometry.py --can IFACE [--left ID] [--right ID] [--cpr N] [--radius M]
                              [--track M] [--period-ms N] [--notifier]
--notifier: frames come through a can.Notifier thread and a can.BufferedReader
(reader.get_message(timeout): a queue with a timeout, i.e. a timed semaphore wait in CPython)
instead of bus.recv(timeout).
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
    p.add_argument("--left", type=int, default=1)
    p.add_argument("--right", type=int, default=2)
    p.add_argument("--cpr", type=int, default=2000)
    p.add_argument("--radius", type=float, default=0.075)
    p.add_argument("--track", type=float, default=0.32)
    p.add_argument("--period-ms", type=int, default=10)
    p.add_argument("--notifier", action="store_true")
    a = p.parse_args()
    stop = []
    signal.signal(signal.SIGTERM, lambda *_: stop.append(1))

    bus = can.Bus(interface="socketcan", channel=a.can)
    ids = (a.left, a.right)
    booted, configured, have = [False, False], [False, False], [False, False]
    pos, last = [0, 0], None
    x = y = theta = 0.0
    cycle = 0
    period = a.period_ms / 1000.0
    t0 = time.monotonic()
    next_tick = t0 + period
    state = "boot"

    if a.notifier:
        reader = can.BufferedReader()
        notifier = can.Notifier(bus, [reader], timeout=0.5)

        def receive(timeout):
            return reader.get_message(timeout=timeout)
    else:
        notifier = None

        def receive(timeout):
            return bus.recv(timeout=timeout)

    def send(arb_id, data):
        bus.send(can.Message(arbitration_id=arb_id, data=bytes(data), is_extended_id=False))

    while not stop:
        msg = receive(max(0.0, next_tick - time.monotonic()))
        if msg is not None:
            for i, node in enumerate(ids):
                d = msg.data
                if msg.arbitration_id == 0x700 + node and len(d) == 1 and d[0] == 0:
                    booted[i] = True
                elif msg.arbitration_id == 0x580 + node and d[:3] == b"\x60\x00\x18":
                    configured[i] = True
                elif msg.arbitration_id == 0x180 + node and len(d) >= 4:
                    pos[i] = struct.unpack_from("<I", d)[0]
                    have[i] = True
            continue
        if time.monotonic() < next_tick:
            continue
        next_tick += period
        if state == "boot" and (all(booted) or time.monotonic() > t0 + 1.0):
            for node in ids:
                send(0x600 + node, [0x2F, 0x00, 0x18, 0x02, 1, 0, 0, 0])
            state = "sdo"
            continue
        if state == "sdo" and all(configured):
            send(0x000, [0x01, 0x00])
            state = "run"
            continue
        if state != "run":
            continue
        send(0x080, [])
        if all(have):
            if last is not None:
                k = 2.0 * math.pi * a.radius / a.cpr
                dl = ((pos[0] - last[0] + 2**31) % 2**32 - 2**31) * k
                dr = ((pos[1] - last[1] + 2**31) % 2**32 - 2**31) * k
                ds, dth = 0.5 * (dl + dr), (dr - dl) / a.track
                x += ds * math.cos(theta + 0.5 * dth)
                y += ds * math.sin(theta + 0.5 * dth)
                theta += dth
            last = list(pos)
        send(0x3C0, struct.pack("<ii", round(x * 1e4), round(y * 1e4)))
        send(0x3C1, struct.pack("<iI", round(theta * 1e6), cycle & 0xFFFFFFFF))
        cycle += 1
    if notifier is not None:
        notifier.stop()
    bus.shutdown()


if __name__ == "__main__":
    main()
