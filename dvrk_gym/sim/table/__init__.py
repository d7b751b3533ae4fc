"""The debridement table: fragments (seeds and raisins) and their layouts on the paper, contact grasping
with the jaws, the judge of each pick, and :class:`~dvrk_gym.sim.table.table.DebridementTable`, which owns
the fragments and the gripper beside the arm's world."""
