"""hcid: identify human-controller models from closed-loop manual-control data."""
