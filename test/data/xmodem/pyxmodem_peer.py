#!/usr/bin/python3
"""An independent XModem peer for the interop tests: the python3-xmodem package on a tty.

usage: pyxmodem_peer.py send|recv checksum|crc|1k DEVICE FILE
Exit status 0 when the package reports success.
"""
import os
import select
import sys
import tty

from xmodem import XMODEM, XMODEM1k


def main():
    direction, mode, device, path = sys.argv[1:5]
    fd = os.open(device, os.O_RDWR | os.O_NOCTTY)
    tty.setraw(fd)

    def getc(size, timeout=1):
        data = b""
        while len(data) < size:
            ready, _, _ = select.select([fd], [], [], timeout)
            if not ready:
                return None
            data += os.read(fd, size - len(data))
        return data

    def putc(data, timeout=1):
        os.write(fd, data)
        return len(data)

    if direction == "send":
        modem = (XMODEM1k if mode == "1k" else XMODEM)(getc, putc)
        with open(path, "rb") as stream:
            ok = modem.send(stream, retry=10, timeout=10, quiet=True)
        return 0 if ok else 1
    modem = XMODEM(getc, putc)
    with open(path, "wb") as stream:
        received = modem.recv(stream, crc_mode=0 if mode == "checksum" else 1, retry=10, timeout=10, quiet=True)
    return 0 if received is not None else 1


if __name__ == "__main__":
    sys.exit(main())
