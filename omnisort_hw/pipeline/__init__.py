"""The use cases of the cell, once each: the CLI and the service are thin layers over these.

    intrinsics     checkerboard images -> camera model (camera.json record)
    extrinsics     one target image -> camera rotation and laser plane (system.json)
    laser_map      laser image -> points on the laser plane -> segments
    registration   floor board image -> robot base pose T_SB (robot_base record)
    locate         colour (+ laser) image -> cubes in S and B
    sort           capture, locate, plan, pick and place through the device interfaces

Each calls the pure core (`omnisort_hw.core`) and the devices' interfaces (`drivers.base`);
none imports the simulator.
"""
