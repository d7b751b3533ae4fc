"""The debridement table: fragments (seeds and raisins), contact grasping with the jaws, the judge of
each pick, and :class:`~dvrk_gym.sim.table.table.DebridementTable`, which owns them beside the arm's world."""
