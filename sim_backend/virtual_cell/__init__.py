"""A virtual cell: the simulated cell behind a UR controller's, a Modbus module's and an IP
camera's real protocols, so the real drivers (ur-rtde, pymodbus, OpenCV) run against it.

`omnisort sim virtual-cell --scene sorting --host 127.0.0.2` runs one (`run.main`);
`launcher.VirtualCellProcess` starts one as a subprocess for tests and demos and talks to
its control channel.
"""
