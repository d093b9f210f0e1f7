%
O2001 (PLATE JOB)
(A user's job as a generic Fanuc post of Fusion 360 writes it: a 120 x 80)
(mm plate, program zero at its front-left corner on the top face; two face)
(passes at Z-1, then a contour at Z-2 with a G2 half circle round the)
(plate's right end.)
(T1 D=75. CR=0. - ZMIN=-2. - FACE MILL)
N10 G90 G94 G17 G49 G40 G80
N15 G21
N20 G28 G91 Z0.
N25 G90
(FACE)
N30 T1 M6
N35 S3600 M3
N40 G54
N45 M8
N50 G0 X-45. Y20.
N55 G43 Z15. H1
N60 G0 Z5.
N65 G1 Z-1. F300.
N70 X120. F1200.
N75 Y60.
N80 X0.
N85 G0 Z15.
M01
(CONTOUR)
N90 G0 X0. Y0.
N95 G0 Z5.
N100 G1 Z-2. F300.
N105 Y80. F1200.
N110 X100.
N115 G2 X100. Y0. R40.
N120 G1 X0.
N122 G0 Z15.
N125 M9
N130 M5
N135 G28 G91 Z0.
N140 G90
N145 M30
%
