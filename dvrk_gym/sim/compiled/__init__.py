"""Hot loops compiled with numba: the same arithmetic as the Python float paths they replace."""
