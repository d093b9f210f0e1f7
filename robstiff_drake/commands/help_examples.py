"""The example at the end of each subcommand's ``--help``."""

# One example per subcommand, shown at the end of its --help (tests/test_help.py
# parses each one, so they stay valid).
EXAMPLES = {
    "robots": "robstiff robots",
    "fk": "robstiff fk 0 -90 90 0 45 0 --robot kr240_r2900",
    "stiffness": "robstiff stiffness 0 30 20 0 40 0 --tool -10,0,350 --kx",
    "stiffness-map": "robstiff stiffness-map --robot kr240_r2900 --out kr240_map.png",
    "kg-study": "robstiff kg-study --grid 3 --json kg.json",
    "make-urdf": "robstiff make-urdf --robot irb6640 --out urdf",
    "import-urdf": "robstiff make-urdf --robot irb6640 --out urdf && robstiff import-urdf "
                   "urdf/robstiff_irb6640/urdf/irb6640.urdf --out my_irb6640.yaml --template irb6640",
    "identify": "robstiff synth stiffness campaign.csv && robstiff identify campaign.csv --plot fit.png",
    "calibrate-payload": "robstiff synth payload payload.csv && robstiff calibrate-payload payload.csv "
                         "--yaml payload.yaml",
    "synth": "robstiff synth stiffness campaign.csv --n 60 --effect lost_motion=0.05",
    "synth stiffness": "robstiff synth stiffness campaign.csv --n 60 --effect lost_motion=0.05",
    "synth payload": "robstiff synth payload payload.csv --mass-kg 120 --com-mm -10,0,250",
    "synth tracker": "robstiff synth tracker tracker.csv --n 300 --seed 1",
    "diagnose": "robstiff synth stiffness campaign.csv --effect lost_motion && robstiff diagnose campaign.csv "
                "--plots views",
    "diagnose-run": "robstiff simulate block_milling --out cut1 && robstiff diagnose-run cut1",
    "plan-poses": "robstiff plan-poses 60 --out plan.csv",
    "table2": "robstiff table2 --plot table2.png",
    "simulate": "robstiff simulate block_milling --out block --replay block.html",
    "compensate-program": "robstiff compensate-program face_and_contour --out corrected --json corrected.json "
                          "--no-simulate",
    "compensate": "robstiff compensate --egm-port 6510 --netft 192.168.1.1:49152 --model model.json "
                  "--payload payload.yaml --reference joint_reference.csv --log cut1",
    "sim-cell": "robstiff sim-cell block_milling --egm-to 127.0.0.1:6510 --netft-port 49152 "
                "--reference-out joint_reference.csv",
    "sweep": "robstiff sweep block_milling --period-ms 4,8,16 --plot sweep.png",
    "examples": "robstiff examples --copy my_cell",
    "demo": "robstiff demo --out robstiff-out",
}
