#!/usr/bin/env python3
"""A serial device server for rostests and benchmarks: ser2net (Debian package ser2net, 4.x).

Writes ser2net's YAML configuration for the ports given and replaces itself with ser2net in the
foreground, so the process roslaunch (or a benchmark) started is the server: killing it is a device
server switched off, and roslaunch's respawn is the server coming back. As in
test/unit/ser2net_server.h: loopback only, no UUCP lock files (-u), `local` (a pty has no modem
lines).

usage: ser2net_server.py --config FILE [--pid-file FILE] PORT...
  PORT: MODE:TCP_PORT:DEVICE[:LINE[:CLIENTS]]  MODE raw (raw TCP) or rfc2217 (Telnet COM Port
        Control); LINE the server's own line settings in ser2net's notation (default 9600n81);
        CLIENTS how many clients the port serves at once (default 1: a second one is told "Port
        already in use" and its connection closed)
"""
import argparse
import os
import sys


def connection(index, spec):
    parts = spec.split(":")
    if len(parts) not in (3, 4, 5) or parts[0] not in ("raw", "rfc2217"):
        raise ValueError("port %r: give MODE:TCP_PORT:DEVICE[:LINE[:CLIENTS]], MODE raw or rfc2217" % spec)
    mode, port, device = parts[:3]
    line = parts[3] if len(parts) >= 4 else "9600n81"
    max_connections = int(parts[4]) if len(parts) == 5 else 1
    accepter = "tcp" if mode == "raw" else "telnet(rfc2217),tcp"
    text = (
        "connection: &port%d\n"
        "  accepter: %s,127.0.0.1,%d\n"
        "  connector: serialdev,%s,%s,local\n" % (index, accepter, int(port), device, line)
    )
    if max_connections > 1:
        text += "  options:\n    max-connections: %d\n" % max_connections
    return text


def main(argv):
    # roslaunch appends __name:= and __log:= to a node's command line.
    argv = [a for a in argv if not a.startswith("__")]
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--config", required=True)
    parser.add_argument("--pid-file")
    parser.add_argument("ports", nargs="+")
    args = parser.parse_args(argv)
    try:
        body = "".join(connection(i, spec) for i, spec in enumerate(args.ports))
    except ValueError as error:
        print("ser2net_server.py: %s" % error, file=sys.stderr)
        return 2
    with open(args.config, "w") as out:
        out.write("%YAML 1.1\n---\n" + body)
    command = ["ser2net", "-n", "-u", "-c", args.config]
    if args.pid_file:
        command += ["-P", args.pid_file]
    sys.stdout.flush()
    os.execvp(command[0], command)


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
