#!/usr/bin/env python3
"""python-can's socketcan interface on a bus (run under `wheelhil exec`): send, receive with
kernel-side filters, timestamps, channel. Prints OK and exits 0 on success."""
import sys

import can


def main():
    channel = sys.argv[1]
    rx = can.Bus(interface="socketcan", channel=channel,
                 can_filters=[{"can_id": 0x100, "can_mask": 0x700, "extended": False}])
    tx = can.Bus(interface="socketcan", channel=channel)
    try:
        tx.send(can.Message(arbitration_id=0x200, data=[1], is_extended_id=False))
        tx.send(can.Message(arbitration_id=0x123, data=[1, 2, 3], is_extended_id=False))
        tx.send(can.Message(arbitration_id=0x10000123, data=[9], is_extended_id=True))
        tx.send(can.Message(arbitration_id=0x1AA, data=[], is_extended_id=False))
        first = rx.recv(timeout=5)
        second = rx.recv(timeout=5)
        assert first is not None and second is not None, (first, second)
        assert first.arbitration_id == 0x123 and list(first.data) == [1, 2, 3], first
        assert not first.is_extended_id and not first.is_error_frame, first
        assert first.channel == channel, first.channel
        assert first.timestamp > 1.6e9, first.timestamp
        assert second.arbitration_id == 0x1AA and second.dlc == 0, second
        assert second.timestamp >= first.timestamp
    finally:
        rx.shutdown()
        tx.shutdown()
    print("OK")
    return 0


if __name__ == "__main__":
    sys.exit(main())
