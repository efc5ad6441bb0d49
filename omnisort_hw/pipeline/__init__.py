"""The use cases of the cell, once each: the CLI and the service are thin layers over these.

A use case is a module of this package with `run(rig, request) -> result`: the request a record
of `requests` (the one declaration of its arguments), the result a typed record with one
`reply()`, the answer every door shows unchanged. Every other module here supports them (the
rig's interface, the calibration store and gate, the capture, the verdict, the sorter).
`USE_CASES` names them; `tests/test_layout.py` checks that it names exactly the modules with a
`run`.

    intrinsics     checkerboard images -> camera model (camera.json record)
    extrinsics     one target image -> camera rotation and laser plane (system.json)
    laser_map      laser image -> points on the laser plane -> segments
    registration   floor board image -> robot base pose T_SB (robot_base record)
    locate         colour (+ laser) image -> cubes in S and B
    drift_check    laser-off image -> has the camera turned since the registration?
    sort_run       capture, locate, plan, pick and place through the device interfaces
    adopt          calibration files made elsewhere -> the cell's store, verified
    detection      a live frame -> a calibration pattern's pixels, for a screen placing it
    views          live frames with the full board -> the intrinsics' views and their coverage
    calibration_history  the store's kept versions of a calibration file, verified
    cell_geometry  system.json, [sorting] and the arm's joints -> the cell in 3D, in S

Each calls the pure core (`omnisort_hw.core`) and the devices' interfaces (`drivers.base`);
none imports the simulator.
"""

USE_CASES = (
    "intrinsics",
    "extrinsics",
    "laser_map",
    "registration",
    "locate",
    "drift_check",
    "sort_run",
    "adopt",
    "detection",
    "views",
    "calibration_history",
    "cell_geometry",
)
