"""The operator interface: `omnisort ui`, a NiceGUI process that is a client of the running
service (the typed client and `describe`'s schema), never of the cell's internals, so a crash
or a reload of a page cannot disturb a job (docs/operator_ui.md)."""
