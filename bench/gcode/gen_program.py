#!/usr/bin/env python3
"""Writes a deterministic CAM-like G-code program of N lines (default 1,000,000) for the parse
benchmark: N numbers, G00/G01 with X/Y/Z/F, G02/G03 arcs (I/J, small sweeps), comments, tool and
spindle blocks, in millimetres."""
import random
import sys

def main():
    path = sys.argv[1]
    lines = int(sys.argv[2]) if len(sys.argv) > 2 else 1000000
    rng = random.Random(6)
    x = y = 0.0
    z = 5.0
    with open(path, "w") as out:
        out.write("%\nO1000 (BENCH)\nG21 G90 G17\nT1 M06\nS12000 M03\n")
        n = 5
        while n < lines - 2:
            n += 1
            k = n % 50
            if k == 0:
                out.write("(pass %d)\n" % n)
            elif k == 1:
                z = round(rng.uniform(-3.0, 2.0), 3)
                out.write("N%d G00 Z%.3f\n" % (n, z))
            elif k % 7 == 0:
                # A short arc: quarter circle of radius 2 mm around a centre 2 mm to the left.
                cx, cy = x - 2.0, y
                x, y = cx, cy + 2.0
                out.write("N%d G03 X%.4f Y%.4f I-2. J0. F800.\n" % (n, x, y))
            else:
                x = round(x + rng.uniform(-1.5, 1.5), 4)
                y = round(y + rng.uniform(-1.5, 1.5), 4)
                out.write("N%d G01 X%.4f Y%.4f F%d.\n" % (n, x, y, rng.choice((600, 800, 1200))))
        out.write("M30\n%\n")

if __name__ == "__main__":
    main()
