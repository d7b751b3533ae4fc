"""Policy factories for the `dvrk-gym evaluate --policy module:factory` tests."""

import numpy as np


def middle_of_the_grid(env):
    """A fixed command over the middle of the grid (an uncalibrated, open-loop policy)."""
    return lambda observation: np.array([0.040, 0.042, -0.154, 0.0], dtype=np.float32)


NOT_CALLABLE = 42


def no_policy(env):
    """A factory that makes no policy (a number): refused in one line."""
    return 42


def takes_nothing():
    """A factory that does not take the env: refused before the env is made."""
    return middle_of_the_grid(None)


def raises_type_error(env):
    """A factory with a bug of its own: its TypeError comes through as it is."""
    return len(42)


def fails_on_its_first_step(env):
    """A policy with a bug of its own that shows only once it runs (a RuntimeError)."""

    def policy(observation):
        raise RuntimeError("the policy's own bug")

    return policy
