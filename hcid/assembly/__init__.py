"""A study assembled from what a user gives: the config file (read once, parsed and completed:
its forcing files read, the stages of the methods a command uses built, criteria looked up,
closed loops and study size checked) and its data set (:mod:`hcid.assembly.resolve`).

Above ``io`` (it reads through it) and the numerical layers (it builds their objects), below
the public API and the pipeline, which take what it assembles."""
