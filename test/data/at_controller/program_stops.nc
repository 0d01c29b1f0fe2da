(The program's own stops for the at_controller_node rostest; ends at X25 Y5 Z2)
G21 G90 G17
S6000 M03
M08
G00 X5. Y5. Z2.
G01 X10. F1200
M00 (measure the part)
G01 X15.
M01 (optional stop)
G01 X20.
G04 P0.3
G01 X25.
M05 M09
M30
G01 X99. (after the end: never sent)
