%
O0100 (CONTOUR WITH ARCS - ROBSTIFF EXAMPLE)
(Written by hand for the robstiff example, in the form a Fanuc-style CAM post)
(writes: a 120 x 80 mm aluminium plate whose top is at Z3 in the work frame;)
(a 75 mm face mill skims 3 mm off it: along Y-20, a half circle of R20,)
(back along Y20, a quarter arc of R20 and out along X-60.)
(Program zero: the plate's centre, 3 mm below its top; the scenario's)
(toolpath.work_offset_mm places it on the robot's table.)
N10 G21 G17 G90 G40 G49 G80 G94
N20 G54
N30 S3600 M3
N40 G0 X-140. Y-20. Z20.
N50 Z5.
N60 G1 Z0. F1200.
N70 X40.
N80 G3 X40. Y20. I0. J20. (half circle, R20)
N90 G1 X-40.
N100 G2 X-60. Y40. R20. (quarter arc, clockwise)
N110 G1 Y100.
N120 G0 Z20.
N130 M5
N140 M30
%
