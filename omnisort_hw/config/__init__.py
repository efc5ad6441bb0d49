"""The cell file's sections, each parsed and validated once (`config.cell.load_cell_config`)."""
