#!/usr/bin/env python3
"""Plain Python `socket` AF_CAN on a bus (run under `wheelhil exec`): bind, send, recv,
recvfrom address, CAN_RAW_FILTER. `--kernel NAME`: binding a kernel name must fail with the
kernel's own error (ENODEV or EAFNOSUPPORT). Prints OK and exits 0 on success."""
import errno
import socket
import struct
import sys

CAN_FRAME = struct.Struct("=IB3x8s")


def frame(can_id, data):
    return CAN_FRAME.pack(can_id, len(data), bytes(data).ljust(8, b"\0"))


def main():
    if sys.argv[1] == "--kernel":
        s = socket.socket(socket.AF_CAN, socket.SOCK_RAW, socket.CAN_RAW)
        try:
            s.bind((sys.argv[2],))
        except OSError as e:
            if e.errno in (errno.ENODEV, errno.EAFNOSUPPORT):
                print("OK kernel error", errno.errorcode[e.errno])
                return 0
            raise
        print("FAIL: bound", sys.argv[2])
        return 1

    bus = sys.argv[1]
    tx = socket.socket(socket.AF_CAN, socket.SOCK_RAW, socket.CAN_RAW)
    rx = socket.socket(socket.AF_CAN, socket.SOCK_RAW, socket.CAN_RAW)
    tx.bind((bus,))
    rx.bind((bus,))
    rx.settimeout(5)
    rx.setsockopt(socket.SOL_CAN_RAW, socket.CAN_RAW_FILTER, struct.pack("=II", 0x100, 0x700))
    for can_id in (0x200, 0x123, 0x7FF, 0x1AA):
        tx.send(frame(can_id, [0x42, can_id & 0xFF]))
    got = []
    for _ in range(2):
        data, addr = rx.recvfrom(16)
        can_id, dlc, payload = CAN_FRAME.unpack(data)
        assert dlc == 2 and payload[0] == 0x42, (hex(can_id), dlc, payload)
        assert addr[0] == bus, addr
        got.append(can_id)
    assert got == [0x123, 0x1AA], [hex(i) for i in got]
    # Sending a frame of the wrong size is EINVAL, as with the kernel.
    try:
        tx.send(b"\0" * 10)
        print("FAIL: short frame accepted")
        return 1
    except OSError as e:
        assert e.errno == errno.EINVAL, e
    tx.close()
    rx.close()
    print("OK")
    return 0


if __name__ == "__main__":
    sys.exit(main())
