"""PyBullet plumbing: one physics client per world, the static scene (phantom, grid, receptacle), mesh files.

This is the only part of dvrk_gym that talks to PyBullet's client API directly for setup;
everything above it names bodies through :class:`~dvrk_gym.sim.physics.client.Physics`.
"""
