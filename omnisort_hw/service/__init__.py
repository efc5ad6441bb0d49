"""The cell service: TCP line-delimited JSON control protocol, state machine, systemd glue.

`protocol` validates requests, `server` runs the asyncio TCP server and the job thread,
`handlers` maps each command to a call on the `omnisort_hw.cell.cell.Cell`, `systemd` speaks the
sd_notify datagram protocol, `rrd` rotates the per-run `.rrd` files, `config` reads the
`[service]`, `[storage]` and `[logging]` sections of the cell configuration.
"""
