#!/usr/bin/env python3
"""Writes a cell description with N machines, cycling through the four kinds of the demo cell
(Haas with XModem/DPRNT/MDC, ethernut mill, '@' router, slave-bus laser), each with its own
simulators and ports, for the scale benchmark: make_cell.py 10 > /tmp/cell10.yaml"""
import sys

import yaml


def haas(i, base):
    name = "haas_%d" % i
    return {
        "name": name, "position": [2.5 * i, 0.0, 0.0],
        "simulators": [
            {"name": "sim_rs232", "command": "sim_haas_serial xmodem --link /tmp/cnc_scale_%s_rs232 --dir /tmp" % name},
            {"name": "sim_dprnt", "command": "sim_haas_serial dprnt --tcp %d --program $(find cnc_bridge)/config/dprnt/grid_probe.nc --repeat 0 --rate 10" % (base + 1)},
            {"name": "sim_mdc", "command": "sim_haas_mdc --port %d --script $(find cnc_bridge)/config/demo/haas_vf2.mdcsim" % base},
        ],
        "nodes": [
            {"launch": "haas_mdc_node", "args": {"host": "127.0.0.1", "tcp_port": base}},
            {"launch": "dnc_node", "remap": {"state": "dnc/state"},
             "args": {"port": "/tmp/cnc_scale_%s_rs232" % name, "program_dir": "/tmp", "keep_open": True}},
            {"launch": "dprnt_node", "remap": {"state": "dprnt/state"},
             "args": {"input": "tcp", "host": "127.0.0.1", "tcp_port": base + 1}},
        ],
    }


def ethernut(i, base):
    return {
        "name": "ethernut_%d" % i, "position": [2.5 * i, 0.0, 0.0],
        "simulators": [{"name": "sim_ethernut", "command": "sim_ethernut --port %d" % base}],
        "nodes": [{"launch": "ethernut_node", "args": {"host": "127.0.0.1", "tcp_port": base, "program_dir": "/tmp"}}],
    }


def router(i, base):
    return {
        "name": "router_%d" % i, "position": [2.5 * i, 0.0, 0.0],
        "simulators": [{"name": "sim_at_controller",
                        "command": "sim_at_controller --command-port %d --report-mode server --report-port %d" % (base, base + 1)}],
        "nodes": [{"launch": "at_controller_node",
                   "args": {"host": "127.0.0.1", "tcp_port": base, "report_mode": "client", "report_port": base + 1}}],
    }


def laser(i, base):
    link = "/tmp/cnc_scale_laser_%d_bus" % i
    return {
        "name": "laser_%d" % i, "position": [2.5 * i, 0.0, 0.0],
        "simulators": [{"name": "sim_slave_bus", "command": "sim_slave_bus --link %s" % link}],
        "nodes": [{"launch": "slave_bus_node", "args": {"port": link}}],
    }


def main():
    count = int(sys.argv[1]) if len(sys.argv) > 1 else 10
    kinds = [haas, ethernut, router, laser]
    machines = [kinds[i % len(kinds)](i, 27000 + 10 * i) for i in range(count)]
    yaml.safe_dump({"cell": "cell", "simulate": True, "machines": machines}, sys.stdout, sort_keys=False)


if __name__ == "__main__":
    main()
