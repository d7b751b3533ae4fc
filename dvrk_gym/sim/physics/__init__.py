"""PyBullet plumbing: one physics client per world, the static scene (phantom, grid, receptacle), mesh files.

It connects, configures and steps the client, and builds the static scene; the layers above
get the client from :class:`~dvrk_gym.sim.physics.client.Physics` and call PyBullet on it for
their own bodies (the tool's joints in ``sim.robot.body``, the fragments, grasp contacts and
holding constraints in ``sim.table``, the env's state save and restore).
"""
