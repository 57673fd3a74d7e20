"""The closed loop: forcing signals, the HC model and the loop simulation (SPEC sections 1 and 2)."""
