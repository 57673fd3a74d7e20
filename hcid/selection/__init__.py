"""Model selection: criteria, each record's selection as a function of W, and W's calibration
(SPEC sections 4 and 10)."""
