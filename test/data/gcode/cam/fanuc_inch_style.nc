%
O2001 (POCKET AND HOLES)
(cross-check: dialect=fanuc)
(cross-check: rule=G04 P: Fanuc milliseconds , P500 = 0.5 s,, LinuxCNC seconds; dwells are not moves and are not compared)
(cross-check: rule=repeats are L on both sides here; Fanuc also takes K, which LinuxCNC does not)
N1 G20 G17 G40 G49 G80 G90
N2 T3 M06
N3 G00 G90 G54 X0.5 Y0.5 S2500 M03
N4 G43 H03 Z1.0 M08
N5 Z0.1
N6 G01 Z-0.125 F10.
N7 M98 P3100 L2
N8 G00 Z1.0
N9 G99 G81 X1.0 Y2.0 Z-0.5 R0.1 F8.
N10 G91 X0.5 L3
N11 G90 G98 G82 X3.0 Y3.0 Z-0.25 R0.1 P500
N12 G80
N13 G00 Z1.0 M09
N14 G91 G28 Z0.
N15 G28 X0. Y0.
N16 G90
N17 M30
O3100 (LAP)
N100 G91 G01 X1.5 F12.
N101 G03 X0.5 Y0.5 R0.5
N102 G01 Y1.0
N103 X-2.0
N104 Y-1.5
N105 G90
N106 M99
%
