"""dvrk-gym: a simulated da Vinci Research Kit for calibration and debridement research.

Importing the package registers its Gymnasium environments::

    import gymnasium as gym
    import dvrk_gym  # noqa: F401

    env = gym.make("dvrk_gym/GridTouch-v0", bias="paper", bias_seed=0)
"""

from dvrk_gym.envs import register_envs

__version__ = "0.1.0"

register_envs()
