#!/usr/bin/env python3
"""Where the time of one transfer goes: cnc_dnc send/receive --share and smbclient put/get, phase
by phase, from the SMB2 requests each client sends (seen with strace, which stops the client only
at its socket writes and reads and its exit). Phases, each ending where the next begins:

  start     process start and library set-up, until the first request (NEGOTIATE)
  login     connect and authenticate: NEGOTIATE .. the share's TREE_CONNECT
  probe     requests before the program is opened (libsmbclient asks for the share's file system
            attributes on every new connection; smbclient does not)
  data      the program's CREATE .. the answer to its CLOSE (its READs or WRITEs between)
  after     after the data, before TREE_DISCONNECT: for cnc_dnc's upload the atomic replace
            (old version moved aside, new one renamed in, old one deleted), for its download
            the local fsync and rename (no requests)
  close     TREE_DISCONNECT .. the process's end

Times are medians in milliseconds, with the requests of each phase; strace makes each request
and answer some tens of microseconds slower, alike for both tools.

  phases.py CNC_DNC URL CREDENTIALS FILE [ROUNDS]     (URL smb://127.0.0.1:PORT/SHARE)
"""
import os
import re
import statistics
import subprocess
import sys
import tempfile

COMMANDS = {0: "NEGOTIATE", 1: "SESSION_SETUP", 2: "LOGOFF", 3: "TREE_CONNECT", 4: "TREE_DISCONNECT", 5: "CREATE",
            6: "CLOSE", 8: "READ", 9: "WRITE", 0xb: "IOCTL", 0xd: "ECHO", 0xe: "QUERY_DIRECTORY", 0x10: "QUERY_INFO",
            0x11: "SET_INFO"}
PHASES = ("start", "login", "probe", "data", "after", "close")
# The first 16 bytes of an SMB2 header in a writev that strace -xx prints: the command is at byte 12.
HEADER = re.compile(r'"\\xfe\\x53\\x4d\\x42((?:\\x[0-9a-f]{2}){12})')


def traced(command, scratch):
    """[(time in ms since the exec, SMB2 command sent, 'answer' (a read from the socket) or 'exit')] of one
    run of command."""
    log = os.path.join(scratch, "strace.log")
    subprocess.run(["strace", "--seccomp-bpf", "-f", "-ttt", "-xx", "-e", "trace=execve,writev,recvfrom,exit_group", "-o", log]
                   + command, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, check=True)
    events, start = [], None
    with open(log) as f:
        for line in f:
            when = float(line.split(None, 2)[1]) * 1000
            start = when if start is None else start
            for match in HEADER.finditer(line) if "writev(" in line else ():
                header = bytes(int(byte, 16) for byte in match.group(1).split("\\x")[1:])
                events.append((when - start, COMMANDS.get(header[8] | header[9] << 8, "other")))
            if "recvfrom(" in line and "<unfinished" not in line:
                events.append((when - start, "answer"))
            if "exit_group" in line:
                events.append((when - start, "exit"))
    return events


def phases(events):
    """{phase: (ms, requests)} of one run."""
    times = [when for when, name in events if name != "answer"]
    names = [name for _, name in events if name != "answer"]
    # the data phase ends with the last answer read before the request after the program's CLOSE
    answers = [when for when, name in events if name == "answer"]
    data_io = [i for i, name in enumerate(names) if name in ("READ", "WRITE")]
    first_io = data_io[0] if data_io else names.index("CLOSE")
    data_start = max(i for i in range(first_io) if names[i] == "CREATE")
    share_tcon = max(i for i in range(data_start) if names[i] == "TREE_CONNECT")
    data_end = next(i for i in range(data_start, len(names)) if names[i] == "CLOSE")
    tdis = len(names) - 1 - names[::-1].index("TREE_DISCONNECT")
    data_done = max(when for when in answers if when <= times[data_end + 1])
    starts = {"login": times[0], "probe": times[share_tcon + 1], "data": times[data_start], "after": data_done,
              "close": times[tdis], "end": times[-1]}
    requests = {"login": share_tcon + 1, "probe": data_start - share_tcon - 1, "data": data_end + 1 - data_start,
                "after": tdis - data_end - 1, "close": len(names) - 1 - tdis}
    result = {"start": (times[0], 0)}
    order = list(starts)
    for phase, following in zip(order, order[1:]):
        result[phase] = (starts[following] - starts[phase], requests[phase])
    return result


def main():
    if len(sys.argv) not in (5, 6):
        sys.exit(__doc__)
    cnc_dnc, url, credentials, local = sys.argv[1:5]
    rounds = int(sys.argv[5]) if len(sys.argv) == 6 else 11
    host_port, share = url[len("smb://"):].split("/", 1)
    host, port = host_port.split(":")
    smbclient = ["smbclient", "//%s/%s" % (host, share), "-p", port, "-A", credentials, "-c"]
    size = os.path.getsize(local)
    with tempfile.TemporaryDirectory() as scratch:
        back = os.path.join(scratch, "back.nc")
        tools = {
            "up": {"cnc_dnc": [cnc_dnc, "send", "--share", url, "--credentials", credentials, "--name",
                               "phases_cnc_dnc.nc", local],
                   "smbclient": smbclient + ["put %s phases_smbclient.nc" % local]},
            "down": {"cnc_dnc": [cnc_dnc, "receive", "--share", url, "--credentials", credentials,
                                 "phases_smbclient.nc", back],
                     "smbclient": smbclient + ["get phases_cnc_dnc.nc %s" % back]}}
        for direction, commands in tools.items():
            runs = {tool: [] for tool in commands}
            for round_number in range(rounds):
                order = list(commands) if round_number % 2 == 0 else list(commands)[::-1]
                for tool in order:
                    if os.path.exists(back):
                        os.remove(back)
                    runs[tool].append(phases(traced(commands[tool], scratch)))
            print("%s, %d bytes, medians of %d: ms (requests)" % (direction, size, rounds))
            print("  %-6s %16s %16s" % ("phase", "cnc_dnc", "smbclient"))
            totals = {}
            for phase in PHASES:
                cells = []
                for tool in commands:
                    ms = statistics.median(run[phase][0] for run in runs[tool])
                    requests = statistics.median(run[phase][1] for run in runs[tool])
                    cells.append("%7.1f (%2d)" % (ms, requests))
                print("  %-6s %16s %16s" % (phase, cells[0], cells[1]))
            for tool in commands:
                totals[tool] = statistics.median(sum(ms for ms, _ in run.values()) for run in runs[tool])
            print("  %-6s %11.1f      %11.1f" % ("total", totals["cnc_dnc"], totals["smbclient"]))


if __name__ == "__main__":
    main()
