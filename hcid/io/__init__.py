"""Input and output: measured file formats, data sets and their factors, run folders, result
tables, and the resolution of a config with its data."""
