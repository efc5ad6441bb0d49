"""The cell the service runs: its devices, calibration store, drift watchdog, job journal,
device states, compute worker and single-instance lock. Import the modules directly
(`omnisort_hw.cell.cell.Cell`); this package imports nothing itself."""
