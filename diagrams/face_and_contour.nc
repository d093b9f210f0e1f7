%
O0200 (FACE AND CONTOUR - ROBSTIFF EXAMPLE)
(Written for the robstiff example in the form a Fanuc-style CAM post writes:)
(a 120 x 80 mm aluminium plate, program zero at its front left corner on its)
(top face. A 75 mm face mill feeds down at the middle of the left edge,)
(faces 3 mm along X, turns 90 degrees and comes back along a contour with)
(R20 arcs, overlapping the face pass, and leaves over the left edge.)
N10 G21 G17 G90 G40 G49 G80 G94
N20 G54
N30 S3600 M3
N40 G0 X0. Y40. Z50.
N50 G1 Z-3. F1200.
N60 X120.
N70 Y80.
N80 G3 X100. Y100. R20.
N90 G1 X20.
N100 G3 X0. Y80. R20.
N110 G1 Y30.
N120 G0 Z20.
N130 M5
N140 M30
%
